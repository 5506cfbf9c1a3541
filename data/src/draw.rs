//! The one text-drawing routine of the workspace (contact sheets, loss curves): 8×8 bitmap
//! glyphs of `font8x8` stamped into an `image::RgbImage`.

use font8x8::UnicodeFonts;
use image::{Rgb, RgbImage};

/// Draws `text` with its top-left corner at (x, y), one glyph every `advance` pixels, in
/// `color`; pixels outside the image are skipped, characters without a glyph leave a gap.
pub fn text(img: &mut RgbImage, x: i64, y: i64, text: &str, color: [u8; 3], advance: u32) {
    for (i, ch) in text.chars().enumerate() {
        let glyph = font8x8::BASIC_FONTS.get(ch).unwrap_or([0; 8]);
        let ox = x + i as i64 * advance as i64;
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8i64 {
                let (px, py) = (ox + col, y + row as i64);
                if bits >> col & 1 == 1
                    && px >= 0
                    && py >= 0
                    && (px as u32) < img.width()
                    && (py as u32) < img.height()
                {
                    img.put_pixel(px as u32, py as u32, Rgb(color));
                }
            }
        }
    }
}

/// The longest prefix of `text` whose glyphs (every `advance` pixels, 8 wide) fit in `width`.
pub fn fitting(text: &str, width: u32, advance: u32) -> &str {
    let n = if width < 8 {
        0
    } else {
        ((width - 8) / advance.max(1) + 1) as usize
    };
    match text.char_indices().nth(n) {
        Some((i, _)) => &text[..i],
        None => text,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glyphs_land_inside_and_clip_at_the_border() {
        let mut img = RgbImage::new(20, 10);
        text(&mut img, 0, 0, "AB", [255, 0, 0], 8);
        let lit = img.pixels().filter(|p| p.0 == [255, 0, 0]).count();
        assert!(lit > 20, "{lit}");
        // Nothing drawn past column 16 (two glyphs of 8).
        for y in 0..10 {
            for x in 16..20 {
                assert_eq!(img.get_pixel(x, y).0, [0, 0, 0]);
            }
        }
        let mut off = RgbImage::new(4, 4);
        text(&mut off, -100, -100, "A", [1, 1, 1], 8);
        assert!(off.pixels().all(|p| p.0 == [0, 0, 0]));
        assert_eq!(fitting("abcdef", 22, 7), "abc");
        assert_eq!(fitting("abc", 100, 7), "abc");
        assert_eq!(fitting("abc", 5, 7), "");
    }
}
