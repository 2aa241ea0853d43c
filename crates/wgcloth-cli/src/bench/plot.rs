//! `bench --plot`: ms/step against particle count on log-log axes, one
//! line per backend × model (GPU solid, CPU dashed) with a linear-growth
//! guide; beside it each stage's share of the default run's step
//! (friction-net solved with multigrid), one bar per backend × grid.

use std::path::Path;

use image::Rgb;

use crate::bench::{BenchReport, HEADLINE, SELF_CONTACT, StepRow, VARIANTS};
use crate::plot::{Canvas, GRID, INK, LogAxis, decade_label};
use wgcloth::config::ModelKind;
use wgcloth::error::{Error, Result};
use wgcloth::stage::Stage;

/// The colour of entry k of [`VARIANTS`].
pub fn variant_color(k: usize) -> Rgb<u8> {
    hue_color(k)
}

/// The colour of stage k of [`Stage::ALL`].
pub fn stage_color(k: usize) -> Rgb<u8> {
    hue_color(VARIANTS.len() + k)
}

/// Hues a golden angle apart, at three lightnesses in turn so that the
/// hues that come round close together differ in it: every variant and
/// stage has its own colour, and a new one needs none chosen by hand.
fn hue_color(k: usize) -> Rgb<u8> {
    let hue = (k as f64 * 137.508 + 210.0) % 360.0 / 60.0;
    let (value, saturation) = [(0.85, 0.75), (0.6, 0.9), (0.95, 0.45)][k % 3];
    let chroma = value * saturation;
    let second = chroma * (1.0 - (hue % 2.0 - 1.0).abs());
    let (r, g, b) = match hue as u32 {
        0 => (chroma, second, 0.0),
        1 => (second, chroma, 0.0),
        2 => (0.0, chroma, second),
        3 => (0.0, second, chroma),
        4 => (second, 0.0, chroma),
        _ => (chroma, 0.0, second),
    };
    let byte = |c: f64| ((c + value - chroma) * 255.0).round() as u8;
    Rgb([byte(r), byte(g), byte(b)])
}

/// The part of a step no stage accounts for.
pub const UNSTAGED: Rgb<u8> = Rgb([225, 225, 225]);

const SIZE: (u32, u32) = (1120, 560);

/// The figure of `report`.
pub fn figure(report: &BenchReport) -> Result<Canvas> {
    let mut c = Canvas::new(SIZE.0, SIZE.1);
    step_lines(&mut c, report, (70.0, 600.0))?;
    stage_bars(&mut c, report, (690.0, 960.0));
    Ok(c)
}

pub fn write(report: &BenchReport, path: &Path) -> Result<()> {
    figure(report)?.save(path)
}

fn row_color(row: &StepRow) -> Rgb<u8> {
    VARIANTS
        .iter()
        .position(|v| v.label() == row.label)
        .map_or(INK, variant_color)
}

/// The log-log panel between x = left and right.
fn step_lines(c: &mut Canvas, report: &BenchReport, (left, right): (f64, f64)) -> Result<()> {
    let (top, bottom) = (40.0, c.height() - 50.0);
    let no_rows = || Error::config("--plot", "no step rows to plot");
    let x = LogAxis::covering(report.rows.iter().map(|r| r.particles as f64), left, right)
        .ok_or_else(no_rows)?;
    let y = LogAxis::covering(
        report.rows.iter().map(|r| r.report.ms_per_step),
        bottom,
        top,
    )
    .ok_or_else(no_rows)?;
    for d in x.decades() {
        c.line((x.at(d), top), (x.at(d), bottom), GRID, 1, None);
        let label = decade_label(d);
        c.text(
            x.at(d) - Canvas::text_width(&label) / 2.0,
            bottom + 8.0,
            &label,
            INK,
        );
    }
    for d in y.decades() {
        c.line((left, y.at(d)), (right, y.at(d)), GRID, 1, None);
        let label = decade_label(d);
        c.text(
            left - 8.0 - Canvas::text_width(&label),
            y.at(d) - 4.0,
            &label,
            INK,
        );
    }
    c.text(left, 16.0, "ms per step (log-log)", INK);
    c.text(
        (left + right) / 2.0 - 100.0,
        bottom + 28.0,
        "particles (cloth vertices)",
        INK,
    );
    // Slope 1 through the smallest GPU (else CPU) friction row.
    let friction = ModelKind::Friction.name();
    if let Some(anchor) = ["gpu", "cpu"].iter().find_map(|b| {
        report
            .rows
            .iter()
            .filter(|r| r.report.backend == *b && r.label == friction)
            .min_by_key(|r| r.particles)
    }) {
        let (p0, ms0) = (anchor.particles as f64, anchor.report.ms_per_step);
        let far = 10f64.powf(x.hi);
        let end = (x.at(far), y.at(ms0 * far / p0));
        c.line((x.at(p0), y.at(ms0)), end, INK, 1, Some(3));
        c.text(end.0 - 60.0, end.1.max(top) - 12.0, "linear", INK);
    }
    for backend in ["cpu", "gpu"] {
        let dash = (backend == "cpu").then_some(6);
        for v in VARIANTS {
            let label = v.label();
            let mut points: Vec<&StepRow> = report
                .rows
                .iter()
                .filter(|r| r.report.backend == backend && r.label == label)
                .collect();
            points.sort_by_key(|r| r.particles);
            let at = |r: &StepRow| (x.at(r.particles as f64), y.at(r.report.ms_per_step));
            for pair in points.windows(2) {
                c.line(at(pair[0]), at(pair[1]), row_color(pair[0]), 2, dash);
            }
            for r in points {
                let (px, py) = at(r);
                c.fill((px - 3.0, py - 3.0), (px + 4.0, py + 4.0), row_color(r));
            }
        }
    }
    // Legend, top left inside the panel.
    let (lx, mut ly) = (left + 10.0, top + 8.0);
    for (k, v) in VARIANTS.iter().enumerate() {
        let color = variant_color(k);
        c.fill((lx, ly + 2.0), (lx + 20.0, ly + 6.0), color);
        c.text(lx + 26.0, ly, &v.label(), INK);
        ly += 12.0;
    }
    c.line((lx, ly + 4.0), (lx + 20.0, ly + 4.0), INK, 2, None);
    c.text(lx + 26.0, ly, "gpu", INK);
    c.line(
        (lx + 70.0, ly + 4.0),
        (lx + 90.0, ly + 4.0),
        INK,
        2,
        Some(6),
    );
    c.text(lx + 96.0, ly, "cpu", INK);
    Ok(())
}

