//! Mesh-free renderer: depth against analytic ray casts, shadow culling, alpha, stability.

use glam::{DVec3, Vec3};
use volcap_engine::analytic::AnalyticScene;
use volcap_engine::field::{FieldError, FnColor, FnField, OccupancyField, Seeded};
use volcap_engine::grid::{Grid, GridSpec, is_inside};
use volcap_engine::localize::{Localizer, Method};
use volcap_engine::render::{RenderOptions, Renderer};

fn dense(field: &dyn OccupancyField, spec: GridSpec) -> Grid {
    let mut g = Grid::new(spec);
    Localizer::new()
        .run(Method::Dense, field, spec, spec.level(), &mut g)
        .unwrap();
    g
}

fn check_scene(name: &str, level: u32) {
    let scene = AnalyticScene::by_name(name).unwrap();
    let spec = GridSpec::new(level).unwrap();
    let mut r = Renderer::new();
    let stats = r
        .render(&scene, &scene, spec, &RenderOptions::default())
        .unwrap();
    let d = dense(&scene, spec);
    let n = spec.n();
    let voxel = spec.spacing() as f64;
    let rgba = r.rgba();
    let mut checked = 0;
    for j in 0..n {
        for i in 0..n {
            let c = i + n * j;
            let column_has_surface = (0..n).any(|k| is_inside(d.value([i, j, k])));
            let alpha = rgba[c * 4 + 3];
            assert_eq!(
                alpha == 255,
                column_has_surface,
                "{name}: alpha at pixel ({i}, {j})"
            );
            assert!(alpha == 0 || alpha == 255);
            if !column_has_surface {
                continue;
            }
            let (x, y) = (spec.coord(i) as f64, spec.coord(j) as f64);
            let z_ref = scene
                .first_hit_z(x, y, voxel / 16.0)
                .expect("a grid point inside implies a ray hit");
            let z = r.depth()[c] as f64;
            assert!(
                (z - z_ref).abs() <= voxel,
                "{name} pixel ({i}, {j}): depth {z} vs analytic {z_ref} (voxel {voxel})"
            );
            checked += 1;
        }
    }
    assert!(checked > 100, "{name}: only {checked} surface pixels");
    assert_eq!(stats.hits as usize, checked);
    // Culling: no node behind a known hit was evaluated in the final pass. A hit is known
    // when predicted (coarse) and when confirmed (final); a node behind both was culled.
    let plane = n * n;
    for &q in r.final_nodes() {
        let c = q as usize % plane;
        let (hc, hf) = (r.coarse_hits()[c], r.hits()[c]);
        let k = (q as usize / plane) as i32;
        assert!(
            hc < 0 || hf < 0 || k >= hc.min(hf),
            "{name}: shadow node {q} evaluated"
        );
    }
    assert!(stats.culled > 0, "{name}: nothing culled");
}

#[test]
fn depth_matches_analytic_surface_within_a_voxel() {
    for name in ["sphere", "torus", "capsule-human"] {
        check_scene(name, 7);
    }
    check_scene("capsule-human", 8);
}

#[test]
fn rear_body_is_culled_and_front_body_is_seen() {
    // A small sphere in front of a big one: the big one's back surface lies behind known
    // hits and must never be evaluated; the depth is the small sphere's where they overlap.
    let front = (DVec3::new(0.0, 0.0, 0.5), 0.25);
    let back = (DVec3::new(0.0, 0.0, -0.3), 0.55);
    let sdf =
        move |p: DVec3| ((p - front.0).length() - front.1).min((p - back.0).length() - back.1);
    let field = FnField(move |p: Vec3| (1.0 / (1.0 + (sdf(p.as_dvec3()) / 0.01).exp())) as f32);
    let white = FnColor(|_| [1.0f32, 1.0, 1.0]);
    let spec = GridSpec::new(7).unwrap();
    let mut r = Renderer::new();
    r.render(&field, &white, spec, &RenderOptions::default())
        .unwrap();
    let n = spec.n();
    let centre = n / 2 + n * (n / 2);
    assert!(
        (r.depth()[centre] - 0.75).abs() < spec.spacing(),
        "depth {}",
        r.depth()[centre]
    );
    // Nodes just inside the back sphere's rear surface along the centre column (z ~ -0.85)
    // are far behind the hit and never evaluated.
    let plane = n * n;
    for &q in r.final_nodes() {
        let (c, k) = (q as usize % plane, q as usize / plane);
        if c == centre {
            assert!(
                spec.coord(k) > 0.4,
                "evaluated node at z {} behind the front sphere",
                spec.coord(k)
            );
        }
    }
}

