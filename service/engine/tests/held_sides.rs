//! The surface's dead band (`volcap_engine::sides`) through the renderer and the localizer:
//! a still, noisy field whose faces lie on grid planes (the crown's case) renders the same
//! frame after frame with it and flickers without; a real move goes through; a frame of
//! another alignment is rendered as if nothing were remembered.

mod common;

use common::noisy_box;
use volcap_engine::field::{FnColor, FnField};
use volcap_engine::grid::{Grid, GridSpec};
use volcap_engine::localize::{Localizer, Method};
use volcap_engine::render::{RenderOptions, Renderer};

/// Per frame: the alpha image and the depth image of the renderer.
fn frames(
    band: f32,
    key: impl Fn(u32) -> Option<u64>,
    half: impl Fn(u32) -> f32,
) -> Vec<(Vec<u8>, Vec<f32>, u64)> {
    let spec = GridSpec::new(6).unwrap();
    let colors = FnColor(|_| [0.5, 0.5, 0.5]);
    let mut r = Renderer::new();
    (0..8)
        .map(|f| {
            let field = FnField(noisy_box(half(f), 0.02, f));
            r.hold_sides(band, key(f));
            let st = r
                .render(&field, &colors, spec, &RenderOptions::default())
                .unwrap();
            let alpha = r.rgba().chunks_exact(4).map(|p| p[3]).collect();
            assert!(r.depth().iter().all(|d| d.is_finite()));
            (alpha, r.depth().to_vec(), st.held_sides)
        })
        .collect()
}

#[test]
fn a_still_noisy_field_renders_steady_with_the_band_and_moves_go_through() {
    let still = |_| 0.5;
    let same_key = |_| Some(1u64);
    let off = frames(0.0, same_key, still);
    let on = frames(0.06, same_key, still);
    let changed = |fs: &[(Vec<u8>, Vec<f32>, u64)]| -> usize {
        fs.windows(2)
            .skip(1)
            .map(|w| {
                let alpha = w[0].0.iter().zip(&w[1].0).filter(|(a, b)| a != b).count();
                // The front face on a grid plane: its surface steps a cell back and forth.
                let depth = w[0].1.iter().zip(&w[1].1);
                alpha + depth.filter(|(a, b)| (*a - *b).abs() > 0.25 / 32.0).count()
            })
            .sum()
    };
    let (c_off, c_on) = (changed(&off), changed(&on));
    eprintln!("pixels changed between frames: {c_off} without the band, {c_on} with");
    assert!(
        c_off > 20,
        "the noise does not flicker the test box: {c_off}"
    );
    assert_eq!(c_on, 0, "the band let a still box flicker");
    // From the second frame on nothing changes at all.
    assert!(
        on.windows(2)
            .skip(1)
            .all(|w| w[0].1 == w[1].1 && w[0].0 == w[1].0)
    );
    assert_eq!(on[0].2, 0, "held points on a first frame");
    assert!(on[1..].iter().all(|f| f.2 > 0));
    // Without a key (or with a new key each frame) nothing is held: frame for frame the
    // frames without the band.
    let no_key = frames(0.06, |_| None, still);
    let new_key = frames(0.06, |f| Some(f as u64), still);
    for fs in [&no_key, &new_key] {
        for (a, b) in fs.iter().zip(&off) {
            assert_eq!(a.0, b.0);
            assert_eq!(a.1, b.1);
            assert_eq!(a.2, 0);
        }
    }
    // A box growing by a cell a frame (1/32 of the half-extent) grows on the display with
    // the band as without it.
    let grow = |f: u32| 0.4 + f as f32 / 32.0;
    let (g_off, g_on) = (frames(0.0, same_key, grow), frames(0.06, same_key, grow));
    for (f, (a, b)) in g_off.iter().zip(&g_on).enumerate() {
        let shown = |x: &[u8]| x.iter().filter(|&&a| a == 255).count();
        let (sa, sb) = (shown(&a.0), shown(&b.0));
        assert!(
            sa.abs_diff(sb) * 50 <= sa,
            "frame {f}: {sa} pixels without, {sb} with"
        );
        if f > 0 {
            assert!(sb > shown(&g_on[f - 1].0), "frame {f} did not grow");
        }
    }
}

/// The localizer holds the same way (`bench temporal`'s path): a still noisy box localizes
/// to the same binarized grid frame after frame.
#[test]
fn the_localizer_holds_the_sides_of_a_still_noisy_field() {
    let spec = GridSpec::new(6).unwrap();
    let mut loc = Localizer::new();
    let mut grid = Grid::new(spec);
    let mut flips = [0usize; 2];
    for (i, band) in [0.0f32, 0.06].into_iter().enumerate() {
        loc.forget_sides();
        let mut last: Option<Vec<bool>> = None;
        for f in 0..6 {
            let field = FnField(noisy_box(0.5, 0.02, f));
            loc.hold_sides(band, Some(3));
            loc.run(Method::Hierarchical, &field, spec, 3, &mut grid)
                .unwrap();
            let bin: Vec<bool> = grid.values.iter().map(|&v| v > 0.5).collect();
            if let Some(l) = last.as_ref().filter(|_| f > 1) {
                flips[i] += l.iter().zip(&bin).filter(|(a, b)| a != b).count();
            }
            last = Some(bin);
        }
    }
    eprintln!(
        "grid points changing side: {} without, {} with",
        flips[0], flips[1]
    );
    assert!(flips[0] > 20);
    assert_eq!(flips[1], 0);
    assert!(loc.held_sides() > 0);
}
