//! The overlay: lines of 8×8 bitmap text drawn into the presented RGBA8 frame (never into the
//! AOV or a screenshot taken without `--overlay`).

use font8x8::legacy::BASIC_LEGACY;

/// Draws `lines` at the top-left of `rgba8` (`width × height`) over a darkened box; `scale`
/// is the glyph magnification (1 = 8 px). Non-ASCII characters draw as `?`.
pub fn draw_text(rgba8: &mut [u8], width: u32, height: u32, lines: &[String], scale: u32) {
    let scale = scale.max(1) as usize;
    let (w, h) = (width as usize, height as usize);
    if rgba8.len() < w * h * 4 {
        return;
    }
    let glyph = 8 * scale;
    let line_h = glyph + 2 * scale;
    let cols = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    let box_w = (cols * glyph + 8 * scale).min(w);
    let box_h = (lines.len() * line_h + 4 * scale).min(h);
    for y in 0..box_h {
        for x in 0..box_w {
            let p = &mut rgba8[(y * w + x) * 4..(y * w + x) * 4 + 3];
            p.iter_mut().for_each(|c| *c /= 3);
        }
    }
    for (row, line) in lines.iter().enumerate() {
        let y0 = 2 * scale + row * line_h;
        for (col, ch) in line.chars().enumerate() {
            let code = if ch.is_ascii() {
                ch as usize
            } else {
                b'?' as usize
            };
            let bits = BASIC_LEGACY[code];
            let x0 = 4 * scale + col * glyph;
            for (gy, byte) in bits.iter().enumerate() {
                for gx in 0..8 {
                    if byte & (1 << gx) == 0 {
                        continue;
                    }
                    for sy in 0..scale {
                        for sx in 0..scale {
                            let (x, y) = (x0 + gx * scale + sx, y0 + gy * scale + sy);
                            if x < w && y < h {
                                rgba8[(y * w + x) * 4..(y * w + x) * 4 + 3]
                                    .copy_from_slice(&[235, 235, 235]);
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_lights_pixels_inside_its_box_only() {
        let (w, h) = (64u32, 32u32);
        let mut px = vec![90u8; (w * h * 4) as usize];
        draw_text(&mut px, w, h, &["Hi".to_string()], 1);
        let at = |x: usize, y: usize| px[(y * w as usize + x) * 4];
        // 'H' has its left stem lit in its first glyph columns; the box darkens the rest.
        let lit = (0..12).flat_map(|y| (0..24).map(move |x| (x, y)));
        assert!(lit.clone().any(|(x, y)| at(x, y) == 235));
        assert!(lit.clone().any(|(x, y)| at(x, y) == 30));
        // Outside the box nothing changed.
        assert_eq!(at(60, 30), 90);
    }
}
