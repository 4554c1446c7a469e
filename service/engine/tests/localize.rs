//! Correctness of every localization method against dense evaluation.

use glam::Vec3;
use volcap_engine::analytic::AnalyticScene;
use volcap_engine::field::{FieldError, FnField, OccupancyField, Seeded};
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{LocalizeError, Localizer, Method, default_coarse};
use volcap_engine::metrics::{components, iou, lost_components};

fn run(scene: &dyn OccupancyField, res: usize, m: Method, coarse: Option<u32>) -> (Grid, u64) {
    let spec = GridSpec::from_resolution(res).unwrap();
    let mut g = Grid::new(spec);
    let st = Localizer::new()
        .run(
            m,
            scene,
            spec,
            coarse.unwrap_or(default_coarse(spec)),
            &mut g,
        )
        .unwrap();
    (g, st.evaluations)
}

fn assert_exact(name: &str, res: usize, method: Method) {
    let scene = AnalyticScene::by_name(name).unwrap();
    let (dense, dn) = run(&scene, res, Method::Dense, None);
    assert_eq!(dn as usize, res * res * res);
    let (g, n) = run(&scene, res, method, None);
    let db = dense.binarized();
    let gb = g.binarized();
    let diff: Vec<usize> = db
        .iter_ones()
        .filter(|&i| !gb.get(i))
        .chain(gb.iter_ones().filter(|&i| !db.get(i)))
        .collect();
    assert!(
        diff.is_empty(),
        "{} on {name} at {res}: {} points differ from dense (first {:?}), {} evaluations",
        method.label(),
        diff.len(),
        diff.first().map(|&i| g.spec().unlinear(i)),
        n
    );
    // The 33^3 coarse level alone is 13% of a 65^3 grid; the savings grow with resolution.
    let factor = match res {
        ..=65 => 3,
        66..=129 => 10,
        _ => 30,
    };
    assert!(
        n * factor < dn,
        "{} on {name} at {res}: {n} evaluations vs dense {dn}",
        method.label()
    );
    // Evaluated values are the field's own.
    for i in g.evaluated.iter_ones().step_by(97) {
        assert_eq!(g.values[i], dense.values[i]);
    }
}

const SMOOTH: [&str; 4] = ["sphere", "torus", "two-bodies", "capsule-human"];

#[test]
fn hierarchical_equals_dense_at_65_and_129() {
    for res in [65, 129] {
        for s in SMOOTH {
            assert_exact(s, res, Method::Hierarchical);
        }
    }
}

#[test]
fn hierarchical_equals_dense_at_257() {
    for s in SMOOTH {
        assert_exact(s, 257, Method::Hierarchical);
    }
}

#[test]
fn tight_variant_equals_dense_at_65_129_257() {
    for res in [65, 129, 257] {
        for s in SMOOTH {
            assert_exact(s, res, Method::HierarchicalTight);
        }
    }
}

#[test]
fn tight_variant_evaluates_fewer_points_than_the_paper() {
    for s in SMOOTH {
        let scene = AnalyticScene::by_name(s).unwrap();
        let (_, paper) = run(&scene, 129, Method::Hierarchical, None);
        let (_, tight) = run(&scene, 129, Method::HierarchicalTight, None);
        assert!(tight < paper, "{s}: tight {tight} vs paper {paper}");
    }
}

/// The thin plate (0.025 thick) sits between the planes of the 33^3 coarsest grid: every
/// coarse-to-fine method starting there never sees it (the coarsest spacing, 0.0625, is an
/// accuracy/time knob). Starting at 65^3 (spacing 0.03125 < thickness) finds it exactly.
#[test]
fn thin_plate_is_lost_below_the_coarsest_spacing_and_found_above_it() {
    let scene = AnalyticScene::by_name("thin-plate").unwrap();
    let (dense, _) = run(&scene, 129, Method::Dense, None);
    let comps = components(dense.spec(), &dense.binarized());
    assert_eq!(comps.len(), 1);
    for m in [
        Method::Hierarchical,
        Method::HierarchicalTight,
        Method::Mise,
    ] {
        let (g, _) = run(&scene, 129, m, Some(5));
        assert_eq!(
            lost_components(&comps, &g.binarized()),
            1,
            "{} saw the plate at 33^3",
            m.label()
        );
        let (g, _) = run(&scene, 129, m, Some(6));
        assert_eq!(
            lost_components(&comps, &g.binarized()),
            0,
            "{} lost the plate at 65^3",
            m.label()
        );
    }
    let (g, _) = run(&scene, 129, Method::Hierarchical, Some(6));
    assert_eq!(iou(&g, &dense), 1.0);
}

