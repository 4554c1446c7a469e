//! The `sim` backend: the scene simulator as a camera, paced at the scene's fps. Frame
//! indices follow the wall clock from the first open, so an unplug window in the scene is
//! lived through in real time and the camera comes back when the scene says so.

use super::{Camera, Fault, Frame, Grab, SimTruth};
use std::time::{Duration, Instant};
use volcap_sim::{SimError, Simulator};

pub struct SimCamera {
    sim: Simulator,
    name: String,
    period: Duration,
    start: Option<Instant>,
    index: u64,
}

impl SimCamera {
    pub fn new(sim: Simulator, name: String) -> Self {
        let fps = sim.scene().camera.fps.0.max(0.1) as f64;
        Self {
            sim,
            name,
            period: Duration::from_secs_f64(1.0 / fps),
            start: None,
            index: 0,
        }
    }
}

/// Subjects covering a visible area of the frame (occluders do not count).
pub fn people_in_view(ids: &[u8], width: usize, height: usize) -> usize {
    let mut area = [0u32; 256];
    for &id in ids {
        area[id as usize] += 1;
    }
    let min_px = (width * height / 2000).max(20) as u32;
    (1..volcap_sim::sim::OCCLUDER_ID as usize)
        .filter(|&i| area[i] >= min_px)
        .count()
}

impl Camera for SimCamera {
    fn describe(&self) -> String {
        format!("sim:{}", self.name)
    }

    fn open(&mut self) -> Result<(), Fault> {
        let start = *self.start.get_or_insert_with(Instant::now);
        // Re-opening after a fault: time went on while the camera was away.
        let now = (start.elapsed().as_secs_f64() / self.period.as_secs_f64()) as u64;
        self.index = self.index.max(now);
        Ok(())
    }

    fn next(&mut self) -> Result<Grab, Fault> {
        let start = *self.start.get_or_insert_with(Instant::now);
        let due = start + self.period.mul_f64(self.index as f64);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        let index = self.index;
        self.index += 1;
        let at = Instant::now();
        match self.sim.render(index) {
            Ok(f) => {
                let people = people_in_view(&f.ids, f.width, f.height);
                Ok(Grab::Frame(Frame {
                    rgb: f.rgb,
                    width: f.width,
                    height: f.height,
                    seq: index,
                    at,
                    truth: Some(SimTruth {
                        gt: self.sim.ground_truth(),
                        people,
                    }),
                }))
            }
            Err(SimError::Unplugged { frame }) => Err(Fault::Unplugged(format!(
                "the scene unplugs the camera at frame {frame}"
            ))),
            Err(SimError::Hung { frame }) => {
                // A hung driver: the read never returns (what the watchdog is for).
                tracing::warn!("sim camera: the scene hangs the driver at frame {frame}");
                loop {
                    std::thread::sleep(Duration::from_secs(3600));
                }
            }
            Err(e) => Err(Fault::Failed(e.to_string())),
        }
    }

    fn close(&mut self) {}
}
