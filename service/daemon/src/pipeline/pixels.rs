//! The published frame's pixels: a render composited over the background for codecs
//! without alpha, and the camera frame letterboxed into the display square.

/// An RGBA render composited over the background colour `bg` (RGB in [0, 1]) into `out`:
/// 3-byte RGB, or with `pad` 4-byte RGBx (x = 255), for codecs without alpha (the JPEG of
/// the encode stage, RTSP's H.264).
pub fn composite_over(rgba: &[u8], bg: [f32; 4], pad: bool, out: &mut Vec<u8>) {
    out.clear();
    let n = if pad { 4 } else { 3 };
    out.reserve(rgba.len() / 4 * n);
    let mix =
        |p: &[u8], c: usize, a: f32| (p[c] as f32 * a + bg[c] * 255.0 * (1.0 - a)).round() as u8;
    // A render's pixels are opaque (the person) or clear (the background), but for the
    // outline's partial ones (`render.antialias`): those two take the pixel or the
    // background as the rule gives them, without its arithmetic per channel.
    let clear = [0, 1, 2].map(|c| mix(&[0, 0, 0], c, 0.0));
    for p in rgba.chunks_exact(4) {
        let rgb = match p[3] {
            255 => [p[0], p[1], p[2]],
            0 => clear,
            a => {
                let a = a as f32 / 255.0;
                [mix(p, 0, a), mix(p, 1, a), mix(p, 2, a)]
            }
        };
        out.extend_from_slice(&rgb);
        if pad {
            out.push(255);
        }
    }
}

/// The camera frame fitted into a `size x size` RGBA square (aspect kept, nearest sample,
/// integer indices), transparent around it.
pub fn letterbox(rgb: &[u8], w: usize, h: usize, size: usize) -> Vec<u8> {
    let mut out = vec![0u8; size * size * 4];
    if w == 0 || h == 0 || rgb.len() < w * h * 3 {
        return out;
    }
    let (fw, fh) = if w >= h {
        (size, (size * h / w).max(1))
    } else {
        ((size * w / h).max(1), size)
    };
    let (ox, oy) = ((size - fw) / 2, (size - fh) / 2);
    for y in 0..fh {
        let sy = (y * h + h / 2) / fh;
        for x in 0..fw {
            let sx = (x * w + w / 2) / fw;
            let i = (sy.min(h - 1) * w + sx.min(w - 1)) * 3;
            let o = ((oy + y) * size + ox + x) * 4;
            out[o..o + 3].copy_from_slice(&rgb[i..i + 3]);
            out[o + 3] = 255;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Compositing equals the rule `round(p a + bg 255 (1 - a))` at every alpha (the opaque
    /// and clear pixels' shortcuts included), with and without the padding byte.
    #[test]
    fn composite_equals_the_rule_at_every_alpha() {
        let rgba: Vec<u8> = (0..256usize)
            .flat_map(|a| {
                [
                    (a * 7 % 256) as u8,
                    (a * 13 % 256) as u8,
                    255 - a as u8,
                    a as u8,
                ]
            })
            .collect();
        for bg in [
            [0.0f32, 0.0, 0.0, 1.0],
            [1.0, 1.0, 1.0, 1.0],
            [0.2, 0.55, 0.9, 0.0],
        ] {
            for pad in [false, true] {
                let mut out = Vec::new();
                composite_over(&rgba, bg, pad, &mut out);
                let n = if pad { 4 } else { 3 };
                assert_eq!(out.len(), 256 * n);
                for (p, o) in rgba.chunks_exact(4).zip(out.chunks_exact(n)) {
                    let a = p[3] as f32 / 255.0;
                    for c in 0..3 {
                        let want = (p[c] as f32 * a + bg[c] * 255.0 * (1.0 - a)).round() as u8;
                        assert_eq!(o[c], want, "alpha {} channel {c}", p[3]);
                    }
                    if pad {
                        assert_eq!(o[3], 255);
                    }
                }
            }
        }
    }

    #[test]
    fn letterbox_keeps_aspect_and_centres() {
        // 4x2 frame, left half red, right half blue, into 8x8.
        let mut rgb = Vec::new();
        for _y in 0..2 {
            for x in 0..4 {
                rgb.extend_from_slice(if x < 2 { &[255, 0, 0] } else { &[0, 0, 255] });
            }
        }
        let out = letterbox(&rgb, 4, 2, 8);
        let px = |x: usize, y: usize| &out[(y * 8 + x) * 4..(y * 8 + x) * 4 + 4];
        // Rows 2..6 hold the picture, the rest is transparent.
        assert_eq!(px(0, 0)[3], 0);
        assert_eq!(px(0, 7)[3], 0);
        assert_eq!(px(0, 2), [255, 0, 0, 255]);
        assert_eq!(px(7, 5), [0, 0, 255, 255]);
        // Portrait frames are pillarboxed.
        let out = letterbox(&[7u8; 2 * 4 * 3], 2, 4, 8);
        assert_eq!(out[3], 0);
        assert_eq!(&out[(8 * 4 + 2) * 4..(8 * 4 + 2) * 4 + 4], [7, 7, 7, 255]);
        // A short buffer gives an empty frame, not a panic.
        assert!(letterbox(&[1, 2], 4, 2, 8).iter().all(|&b| b == 0));
    }
}
