//! The fuzz targets' bodies (service/daemon/fuzz/bodies/, the same code `cargo fuzz` runs) on
//! inputs made without the fuzzer: seeds (the committed board configs and scene files, a JPEG
//! and YUYV frames, HTTP requests), every file of `fuzz/corpus/<target>/` and
//! `fuzz/artifacts/<target>/` that exists (what a fuzzing run by hand found: crashes stay
//! regression inputs), and a fixed number of seeded mutations of the seeds (bytes flipped,
//! cut, repeated, spliced with another seed, tokens that parsers trip on inserted).
//!
//! This is what CI runs of the fuzz targets: their assertions (an error names the file, no
//! panic, no huge allocation, no foreign host let through) on a few thousand inputs each, in
//! seconds and without cargo-fuzz's instrumented build of every dependency (ten minutes on two
//! cores). Coverage-guided fuzzing stays a command run by hand (README, "Fuzzing").
use std::path::{Path, PathBuf};

#[path = "../fuzz/bodies/config_file.rs"]
mod config_file;
#[path = "../fuzz/bodies/config_parse.rs"]
mod config_parse;
#[path = "../fuzz/bodies/frame_decode.rs"]
mod frame_decode;
#[path = "../fuzz/bodies/host_check.rs"]
mod host_check;
#[path = "../fuzz/bodies/http_request.rs"]
mod http_request;
#[path = "../fuzz/bodies/scene_parse.rs"]
mod scene_parse;

/// Mutations per target (a multiple of the seed count is run).
const MUTATIONS: usize = 3000;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Every file of `dir` with the given extension (none: every file), sorted.
fn files(dir: &Path, ext: Option<&str>) -> Vec<Vec<u8>> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    paths.retain(|p| p.is_file() && ext.is_none_or(|x| p.extension().is_some_and(|e| e == x)));
    paths.sort();
    paths
        .iter()
        .map(|p| std::fs::read(p).unwrap_or_else(|e| panic!("{}: {e}", p.display())))
        .collect()
}

/// The corpus and crash reproducers a fuzzing run by hand left for `target`.
fn found(target: &str) -> Vec<Vec<u8>> {
    let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let mut v = files(&fuzz.join("corpus").join(target), None);
    v.extend(files(&fuzz.join("artifacts").join(target), None));
    v
}

/// splitmix64: a seeded, reproducible source of mutations.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
}

/// Text that parsers of TOML, numbers, URLs and headers trip on.
const TOKENS: &[&[u8]] = &[
    b"=",
    b"\"",
    b"'",
    b"[",
    b"]",
    b"[[",
    b"{",
    b"}",
    b"\n",
    b"\r\n",
    b"#",
    b",",
    b".",
    b"-1",
    b"0",
    b"1e309",
    b"-0.0",
    b"nan",
    b"inf",
    b"99999999999999999999",
    b"4294967296",
    b"\xff\xfe",
    b"\0",
    b"%",
    b"%00",
    b"%zz",
    b"?",
    b"&",
    b"/..",
    b"//",
    b":",
    b"@",
    b"http://",
    b"volcap.lan",
    b"[::1]",
    b"\xc3\x28",
    b"\xe2\x82",
    b"true",
    b"\"\"\"",
    b"\xff\xd8\xff",
    b"\xff\xd9",
    b"\xff\xc0",
];

fn mutate(rng: &mut Rng, seeds: &[Vec<u8>]) -> Vec<u8> {
    let mut v = seeds[rng.below(seeds.len())].clone();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(v.len() + 1);
        match rng.below(7) {
            0 if !v.is_empty() => {
                let i = rng.below(v.len());
                v[i] ^= 1 << rng.below(8);
            }
            1 if !v.is_empty() => {
                let i = rng.below(v.len());
                v[i] = rng.next() as u8;
            }
            2 => {
                let end = (at + 1 + rng.below(64)).min(v.len());
                v.drain(at.min(end)..end);
            }
            3 => v.truncate(at),
            4 => {
                let end = (at + 1 + rng.below(32)).min(v.len());
                let piece = v[at.min(end)..end].to_vec();
                for _ in 0..1 + rng.below(8) {
                    v.splice(at..at, piece.iter().copied());
                }
            }
            5 => {
                let other = &seeds[rng.below(seeds.len())];
                let from = rng.below(other.len() + 1);
                let end = (from + rng.below(256)).min(other.len());
                v.splice(at..at, other[from..end].iter().copied());
            }
            _ => {
                let t = TOKENS[rng.below(TOKENS.len())];
                v.splice(at..at, t.iter().copied());
            }
        }
    }
    v
}

