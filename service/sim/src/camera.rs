//! Cameras: weak-perspective (orthographic with a scale, like the paper's training renders)
//! or pinhole with intrinsics. World frame: metres, y up.
//!
//! Pixel `(i, j)` has its centre at `(i, j)`; the render view's NDC follows the engine's
//! convention (`volcap_engine::grid`): `x = -1 + 2 i / (W - 1)` right, `y = -1 + 2 j / (H - 1)`
//! down, `z` linear in depth between `near` (z = +1) and `far` (z = -1), larger z nearer.

use glam::Vec3;
use serde::Serialize;

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "model", rename_all = "kebab-case")]
pub enum Projection {
    /// Orthographic: `height_m` metres of the world span the image height.
    WeakPerspective { height_m: f32 },
    /// Pinhole: focal lengths and principal point in pixels.
    Pinhole { fx: f32, fy: f32, cx: f32, cy: f32 },
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Camera {
    pub width: usize,
    pub height: usize,
    pub eye: Vec3,
    pub target: Vec3,
    pub projection: Projection,
    pub near: f32,
    pub far: f32,
}

/// A point in screen space: pixel coordinates and depth along the view direction.
#[derive(Debug, Clone, Copy)]
pub struct Screen {
    pub px: f32,
    pub py: f32,
    pub depth: f32,
}

/// A camera with its view basis computed once, for projecting many points (rasterizer
/// vertices, oracle queries); [`Camera`]'s own methods build one per call.
#[derive(Debug, Clone, Copy)]
pub struct Projector {
    cam: Camera,
    r: Vec3,
    u: Vec3,
    f: Vec3,
    cx: f32,
    cy: f32,
}

impl Camera {
    pub fn projector(&self) -> Projector {
        let f = (self.target - self.eye).normalize_or(Vec3::NEG_Z);
        let up = if f.cross(Vec3::Y).length_squared() < 1e-8 {
            Vec3::Z
        } else {
            Vec3::Y
        };
        let r = f.cross(up).normalize();
        let u = r.cross(f);
        let (cx, cy) = match self.projection {
            Projection::Pinhole { cx, cy, .. } => (cx, cy),
            Projection::WeakPerspective { .. } => (
                0.5 * (self.width as f32 - 1.0),
                0.5 * (self.height as f32 - 1.0),
            ),
        };
        Projector {
            cam: *self,
            r,
            u,
            f,
            cx,
            cy,
        }
    }

    pub fn to_screen(&self, p: Vec3) -> Screen {
        self.projector().to_screen(p)
    }

    /// True for projections where screen-space interpolation needs `1/depth` weighting.
    pub fn is_perspective(&self) -> bool {
        matches!(self.projection, Projection::Pinhole { .. })
    }

    /// Render-view NDC of a world point.
    pub fn world_to_ndc(&self, p: Vec3) -> Vec3 {
        self.projector().world_to_ndc(p)
    }

    /// World point of a render-view NDC position (inverse of [`Self::world_to_ndc`]).
    pub fn ndc_to_world(&self, n: Vec3) -> Vec3 {
        self.projector().ndc_to_world(n)
    }
}

impl Projector {
    /// The unit view direction (from the eye towards the target).
    pub fn forward(&self) -> Vec3 {
        self.f
    }

    pub fn to_screen(&self, p: Vec3) -> Screen {
        let d = p - self.cam.eye;
        let (xr, yu, depth) = (d.dot(self.r), d.dot(self.u), d.dot(self.f));
        match self.cam.projection {
            Projection::Pinhole { fx, fy, .. } => {
                let z = depth.max(1e-6);
                Screen {
                    px: self.cx + fx * xr / z,
                    py: self.cy - fy * yu / z,
                    depth,
                }
            }
            Projection::WeakPerspective { height_m } => {
                let s = (self.cam.height as f32 - 1.0) / height_m;
                Screen {
                    px: self.cx + s * xr,
                    py: self.cy - s * yu,
                    depth,
                }
            }
        }
    }

    pub fn world_to_ndc(&self, p: Vec3) -> Vec3 {
        let c = &self.cam;
        let s = self.to_screen(p);
        Vec3::new(
            2.0 * s.px / (c.width as f32 - 1.0) - 1.0,
            2.0 * s.py / (c.height as f32 - 1.0) - 1.0,
            1.0 - 2.0 * (s.depth - c.near) / (c.far - c.near),
        )
    }

    pub fn ndc_to_world(&self, n: Vec3) -> Vec3 {
        let c = &self.cam;
        let depth = c.near + 0.5 * (1.0 - n.z) * (c.far - c.near);
        let px = 0.5 * (n.x + 1.0) * (c.width as f32 - 1.0);
        let py = 0.5 * (n.y + 1.0) * (c.height as f32 - 1.0);
        let (xr, yu) = match c.projection {
            Projection::Pinhole { fx, fy, .. } => {
                ((px - self.cx) * depth / fx, -(py - self.cy) * depth / fy)
            }
            Projection::WeakPerspective { height_m } => {
                let s = (c.height as f32 - 1.0) / height_m;
                ((px - self.cx) / s, -(py - self.cy) / s)
            }
        };
        c.eye + self.r * xr + self.u * yu + self.f * depth
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ndc_round_trip_both_models() {
        for projection in [
            Projection::WeakPerspective { height_m: 2.2 },
            Projection::Pinhole {
                fx: 600.0,
                fy: 600.0,
                cx: 255.5,
                cy: 250.0,
            },
        ] {
            let cam = Camera {
                width: 512,
                height: 512,
                eye: Vec3::new(0.5, 1.2, 3.0),
                target: Vec3::new(0.0, 0.9, 0.0),
                projection,
                near: 1.5,
                far: 4.5,
            };
            for p in [
                Vec3::new(0.1, 0.9, 0.2),
                Vec3::new(-0.3, 1.7, -0.4),
                Vec3::new(0.0, 0.05, 0.3),
            ] {
                let n = cam.world_to_ndc(p);
                let back = cam.ndc_to_world(n);
                assert!(
                    (back - p).length() < 1e-4,
                    "{projection:?} {p} -> {n} -> {back}"
                );
            }
            // The look-at target projects near the image centre; nearer points have larger z.
            let t = cam.world_to_ndc(cam.target);
            let nearer = cam.world_to_ndc(cam.target + (cam.eye - cam.target).normalize() * 0.1);
            assert!(nearer.z > t.z);
        }
    }

    #[test]
    fn image_rows_go_down() {
        let cam = Camera {
            width: 64,
            height: 64,
            eye: Vec3::new(0.0, 1.0, 3.0),
            target: Vec3::new(0.0, 1.0, 0.0),
            projection: Projection::WeakPerspective { height_m: 2.0 },
            near: 1.0,
            far: 5.0,
        };
        assert!(
            cam.to_screen(Vec3::new(0.0, 1.5, 0.0)).py < cam.to_screen(Vec3::new(0.0, 0.5, 0.0)).py
        );
        assert!(
            cam.to_screen(Vec3::new(0.5, 1.0, 0.0)).px
                > cam.to_screen(Vec3::new(-0.5, 1.0, 0.0)).px
        );
    }
}
