//! Reading input files safely: only regular files, never blocking on a FIFO or a device,
//! bounded in size. Used by the scene loader and by the daemon's file camera.

use std::io::Read;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;

/// `O_NONBLOCK`: opening a FIFO without a writer returns at once instead of waiting.
const O_NONBLOCK: i32 = 0o4000;

/// The bytes of `path` when it is a regular file (symlinks followed) of at most `limit`
/// bytes; otherwise an error that says what it is (a directory, a FIFO, a device, too
/// large). The open never blocks; the read stops at `limit + 1` bytes whatever the file
/// claims.
pub fn read_regular(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(O_NONBLOCK)
        .open(path)?;
    let meta = f.metadata()?;
    let ft = meta.file_type();
    if !ft.is_file() {
        use std::os::unix::fs::FileTypeExt;
        let what = if ft.is_dir() {
            "a directory"
        } else if ft.is_fifo() {
            "a FIFO"
        } else if ft.is_char_device() || ft.is_block_device() {
            "a device"
        } else if ft.is_socket() {
            "a socket"
        } else {
            "not a regular file"
        };
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{what}, not a regular file"),
        ));
    }
    if meta.len() > limit {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{} bytes is more than the {limit} accepted", meta.len()),
        ));
    }
    let mut out = Vec::with_capacity(meta.len() as usize);
    f.take(limit + 1).read_to_end(&mut out)?;
    if out.len() as u64 > limit {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("grew past the {limit} bytes accepted while being read"),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_bounded_regular_files_are_read() {
        let d = std::env::temp_dir().join(format!("volcap-files-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let f = d.join("a.toml");
        std::fs::write(&f, b"hello").unwrap();
        assert_eq!(read_regular(&f, 5).unwrap(), b"hello");
        let e = read_regular(&f, 4).unwrap_err().to_string();
        assert!(e.contains("more than the 4"), "{e}");
        let e = read_regular(&d, 100).unwrap_err().to_string();
        assert!(e.contains("directory"), "{e}");
        let e = read_regular(Path::new("/dev/zero"), 100)
            .unwrap_err()
            .to_string();
        assert!(e.contains("device"), "{e}");
        let fifo = d.join("pipe");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let t = std::time::Instant::now();
            let e = read_regular(&fifo, 100).unwrap_err().to_string();
            assert!(e.contains("FIFO"), "{e}");
            assert!(
                t.elapsed() < std::time::Duration::from_secs(1),
                "a FIFO must not block"
            );
        }
        std::fs::remove_dir_all(&d).ok();
    }
}
