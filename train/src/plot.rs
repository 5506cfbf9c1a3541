//! Loss curves as PNG, drawn by a small rasteriser into `image` (lines, axes, and labels through
//! the workspace's one text routine, `data::draw`): one file per loss term, training in blue (raw, light; moving average, dark) and
//! validation as red dots.

use std::path::Path;

use image::{Rgb, RgbImage};

use crate::error::{Result, TrainError};

const W: u32 = 720;
const H: u32 = 420;
const LEFT: i64 = 80;
const RIGHT: i64 = 20;
const TOP: i64 = 36;
const BOTTOM: i64 = 40;

fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, c);
    }
}

fn line(img: &mut RgbImage, (x0, y0): (i64, i64), (x1, y1): (i64, i64), c: Rgb<u8>) {
    let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
    let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
    let (mut x, mut y, mut err) = (x0, y0, dx + dy);
    loop {
        put(img, x, y, c);
        if x == x1 && y == y1 {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
        }
    }
}

fn text(img: &mut RgbImage, x: i64, y: i64, s: &str, c: Rgb<u8>) {
    data::draw::text(img, x, y, s, c.0, 8);
}

fn fmt(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.2e}")
    } else {
        format!("{v:.3}")
    }
}

/// Draws `train` (step, value) as a curve, `val` (cold-memory windows) as red dots and
/// `walked` (validation episodes walked with carried memory) as green dots into a PNG at `path`.
pub fn loss_curve(
    path: &Path,
    title: &str,
    train: &[(u64, f64)],
    val: &[(u64, f64)],
    walked: &[(u64, f64)],
) -> Result<()> {
    let mut img = RgbImage::from_pixel(W, H, Rgb([255, 255, 255]));
    let finite = |v: &&(u64, f64)| v.1.is_finite();
    let all: Vec<(u64, f64)> = train
        .iter()
        .chain(val)
        .chain(walked)
        .filter(finite)
        .copied()
        .collect();
    let (x_max, y_min, y_max) = if all.is_empty() {
        (1, 0.0, 1.0)
    } else {
        let x_max = all.iter().map(|p| p.0).max().unwrap_or(1).max(1);
        let lo = all
            .iter()
            .map(|p| p.1)
            .fold(f64::INFINITY, f64::min)
            .min(0.0);
        let hi = all.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        (x_max, lo, if hi > lo { hi } else { lo + 1.0 })
    };
    let (pw, ph) = (W as i64 - LEFT - RIGHT, H as i64 - TOP - BOTTOM);
    let px = |s: u64| LEFT + (s as f64 / x_max as f64 * pw as f64).round() as i64;
    let py = |v: f64| TOP + ph - ((v - y_min) / (y_max - y_min) * ph as f64).round() as i64;
    let grey = Rgb([200, 200, 200]);
    let black = Rgb([0, 0, 0]);
    for k in 0..=4 {
        let y = TOP + ph * k / 4;
        line(&mut img, (LEFT, y), (LEFT + pw, y), grey);
        let v = y_max - (y_max - y_min) * k as f64 / 4.0;
        text(&mut img, 4, y - 4, &fmt(v), black);
    }
    line(&mut img, (LEFT, TOP), (LEFT, TOP + ph), black);
    line(&mut img, (LEFT, TOP + ph), (LEFT + pw, TOP + ph), black);
    text(&mut img, LEFT, TOP + ph + 10, "0", black);
    let xl = format!("step {x_max}");
    text(
        &mut img,
        LEFT + pw - 8 * xl.len() as i64,
        TOP + ph + 10,
        &xl,
        black,
    );
    text(&mut img, LEFT, 12, title, black);
    let pts: Vec<(u64, f64)> = train.iter().filter(finite).copied().collect();
    let light = Rgb([160, 190, 240]);
    for w in pts.windows(2) {
        line(
            &mut img,
            (px(w[0].0), py(w[0].1)),
            (px(w[1].0), py(w[1].1)),
            light,
        );
    }
    // Moving average over ~1/50 of the run.
    let k = (pts.len() / 50).max(1);
    let mut avg = Vec::with_capacity(pts.len());
    let mut sum = 0.0;
    for (i, p) in pts.iter().enumerate() {
        sum += p.1;
        if i >= k {
            sum -= pts[i - k].1;
        }
        avg.push((p.0, sum / (i + 1).min(k) as f64));
    }
    let blue = Rgb([20, 60, 200]);
    for w in avg.windows(2) {
        line(
            &mut img,
            (px(w[0].0), py(w[0].1)),
            (px(w[1].0), py(w[1].1)),
            blue,
        );
    }
    let red = Rgb([220, 30, 30]);
    let green = Rgb([20, 150, 40]);
    for (points, colour) in [(val, red), (walked, green)] {
        for &(s, v) in points.iter().filter(finite) {
            for d in -2..=2 {
                line(
                    &mut img,
                    (px(s) - 2, py(v) + d),
                    (px(s) + 2, py(v) + d),
                    colour,
                );
            }
        }
    }
    text(&mut img, LEFT + pw - 260, 12, "train", blue);
    text(&mut img, LEFT + pw - 200, 12, "val", red);
    if !walked.is_empty() {
        text(&mut img, LEFT + pw - 160, 12, "walked", green);
    }
    data::fsio::write_png(path, &img).map_err(TrainError::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_a_png_with_the_curve() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("loss.png");
        let train: Vec<(u64, f64)> = (1..100).map(|s| (s, 1.0 / s as f64)).collect();
        loss_curve(&p, "loss", &train, &[(50, 0.1), (99, f64::NAN)], &[]).unwrap();
        let img = image::open(&p).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (W, H));
        assert!(img.pixels().any(|p| *p == Rgb([20, 60, 200])));
        assert!(img.pixels().any(|p| *p == Rgb([220, 30, 30])));
        assert!(!img.pixels().any(|p| *p == Rgb([20, 150, 40])));
        loss_curve(&p, "loss", &train, &[(50, 0.1)], &[(50, 0.3)]).unwrap();
        let img = image::open(&p).unwrap().to_rgb8();
        assert!(img.pixels().any(|p| *p == Rgb([20, 150, 40])));
        loss_curve(&p, "empty", &[], &[], &[]).unwrap();
    }
}