/// The field's seeds (`OccupancyField::seeds`): one inside point of the thin plate makes the
/// hierarchical methods find all of it from 33^3, where without it they lose it (above),
/// and every other point stays as dense has it. Seeds outside the cube or outside the
/// surface change nothing.
#[test]
fn one_seed_on_a_thin_part_brings_it_back_exactly() {
    let scene = AnalyticScene::by_name("thin-plate").unwrap();
    let (dense, _) = run(&scene, 129, Method::Dense, None);
    let db = dense.binarized();
    let comps = components(dense.spec(), &db);
    assert_eq!(comps.len(), 1);
    let spec = dense.spec();
    // The plate's inside point nearest the cube's centre, moved off the grid by a third of a
    // spacing (a seed is snapped to each level's nearest point).
    let q = db
        .iter_ones()
        .min_by_key(|&i| {
            let p = spec.world(spec.unlinear(i));
            (p.length_squared() * 1e6) as u64
        })
        .unwrap();
    let seed = spec.world(spec.unlinear(q)) + Vec3::splat(spec.spacing() / 3.0);
    let seeded = Seeded {
        field: &scene,
        seeds: vec![seed],
    };
    let junk = Seeded {
        field: &scene,
        seeds: vec![
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::NAN,
            Vec3::new(-0.9, -0.9, -0.9),
        ],
    };
    for m in [Method::Hierarchical, Method::HierarchicalTight] {
        let (g, n) = run(&seeded, 129, m, Some(5));
        assert_eq!(lost_components(&comps, &g.binarized()), 0, "{}", m.label());
        assert_eq!(iou(&g, &dense), 1.0, "{}", m.label());
        assert!(n < 129 * 129 * 129 / 4, "{}: {n} evaluations", m.label());
        let (g, _) = run(&junk, 129, m, Some(5));
        assert_eq!(lost_components(&comps, &g.binarized()), 1, "{}", m.label());
    }
    // The baselines take no seeds.
    let (g, _) = run(&seeded, 129, Method::Mise, Some(5));
    assert_eq!(lost_components(&comps, &g.binarized()), 1);
}

#[test]
fn adversarial_fields_terminate_stay_finite_and_never_exceed_dense() {
    for name in ["flat-half", "noise"] {
        let scene = AnalyticScene::by_name(name).unwrap();
        for res in [33, 65] {
            let (dense, dn) = run(&scene, res, Method::Dense, Some(3));
            for m in Method::all() {
                let (g, n) = run(&scene, res, m, Some(3));
                assert!(n <= dn, "{} on {name}: {n} > dense {dn}", m.label());
                assert!(
                    g.values
                        .iter()
                        .all(|v| v.is_finite() && (0.0..=1.0).contains(v)),
                    "{}",
                    m.label()
                );
                let i = iou(&g, &dense);
                assert!(i.is_finite() && (0.0..=1.0).contains(&i));
            }
        }
    }
}

#[test]
fn flat_half_region_is_outside_for_every_method() {
    // Exactly 0.5 is outside by the one binarization rule (value > 0.5 is inside).
    let scene = AnalyticScene::by_name("flat-half").unwrap();
    for m in Method::all() {
        let (g, _) = run(&scene, 65, m, None);
        let spec = g.spec();
        let idx = spec.index_of(Vec3::new(-0.6, 0.0, 0.0)).unwrap();
        assert!(
            g.value(idx) <= 0.5,
            "{} put the flat region inside",
            m.label()
        );
    }
}

