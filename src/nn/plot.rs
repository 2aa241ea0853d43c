//! The loss curve as a PNG: training and validation MSE per epoch on a
//! log scale, drawn directly with an 8×8 bitmap font for the labels.

use std::path::Path;

use font8x8::{BASIC_FONTS, UnicodeFonts};
use image::{Rgb, RgbImage};

const INK: Rgb<u8> = Rgb([40, 40, 40]);
const TRAIN: Rgb<u8> = Rgb([40, 90, 200]);
const VALIDATION: Rgb<u8> = Rgb([220, 60, 40]);

/// Writes `text` with its top-left corner at (x, y), clipped to the image.
fn text(img: &mut RgbImage, x: i64, y: i64, text: &str, color: Rgb<u8>) {
    for (k, ch) in text.chars().enumerate() {
        let glyph = BASIC_FONTS.get(ch).unwrap_or([0; 8]);
        for (row, bits) in glyph.iter().enumerate() {
            for col in 0..8 {
                let (px, py) = (x + 8 * k as i64 + col, y + row as i64);
                let inside =
                    px >= 0 && py >= 0 && px < img.width() as i64 && py < img.height() as i64;
                if bits >> col & 1 == 1 && inside {
                    img.put_pixel(px as u32, py as u32, color);
                }
            }
        }
    }
}

use crate::error::{Error, Result};

pub fn loss_curve(curve: &[(f64, f64)], path: &Path) -> Result<()> {
    let (w, h) = (640u32, 400u32);
    let mut img = RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let values: Vec<f64> = curve
        .iter()
        .flat_map(|(a, b)| [*a, *b])
        .filter(|v| *v > 0.0)
        .collect();
    if values.is_empty() {
        return Err(Error::config("--plot", "no epochs to plot"));
    }
    let lo = values
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min)
        .log10()
        .floor();
    let hi = values
        .iter()
        .cloned()
        .fold(0.0, f64::max)
        .log10()
        .ceil()
        .max(lo + 1.0);
    let (left, right, top, bottom) = (56.0, w as f64 - 10.0, 28.0, h as f64 - 36.0);
    let px = |epoch: usize| left + (right - left) * epoch as f64 / (curve.len().max(2) - 1) as f64;
    let py = |v: f64| top + (bottom - top) * (hi - v.max(1e-30).log10()) / (hi - lo);
    // Decade grid lines.
    let mut decade = lo;
    while decade <= hi {
        let y = py(10f64.powf(decade)) as u32;
        for x in left as u32..right as u32 {
            img.put_pixel(x, y.min(h - 1), Rgb([220, 220, 220]));
        }
        text(&mut img, 4, y as i64 - 4, &format!("1e{decade}"), INK);
        decade += 1.0;
    }
    let last = curve.len().max(2) - 1;
    for epoch in [0, last / 2, last] {
        let label = format!("{}", epoch + 1);
        let width = 8 * label.len() as i64;
        let x = (px(epoch) as i64 - width / 2).min(w as i64 - width - 2);
        text(&mut img, x, bottom as i64 + 6, &label, INK);
    }
    text(
        &mut img,
        (left + right) as i64 / 2 - 20,
        h as i64 - 14,
        "epoch",
        INK,
    );
    text(&mut img, left as i64, 8, "standardised MSE:", INK);
    text(&mut img, left as i64 + 8 * 18, 8, "train", TRAIN);
    text(&mut img, left as i64 + 8 * 24, 8, "validation", VALIDATION);
    for (series, color) in [(0usize, TRAIN), (1, VALIDATION)] {
        for e in 1..curve.len() {
            let v = |k: usize| if series == 0 { curve[k].0 } else { curve[k].1 };
            let (x0, y0, x1, y1) = (px(e - 1), py(v(e - 1)), px(e), py(v(e)));
            let steps = ((x1 - x0).abs().max((y1 - y0).abs()) as usize).max(1);
            for s in 0..=steps {
                let t = s as f64 / steps as f64;
                let (x, y) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
                if x >= 0.0 && y >= 0.0 && (x as u32) < w && (y as u32) < h {
                    img.put_pixel(x as u32, y as u32, color);
                }
            }
        }
    }
    img.save(path)
        .map_err(|e| Error::file(path, format!("cannot write the plot: {e}")))
}
