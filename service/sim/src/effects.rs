//! Effect stages. The simulator builds one stage per declared effect and runs only those;
//! a scene without an effect computes nothing for it. Stages run in a fixed physical order
//! whatever the declaration order: camera (shake) -> geometry (occluder) -> optics
//! (vignetting) -> motion blur -> rolling shutter -> exposure and white balance -> sensor
//! noise -> JPEG. `unplug` decides whether a frame exists at all.

use crate::camera::Camera;
use crate::scene::EffectSpec;
use glam::Vec3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use volcap_engine::render::rgb8;

/// An image in linear [0, 1] RGB, row-major.
pub struct Image<'a> {
    pub width: usize,
    pub height: usize,
    pub rgb: &'a mut Vec<[f32; 3]>,
}

/// A world-space box to draw (the occluder).
#[derive(Debug, Clone, Copy)]
pub struct BoxShape {
    pub center: Vec3,
    pub size: Vec3,
    pub color: [f32; 3],
}

/// What a stage may touch.
pub enum Hook<'a, 'b> {
    Camera(&'a mut Camera),
    Geometry(&'a mut Vec<BoxShape>),
    Image(&'a mut Image<'b>, &'a mut FrameMeta),
}

/// Per-frame facts stages report (e.g. the JPEG size).
#[derive(Debug, Clone, Default)]
pub struct FrameMeta {
    pub jpeg_bytes: Option<usize>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Phase {
    Source,
    Camera,
    Geometry,
    Optics,
    Blur,
    Shutter,
    Exposure,
    Noise,
    Codec,
}

/// One effect stage.
pub trait Stage: Send {
    fn kind(&self) -> &'static str;
    fn phase(&self) -> Phase;
    /// Apply to frame `index` at time `t` seconds.
    fn apply(&mut self, index: u64, t: f64, hook: Hook);
    /// `Source` stages: whether frame `index` exists.
    fn frame_exists(&self, _index: u64) -> bool {
        true
    }
    /// `Source` stages: whether reading frame `index` never returns.
    fn frame_hangs(&self, _index: u64) -> bool {
        false
    }
}

/// Build the stages for exactly the declared effects, in physical order.
pub fn build(specs: &[EffectSpec]) -> Vec<Box<dyn Stage>> {
    let mut v: Vec<Box<dyn Stage>> = specs.iter().map(stage_for).collect();
    v.sort_by_key(|s| s.phase());
    v
}

fn stage_for(s: &EffectSpec) -> Box<dyn Stage> {
    match *s {
        EffectSpec::SensorNoise { shot, read, seed } => Box::new(SensorNoise {
            shot: shot.0,
            read: read.0,
            seed,
        }),
        EffectSpec::MotionBlur {
            length_px,
            angle_deg,
        } => Box::new(MotionBlur::new(length_px.0, angle_deg.0)),
        EffectSpec::ExposureDrift {
            amplitude,
            period_s,
        } => Box::new(Drift {
            amp: amplitude.0,
            period: period_s.0,
            white_balance: false,
        }),
        EffectSpec::WhiteBalanceDrift {
            amplitude,
            period_s,
        } => Box::new(Drift {
            amp: amplitude.0,
            period: period_s.0,
            white_balance: true,
        }),
        EffectSpec::Jpeg { quality } => Box::new(Jpeg { quality: quality.0 }),
        EffectSpec::RollingShutter { skew_px } => Box::new(RollingShutter { skew: skew_px.0 }),
        EffectSpec::Vignetting { strength } => Box::new(Vignetting {
            strength: strength.0,
        }),
        EffectSpec::Occluder {
            center,
            size,
            color,
        } => Box::new(Occluder(BoxShape {
            center: Vec3::new(center[0].0, center[1].0, center[2].0),
            size: Vec3::new(size[0].0, size[1].0, size[2].0),
            color: color.map(|c| c.0),
        })),
        EffectSpec::CameraShake {
            amplitude_deg,
            seed,
        } => Box::new(CameraShake::new(amplitude_deg.0, seed)),
        EffectSpec::Unplug {
            at_frame,
            for_frames,
        } => Box::new(Unplug {
            at: at_frame,
            until: for_frames.map(|n| at_frame.saturating_add(n)),
        }),
        EffectSpec::Hang { at_frame } => Box::new(Hang { at: at_frame }),
    }
}

fn frame_rng(seed: u64, index: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed ^ index.wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// Standard normal by Box-Muller.
fn normal(r: &mut ChaCha8Rng) -> f32 {
    let u1: f32 = r.random_range(f32::MIN_POSITIVE..1.0);
    let u2: f32 = r.random();
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

struct SensorNoise {
    shot: f32,
    read: f32,
    seed: u64,
}

impl Stage for SensorNoise {
    fn kind(&self) -> &'static str {
        "sensor-noise"
    }
    fn phase(&self) -> Phase {
        Phase::Noise
    }
    fn apply(&mut self, index: u64, _t: f64, hook: Hook) {
        let Hook::Image(img, _) = hook else { return };
        let mut r = frame_rng(self.seed, index);
        for px in img.rgb.iter_mut() {
            for c in px.iter_mut() {
                let sd = (self.shot * self.shot * *c + self.read * self.read).sqrt();
                *c = (*c + sd * normal(&mut r)).clamp(0.0, 1.0);
            }
        }
    }
}

/// Bilinear sample with clamp to the edge.
fn sample(rgb: &[[f32; 3]], w: usize, h: usize, x: f32, y: f32) -> [f32; 3] {
    let x = x.clamp(0.0, (w - 1) as f32);
    let y = y.clamp(0.0, (h - 1) as f32);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let p = |x: usize, y: usize| Vec3::from_array(rgb[y * w + x]);
    let top = p(x0, y0).lerp(p(x1, y0), fx);
    let bot = p(x0, y1).lerp(p(x1, y1), fx);
    top.lerp(bot, fy).to_array()
}

pub struct MotionBlur {
    length: f32,
    dir: (f32, f32),
    scratch: Vec<[f32; 3]>,
}

impl MotionBlur {
    fn new(length: f32, angle_deg: f32) -> Self {
        let a = angle_deg.to_radians();
        Self {
            length: length.min(crate::scene::MAX_BLUR_PX),
            dir: (a.cos(), a.sin()),
            scratch: Vec::new(),
        }
    }
}

impl Stage for MotionBlur {
    fn kind(&self) -> &'static str {
        "motion-blur"
    }
    fn phase(&self) -> Phase {
        Phase::Blur
    }
    fn apply(&mut self, _index: u64, _t: f64, hook: Hook) {
        let Hook::Image(img, _) = hook else { return };
        let (w, h) = (img.width, img.height);
        let n = (self.length.ceil() as usize).max(1) + 1;
        self.scratch.clone_from(img.rgb);
        for y in 0..h {
            for x in 0..w {
                let mut acc = Vec3::ZERO;
                for k in 0..n {
                    let t = (k as f32 / (n - 1) as f32 - 0.5) * self.length;
                    acc += Vec3::from_array(sample(
                        &self.scratch,
                        w,
                        h,
                        x as f32 + t * self.dir.0,
                        y as f32 + t * self.dir.1,
                    ));
                }
                img.rgb[y * w + x] = (acc / n as f32).to_array();
            }
        }
    }
}

struct Drift {
    amp: f32,
    period: f32,
    white_balance: bool,
}

impl Stage for Drift {
    fn kind(&self) -> &'static str {
        if self.white_balance {
            "white-balance-drift"
        } else {
            "exposure-drift"
        }
    }
    fn phase(&self) -> Phase {
        Phase::Exposure
    }
    fn apply(&mut self, _index: u64, t: f64, hook: Hook) {
        let Hook::Image(img, _) = hook else { return };
        let s = self.amp * (std::f64::consts::TAU * t / self.period as f64).sin() as f32;
        let gain = if self.white_balance {
            [1.0 + s, 1.0, 1.0 - s]
        } else {
            [1.0 + s; 3]
        };
        for px in img.rgb.iter_mut() {
            for c in 0..3 {
                px[c] = (px[c] * gain[c]).clamp(0.0, 1.0);
            }
        }
    }
}

struct Jpeg {
    quality: u8,
}

impl Stage for Jpeg {
    fn kind(&self) -> &'static str {
        "jpeg"
    }
    fn phase(&self) -> Phase {
        Phase::Codec
    }
    fn apply(&mut self, _index: u64, _t: f64, hook: Hook) {
        let Hook::Image(img, meta) = hook else { return };
        let bytes = rgb8(img.rgb);
        let mut out = Vec::new();
        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, self.quality)
            .encode(
                &bytes,
                img.width as u32,
                img.height as u32,
                image::ExtendedColorType::Rgb8,
            );
        if enc.is_err() {
            return; // in-memory encoding of a valid buffer does not fail; leave the frame as is
        }
        meta.jpeg_bytes = Some(out.len());
        if let Ok(dec) = image::load_from_memory_with_format(&out, image::ImageFormat::Jpeg) {
            for (px, d) in img.rgb.iter_mut().zip(dec.to_rgb8().pixels()) {
                *px = d.0.map(|v| v as f32 / 255.0);
            }
        }
    }
}

struct RollingShutter {
    skew: f32,
}

impl Stage for RollingShutter {
    fn kind(&self) -> &'static str {
        "rolling-shutter"
    }
    fn phase(&self) -> Phase {
        Phase::Shutter
    }
    fn apply(&mut self, _index: u64, _t: f64, hook: Hook) {
        let Hook::Image(img, _) = hook else { return };
        let (w, h) = (img.width, img.height);
        let src = img.rgb.clone();
        for y in 0..h {
            // Row y was read later: the scene had moved by `shift` pixels.
            let shift = self.skew * y as f32 / (h - 1).max(1) as f32;
            for x in 0..w {
                img.rgb[y * w + x] = sample(&src, w, h, x as f32 - shift, y as f32);
            }
        }
    }
}