#[test]
fn nan_from_a_field_is_an_error_naming_the_point() {
    let bad = FnField(|p: Vec3| {
        if p.x > 0.3 && p.y > 0.3 {
            f32::NAN
        } else {
            0.2
        }
    });
    for m in Method::all() {
        let spec = GridSpec::new(5).unwrap();
        let mut g = Grid::new(spec);
        let err = Localizer::new().run(m, &bad, spec, 3, &mut g).unwrap_err();
        match err {
            LocalizeError::Field(FieldError::NonFinite {
                index: Some(idx),
                point,
                value,
            }) => {
                assert!(value.is_nan());
                assert!(point[0] > 0.3 && point[1] > 0.3);
                assert_eq!(spec.world(idx).to_array(), point);
            }
            e => panic!("{}: unexpected {e:?}", m.label()),
        }
        assert!(err_text(&bad).contains("non-finite"));
    }
    let inf = FnField(|p: Vec3| if p.z < -0.9 { f32::INFINITY } else { 0.0 });
    assert!(err_text(&inf).contains("inf"));
    let big = FnField(|_| 1.5f32);
    assert!(err_text(&big).contains("outside [0, 1]"));
}

fn err_text(f: &dyn OccupancyField) -> String {
    let spec = GridSpec::new(4).unwrap();
    let mut g = Grid::new(spec);
    Localizer::new()
        .run(Method::Dense, f, spec, 2, &mut g)
        .unwrap_err()
        .to_string()
}

#[test]
fn bad_coarse_level_is_refused() {
    let scene = AnalyticScene::by_name("sphere").unwrap();
    let spec = GridSpec::new(4).unwrap();
    let mut g = Grid::new(spec);
    let e = Localizer::new()
        .run(Method::Hierarchical, &scene, spec, 5, &mut g)
        .unwrap_err();
    assert!(e.to_string().contains("coarsest level 5"), "{e}");
    assert!(
        Localizer::new()
            .run(Method::Hierarchical, &scene, spec, 0, &mut g)
            .is_err()
    );
}

#[test]
fn buffers_are_reused_across_frames_with_identical_results() {
    let mut loc = Localizer::new();
    let spec = GridSpec::new(6).unwrap();
    let mut g = Grid::new(spec);
    let a = AnalyticScene::by_name("torus").unwrap();
    let b = AnalyticScene::by_name("two-bodies").unwrap();
    for m in Method::all() {
        let s1 = loc.run(m, &a, spec, 4, &mut g).unwrap();
        let first = g.values.clone();
        loc.run(m, &b, spec, 4, &mut g).unwrap();
        let s2 = loc.run(m, &a, spec, 4, &mut g).unwrap();
        assert_eq!(s1, s2, "{}", m.label());
        assert_eq!(first, g.values, "{}", m.label());
    }
}

#[test]
fn baselines_are_close_but_cheaper_than_dense() {
    let scene = AnalyticScene::by_name("capsule-human").unwrap();
    let (dense, dn) = run(&scene, 129, Method::Dense, None);
    // From a 33^3 start, close to PIFu's published setting (init 64 of 512).
    for m in [
        Method::Mise,
        Method::OctreeThreshold(0.01),
        Method::OctreeThreshold(0.3),
    ] {
        let (g, n) = run(&scene, 129, m, Some(5));
        assert!(n < dn / 4, "{}: {n}", m.label());
        assert!(
            iou(&g, &dense) > 0.9,
            "{}: iou {}",
            m.label(),
            iou(&g, &dense)
        );
    }
}

/// The public demo's "faster" mode, checked by hand on a 9^3 grid from a 3^3 start: the
/// coarse 27 points, then (first upsampled level, 9^3 dilation = the whole 5^3 lattice) the
/// remaining 98 points of level 2, then the finest level is never evaluated; its values are
/// the trilinear mean of their level-2 parents (continuous values, not binarized).
#[test]
fn demo_faster_matches_a_hand_checked_case() {
    let sphere = FnField(|p: Vec3| (1.0 - p.length() / 0.7).clamp(0.0, 1.0));
    let spec = GridSpec::from_resolution(9).unwrap();
    let mut g = Grid::new(spec);
    let st = Localizer::new()
        .run(Method::DemoFaster, &sphere, spec, 1, &mut g)
        .unwrap();
    assert!(!st.empty);
    assert_eq!(st.evaluations, 125);
    assert_eq!(st.conflict_rounds, 0);
    for i in g.evaluated.iter_ones() {
        let [x, y, z] = spec.unlinear(i);
        assert!(
            x % 2 == 0 && y % 2 == 0 && z % 2 == 0,
            "finest-level point {:?} was evaluated",
            [x, y, z]
        );
    }
    assert_eq!(g.evaluated_count(), 125);
    // A finest point between 8 level-2 parents: their mean.
    let mut mean = 0.0f32;
    for a in [2usize, 4] {
        for b in [2usize, 4] {
            for c in [2usize, 4] {
                mean += g.value([a, b, c]) / 8.0;
            }
        }
    }
    assert!((g.value([3, 3, 3]) - mean).abs() < 1e-6);
    // Evaluated values are the field's.
    let mut v = [0.0f32];
    sphere.occupancy(&[spec.world([2, 4, 6])], &mut v).unwrap();
    assert_eq!(g.value([2, 4, 6]), v[0]);
}