/// The thin plate falls between the samples of a 33^3 start: the render shows nothing of
/// it. With one seed on it (`OccupancyField::seeds`) every pixel whose column dense
/// evaluation finds inside is drawn, and no other.
#[test]
fn a_seed_brings_a_thin_part_into_the_render() {
    let scene = AnalyticScene::by_name("thin-plate").unwrap();
    let spec = GridSpec::new(7).unwrap();
    let d = dense(&scene, spec);
    let n = spec.n();
    let covered: Vec<bool> = (0..n * n)
        .map(|c| (0..n).any(|k| is_inside(d.value([c % n, c / n, k]))))
        .collect();
    let seed = (0..spec.len())
        .find(|&q| is_inside(d.values[q]))
        .map(|q| spec.world(spec.unlinear(q)))
        .unwrap();
    let opts = RenderOptions {
        coarse_level: 5,
        ..RenderOptions::default()
    };
    let drawn = |f: &dyn OccupancyField| -> Vec<bool> {
        let mut r = Renderer::new();
        r.render(f, &scene, spec, &opts).unwrap();
        r.rgba().chunks_exact(4).map(|p| p[3] == 255).collect()
    };
    assert!(covered.iter().filter(|c| **c).count() > 100);
    assert!(
        !drawn(&scene).iter().any(|a| *a),
        "the plate was seen from 33^3"
    );
    let seeded = Seeded {
        field: &scene,
        seeds: vec![seed],
    };
    assert_eq!(drawn(&seeded), covered);
}

#[test]
fn transparent_background_and_colours() {
    let scene = AnalyticScene::by_name("two-bodies").unwrap();
    let spec = GridSpec::new(6).unwrap();
    let mut r = Renderer::new();
    let opts = RenderOptions {
        background: [0.1, 0.2, 0.3, 0.0],
        ..Default::default()
    };
    r.render(&scene, &scene, spec, &opts).unwrap();
    let rgba = r.rgba();
    assert_eq!(&rgba[0..4], &[26, 51, 77, 0]);
    let n = spec.n();
    // Left body is red-ish, right body green-ish.
    let left = spec.index_of(Vec3::new(-0.45, 0.05, 0.0)).unwrap();
    let right = spec.index_of(Vec3::new(0.48, -0.1, 0.0)).unwrap();
    let px = |i: usize, j: usize| &rgba[(i + n * j) * 4..(i + n * j) * 4 + 4];
    assert!(px(left[0], left[1])[0] > 200 && px(left[0], left[1])[3] == 255);
    assert!(px(right[0], right[1])[1] > 150 && px(right[0], right[1])[3] == 255);
}

#[test]
fn shading_and_adversarial_fields_stay_finite() {
    // With pieces apart from the body dropped too: the noise scene's speckle is thousands of
    // pieces.
    let apart = [None, Some(volcap_engine::pieces::DEFAULT_GAP)];
    for (name, drop_apart) in ["flat-half", "noise", "thin-plate", "capsule-human"]
        .into_iter()
        .flat_map(|n| apart.map(|a| (n, a)))
    {
        let scene = AnalyticScene::by_name(name).unwrap();
        let spec = GridSpec::new(6).unwrap();
        let mut r = Renderer::new();
        let opts = RenderOptions {
            shade: true,
            drop_apart,
            coarse_level: 3,
            ..Default::default()
        };
        let st = r.render(&scene, &scene, spec, &opts).unwrap();
        assert!(
            r.depth()
                .iter()
                .all(|z| z.is_finite() && (-1.0..=1.0).contains(z)),
            "{name} {drop_apart:?}"
        );
        assert_eq!(st.normal_evaluations, 6 * st.hits, "{name} {drop_apart:?}");
    }
}

