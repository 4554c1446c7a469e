//! The temporal filter of the Fourier maps on the adapter (`gpu::maps`, the GPU backend's
//! frames) against the host's `Temporal::steady_maps` on the same maps, frame by frame: a
//! still person with tremor, a moving crop, a frame whose maps are not finite, a gap that
//! starts the filter again, and the colour features of a turned view (blended on the host
//! with the weights the adapter gives back). Lavapipe here and in CI.
#![cfg(feature = "wgpu")]

mod common;

use common::gpu;
use volcap_engine::gpu::maps::{FrameError, MapsHead, maps_frame};
use volcap_engine::model::fourier::{Basis, FourierMaps};
use volcap_engine::model::preprocess::Crop;
use volcap_engine::model::temporal::{MapLayout, Temporal, TemporalSettings};

const S: usize = 256;

/// A person's box in the letterboxed mask, shifted right by `dx` pixels.
fn mask(dx: usize) -> Vec<f32> {
    let mut m = vec![0.0f32; S * S];
    for y in 40..220 {
        for x in 90 + dx..150 + dx {
            m[y * S + x] = 0.95;
        }
    }
    m
}

/// Planar maps `[2K + 1, size, size]`: a smooth pattern that drifts with `frame` where
/// `moving` (its right half), with a per-frame tremor of 2 % everywhere.
fn planar(head: MapsHead, frame: usize, moving: bool) -> Vec<f32> {
    let (c, size) = (head.channels(), head.size);
    let mut out = Vec::with_capacity(c * size * size);
    for ch in 0..c {
        for p in 0..size * size {
            let (x, y) = (
                (p % size) as f32 / size as f32,
                (p / size) as f32 / size as f32,
            );
            let drift = if moving && x > 0.5 {
                0.3 * frame as f32
            } else {
                0.0
            };
            let base = ((ch as f32 + 1.0) * (3.0 * x + 2.0 * y + drift)).sin() / (ch as f32 + 1.0);
            let tremor = 0.02 * (((p * 7 + ch * 13 + frame * 31) % 17) as f32 / 8.0 - 1.0);
            out.push(base + tremor);
        }
    }
    out
}

/// Colour features `[channels, size, size]` (planar) of a frame.
fn colour(l: MapLayout, frame: usize) -> Vec<f32> {
    (0..l.channels * l.size * l.size)
        .map(|i| ((i * 31 + frame * 7) % 23) as f32 / 11.0 - 1.0)
        .collect()
}

fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

#[test]
fn the_maps_filter_on_the_adapter_gives_the_hosts_maps_frame_by_frame() {
    let Some(gpu) = gpu() else { return };
    // The maps not following the mask's motion, and following it (`map_motion_weight`, at
    // a weight under the default 1 so that those pixels still blend): the same maps on
    // both sides, and the motion changes them where the box moves.
    let plain = parity(
        &gpu,
        TemporalSettings {
            map_motion_weight: 0.0,
            ..TemporalSettings::default()
        },
    );
    let following = parity(
        &gpu,
        TemporalSettings {
            map_motion_weight: 0.7,
            ..TemporalSettings::default()
        },
    );
    let changed = plain
        .iter()
        .zip(&following)
        .filter(|(a, b)| max_diff(a, b) > 1e-3)
        .count();
    assert!(changed >= 3, "the mask's motion changed {changed} frames");
}