/// Larger grids: every level but the finest is evaluated near the surface, the finest never;
/// fewer evaluations than the paper's method, close to dense but not exact.
#[test]
fn demo_faster_never_evaluates_the_finest_level_and_is_close_to_dense() {
    let scene = AnalyticScene::by_name("capsule-human").unwrap();
    for (res, coarse) in [(65usize, 3u32), (129, 4)] {
        let (dense, _) = run(&scene, res, Method::Dense, None);
        let (g, n) = run(&scene, res, Method::DemoFaster, Some(coarse));
        let (_, paper) = run(&scene, res, Method::Hierarchical, Some(coarse));
        assert!(n < paper, "demo {n} vs paper {paper} at {res}");
        let spec = g.spec();
        assert!(
            g.evaluated
                .iter_ones()
                .all(|i| spec.unlinear(i).iter().all(|c| c % 2 == 0)),
            "the finest level was evaluated at {res}"
        );
        let i = iou(&g, &dense);
        assert!(i > 0.75 && i < 1.0, "IoU {i} at {res}");
    }
}

/// No inside point on the coarsest grid: the demo returns nothing (all outside, reported).
#[test]
fn demo_faster_gives_an_empty_result_when_the_coarse_grid_sees_nothing() {
    // A small ball between the 9^3 coarse points.
    let ball = FnField(|p: Vec3| {
        if (p - Vec3::splat(0.125)).length() < 0.08 {
            1.0
        } else {
            0.0
        }
    });
    let spec = GridSpec::from_resolution(65).unwrap();
    let mut g = Grid::new(spec);
    let st = Localizer::new()
        .run(Method::DemoFaster, &ball, spec, 3, &mut g)
        .unwrap();
    assert!(st.empty);
    assert_eq!(st.evaluations, 729);
    assert!(g.values.iter().all(|v| *v == 0.0));
    let st = Localizer::new()
        .run(Method::Hierarchical, &ball, spec, 3, &mut g)
        .unwrap();
    assert!(!st.empty);
}

/// Field evaluation split across threads changes neither the values nor the evaluated set
/// (every method, the capsule human at 129^3), and a field error from any part is reported.
#[test]
fn threads_change_nothing_but_time() {
    let scene = AnalyticScene::by_name("capsule-human").unwrap();
    let spec = GridSpec::from_resolution(129).unwrap();
    for m in [
        Method::Dense,
        Method::Hierarchical,
        Method::HierarchicalTight,
    ] {
        let mut one = Grid::new(spec);
        let mut two = Grid::new(spec);
        let a = Localizer::new().run(m, &scene, spec, 3, &mut one).unwrap();
        let mut loc = Localizer::new();
        loc.set_threads(3);
        let b = loc.run(m, &scene, spec, 3, &mut two).unwrap();
        assert_eq!(a.evaluations, b.evaluations, "{}", m.label());
        assert!(
            one.values
                .iter()
                .zip(&two.values)
                .all(|(x, y)| x.to_bits() == y.to_bits()),
            "{}: values differ",
            m.label()
        );
        assert!(
            one.evaluated.iter_ones().eq(two.evaluated.iter_ones()),
            "{}: evaluated sets differ",
            m.label()
        );
    }
    // A NaN in the second half of a batch is still reported, naming the point.
    let field = FnField(|p: Vec3| if p.x > 0.5 { f32::NAN } else { 0.0 });
    let mut loc = Localizer::new();
    loc.set_threads(2);
    let mut g = Grid::new(spec);
    let e = loc.run(Method::Dense, &field, spec, 3, &mut g).unwrap_err();
    assert!(e.to_string().contains("non-finite"), "{e}");
}
