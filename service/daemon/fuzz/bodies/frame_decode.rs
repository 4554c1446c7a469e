//! Camera frame decoding: MJPEG frames, YUYV buffers of any size claim, MJPEG recordings.
//! Bad frames are errors (skipped and counted by the daemon), never a panic or a huge
//! allocation.
//!
//! The body of the fuzz target of the same name (fuzz_targets/), shared with the replay test
//! (service/daemon/tests/fuzz_replay.rs) that CI runs.
use volcapd::capture::{decode, file};

pub fn run(data: &[u8]) {
    let Some((&sel, rest)) = data.split_first() else {
        return;
    };
    match sel % 3 {
        0 => {
            if let Ok((rgb, w, h)) = decode::mjpeg(rest) {
                assert_eq!(rgb.len(), w * h * 3);
            }
        }
        1 => {
            if rest.len() < 4 {
                return;
            }
            let w = u16::from_le_bytes([rest[0], rest[1]]) as usize % 4096;
            let h = u16::from_le_bytes([rest[2], rest[3]]) as usize % 4096;
            if let Ok(rgb) = decode::yuyv(&rest[4..], w, h) {
                assert_eq!(rgb.len(), w * h * 3);
            }
        }
        _ => {
            // The index is bounded by the bytes, whatever they are (30 MB of `FF D8 FF`
            // once built a 286 MB index).
            let frames = file::split_mjpeg(rest, file::MAX_FRAMES).unwrap_or_default();
            assert!(frames.len() <= rest.len() / file::MIN_FRAME_BYTES + 1);
            for (a, b) in frames {
                assert!(a < b && b <= rest.len());
                let _ = decode::mjpeg(&rest[a..b]);
            }
        }
    }
}