/// The frames of the test above under `settings`, on the adapter and the host, compared
/// frame by frame; the host's filtered maps of each frame that has them.
fn parity(
    gpu: &std::sync::Arc<volcap_engine::gpu::Gpu>,
    settings: TemporalSettings,
) -> Vec<Vec<f32>> {
    let gpu = gpu.clone();
    let head = MapsHead {
        k: 15,
        size: 128,
        basis: Basis::Fourier,
        zeta_scale: 1.0,
        iso_level: 0.55,
        smooth: 0,
    };
    let interleaved = MapLayout {
        channels: head.channels(),
        size: head.size,
        interleaved: true,
    };
    // The colour features at another size on some frames, at the maps' size on others.
    let colour_small = MapLayout {
        channels: 4,
        size: 64,
        interleaved: false,
    };
    let colour_same = MapLayout {
        channels: 3,
        size: 128,
        interleaved: false,
    };
    let mut host = Temporal::new(settings);
    let mut dev = Temporal::new(settings);
    let mut out = Vec::new();
    // (time s, crop shift px, maps drifting, maps not finite, colour features)
    let mut frames: Vec<(f64, usize, bool, bool, Option<MapLayout>)> = Vec::new();
    let mut t = 0.0;
    for i in 0..4 {
        frames.push((t, 0, false, false, None));
        t += 1.0 / 30.0;
        let _ = i;
    }
    for i in 0..4 {
        frames.push((t, 3 * (i + 1), true, false, None));
        t += 1.0 / 30.0;
    }
    frames.push((t, 12, true, true, None));
    t += 1.0 / 30.0;
    frames.push((t, 12, false, false, None));
    t += 2.0; // a gap: starts again
    frames.push((t, 12, false, false, Some(colour_small)));
    for i in 0..3 {
        t += 1.0 / 30.0;
        frames.push((t, 12 + i, i > 0, false, Some(colour_small)));
    }
    for i in 0..2 {
        t += 1.0 / 30.0;
        frames.push((t, 15 + 2 * i, true, false, Some(colour_same)));
    }
    let mut filtered_somewhere = 0usize;
    let mut worst = 0.0f32;
    let mut colour_blended = 0usize;
    for (f, &(t_s, dx, moving, bad, col)) in frames.iter().enumerate() {
        let mut m_host = mask(dx);
        let mut m_dev = m_host.clone();
        let raw = Crop::from_mask(&m_host, S).expect("a person");
        let (c_host, _) = host.steady_input(t_s, 1, &mut m_host, raw);
        let (c_dev, _) = dev.steady_input(t_s, 1, &mut m_dev, raw);
        let crop = c_host.expect("a person");
        assert_eq!(Some(crop), c_dev);
        let mut maps = planar(head, f, moving);
        if bad {
            maps[12345] = f32::NAN;
        }
        let mut col_host = col.map(|l| (l, colour(l, f)));
        let mut col_dev = col_host.clone();
        // The device's frame: the filter's step, the maps through it, the colour after.
        let filter = dev
            .adapter_filter(
                &gpu,
                head,
                crop,
                col_dev.as_ref().map(|(_, d)| d.as_slice()),
            )
            .expect("filter state");
        let got = maps_frame(&gpu, &maps, head, Some(filter));
        // The host's frame: maps that are not finite stop before the filter (the encoder
        // refuses them: `FourierMaps::from_planar`).
        let Some(host_maps) = FourierMaps::from_planar(&maps, head.k, head.size, head.zeta_scale)
        else {
            assert!(bad);
            assert_eq!(got.err(), Some(FrameError::NotFinite), "frame {f}");
            continue;
        };
        assert!(!bad);
        let (dev_maps, weights) = got.expect("a frame");
        dev.adapter_done(
            crop,
            weights,
            col_dev.as_mut().map(|(l, d)| (*l, d.as_mut_slice())),
        );
        let mut host_maps = host_maps.with_iso_level(head.iso_level);
        let raw_maps = host_maps.coefficients().to_vec();
        host.steady_maps(
            crop,
            (interleaved, host_maps.coefficients_mut()),
            col_host.as_mut().map(|(l, d)| (*l, d.as_mut_slice())),
        );
        out.push(host_maps.coefficients().to_vec());
        let back = dev_maps.host().expect("maps read back");
        let d = max_diff(back.coefficients(), host_maps.coefficients());
        assert!(d <= 1e-5, "frame {f}: the adapter's maps differ by {d}");
        worst = worst.max(d);
        assert_eq!(back.iso_level(), host_maps.iso_level());
        // The filter did something (so the comparison is not of two unfiltered copies).
        if max_diff(&raw_maps, host_maps.coefficients()) > 1e-3 {
            filtered_somewhere += 1;
        }
        if let (Some((_, a)), Some((_, b))) = (&col_dev, &col_host) {
            let d = max_diff(a, b);
            assert!(d <= 1e-5, "frame {f}: colour features differ by {d}");
            worst = worst.max(d);
            if max_diff(a, &colour(col.expect("colour"), f)) > 1e-3 {
                colour_blended += 1;
            }
        }
    }
    println!("largest difference from the host's filter: {worst:e}");
    assert!(
        filtered_somewhere >= 8,
        "the maps were filtered on {filtered_somewhere} frames"
    );
    assert!(
        colour_blended >= 3,
        "colour blended on {colour_blended} frames"
    );
    out
}

