//! Contact sheets: labelled tiles of rendered frames in one PNG (`docs/tasks.png`).

use image::{Rgb, RgbImage};

use crate::engine::render::Frame;

/// Height of the label strip under each tile, in pixels.
const LABEL_H: u32 = 12;

/// Lays `tiles` out `cols` per row, each with its label (8×8 bitmap font) underneath.
pub fn contact_sheet(tiles: &[(String, Frame)], cols: usize) -> Option<RgbImage> {
    let first = &tiles.first()?.1;
    let (tw, th) = (first.width as u32, first.height as u32);
    let cols = cols.max(1) as u32;
    let rows = (tiles.len() as u32).div_ceil(cols);
    let pad = 4;
    let mut img = RgbImage::from_pixel(
        cols * (tw + pad) + pad,
        rows * (th + LABEL_H + pad) + pad,
        Rgb([255, 255, 255]),
    );
    for (k, (label, frame)) in tiles.iter().enumerate() {
        let rgb = frame.rgb.as_ref()?;
        if frame.width as u32 != tw || frame.height as u32 != th {
            return None;
        }
        let (cx, cy) = (
            (k as u32 % cols) * (tw + pad) + pad,
            (k as u32 / cols) * (th + LABEL_H + pad) + pad,
        );
        for y in 0..th {
            for x in 0..tw {
                let i = 3 * (y * tw + x) as usize;
                img.put_pixel(cx + x, cy + y, Rgb([rgb[i], rgb[i + 1], rgb[i + 2]]));
            }
        }
        draw_text(&mut img, cx, cy + th + 2, label, tw);
    }
    Some(img)
}

/// Draws `text` in black at (x, y), cut to the glyphs that fit in `max_w` pixels.
fn draw_text(img: &mut RgbImage, x: u32, y: u32, text: &str, max_w: u32) {
    let shown = data::draw::fitting(text, max_w, 7);
    data::draw::text(img, x as i64, y as i64, shown, [0, 0, 0], 7);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_and_labels_land_where_expected() {
        let frame = |v: u8| Frame {
            width: 4,
            height: 4,
            rgb: Some(vec![v; 48]),
            ..Frame::default()
        };
        let img = contact_sheet(
            &[
                ("a".into(), frame(10)),
                ("b".into(), frame(200)),
                ("c".into(), frame(90)),
            ],
            2,
        )
        .unwrap();
        assert_eq!(img.dimensions(), (2 * 8 + 4, 2 * (4 + 12 + 4) + 4));
        assert_eq!(img.get_pixel(4, 4).0, [10, 10, 10]);
        assert_eq!(img.get_pixel(12, 4).0, [200, 200, 200]);
        assert_eq!(img.get_pixel(4, 24).0, [90, 90, 90]);
        assert!(contact_sheet(&[], 2).is_none());
    }
}
