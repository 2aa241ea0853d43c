//! PNG charts drawn straight into an image: a canvas with an 8×8 bitmap
//! font, lines and filled boxes, and a log₁₀ axis. Enough for the training
//! loss curve (`train --plot`) and the benchmark figure (`bench --plot`)
//! without a font file or a system font library.

use std::path::Path;

use font8x8::{BASIC_FONTS, UnicodeFonts};
use image::{Rgb, RgbImage};

use wgcloth::error::{Error, Result};

pub const INK: Rgb<u8> = Rgb([40, 40, 40]);
pub const GRID: Rgb<u8> = Rgb([220, 220, 220]);

pub struct Canvas {
    img: RgbImage,
}

impl Canvas {
    /// A white canvas of `w`×`h` pixels.
    pub fn new(w: u32, h: u32) -> Canvas {
        Canvas {
            img: RgbImage::from_pixel(w, h, Rgb([255, 255, 255])),
        }
    }

    pub fn width(&self) -> f64 {
        self.img.width() as f64
    }

    pub fn height(&self) -> f64 {
        self.img.height() as f64
    }

    fn put(&mut self, x: i64, y: i64, color: Rgb<u8>) {
        if x >= 0 && y >= 0 && x < self.img.width() as i64 && y < self.img.height() as i64 {
            self.img.put_pixel(x as u32, y as u32, color);
        }
    }

    /// Writes `text` with its top-left corner at (x, y), clipped.
    pub fn text(&mut self, x: f64, y: f64, text: &str, color: Rgb<u8>) {
        for (k, ch) in text.chars().enumerate() {
            let glyph = BASIC_FONTS.get(ch).unwrap_or([0; 8]);
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits >> col & 1 == 1 {
                        let px = x as i64 + 8 * k as i64 + col;
                        self.put(px, y as i64 + row as i64, color);
                    }
                }
            }
        }
    }

    /// Pixels `text` takes across.
    pub fn text_width(text: &str) -> f64 {
        8.0 * text.chars().count() as f64
    }

    /// A `width`-pixel line from a to b; with `dash` = Some(n), drawn n
    /// pixels on, n off.
    pub fn line(
        &mut self,
        a: (f64, f64),
        b: (f64, f64),
        color: Rgb<u8>,
        width: u32,
        dash: Option<u32>,
    ) {
        let steps = ((b.0 - a.0).abs().max((b.1 - a.1).abs()) as u32).max(1);
        for s in 0..=steps {
            if dash.is_some_and(|n| (s / n) % 2 == 1) {
                continue;
            }
            let t = s as f64 / steps as f64;
            let (x, y) = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
            for d in 0..width as i64 {
                let o = d - (width as i64 - 1) / 2;
                self.put(x as i64 + o, y as i64, color);
                self.put(x as i64, y as i64 + o, color);
            }
        }
    }

    /// Fills the box from (x0, y0) to (x1, y1).
    pub fn fill(&mut self, (x0, y0): (f64, f64), (x1, y1): (f64, f64), color: Rgb<u8>) {
        for y in y0.min(y1).round() as i64..y0.max(y1).round() as i64 {
            for x in x0.min(x1).round() as i64..x0.max(x1).round() as i64 {
                self.put(x, y, color);
            }
        }
    }

    pub fn save(&self, path: &Path) -> Result<()> {
        self.img
            .save(path)
            .map_err(|e| Error::file(path, format!("cannot write the plot: {e}")))
    }

    /// The pixel at (x, y), for tests.
    pub fn pixel(&self, x: u32, y: u32) -> Rgb<u8> {
        *self.img.get_pixel(x, y)
    }
}

/// A log₁₀ axis: whole decades `lo`..=`hi` mapped onto pixels `from`..`to`
/// (`to` < `from` for an axis that grows upwards).
#[derive(Clone, Copy, Debug)]
pub struct LogAxis {
    pub lo: f64,
    pub hi: f64,
    from: f64,
    to: f64,
}

impl LogAxis {
    /// The whole decades covering every positive value (at least one), or
    /// None when there is none.
    pub fn covering(values: impl IntoIterator<Item = f64>, from: f64, to: f64) -> Option<LogAxis> {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values.into_iter().filter(|v| *v > 0.0 && v.is_finite()) {
            lo = lo.min(v.log10());
            hi = hi.max(v.log10());
        }
        (lo <= hi).then(|| LogAxis {
            lo: lo.floor(),
            hi: hi.ceil().max(lo.floor() + 1.0),
            from,
            to,
        })
    }

    /// The pixel of value `v` (> 0).
    pub fn at(&self, v: f64) -> f64 {
        self.from + (self.to - self.from) * (v.max(1e-300).log10() - self.lo) / (self.hi - self.lo)
    }

    /// 10^k for every whole decade k on the axis.
    pub fn decades(&self) -> impl Iterator<Item = f64> + '_ {
        (self.lo as i32..=self.hi as i32).map(|k| 10f64.powi(k))
    }
}

/// A decade's label: 0.01, 0.1, 1, 10, 100, 1k, 10k, 100k, 1M, …
pub fn decade_label(v: f64) -> String {
    match v {
        v if v >= 1e6 => format!("{}M", v / 1e6),
        v if v >= 1e3 => format!("{}k", v / 1e3),
        v => format!("{v}"),
    }
}

/// Refuses a `--plot` path the PNG encoder would not write, before any
/// work.
pub fn check_png(path: &Path) -> Result<()> {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("png") => Ok(()),
        _ => Err(Error::config(
            "--plot",
            format!("{} must end in .png", path.display()),
        )),
    }
}
