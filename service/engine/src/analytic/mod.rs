//! Analytic occupancy fields with exact ground truth, for tests and benchmarks.
//!
//! Each scene is a signed distance function (negative inside) in NDC units, turned into a
//! smooth occupancy like a network's output: `occ = sigmoid(-sdf / width)`. The geometry is
//! evaluated in f64 (it is the reference the tests compare against) and rounded once to f32
//! at the field boundary; the engine's hot paths are f32.
//!
//! Scene names (see [`SCENES`]): `sphere`, `torus`, `two-bodies`, `thin-plate`,
//! `capsule-human`, and the adversarial `flat-half` (exactly 0.5 over a region) and `noise`
//! (high-frequency noise around 0.5).

use crate::field::{ColorField, FieldError, OccupancyField};
use glam::{DMat3, DVec3, Vec3};

mod prim;
use prim::{Bound, Prim};

/// Names of all analytic scenes, in benchmark order.
pub const SCENES: [&str; 7] = [
    "sphere",
    "torus",
    "two-bodies",
    "thin-plate",
    "capsule-human",
    "flat-half",
    "noise",
];

/// Default sigmoid width (NDC units) of the occupancy transition: about one voxel at 257^3.
pub const DEFAULT_WIDTH: f64 = 0.008;

#[derive(Debug, Clone, Copy)]
struct Part {
    prim: Prim,
    color: [f32; 3],
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Special {
    None,
    /// Occupancy exactly 0.5 wherever x < FLAT_X.
    FlatHalf,
    /// High-frequency noise of small amplitude around 0.5 inside a ball.
    Noise,
}

const FLAT_X: f64 = -0.2;
const NOISE_R: f64 = 0.75;
const NOISE_AMP: f64 = 0.03;

/// An analytic scene: union of primitives plus an optional adversarial modification.
#[derive(Debug, Clone)]
pub struct AnalyticScene {
    name: &'static str,
    parts: Vec<Part>,
    special: Special,
    width: f64,
    bodies: usize,
    /// `parts[i].prim.prepared()` and its bound.
    prepared: Vec<(Prim, Bound)>,
}

/// Margin (NDC units) by which a bound must exceed the running minimum before a primitive is
/// skipped: far above the f64 rounding of either side, so skipping never changes the minimum.
const CULL_MARGIN: f64 = 1e-9;

const SKIN: [f32; 3] = [0.87, 0.68, 0.55];
const SHIRT: [f32; 3] = [0.20, 0.40, 0.75];
const TROUSERS: [f32; 3] = [0.25, 0.25, 0.32];
const SHOES: [f32; 3] = [0.12, 0.09, 0.08];
const HAIR: [f32; 3] = [0.25, 0.16, 0.10];

fn part(prim: Prim, color: [f32; 3]) -> Part {
    Part { prim, color }
}

/// Scale from the capsule human's design units (metres, 1.70 m tall) to NDC: 1.45 NDC units
/// tall, 72% of the grid height, like a person in a capture volume with some head room.
pub const HUMAN_SCALE: f64 = 0.85;

/// The capsule human: a 1.70 m person designed in metres (y up, feet at 0), arms abducted
/// about 45 degrees away from the body, legs slightly apart, one foot forward; scaled by
/// [`HUMAN_SCALE`] and flipped to the engine's y-down convention (head top at y = -0.72,
/// soles at y = +0.73).
fn capsule_human() -> Vec<Part> {
    let up = |x: f64, h: f64, z: f64| DVec3::new(x, 0.85 - h, z) * HUMAN_SCALE;
    let r = |x: f64| x * HUMAN_SCALE;
    let mut v = vec![
        part(
            Prim::Ellipsoid {
                c: up(0.0, 1.58, 0.0),
                r: HUMAN_SCALE * DVec3::new(0.085, 0.115, 0.10),
            },
            SKIN,
        ),
        part(
            Prim::Ellipsoid {
                c: up(0.0, 1.64, -0.015),
                r: HUMAN_SCALE * DVec3::new(0.09, 0.07, 0.095),
            },
            HAIR,
        ),
        part(
            Prim::Capsule {
                a: up(0.0, 1.40, 0.0),
                b: up(0.0, 1.50, 0.0),
                r: r(0.05),
            },
            SKIN,
        ),
        part(
            Prim::Ellipsoid {
                c: up(0.0, 1.17, 0.0),
                r: HUMAN_SCALE * DVec3::new(0.17, 0.27, 0.11),
            },
            SHIRT,
        ),
        part(
            Prim::Ellipsoid {
                c: up(0.0, 0.92, 0.0),
                r: HUMAN_SCALE * DVec3::new(0.16, 0.13, 0.11),
            },
            TROUSERS,
        ),
    ];
    for s in [-1.0f64, 1.0] {
        let shoulder = up(s * 0.18, 1.37, 0.0);
        let elbow = up(s * 0.38, 1.17, 0.03);
        let wrist = up(s * 0.53, 0.97, 0.07);
        let hand = up(s * 0.59, 0.90, 0.08);
        let hip = up(s * 0.09, 0.90, 0.0);
        let knee = up(s * 0.13, 0.48, s * 0.04);
        let ankle = up(s * 0.14, 0.08, s * 0.02);
        let toe = up(s * 0.16, 0.035, s * 0.02 + 0.16);
        v.extend([
            part(
                Prim::Capsule {
                    a: shoulder,
                    b: elbow,
                    r: r(0.05),
                },
                SHIRT,
            ),
            part(
                Prim::Capsule {
                    a: elbow,
                    b: wrist,
                    r: r(0.042),
                },
                SKIN,
            ),
            part(
                Prim::Ellipsoid {
                    c: hand,
                    r: HUMAN_SCALE * DVec3::new(0.045, 0.075, 0.04),
                },
                SKIN,
            ),
            part(
                Prim::Capsule {
                    a: hip,
                    b: knee,
                    r: r(0.075),
                },
                TROUSERS,
            ),
            part(
                Prim::Capsule {
                    a: knee,
                    b: ankle,
                    r: r(0.055),
                },
                TROUSERS,
            ),
            part(
                Prim::Capsule {
                    a: up(s * 0.14, 0.05, s * 0.02 - 0.02),
                    b: toe,
                    r: r(0.042),
                },
                SHOES,
            ),
        ]);
    }
    v
}

impl AnalyticScene {
    /// The scene called `name` (see [`SCENES`]).
    pub fn by_name(name: &str) -> Option<Self> {
        // Single-part scenes are coloured by position (see `color64`); this is unused there.
        let c = [0.8, 0.8, 0.8];
        let (parts, special, bodies, name) = match name {
            "sphere" => (
                vec![part(
                    Prim::Sphere {
                        c: DVec3::new(0.05, -0.03, 0.02),
                        r: 0.6,
                    },
                    c,
                )],
                Special::None,
                1,
                "sphere",
            ),
            "torus" => (
                vec![part(
                    Prim::Torus {
                        c: DVec3::new(0.01, 0.02, -0.03),
                        rot: DMat3::from_rotation_x(0.5) * DMat3::from_rotation_z(0.2),
                        major: 0.55,
                        minor: 0.18,
                    },
                    c,
                )],
                Special::None,
                1,
                "torus",
            ),
            "two-bodies" => (
                vec![
                    part(
                        Prim::Sphere {
                            c: DVec3::new(-0.45, 0.05, 0.0),
                            r: 0.32,
                        },
                        [0.9, 0.3, 0.2],
                    ),
                    part(
                        Prim::Ellipsoid {
                            c: DVec3::new(0.48, -0.1, 0.05),
                            r: DVec3::new(0.25, 0.4, 0.3),
                        },
                        [0.2, 0.7, 0.3],
                    ),
                ],
                Special::None,
                2,
                "two-bodies",
            ),
            // 0.025 thick, centred between the planes z = 0 and z = 0.0625 of a 33^3 grid (so
            // no 33^3 point lies inside it) but on a plane of the 65^3 grid.
            "thin-plate" => (
                vec![part(
                    Prim::Slab {
                        c: DVec3::new(0.0, 0.0, 0.03125),
                        half: DVec3::new(0.5, 0.45, 0.0125),
                    },
                    [0.6, 0.6, 0.9],
                )],
                Special::None,
                1,
                "thin-plate",
            ),
            "capsule-human" => (capsule_human(), Special::None, 1, "capsule-human"),
            "flat-half" => (
                vec![part(
                    Prim::Sphere {
                        c: DVec3::new(0.1, 0.0, 0.0),
                        r: 0.6,
                    },
                    c,
                )],
                Special::FlatHalf,
                1,
                "flat-half",
            ),
            "noise" => (
                vec![part(
                    Prim::Sphere {
                        c: DVec3::ZERO,
                        r: NOISE_R,
                    },
                    c,
                )],
                Special::Noise,
                0,
                "noise",
            ),
            _ => return None,
        };
        let prepared = parts
            .iter()
            .map(|q| {
                let p = q.prim.prepared();
                (p, p.bound())
            })
            .collect();
        Some(Self {
            name,
            parts,
            special,
            width: DEFAULT_WIDTH,
            bodies,
            prepared,
        })
    }

