//! Placeholder frames: what the stream shows while there is nothing true to render (camera
//! gone, no person or several people in view), so a TV viewer reads why instead of staring
//! at a frozen or garbled picture. Text is drawn with the public-domain 8x8 bitmap font.

use font8x8::UnicodeFonts;

/// An RGBA frame `size x size`: the background colour (opaque), a title line and the reason,
/// word-wrapped, centred.
pub fn frame(size: usize, background: [f32; 4], title: &str, reason: &str) -> Vec<u8> {
    let bg = [0, 1, 2].map(|c| (background[c].clamp(0.0, 1.0) * 255.0).round() as u8);
    let mut px: Vec<u8> = std::iter::repeat_n([bg[0], bg[1], bg[2], 255], size * size)
        .flatten()
        .collect();
    let scale = (size / 256).max(1);
    let cols = (size / (8 * scale)).saturating_sub(2).max(1);
    let mut lines = vec![(title.to_string(), [255u8, 190, 60])];
    lines.extend(wrap(reason, cols).into_iter().map(|l| (l, [230, 230, 230])));
    let line_h = 10 * scale;
    let top = size.saturating_sub(lines.len() * line_h) / 2;
    for (k, (line, colour)) in lines.iter().enumerate() {
        let width = line.chars().count() * 8 * scale;
        let left = size.saturating_sub(width) / 2;
        for (i, ch) in line.chars().enumerate() {
            let glyph = font8x8::BASIC_FONTS.get(ch).unwrap_or([0; 8]);
            for (gy, row) in glyph.iter().enumerate() {
                for gx in 0..8 {
                    if row >> gx & 1 == 0 {
                        continue;
                    }
                    for sy in 0..scale {
                        for sx in 0..scale {
                            let x = left + (i * 8 + gx) * scale + sx;
                            let y = top + k * line_h + gy * scale + sy;
                            if x < size && y < size {
                                let o = (y * size + x) * 4;
                                px[o..o + 3].copy_from_slice(colour);
                            }
                        }
                    }
                }
            }
        }
    }
    px
}

/// Greedy word wrap at `cols` characters; words longer than a line are cut.
fn wrap(text: &str, cols: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut cur = String::new();
    for word in text.split_whitespace() {
        let mut word: Vec<char> = word.chars().collect();
        while word.len() > cols {
            if !cur.is_empty() {
                lines.push(std::mem::take(&mut cur));
            }
            lines.push(word.drain(..cols).collect());
        }
        let word: String = word.into_iter().collect();
        if word.is_empty() {
            continue;
        }
        if !cur.is_empty() && cur.chars().count() + 1 + word.chars().count() > cols {
            lines.push(std::mem::take(&mut cur));
        }
        if !cur.is_empty() {
            cur.push(' ');
        }
        cur.push_str(&word);
    }
    if !cur.is_empty() {
        lines.push(cur);
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wraps_within_the_line_and_keeps_every_word() {
        let text = "camera unplugged mid-stream: /dev/video0: No such device; retrying in 2.0 s";
        for cols in [8, 14, 30] {
            let l = wrap(text, cols);
            assert!(l.iter().all(|s| s.chars().count() <= cols), "{l:?}");
            assert_eq!(l.concat().replace(' ', ""), text.replace(' ', ""));
        }
    }

    #[test]
    fn text_is_drawn_opaque_on_the_background() {
        for size in [129, 257, 513] {
            let f = frame(
                size,
                [0.1, 0.1, 0.1, 0.0],
                "CAMERA LOST",
                "no device: /dev/video0",
            );
            assert_eq!(f.len(), size * size * 4);
            assert!(f.chunks_exact(4).all(|p| p[3] == 255));
            let lit = f.chunks_exact(4).filter(|p| p[0] > 200).count();
            // Some glyph pixels, but far from all of the frame.
            assert!(lit > 40 && lit < size * size / 4, "{size}: {lit}");
        }
    }
}
