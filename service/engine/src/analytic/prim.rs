//! The primitives of the analytic scenes: signed distances (f64) and the lower bounds that
//! let a union skip primitives without changing its minimum.

use glam::{DMat3, DVec3};

#[derive(Debug, Clone, Copy)]
pub(super) enum Prim {
    Sphere {
        c: DVec3,
        r: f64,
    },
    Ellipsoid {
        c: DVec3,
        r: DVec3,
    },
    /// A capsule with its axis and the reciprocal of its squared length (see
    /// [`Prim::prepared`]).
    CapsuleInv {
        a: DVec3,
        ba: DVec3,
        inv_len2: f64,
        r: f64,
    },
    /// An ellipsoid with reciprocal radii and their squares (see [`Prim::prepared`]).
    EllipsoidInv {
        c: DVec3,
        inv: DVec3,
        inv2: DVec3,
        rmin: f64,
        rmax: f64,
    },
    Capsule {
        a: DVec3,
        b: DVec3,
        r: f64,
    },
    Torus {
        c: DVec3,
        rot: DMat3,
        major: f64,
        minor: f64,
    },
    Slab {
        c: DVec3,
        half: DVec3,
    },
}

/// A lower bound of a primitive's `sdf` from the distance `rho = |p - c|` to a centre, used to
/// skip primitives that cannot hold the union's minimum (see [`super::AnalyticScene::sdf_culled`]):
/// `sdf(p) > t` whenever `rho > a + b max(t, floor)`.
/// - A primitive in the ball of radius `r` about `c` whose `sdf` is a Euclidean distance
///   (negative inside) has `sdf >= rho - r`: `a = r`, `b = 1`, no floor.
/// - Quilez's ellipsoid value `k0 (k0 - 1) / k1` with radii in `[rmin, rmax]`: `k0 / k1` lies in
///   `[rmin, rmax]` and `k0 >= rho / rmax`, so where `rho > rmax` it is at least
///   `(rho / rmax - 1) rmin > 0`: `a = rmax`, `b = rmax / rmin`, floor 0.
#[derive(Debug, Clone, Copy)]
pub(super) struct Bound {
    pub(super) c: DVec3,
    a: f64,
    b: f64,
    floor: f64,
}

impl Bound {
    /// True when the bound proves `sdf(p) > t` (`rho2 = |p - c|^2`).
    #[inline]
    pub(super) fn exceeds(&self, rho2: f64, t: f64) -> bool {
        let reach = self.a + self.b * t.max(self.floor);
        reach < 0.0 || rho2 > reach * reach
    }
}

impl Prim {
    pub(super) fn bound(&self) -> Bound {
        let ball = |c: DVec3, r: f64| Bound {
            c,
            a: r,
            b: 1.0,
            floor: f64::NEG_INFINITY,
        };
        match *self {
            Prim::Sphere { c, r } => ball(c, r),
            Prim::Ellipsoid { .. } | Prim::Capsule { .. } => self.prepared().bound(),
            Prim::EllipsoidInv { c, rmin, rmax, .. } => Bound {
                c,
                a: rmax,
                b: rmax / rmin,
                floor: 0.0,
            },
            Prim::CapsuleInv { a, ba, r, .. } => ball(a + 0.5 * ba, 0.5 * ba.length() + r),
            Prim::Torus {
                c, major, minor, ..
            } => ball(c, major + minor),
            Prim::Slab { c, half } => ball(c, half.length()),
        }
    }

    /// The same primitive ready for repeated evaluation: reciprocals computed once (the raw
    /// primitive's `sdf` goes through this, so values are equal bit for bit).
    pub(super) fn prepared(&self) -> Prim {
        match *self {
            Prim::Capsule { a, b, r } => Prim::CapsuleInv {
                a,
                ba: b - a,
                inv_len2: 1.0 / (b - a).dot(b - a),
                r,
            },
            Prim::Ellipsoid { c, r } => Prim::EllipsoidInv {
                c,
                inv: DVec3::ONE / r,
                inv2: DVec3::ONE / (r * r),
                rmin: r.min_element(),
                rmax: r.max_element(),
            },
            p => p,
        }
    }

    /// Signed distance (Quilez's bound for ellipsoids). Raw ellipsoids and capsules are
    /// prepared on the fly; [`Prim::prepared`] ones skip that.
    #[inline]
    pub(super) fn sdf(&self, p: DVec3) -> f64 {
        match *self {
            Prim::Sphere { c, r } => (p - c).length() - r,
            Prim::Ellipsoid { .. } | Prim::Capsule { .. } => self.prepared().sdf(p),
            Prim::EllipsoidInv {
                c, inv, inv2, rmin, ..
            } => {
                // Quilez's bound: exact zero set, close to Euclidean near the surface.
                let q = p - c;
                let k0 = (q * inv).length();
                let k1 = (q * inv2).length();
                if k1 == 0.0 {
                    -rmin
                } else {
                    k0 * (k0 - 1.0) / k1
                }
            }
            Prim::CapsuleInv { a, ba, inv_len2, r } => {
                let pa = p - a;
                let h = (pa.dot(ba) * inv_len2).clamp(0.0, 1.0);
                (pa - ba * h).length() - r
            }
            Prim::Torus {
                c,
                rot,
                major,
                minor,
            } => {
                let q = rot * (p - c);
                let ring = (q.x * q.x + q.z * q.z).sqrt() - major;
                (ring * ring + q.y * q.y).sqrt() - minor
            }
            Prim::Slab { c, half } => {
                let q = (p - c).abs() - half;
                q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
            }
        }
    }
}
