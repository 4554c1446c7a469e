//! The `sim` backend: the scene simulator as a camera, paced at the scene's fps. Frame
//! indices follow the wall clock from the first open, so an unplug window in the scene is
//! lived through in real time and the camera comes back when the scene says so. The ground
//! truth rides with each frame only where the pipeline renders it (oracle mode): copying the
//! posed meshes every frame is wasted work for the model and camera modes.

use super::{Camera, Fault, Frame, Grab, SimTruth};
use std::time::{Duration, Instant};
use volcap_sim::{SimError, Simulator};

pub struct SimCamera {
    sim: Simulator,
    name: String,
    period: Duration,
    start: Option<Instant>,
    index: u64,
    with_truth: bool,
}

impl SimCamera {
    /// `with_truth`: attach the ground truth to every frame (the oracle field mode needs it).
    pub fn new(sim: Simulator, name: String, with_truth: bool) -> Self {
        let fps = sim.scene().camera.fps.0.max(0.1) as f64;
        Self {
            sim,
            name,
            period: Duration::from_secs_f64(1.0 / fps),
            start: None,
            index: 0,
            with_truth,
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
                let truth = self.with_truth.then(|| SimTruth {
                    gt: self.sim.ground_truth(),
                    people: people_in_view(&f.ids, f.width, f.height),
                });
                Ok(Grab::Frame(Frame {
                    rgb: f.rgb,
                    width: f.width,
                    height: f.height,
                    seq: index,
                    at,
                    truth,
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    fn camera(with_truth: bool) -> SimCamera {
        let text = "[camera]\nwidth = 64\nheight = 64\nfps = 1000\n[[subject]]\nid = \"a\"\n\
                    motion = { kind = \"static\", pose = \"rest\" }\n";
        let scene = volcap_sim::Scene::parse(text, std::path::Path::new("t.toml")).unwrap();
        let assets = Arc::new(volcap_sim::HumanAssets::embedded().unwrap());
        SimCamera::new(
            Simulator::new(scene, assets).unwrap(),
            "t".into(),
            with_truth,
        )
    }

    /// The truth rides with the frames only when asked for (oracle mode); the frames are the
    /// same either way.
    #[test]
    fn frames_carry_the_truth_only_when_asked() {
        let grab = |with_truth| {
            let mut cam = camera(with_truth);
            cam.open().unwrap();
            match cam.next() {
                Ok(Grab::Frame(f)) => f,
                _ => panic!("no frame"),
            }
        };
        let (with, without) = (grab(true), grab(false));
        let truth = with.truth.as_ref().expect("truth attached");
        assert_eq!(truth.people, 1);
        assert_eq!(truth.gt.camera.width, 64);
        assert!(without.truth.is_none());
        assert_eq!(with.rgb, without.rgb);
    }
}