    pub fn name(&self) -> &'static str {
        self.name
    }

    /// The same scene with another occupancy transition width (NDC units, > 0).
    pub fn with_width(mut self, width: f64) -> Self {
        assert!(
            width > 0.0 && width.is_finite(),
            "width must be positive and finite"
        );
        self.width = width;
        self
    }

    /// Number of disjoint bodies by construction (0 where undefined, as for `noise`).
    pub fn bodies(&self) -> usize {
        self.bodies
    }

    /// True for the adversarial scenes, whose binarization is not a smooth surface.
    pub fn is_adversarial(&self) -> bool {
        self.special != Special::None
    }

    /// Signed distance of the union of primitives (negative inside), f64.
    pub fn sdf(&self, p: DVec3) -> f64 {
        self.parts
            .iter()
            .map(|q| q.prim.sdf(p))
            .fold(f64::INFINITY, f64::min)
    }

    /// [`AnalyticScene::sdf`], bit for bit, skipping every primitive whose bound proves it
    /// cannot hold the minimum. `hint` is the part to try first (the last call's nearest part:
    /// neighbouring points share it), updated on return.
    pub fn sdf_culled(&self, p: DVec3, hint: &mut usize) -> f64 {
        let first = (*hint).min(self.prepared.len().saturating_sub(1));
        let Some((q, _)) = self.prepared.get(first) else {
            return f64::INFINITY;
        };
        let mut best = q.sdf(p);
        if best.is_nan() {
            best = f64::INFINITY;
        }
        for (i, (q, b)) in self.prepared.iter().enumerate() {
            if i == first || b.exceeds((p - b.c).length_squared(), best + CULL_MARGIN) {
                continue;
            }
            let d = q.sdf(p);
            if d < best {
                best = d;
                *hint = i;
            }
        }
        best
    }

