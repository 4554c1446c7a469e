//! `Crop::paste_max`, the second segmentation pass's rule (`Models::person_mask` with
//! `segment_passes` 2; `seg_masks.paste_max` in training).

use volcap_engine::model::preprocess::Crop;

/// `Crop::paste_max` (the second segmentation pass's rule, `seg_masks.paste_max` in
/// training): the larger value inside the crop's square, nothing outside it changed.
#[test]
fn a_crop_mask_is_pasted_back_by_its_larger_value_inside_the_crop_only() {
    let n = 64;
    let mut into = vec![0.0f32; n * n];
    for v in &mut into[30 * n..34 * n] {
        *v = 0.7;
    }
    let m2: Vec<f32> = (0..n * n)
        .map(|i| ((i * 37) % 101) as f32 / 100.0)
        .collect();
    let id = Crop {
        s: 1.0,
        tx: 0.0,
        ty: 0.0,
        cut_by_frame: false,
    };
    let mut out = into.clone();
    id.paste_max(&m2, n, &mut out);
    // (Within f32 rounding: a pixel's NDC and back lands a hair off its centre.)
    for i in 0..n * n {
        assert!((out[i] - into[i].max(m2[i])).abs() < 1e-4, "pixel {i}");
    }
    // A half-size crop over the upper left quadrant (input NDC x, y <= 0).
    let q = Crop {
        s: 0.5,
        tx: -0.5,
        ty: -0.5,
        cut_by_frame: false,
    };
    let mut out = into.clone();
    q.paste_max(&vec![1.0; n * n], n, &mut out);
    let ndc = |i: usize| -1.0 + 2.0 * i as f32 / (n - 1) as f32;
    for y in 0..n {
        for x in 0..n {
            let i = y * n + x;
            if ndc(x) <= 0.0 && ndc(y) <= 0.0 {
                assert!((out[i] - 1.0).abs() < 1e-6, "({x}, {y}) inside");
            } else {
                assert_eq!(out[i], into[i], "({x}, {y}) outside");
            }
        }
    }
    // Nothing is lowered.
    let mut out = into.clone();
    q.paste_max(&vec![0.0; n * n], n, &mut out);
    assert_eq!(out, into);
}