struct Vignetting {
    strength: f32,
}

impl Stage for Vignetting {
    fn kind(&self) -> &'static str {
        "vignetting"
    }
    fn phase(&self) -> Phase {
        Phase::Optics
    }
    fn apply(&mut self, _index: u64, _t: f64, hook: Hook) {
        let Hook::Image(img, _) = hook else { return };
        let (w, h) = (img.width, img.height);
        let (cx, cy) = (0.5 * (w - 1) as f32, 0.5 * (h - 1) as f32);
        let r2max = cx * cx + cy * cy;
        for y in 0..h {
            for x in 0..w {
                let r2 = ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)) / r2max;
                let g = 1.0 - self.strength * r2;
                for c in &mut img.rgb[y * w + x] {
                    *c *= g;
                }
            }
        }
    }
}

struct Occluder(BoxShape);

impl Stage for Occluder {
    fn kind(&self) -> &'static str {
        "occluder"
    }
    fn phase(&self) -> Phase {
        Phase::Geometry
    }
    fn apply(&mut self, _index: u64, _t: f64, hook: Hook) {
        if let Hook::Geometry(list) = hook {
            list.push(self.0);
        }
    }
}

struct CameraShake {
    amp: f32,
    phases: [f32; 4],
}

impl CameraShake {
    fn new(amp: f32, seed: u64) -> Self {
        let mut r = ChaCha8Rng::seed_from_u64(seed);
        Self {
            amp,
            phases: [r.random(), r.random(), r.random(), r.random()],
        }
    }
}

