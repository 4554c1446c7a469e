//! The `replay` camera: frames held in memory, delivered in a loop at a fixed rate. It costs
//! no decoding and no simulation on the capture thread, so a benchmark of the pipeline
//! measures the pipeline (`volcap bench pipeline` renders a scene's frames once, then replays
//! them faster than any stage can keep up with).

use super::{Camera, Fault, Frame, Grab};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// One RGB8 frame, row-major.
#[derive(Clone)]
pub struct Still {
    pub rgb: Arc<Vec<u8>>,
    pub width: usize,
    pub height: usize,
}

pub struct ReplayCamera {
    frames: Arc<Vec<Still>>,
    period: Duration,
    next_due: Option<Instant>,
    seq: u64,
}

impl ReplayCamera {
    /// `frames` looped at `fps` (clamped to 0.1..=1000). An empty list is a camera with no
    /// device (the supervisor reports it).
    pub fn new(frames: Arc<Vec<Still>>, fps: f64) -> Self {
        let fps = if fps.is_finite() {
            fps.clamp(0.1, 1000.0)
        } else {
            30.0
        };
        Self {
            frames,
            period: Duration::from_secs_f64(1.0 / fps),
            next_due: None,
            seq: 0,
        }
    }
}

impl Camera for ReplayCamera {
    fn describe(&self) -> String {
        format!("replay:{} frames", self.frames.len())
    }

    fn open(&mut self) -> Result<(), Fault> {
        if self.frames.is_empty() {
            return Err(Fault::NoDevice("replay: no frames".into()));
        }
        Ok(())
    }

    fn next(&mut self) -> Result<Grab, Fault> {
        let Some(f) = self
            .frames
            .get(self.seq as usize % self.frames.len().max(1))
        else {
            return Err(Fault::NoDevice("replay: no frames".into()));
        };
        let due = *self.next_due.get_or_insert_with(Instant::now);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        // A late frame is not made up for: the next one is due a period after this one.
        self.next_due = Some(due.max(now) + self.period);
        self.seq += 1;
        Ok(Grab::Frame(Frame {
            rgb: f.rgb.as_ref().clone(),
            width: f.width,
            height: f.height,
            seq: self.seq,
            at: Instant::now(),
            truth: None,
        }))
    }

    fn close(&mut self) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replays_in_order_at_its_rate_and_loops() {
        let still = |v: u8| Still {
            rgb: Arc::new(vec![v; 12]),
            width: 2,
            height: 2,
        };
        let mut cam = ReplayCamera::new(Arc::new(vec![still(1), still(2)]), 200.0);
        cam.open().unwrap();
        let t = Instant::now();
        let got: Vec<u8> = (0..5)
            .map(|_| match cam.next().unwrap() {
                Grab::Frame(f) => f.rgb[0],
                Grab::Skipped(_) => 0,
            })
            .collect();
        assert_eq!(got, [1, 2, 1, 2, 1]);
        // Four periods of 5 ms at least between the first and the fifth frame.
        assert!(t.elapsed() >= Duration::from_millis(19));
        let mut empty = ReplayCamera::new(Arc::new(Vec::new()), 30.0);
        assert!(empty.open().is_err());
        assert!(empty.next().is_err());
    }
}
