//! Property tests: exactness of the hierarchical methods on random sphere/capsule sets (creases
//! rounded to the coarse spacing), and
//! the index <-> world round trip of the coordinate convention.

use glam::{DVec3, Vec3};
use proptest::prelude::*;
use volcap_engine::field::FnField;
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{Localizer, Method};

#[derive(Debug, Clone)]
enum Shape {
    Sphere(DVec3, f64),
    Capsule(DVec3, DVec3, f64),
}

impl Shape {
    fn sdf(&self, p: DVec3) -> f64 {
        match self {
            Shape::Sphere(c, r) => (p - *c).length() - r,
            Shape::Capsule(a, b, r) => {
                let (pa, ba) = (p - *a, *b - *a);
                let h = (pa.dot(ba) / ba.dot(ba)).clamp(0.0, 1.0);
                (pa - ba * h).length() - r
            }
        }
    }
}

/// Radius (NDC) over which creases of a union are rounded: the coarse spacing (9^3: 0.25). A
/// sharp crease between overlapping shapes can hide an outside point inside a coarse cell
/// whose corners are all inside (three overlapping capsules at 65^3 did: one point at
/// occupancy 0.36 with every neighbour inside), which no coarse-to-fine method can see: the
/// methods assume features, gaps included, larger than the coarsest spacing.
const CREASE: f64 = 0.25;

/// Polynomial smooth minimum (Quilez): `min(a, b)` where they differ by more than `k`,
/// rounded below it.
fn smooth_min(a: f64, b: f64, k: f64) -> f64 {
    if !b.is_finite() || !a.is_finite() {
        return a.min(b);
    }
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - h * h * k * 0.25
}

fn point() -> impl Strategy<Value = DVec3> {
    (-0.5f64..0.5, -0.5f64..0.5, -0.5f64..0.5).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

/// Radii above sqrt(3)/2 of the 9^3 coarse spacing (0.25): every shape contains a coarse
/// point, so exactness is expected (features larger than the coarsest spacing).
fn shape() -> impl Strategy<Value = Shape> {
    prop_oneof![
        (point(), 0.22f64..0.4).prop_map(|(c, r)| Shape::Sphere(c, r)),
        (point(), point(), 0.22f64..0.35).prop_map(|(a, b, r)| Shape::Capsule(
            a,
            b + DVec3::splat(1e-3),
            r
        )),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    #[test]
    fn hierarchical_methods_equal_dense_on_random_shapes(
        shapes in prop::collection::vec(shape(), 1..4),
        width in 0.005f64..0.05,
    ) {
        let field = FnField(move |p: Vec3| {
            let d = shapes.iter().map(|s| s.sdf(p.as_dvec3())).fold(f64::INFINITY, |a, b| smooth_min(a, b, CREASE));
            (1.0 / (1.0 + (d / width).exp())) as f32
        });
        let spec = GridSpec::new(6).unwrap();
        let mut loc = Localizer::new();
        let mut dense = Grid::new(spec);
        loc.run(Method::Dense, &field, spec, 3, &mut dense).unwrap();
        let want = dense.binarized();
        for m in [Method::Hierarchical, Method::HierarchicalTight] {
            let mut g = Grid::new(spec);
            let st = loc.run(m, &field, spec, 3, &mut g).unwrap();
            let got = g.binarized();
            let diff = want.iter_ones().filter(|&i| !got.get(i)).count() + got.iter_ones().filter(|&i| !want.get(i)).count();
            prop_assert_eq!(diff, 0, "{} differs from dense", m.label());
            prop_assert!(st.evaluations <= spec.len() as u64);
        }
    }

    #[test]
    fn index_world_round_trip(level in 1u32..=10, a in any::<u32>(), b in any::<u32>(), c in any::<u32>()) {
        let spec = GridSpec::new(level).unwrap();
        let n = spec.n() as u32;
        let idx = [(a % n) as usize, (b % n) as usize, (c % n) as usize];
        let w = spec.world(idx);
        prop_assert!(w.abs().max_element() <= 1.0);
        prop_assert_eq!(spec.index_of(w), Some(idx));
        // And the linear index round trip.
        prop_assert_eq!(spec.unlinear(spec.linear(idx)), idx);
    }

    #[test]
    fn world_index_world_is_within_half_a_spacing(level in 1u32..=9, x in -1f32..=1.0, y in -1f32..=1.0, z in -1f32..=1.0) {
        let spec = GridSpec::new(level).unwrap();
        let p = Vec3::new(x, y, z);
        let idx = spec.index_of(p).unwrap();
        let back = spec.world(idx);
        prop_assert!((back - p).abs().max_element() <= 0.5 * spec.spacing() * 1.0001);
    }
}

#[test]
fn index_of_refuses_outside_and_non_finite() {
    let spec = GridSpec::new(5).unwrap();
    assert_eq!(spec.index_of(Vec3::new(1.0001, 0.0, 0.0)), None);
    assert_eq!(spec.index_of(Vec3::new(f32::NAN, 0.0, 0.0)), None);
    assert_eq!(spec.index_of(Vec3::new(0.0, f32::NEG_INFINITY, 0.0)), None);
    assert_eq!(spec.index_of(Vec3::new(-1.0, 1.0, 0.0)), Some([0, 32, 16]));
}
