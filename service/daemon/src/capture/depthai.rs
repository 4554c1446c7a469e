//! The `depthai` backend: an OAK camera over the DepthAI-Core library (the `depthai` crate).
//! Build with `--features depthai` on a machine that can build DepthAI-Core; CI type-checks
//! this file with the crate's no-native `docs` build (`--features depthai-typecheck`), which
//! cannot link. OAK cameras in UVC mode need none of this: they are V4L2 devices, use the
//! `v4l2` backend.
//!
//! The DepthAI handles are not `Send`, so this camera is built on the capture thread.

use super::{Camera, DRIVER_TIMEOUT, Fault, Frame, Grab, Skip};
use depthai::camera::{CameraNode, CameraOutputConfig, OutputQueue};
use depthai::common::{CameraBoardSocket, ImageFrameType, ResizeMode};
use depthai::device::Device;
use depthai::pipeline::Pipeline;
use std::time::Instant;

pub struct DepthaiCamera {
    size: (u32, u32),
    fps: f32,
    running: Option<(Device, Pipeline, OutputQueue)>,
    seq: u64,
}

impl DepthaiCamera {
    pub fn new(size: (u32, u32), fps: f32) -> Self {
        Self {
            size,
            fps,
            running: None,
            seq: 0,
        }
    }
}

impl Camera for DepthaiCamera {
    fn describe(&self) -> String {
        format!("depthai:CAM_A {}x{}@{}", self.size.0, self.size.1, self.fps)
    }

    fn open(&mut self) -> Result<(), Fault> {
        let device = Device::new().map_err(|e| Fault::NoDevice(format!("DepthAI: {e}")))?;
        let pipeline = Pipeline::new()
            .with_device(&device)
            .build()
            .map_err(|e| Fault::Failed(format!("DepthAI pipeline: {e}")))?;
        let cam = pipeline
            .create_with::<CameraNode, _>(CameraBoardSocket::CamA)
            .map_err(|e| Fault::Failed(format!("DepthAI camera node: {e}")))?;
        let out = cam
            .request_output(CameraOutputConfig {
                size: self.size,
                frame_type: Some(ImageFrameType::RGB888i),
                resize_mode: ResizeMode::Crop,
                fps: Some(self.fps),
                enable_undistortion: None,
            })
            .map_err(|e| Fault::FormatRefused {
                wanted: format!("RGB888i {}x{}@{}", self.size.0, self.size.1, self.fps),
                offered: e.to_string(),
            })?;
        let queue = out
            .create_queue(2, false)
            .map_err(|e| Fault::Failed(format!("DepthAI queue: {e}")))?;
        pipeline
            .start()
            .map_err(|e| Fault::Failed(format!("DepthAI start: {e}")))?;
        self.running = Some((device, pipeline, queue));
        Ok(())
    }

    fn next(&mut self) -> Result<Grab, Fault> {
        let Some((device, _, queue)) = &self.running else {
            return Err(Fault::Failed("read before open".into()));
        };
        let frame = match queue.blocking_next(Some(DRIVER_TIMEOUT)) {
            Ok(Some(f)) => f,
            Ok(None) if device.is_connected() => {
                return Err(Fault::NoSignal(DRIVER_TIMEOUT.as_millis() as u64));
            }
            Ok(None) => return Err(Fault::Unplugged("DepthAI device disconnected".into())),
            Err(e) => return Err(Fault::Unplugged(format!("DepthAI: {e}"))),
        };
        let at = Instant::now();
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        let rgb = frame.bytes();
        if rgb.len() < w * h * 3 || w == 0 || h == 0 {
            return Ok(Grab::Skipped(Skip::Truncated(format!(
                "RGB888i {w}x{h} needs {} bytes, got {}",
                w * h * 3,
                rgb.len()
            ))));
        }
        self.seq += 1;
        Ok(Grab::Frame(Frame {
            rgb: rgb[..w * h * 3].to_vec(),
            width: w,
            height: h,
            seq: self.seq - 1,
            at,
            truth: None,
        }))
    }

    fn close(&mut self) {
        if let Some((device, _, _)) = self.running.take() {
            let _ = device.close();
        }
    }
}