    /// Reference occupancy, f64.
    pub fn occupancy64(&self, p: DVec3) -> f64 {
        self.occupancy_from(p, || self.sdf(p))
    }

    /// The occupancy at `p` with the union's distance from `sdf`, called only where the
    /// scene's value depends on it.
    fn occupancy_from(&self, p: DVec3, sdf: impl FnOnce() -> f64) -> f64 {
        match self.special {
            Special::FlatHalf if p.x < FLAT_X => 0.5,
            Special::Noise => {
                let r = p.length();
                if r < NOISE_R {
                    let s = (173.0 * p.x + 1.0).sin()
                        * (191.0 * p.y + 2.0).sin()
                        * (211.0 * p.z + 3.0).sin();
                    0.5 + NOISE_AMP * s
                } else {
                    0.5 * sigmoid(-(r - NOISE_R) / self.width)
                }
            }
            _ => sigmoid(-sdf() / self.width),
        }
    }

    /// Colour of the nearest part at `p`.
    pub fn color64(&self, p: DVec3) -> [f32; 3] {
        let mut best = (f64::INFINITY, [0.0f32; 3]);
        for q in &self.parts {
            let d = q.prim.sdf(p);
            if d < best.0 {
                best = (d, q.color);
            }
        }
        if self.parts.len() == 1 {
            // Single-part scenes: a smooth positional gradient so texture lookups are visible.
            let n = p.normalize_or_zero();
            return [
                (0.5 + 0.4 * n.x) as f32,
                (0.5 + 0.4 * n.y) as f32,
                (0.5 + 0.4 * n.z) as f32,
            ];
        }
        best.1
    }

    /// Reference ray cast along the pixel ray `(x, y)` from `z = +1` (nearest) towards
    /// `z = -1`: the NDC `z` of the first 0.5 crossing of the occupancy, found by marching in
    /// steps of `step` and bisecting in f64. `None` if the ray stays outside.
    pub fn first_hit_z(&self, x: f64, y: f64, step: f64) -> Option<f64> {
        let occ = |z: f64| self.occupancy64(DVec3::new(x, y, z));
        let mut z_prev = 1.0;
        if occ(z_prev) > 0.5 {
            return Some(1.0);
        }
        let mut z = 1.0;
        while z > -1.0 {
            z = (z - step).max(-1.0);
            if occ(z) > 0.5 {
                let (mut lo, mut hi) = (z, z_prev); // occ(lo) > 0.5 >= occ(hi)
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if occ(mid) > 0.5 { lo = mid } else { hi = mid }
                }
                return Some(0.5 * (lo + hi));
            }
            z_prev = z;
        }
        None
    }
}

#[inline]
fn sigmoid(x: f64) -> f64 {
    // exp overflows to +inf for large -x, giving exactly 0; never NaN for finite or infinite x.
    1.0 / (1.0 + (-x).exp())
}

impl OccupancyField for AnalyticScene {
    /// [`AnalyticScene::occupancy64`] rounded to f32 (the same values; the SDF is culled).
    fn occupancy(&self, points: &[Vec3], out: &mut [f32]) -> Result<(), FieldError> {
        let mut hint = 0;
        for (o, p) in out.iter_mut().zip(points) {
            let p = p.as_dvec3();
            *o = self.occupancy_from(p, || self.sdf_culled(p, &mut hint)) as f32;
        }
        Ok(())
    }
}