/// The per-stage panel between x = left and right, legend beyond it: the
/// default run, and beside it the same with self-contact ("+self").
fn stage_bars(c: &mut Canvas, report: &BenchReport, (left, right): (f64, f64)) {
    let (top, bottom) = (40.0, c.height() - 66.0);
    let (model, with_self) = (HEADLINE.label(), SELF_CONTACT.label());
    c.text(
        left - 40.0,
        16.0,
        &format!("share of the step per stage, {model} (+self: self-contact)"),
        INK,
    );
    for pct in [0, 25, 50, 75, 100] {
        let py = bottom - (bottom - top) * pct as f64 / 100.0;
        c.line((left, py), (right, py), GRID, 1, None);
        c.text(left - 40.0, py - 4.0, &format!("{pct:>3}%"), INK);
    }
    let bars: Vec<&StepRow> = report
        .rows
        .iter()
        .filter(|r| r.label == model || r.label == with_self)
        .collect();
    let slot = (right - left) / bars.len().max(1) as f64;
    for (k, row) in bars.iter().enumerate() {
        let (x0, x1) = (
            left + slot * (k as f64 + 0.2),
            left + slot * (k as f64 + 0.8),
        );
        let step = row.report.ms_per_step;
        let mut share = 0.0;
        let mut y_at = |ms: f64| {
            share = (share + ms / step).min(1.0);
            bottom - (bottom - top) * share
        };
        let mut below = bottom;
        for (k, stage) in Stage::ALL.iter().enumerate() {
            let color = stage_color(k);
            if let Some(ms) = row.report.stage_ms.get(stage.name()) {
                // At least a pixel, so every timed stage shows.
                let above = y_at(*ms).min(below - 1.0);
                c.fill((x0, above), (x1, below), color);
                below = above;
            }
        }
        c.fill((x0, top), (x1, below), UNSTAGED);
        let grid = row.report.grid[0].to_string();
        let mid = (x0 + x1) / 2.0;
        c.text(
            mid - Canvas::text_width(&grid) / 2.0,
            bottom + 6.0,
            &grid,
            INK,
        );
        c.text(mid - 12.0, bottom + 18.0, &row.report.backend, INK);
        if row.label == with_self {
            c.text(mid - 14.0, bottom + 30.0, "+self", INK);
        }
    }
    c.text(left + 40.0, bottom + 44.0, "grid (N x N) and backend", INK);
    let (lx, mut ly) = (right + 24.0, top + 8.0);
    for (k, stage) in Stage::ALL.iter().enumerate().rev() {
        let color = stage_color(k);
        c.fill((lx, ly), (lx + 14.0, ly + 8.0), color);
        c.text(lx + 20.0, ly, stage.name(), INK);
        ly += 14.0;
    }
    c.fill((lx, ly), (lx + 14.0, ly + 8.0), UNSTAGED);
    c.text(lx + 20.0, ly, "unstaged", INK);
}