/// Runs `body` on every seed, every found input and `MUTATIONS` mutations; a panic names the
/// input (as an escaped string) so that it can be kept as a corpus file.
fn replay(target: &str, seeds: Vec<Vec<u8>>, body: fn(&[u8])) {
    assert!(!seeds.is_empty(), "{target}: no seeds");
    let mut rng = Rng(target
        .bytes()
        .fold(0x5EED, |h, b| h.rotate_left(8) ^ b as u64));
    let mut inputs = seeds.clone();
    inputs.extend(found(target));
    inputs.extend((0..MUTATIONS).map(|_| mutate(&mut rng, &seeds)));
    for data in &inputs {
        if let Err(e) = std::panic::catch_unwind(|| body(data)) {
            let msg = e
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()));
            panic!(
                "{target} failed ({}) on input {:?}",
                msg.unwrap_or_default(),
                String::from_utf8_lossy(data)
            );
        }
    }
}

/// Text seeds as bytes.
fn texts(seeds: &[&str]) -> Vec<Vec<u8>> {
    seeds.iter().map(|s| s.as_bytes().to_vec()).collect()
}

fn board_configs() -> Vec<Vec<u8>> {
    let v = files(&repo().join("board-config"), Some("toml"));
    assert!(v.len() >= 4, "board-config/ has the example configs");
    v
}

#[test]
fn config_parse_on_board_configs_and_their_mutations() {
    replay("config_parse", board_configs(), config_parse::run);
}

#[test]
fn config_file_on_both_sides_of_the_size_limit() {
    // The first byte is the body's pad selector: 0 leaves the file as it is, 251..=255 pads it
    // to the limit - 2 ..= the limit + 2.
    let mut seeds = Vec::new();
    for c in board_configs() {
        for pad in [0u8, 251, 253, 255] {
            let mut v = vec![pad];
            v.extend_from_slice(&c);
            seeds.push(v);
        }
    }
    replay("config_file", seeds, config_file::run);
}

#[test]
fn scene_parse_on_the_test_scenes_and_their_mutations() {
    let seeds = files(&repo().join("tests/scenes"), Some("toml"));
    assert!(seeds.len() >= 10, "tests/scenes has the scene files");
    replay("scene_parse", seeds, scene_parse::run);
}

#[test]
fn frame_decode_on_jpegs_yuyv_and_recordings() {
    // A small JPEG (a gradient: cheap to decode thousands of times), two of them back to back
    // as a recording, and YUYV buffers with exact, short and long sizes.
    let img = image::RgbImage::from_fn(40, 30, |x, y| {
        image::Rgb([(x * 6) as u8, (y * 8) as u8, 128])
    });
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 80)
        .encode_image(&img)
        .expect("encode a JPEG");
    let mut seeds = vec![
        [&[0u8][..], &jpeg].concat(),
        [&[2u8][..], &jpeg, &jpeg].concat(),
    ];
    for (w, h, len) in [
        (8u16, 4u16, 64usize),
        (8, 4, 10),
        (640, 480, 100),
        (2, 2, 8),
    ] {
        let mut v = vec![1u8];
        v.extend_from_slice(&w.to_le_bytes());
        v.extend_from_slice(&h.to_le_bytes());
        v.extend((0..len).map(|i| (i * 37) as u8));
        seeds.push(v);
    }
    replay("frame_decode", seeds, frame_decode::run);
}

#[test]
fn host_check_on_request_heads() {
    let seeds = texts(&[
        "1 /\nvolcap.lan",
        "1 /state\nvolcap.lan:8080",
        "0 /",
        "1 http://volcap.lan/state\nvolcap.lan",
        "1 http://evil.example/\nvolcap.lan",
        "1 /\nvolcap.lan\nvolcap.lan",
        "1 /\n127.0.0.1:8080",
        "1 /\n[::1]:8080",
        "1 volcap.lan:80",
        "1 /\nVOLCAP.LAN.",
    ]);
    replay("host_check", seeds, host_check::run);
}

#[test]
fn http_request_on_every_route() {
    let seeds = texts(&[
        "GET\n/\n",
        "GET\n/state\nhost: 127.0.0.1",
        "GET\n/metrics\n",
        "GET\n/snapshot.jpg\n",
        "GET\n/snapshot.png?bg=0.1,0.2,0.3\n",
        "GET\n/mesh.glb\nauthorization: Bearer fuzz-token-123",
        "HEAD\n/mesh.glb\n",
        "POST\n/view?yaw=30&pitch=-10&zoom=1.5\nauthorization: Bearer fuzz-token-123",
        "POST\n/view?reset=1\nauthorization: Bearer wrong",
        "GET\n/stream.mjpg?fps=5\n",
        "0.5,0.5,0.5",
        "DELETE\n/state\n",
    ]);
    replay("http_request", seeds, http_request::run);
}
