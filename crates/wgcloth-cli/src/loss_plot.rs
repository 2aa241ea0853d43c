//! The loss curve as a PNG: training and validation MSE per epoch on a
//! log scale.

use std::path::Path;

use image::Rgb;

use crate::plot::{Canvas, GRID, INK, LogAxis};
use wgcloth::error::{Error, Result};

const TRAIN: Rgb<u8> = Rgb([40, 90, 200]);
const VALIDATION: Rgb<u8> = Rgb([220, 60, 40]);

pub fn loss_curve(curve: &[(f64, f64)], path: &Path) -> Result<()> {
    let mut c = Canvas::new(640, 400);
    let (left, right, top, bottom) = (56.0, c.width() - 10.0, 28.0, c.height() - 36.0);
    let values = curve.iter().flat_map(|(a, b)| [*a, *b]);
    let Some(y) = LogAxis::covering(values, bottom, top) else {
        return Err(Error::config("--plot", "no epochs to plot"));
    };
    let last = curve.len().max(2) - 1;
    let px = |epoch: usize| left + (right - left) * epoch as f64 / last as f64;
    for decade in y.decades() {
        c.line((left, y.at(decade)), (right, y.at(decade)), GRID, 1, None);
        let label = format!("1e{}", decade.log10().round());
        c.text(4.0, y.at(decade) - 4.0, &label, INK);
    }
    for epoch in [0, last / 2, last] {
        let label = format!("{}", epoch + 1);
        let width = Canvas::text_width(&label);
        let x = (px(epoch) - width / 2.0).min(c.width() - width - 2.0);
        c.text(x, bottom + 6.0, &label, INK);
    }
    c.text((left + right) / 2.0 - 20.0, c.height() - 14.0, "epoch", INK);
    c.text(left, 8.0, "standardised MSE:", INK);
    c.text(left + 8.0 * 18.0, 8.0, "train", TRAIN);
    c.text(left + 8.0 * 24.0, 8.0, "validation", VALIDATION);
    for (series, color) in [(0usize, TRAIN), (1, VALIDATION)] {
        let v = |k: usize| if series == 0 { curve[k].0 } else { curve[k].1 };
        for e in 1..curve.len() {
            let (a, b) = ((px(e - 1), y.at(v(e - 1))), (px(e), y.at(v(e))));
            c.line(a, b, color, 1, None);
        }
    }
    c.save(path)
}