impl ColorField for AnalyticScene {
    fn color(&self, points: &[Vec3], out: &mut [[f32; 3]]) -> Result<(), FieldError> {
        for (o, p) in out.iter_mut().zip(points) {
            *o = self.color64(p.as_dvec3());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_resolves() {
        for n in SCENES {
            assert_eq!(AnalyticScene::by_name(n).unwrap().name(), n);
        }
        assert!(AnalyticScene::by_name("cube").is_none());
    }

    #[test]
    fn human_fills_most_of_the_height_and_stays_in_the_cube() {
        let h = AnalyticScene::by_name("capsule-human").unwrap();
        let step = 0.01;
        let (mut ymin, mut ymax) = (f64::MAX, f64::MIN);
        let mut y = -1.0;
        while y <= 1.0 {
            let mut x = -1.0;
            while x <= 1.0 {
                let mut z = -1.0;
                while z <= 1.0 {
                    if h.sdf(DVec3::new(x, y, z)) < 0.0 {
                        ymin = ymin.min(y);
                        ymax = ymax.max(y);
                    }
                    z += 0.05;
                }
                x += 0.02;
            }
            y += step;
        }
        assert!(ymax - ymin > 1.4, "human spans {ymin}..{ymax}");
        assert!(ymin > -0.95 && ymax < 0.95);
        // Head (top) has negative y: y points down.
        assert!(h.sdf(DVec3::new(0.0, -0.62, 0.0)) < 0.0);
        // Feet near +y.
        assert!(h.sdf(DVec3::new(0.12, 0.68, 0.02)) < 0.0);
        // Arms away from the body: a point between the hand and the hip is outside.
        assert!(h.sdf(DVec3::new(0.30, -0.04, 0.0)) > 0.0);
    }

    #[test]
    fn culled_sdf_and_field_equal_the_reference_bit_for_bit() {
        // A lattice over the cube and beyond (points in every primitive's bound, on both sides
        // of every surface, far away), then pseudo-random points, with the hint carried from
        // point to point as the field carries it.
        let mut pts: Vec<DVec3> = Vec::new();
        let m = 48;
        for k in 0..m {
            for j in 0..m {
                for i in 0..m {
                    let c = |t: usize| -1.2 + 2.4 * t as f64 / (m - 1) as f64;
                    pts.push(DVec3::new(c(i), c(j), c(k)));
                }
            }
        }
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64 * 2.4 - 1.2
        };
        for _ in 0..50_000 {
            pts.push(DVec3::new(next(), next(), next()));
        }
        pts.push(DVec3::splat(f64::NAN));
        pts.push(DVec3::splat(1e30));
        for n in SCENES {
            let s = AnalyticScene::by_name(n).unwrap();
            let mut hint = 0;
            for p in &pts {
                let (a, b) = (s.sdf(*p), s.sdf_culled(*p, &mut hint));
                assert!(
                    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                    "{n} at {p:?}: {a} vs {b}"
                );
            }
            let p32: Vec<Vec3> = pts.iter().map(|p| p.as_vec3()).collect();
            let mut got = vec![0.0f32; p32.len()];
            s.occupancy(&p32, &mut got).unwrap();
            for (p, g) in p32.iter().zip(&got) {
                let want = s.occupancy64(p.as_dvec3()) as f32;
                assert!(
                    want.to_bits() == g.to_bits() || (want.is_nan() && g.is_nan()),
                    "{n} at {p:?}: {want} vs {g}"
                );
            }
        }
    }

    #[test]
    fn flat_half_is_exactly_half() {
        let f = AnalyticScene::by_name("flat-half").unwrap();
        assert_eq!(f.occupancy64(DVec3::new(-0.5, 0.3, 0.1)), 0.5);
        let mut out = [0.0f32];
        f.occupancy(&[Vec3::new(-0.9, 0.0, 0.0)], &mut out).unwrap();
        assert_eq!(out[0], 0.5);
    }

    #[test]
    fn occupancy_is_finite_and_in_range_far_away() {
        for n in SCENES {
            let s = AnalyticScene::by_name(n).unwrap().with_width(1e-6);
            for p in [
                DVec3::splat(1e30),
                DVec3::splat(-1e30),
                DVec3::ZERO,
                DVec3::new(1.0, -1.0, 1.0),
            ] {
                let v = s.occupancy64(p);
                assert!(v.is_finite() && (0.0..=1.0).contains(&v), "{n} {p:?} {v}");
            }
        }
    }

    #[test]
    fn ray_cast_finds_sphere_front() {
        let s = AnalyticScene::by_name("sphere").unwrap();
        let z = s.first_hit_z(0.05, -0.03, 0.01).unwrap();
        assert!((z - 0.62).abs() < 1e-3, "{z}");
        assert!(s.first_hit_z(0.95, 0.95, 0.01).is_none());
    }
}