impl Stage for CameraShake {
    fn kind(&self) -> &'static str {
        "camera-shake"
    }
    fn phase(&self) -> Phase {
        Phase::Camera
    }
    fn apply(&mut self, _index: u64, t: f64, hook: Hook) {
        let Hook::Camera(cam) = hook else { return };
        let tau = std::f32::consts::TAU;
        let t = t as f32;
        let p = self.phases;
        // Smooth hand shake: two incommensurate frequencies per axis.
        let yaw = self.amp
            * 0.7
            * ((tau * (1.3 * t + p[0])).sin() + 0.5 * (tau * (3.7 * t + p[1])).sin());
        let pitch = self.amp
            * 0.7
            * ((tau * (1.1 * t + p[2])).sin() + 0.5 * (tau * (4.3 * t + p[3])).sin());
        let off = cam.eye - cam.target;
        let q = glam::Quat::from_rotation_y(yaw.to_radians())
            * glam::Quat::from_axis_angle(
                off.cross(Vec3::Y).normalize_or(Vec3::X),
                pitch.to_radians(),
            );
        cam.eye = cam.target + q * off;
    }
}

struct Unplug {
    at: u64,
    until: Option<u64>,
}

impl Stage for Unplug {
    fn kind(&self) -> &'static str {
        "unplug"
    }
    fn phase(&self) -> Phase {
        Phase::Source
    }
    fn apply(&mut self, _index: u64, _t: f64, _hook: Hook) {}
    fn frame_exists(&self, index: u64) -> bool {
        index < self.at || self.until.is_some_and(|u| index >= u)
    }
}

struct Hang {
    at: u64,
}

impl Stage for Hang {
    fn kind(&self) -> &'static str {
        "hang"
    }
    fn phase(&self) -> Phase {
        Phase::Source
    }
    fn apply(&mut self, _index: u64, _t: f64, _hook: Hook) {}
    fn frame_hangs(&self, index: u64) -> bool {
        index >= self.at
    }
}