/// The maps' buffer on the adapter holds the network's output interleaved (the host's
/// layout), and a frame with a value that is not finite is refused without filtering.
#[test]
fn maps_on_the_adapter_are_the_hosts_interleaved_maps() {
    let Some(gpu) = gpu() else { return };
    for (k, size) in [(15, 128), (7, 33)] {
        let head = MapsHead {
            k,
            size,
            basis: Basis::Cosine,
            zeta_scale: 0.8,
            iso_level: 0.45,
            smooth: 0,
        };
        let maps = planar(head, 3, true);
        let before = gpu.counters();
        let (m, w) = maps_frame(&gpu, &maps, head, None).expect("a frame");
        let after = gpu.counters();
        assert!(w.is_none());
        // One wait (the flag, with the timestamps where the adapter has them); the maps do
        // not come back.
        assert_eq!(after.waits - before.waits, 1);
        let stamps = if gpu.has_timestamps() { 16 } else { 0 };
        assert_eq!(after.bytes_down - before.bytes_down, 4 + stamps);
        assert_eq!(
            after.maps_gpu_ns > before.maps_gpu_ns,
            gpu.has_timestamps(),
            "the frame timed on the adapter's clock"
        );
        let want = FourierMaps::from_planar(&maps, k, size, 0.8)
            .expect("finite")
            .with_iso_level(0.45)
            .with_basis(Basis::Cosine);
        let got = m.host().expect("read back");
        assert_eq!(got.coefficients(), want.coefficients());
        assert_eq!(got.basis(), Basis::Cosine);
        assert_eq!(got.iso_level(), want.iso_level());
        let mut bad = maps.clone();
        bad[maps.len() - 1] = f32::INFINITY;
        assert_eq!(
            maps_frame(&gpu, &bad, head, None).err(),
            Some(FrameError::NotFinite)
        );
        assert!(maps_frame(&gpu, &maps[1..], head, None).is_err());
    }
}

/// The smoothing across pixels on the adapter (`gpu/maps/smooth_region.wgsl`,
/// `smooth.wgsl` and `smooth_keep.wgsl`) is the host's `FourierMaps::smoothed`: the region,
/// a thin strip left out, then one to three passes (odd counts end in the other buffer and
/// are copied back), then the pixels whose smoothed rays lost one of their own inside runs
/// given their own back (the adapter without it is 0.023 off), frame buffers reused from
/// the pool between counts, the maps changed where the person is; a frame with a value that
/// is not finite is still refused.
#[test]
fn the_maps_smoothed_on_the_adapter_are_the_hosts() {
    let Some(gpu) = gpu() else { return };
    for (k, size) in [(15, 128), (7, 33)] {
        for smooth in [1u8, 2, 3, 1] {
            let head = MapsHead {
                k,
                size,
                basis: Basis::Fourier,
                zeta_scale: 1.0,
                iso_level: 0.5,
                smooth,
            };
            let mut maps = planar(head, 2, false);
            // A gap of 6 columns across the upper rows with a strip 2 pixels wide in it (c0
            // negative beside it): the region leaves the strip out, which the adapter's
            // erosion and dilation must agree on.
            for (p, c0) in maps.iter_mut().enumerate().take(size * size / 2) {
                let x = p % size;
                if (4..10).contains(&x) && !(6..8).contains(&x) {
                    *c0 = -0.5;
                }
            }
            let (m, _) = maps_frame(&gpu, &maps, head, None).expect("a frame");
            let plain = FourierMaps::from_planar(&maps, k, size, 1.0).expect("finite");
            let want = plain.clone().smoothed(smooth);
            let got = m.host().expect("read back");
            let d = max_diff(got.coefficients(), want.coefficients());
            assert!(d < 1e-5, "K {k}, {size} px, {smooth} passes: {d}");
            let moved = max_diff(got.coefficients(), plain.coefficients());
            assert!(
                moved > 1e-3,
                "K {k}, {size} px, {smooth} passes changed nothing"
            );
            let c = head.channels();
            let strip = &plain.coefficients()[(2 * size + 6) * c..(2 * size + 8) * c];
            assert_eq!(
                &got.coefficients()[(2 * size + 6) * c..(2 * size + 8) * c],
                strip
            );
            let mut bad = maps.clone();
            bad[size * size / 2] = f32::NAN;
            assert_eq!(
                maps_frame(&gpu, &bad, head, None).err(),
                Some(FrameError::NotFinite)
            );
        }
    }
}