#[test]
fn step_field_with_equal_plateaus_gives_no_nan() {
    // Occupancy jumps straight from 0 to 1: interpolation sees only 0 and 1, never a 0/0.
    let field = FnField(|p: Vec3| if p.length() < 0.5 { 1.0 } else { 0.0 });
    let grey = FnColor(|_| [0.5f32; 3]);
    let spec = GridSpec::new(6).unwrap();
    let mut r = Renderer::new();
    r.render(
        &field,
        &grey,
        spec,
        &RenderOptions {
            shade: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(r.depth().iter().all(|z| z.is_finite()));
    let n = spec.n();
    let c = n / 2 + n * (n / 2);
    assert!((r.depth()[c] - 0.5).abs() <= spec.spacing());
}

#[test]
fn nan_colour_and_nan_occupancy_are_errors() {
    let scene = AnalyticScene::by_name("sphere").unwrap();
    let bad_col = FnColor(|_| [f32::NAN, 0.0, 0.0]);
    let spec = GridSpec::new(5).unwrap();
    let mut r = Renderer::new();
    assert!(
        r.render(&scene, &bad_col, spec, &RenderOptions::default())
            .is_err()
    );
    let bad_occ = FnField(|p: Vec3| if p.z > 0.9 { f32::NAN } else { 0.0 });
    let e = r
        .render(&bad_occ, &scene, spec, &RenderOptions::default())
        .unwrap_err();
    assert!(
        matches!(
            e,
            volcap_engine::localize::LocalizeError::Field(FieldError::NonFinite { .. })
        ),
        "{e:?}"
    );
}

#[test]
fn coarse_level_must_leave_a_level_to_refine() {
    let scene = AnalyticScene::by_name("sphere").unwrap();
    let spec = GridSpec::new(4).unwrap();
    let mut r = Renderer::new();
    let e = r.render(
        &scene,
        &scene,
        spec,
        &RenderOptions {
            coarse_level: 4,
            ..Default::default()
        },
    );
    assert!(e.is_err());
}

/// Issue #37, item 4: the display image at the grid's own size is the grid image, pixel for
/// pixel and depth for depth (the display pass adds rays, it does not change the rule).
#[test]
fn display_at_grid_size_is_the_grid_image() {
    let bg = [0.1, 0.2, 0.3, 0.0];
    for name in ["sphere", "two-bodies", "capsule-human", "thin-plate"] {
        let scene = AnalyticScene::by_name(name).unwrap();
        let spec = GridSpec::new(6).unwrap();
        let mut r = Renderer::new();
        let opts = RenderOptions {
            background: bg,
            ..RenderOptions::default()
        };
        r.render(&scene, &scene, spec, &opts).unwrap();
        let grid_rgba = r.rgba().to_vec();
        let grid_depth = r.depth().to_vec();
        let display = r.render_display(spec.n(), bg).to_vec();
        assert_eq!(display, grid_rgba, "{name}");
        assert_eq!(r.display_depth(), &grid_depth[..], "{name}");
    }
}

/// Issue #37, item 4: a 129^3 render shown at ~620 px had 129 px blocks (here 65^3 at 257). The display pass
/// follows the true silhouette closer than the grid image scaled up (nearest), and its depth
/// stays within a voxel of the analytic surface.
#[test]
fn display_resolution_follows_the_analytic_silhouette_and_depth() {
    let scene = AnalyticScene::by_name("capsule-human").unwrap();
    let spec = GridSpec::new(6).unwrap();
    let (n, s) = (spec.n(), 257usize);
    let mut r = Renderer::new();
    r.render(&scene, &scene, spec, &RenderOptions::default())
        .unwrap();
    let grid_alpha: Vec<bool> = r.rgba().chunks_exact(4).map(|p| p[3] == 255).collect();
    let display = r.render_display(s, [0.0; 4]).to_vec();
    let depth = r.display_depth().to_vec();
    let voxel = spec.spacing() as f64;
    let (mut inter_d, mut union_d, mut inter_n, mut union_n) = (0, 0, 0, 0);
    let (mut checked, mut within) = (0usize, 0usize);
    for v in 0..s {
        for u in 0..s {
            let (x, y) = (
                -1.0 + 2.0 * u as f64 / (s - 1) as f64,
                -1.0 + 2.0 * v as f64 / (s - 1) as f64,
            );
            let truth = scene.first_hit_z(x, y, voxel / 8.0);
            let shown = display[(v * s + u) * 4 + 3] == 255;
            // The grid image scaled up by nearest sample (what a browser showed).
            let (i, j) = (
                (u * (n - 1) + (s - 1) / 2) / (s - 1),
                (v * (n - 1) + (s - 1) / 2) / (s - 1),
            );
            let nearest = grid_alpha[i + n * j];
            inter_d += (shown && truth.is_some()) as usize;
            union_d += (shown || truth.is_some()) as usize;
            inter_n += (nearest && truth.is_some()) as usize;
            union_n += (nearest || truth.is_some()) as usize;
            if let (true, Some(z)) = (shown, truth) {
                assert!(depth[v * s + u].is_finite());
                checked += 1;
                within += ((depth[v * s + u] as f64 - z).abs() <= voxel) as usize;
            }
        }
    }
    let (iou_d, iou_n) = (
        inter_d as f64 / union_d as f64,
        inter_n as f64 / union_n as f64,
    );
    let frac = within as f64 / checked as f64;
    eprintln!(
        "silhouette IoU at 257 px from 65^3: display {iou_d:.4}, nearest {iou_n:.4}; depth within a voxel {frac:.4}"
    );
    // Measured: 0.966 against 0.862.
    assert!(iou_d > iou_n + 0.05, "display {iou_d} vs nearest {iou_n}");
    assert!(iou_d > 0.95, "{iou_d}");
    assert!(frac > 0.97, "{frac}");
    assert!(display.chunks_exact(4).all(|p| p[3] == 0 || p[3] == 255));
}

/// The display image is drawn in bands of rows on the renderer's threads: the same bytes and
/// depths at 1, 2, 3 and 8 threads (sizes that do and do not split evenly, one under a
/// band's least rows).
#[test]
fn display_image_is_the_same_on_any_number_of_threads() {
    let scene = AnalyticScene::by_name("capsule-human").unwrap();
    let spec = GridSpec::new(6).unwrap();
    let bg = [0.1, 0.2, 0.3, 1.0];
    let mut one = Renderer::new();
    one.render(&scene, &scene, spec, &RenderOptions::default())
        .unwrap();
    for size in [20, 97, 257, 512] {
        let want = one.render_display(size, bg).to_vec();
        let want_depth = one.display_depth().to_vec();
        assert!(
            want.chunks_exact(4).any(|p| p[3] == 255),
            "{size}: a person drawn"
        );
        for threads in [2, 3, 8] {
            let mut r = Renderer::new();
            r.set_threads(threads);
            r.render(&scene, &scene, spec, &RenderOptions::default())
                .unwrap();
            let got = r.render_display(size, bg).to_vec();
            assert!(got == want, "{size} px on {threads} threads: image differs");
            assert_eq!(r.display_depth(), &want_depth[..], "{size} px on {threads}");
        }
    }
}

/// Pieces apart from the body (`RenderOptions::drop_apart`): a ball floating in front of the
/// body hides part of it. With the pass on, the frame equals, bit for bit (hits, depths, the
/// grid image and a display image), the frame of the same field without the floater, though
/// a seed lies inside the floater; a hand a little apart from the body stays. With it off the
/// floater is drawn, and a renderer that ran the pass draws it again on its next frame.
#[test]
fn pieces_apart_from_the_body_leave_the_render() {
    use volcap_engine::pieces::DEFAULT_GAP;
    fn balls(list: Vec<(Vec3, f32)>) -> impl OccupancyField {
        FnField(move |p: Vec3| {
            let sdf = list
                .iter()
                .map(|(c, r)| (p - *c).length() - r)
                .fold(f32::INFINITY, f32::min);
            (0.5 - sdf / 0.02).clamp(0.0, 1.0)
        })
    }
    let (hand, floater) = (Vec3::new(0.6, 0.0, 0.0), Vec3::new(0.0, 0.0, 0.88));
    // Gaps in NDC (the side is 2): hand 0.15 (7.5 % of the side), floater 0.42 (21 %).
    let with = Seeded {
        field: balls(vec![(Vec3::ZERO, 0.4), (hand, 0.05), (floater, 0.06)]),
        // Off the level L - 1 lattice (z index 121 of 129), where only level L's seeds reach.
        seeds: vec![hand, floater + Vec3::new(0.0, 0.0, 0.016)],
    };
    let without = Seeded {
        field: balls(vec![(Vec3::ZERO, 0.4), (hand, 0.05)]),
        seeds: vec![hand],
    };
    let color = FnColor(|p: Vec3| {
        let c = p.clamp(Vec3::splat(-1.0), Vec3::ONE);
        [0.5 + 0.4 * c.x, 0.5, 0.5 + 0.4 * c.z]
    });
    let spec = GridSpec::new(7).unwrap();
    let n = spec.n();
    let column = |p: Vec3| {
        let [i, j, _] = spec.index_of(p).unwrap();
        i + n * j
    };
    let on = RenderOptions {
        drop_apart: Some(DEFAULT_GAP),
        ..Default::default()
    };
    let (mut a, mut b) = (Renderer::new(), Renderer::new());
    let sa = a.render(&with, &color, spec, &on).unwrap();
    let sb = b.render(&without, &color, spec, &on).unwrap();
    assert!(sa.dropped_apart > 0, "{sa:?}");
    assert_eq!(sb.dropped_apart, 0);
    // (Whole images: a bare assert, not a printed diff.)
    assert!(a.hits() == b.hits(), "hits differ");
    assert!(a.depth() == b.depth(), "depths differ");
    assert!(a.rgba() == b.rgba(), "images differ");
    let bg = [0.1, 0.2, 0.3, 1.0];
    let da = a.render_display(300, bg).to_vec();
    assert!(da == b.render_display(300, bg), "display images differ");
    // The body's front (z = 0.4) where the floater was, and the hand's (z = 0.05).
    let body_z = a.depth()[column(floater)];
    assert!((body_z - 0.4).abs() < 0.03, "{body_z}");
    let hand_z = a.depth()[column(hand)];
    assert!((hand_z - 0.05).abs() < 0.03, "{hand_z}");
    // Off: the floater's front (z = 0.94) is drawn.
    let mut c = Renderer::new();
    let off = RenderOptions::default();
    let sc = c.render(&with, &color, spec, &off).unwrap();
    assert_eq!(sc.dropped_apart, 0);
    let floater_z = c.depth()[column(floater)];
    assert!((floater_z - 0.94).abs() < 0.03, "{floater_z}");
    a.render(&with, &color, spec, &off).unwrap();
    assert!(a.hits() == c.hits(), "hits differ from a fresh renderer's");
    assert!(
        a.rgba() == c.rgba(),
        "images differ from a fresh renderer's"
    );
}

/// Antialiased outline (`Renderer::set_antialias`): each display pixel's coverage against the
/// analytic silhouette's, supersampled 4 x 4 in the pixel (f64 ray casts), where the outline
/// passes (129^3 at 257 pixels). The partial pixels follow the true coverage closer than the binary rule's whole
/// ones; a pixel is covered more than half exactly where the binary rule draws it (the
/// outline stays where it was); inside the silhouette and apart from it nothing changes; the
/// depth is finite wherever something is drawn.
#[test]
fn antialiased_outline_follows_the_analytic_coverage() {
    let scene = AnalyticScene::by_name("capsule-human").unwrap();
    // Two display pixels a cell, as the main job's 257^3 grid at 512 pixels.
    let spec = GridSpec::new(7).unwrap();
    let s = 257usize;
    let mut r = Renderer::new();
    r.render(&scene, &scene, spec, &RenderOptions::default())
        .unwrap();
    let binary = r.render_display(s, [0.0; 4]).to_vec();
    r.set_antialias(true);
    let aa = r.render_display(s, [0.0; 4]).to_vec();
    let aa_depth = r.display_depth().to_vec();
    let voxel = spec.spacing() as f64;
    let px = 2.0 / (s - 1) as f64;
    let shown = |x: f64, y: f64| scene.first_hit_z(x, y, voxel / 4.0).is_some();
    let centre: Vec<bool> = (0..s * s)
        .map(|p| shown(-1.0 + px * (p % s) as f64, -1.0 + px * (p / s) as f64))
        .collect();
    let (mut err_aa, mut err_bin, mut outline, mut partial) = (0.0f64, 0.0f64, 0usize, 0usize);
    for v in 1..s - 1 {
        for u in 1..s - 1 {
            let p = v * s + u;
            let a_aa = aa[p * 4 + 3];
            let a_bin = binary[p * 4 + 3];
            assert_eq!(
                a_aa > 127,
                a_bin == 255,
                "pixel ({u}, {v}): {a_aa} vs {a_bin}"
            );
            if a_aa > 0 {
                assert!(aa_depth[p].is_finite() && aa_depth[p] >= -1.0, "({u}, {v})");
            }
            let near_outline = [p - 1, p + 1, p - s, p + s]
                .iter()
                .any(|&q| centre[q] != centre[p]);
            partial += (a_aa != 0 && a_aa != 255) as usize;
            if !near_outline && a_aa != 0 && a_aa != 255 {
                // A partial pixel away from the true outline: allowed only within a pixel
                // of it (the grid's outline is within a cell of the truth).
                let near2 = [p - 2, p + 2, p - 2 * s, p + 2 * s]
                    .iter()
                    .any(|&q| q < s * s && centre[q] != centre[p]);
                assert!(near2, "partial pixel ({u}, {v}) apart from the outline");
            }
            if !near_outline && a_aa == a_bin {
                continue;
            }
            outline += 1;
            let (x, y) = (-1.0 + px * u as f64, -1.0 + px * v as f64);
            let mut truth = 0.0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let (dx, dy) = ((sx as f64 + 0.5) / 4.0 - 0.5, (sy as f64 + 0.5) / 4.0 - 0.5);
                    truth += shown(x + dx * px, y + dy * px) as u8 as f64 / 16.0;
                }
            }
            err_aa += (a_aa as f64 / 255.0 - truth).abs();
            err_bin += (a_bin as f64 / 255.0 - truth).abs();
        }
    }
    eprintln!(
        "{outline} outline pixels ({partial} partial): coverage error antialiased {:.4}, binary {:.4} a pixel",
        err_aa / outline as f64,
        err_bin / outline as f64
    );
    assert!(partial > outline / 3, "{partial} of {outline}");
    assert!(
        err_aa < 0.7 * err_bin,
        "antialiased {err_aa} vs binary {err_bin}"
    );
    // Opaque background: every drawn pixel opaque, partial ones between the colour and the
    // background.
    let bg = [0.2, 0.4, 0.6, 1.0];
    let opaque = r.render_display(s, bg).to_vec();
    assert!(opaque.chunks_exact(4).all(|p| p[3] == 255));
}
