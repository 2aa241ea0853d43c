//! A uniform grid over bounding boxes: the broad phase of the cloth's
//! checks against itself. Each box is listed in every cell it overlaps, the
//! lists sorted by cell, and each pair of overlapping boxes taken once, in
//! the cell holding the low corner of their overlap.

use glam::Vec3;
use rayon::prelude::*;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug)]
pub struct Aabb {
    /// Least corner.
    pub lo: Vec3,
    /// Greatest corner.
    pub hi: Vec3,
}

impl Aabb {
    /// The box around `points`, grown by `margin` on every side.
    pub fn around(points: impl IntoIterator<Item = Vec3>, margin: f32) -> Aabb {
        let (lo, hi) = points.into_iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(p), hi.max(p)),
        );
        Aabb {
            lo: lo - margin,
            hi: hi + margin,
        }
    }

    /// The two boxes' common part, if they overlap.
    pub fn overlap(&self, other: &Aabb) -> Option<Aabb> {
        let (lo, hi) = (self.lo.max(other.lo), self.hi.min(other.hi));
        lo.cmple(hi).all().then_some(Aabb { lo, hi })
    }
}

/// Boxes listed in every cell they overlap, sorted by cell. Cells are as
/// wide as the widest box, so a box overlaps at most two along each axis.
/// Boxes that are not finite are left out.
pub struct Cells {
    cell: f32,
    listed: Vec<Listed>,
}

/// A box's index under a cell's key.
type Listed = ([i32; 3], u32);

impl Cells {
    /// `None` when no box has a finite, positive width.
    pub fn new(boxes: &[Aabb]) -> Option<Cells> {
        let cell = boxes
            .iter()
            .map(|b| (b.hi - b.lo).max_element())
            .filter(|s| s.is_finite())
            .reduce(f32::max)
            .filter(|s| *s > 0.0)?;
        let mut cells = Cells {
            cell,
            listed: Vec::new(),
        };
        let key = |p| cells.key(p);
        let mut listed: Vec<Listed> = boxes
            .par_iter()
            .enumerate()
            .filter(|(_, b)| b.lo.is_finite() && b.hi.is_finite())
            .flat_map_iter(|(i, b)| {
                let (lo, hi) = (key(b.lo), key(b.hi));
                (lo[0]..=hi[0]).flat_map(move |x| {
                    (lo[1]..=hi[1])
                        .flat_map(move |y| (lo[2]..=hi[2]).map(move |z| ([x, y, z], i as u32)))
                })
            })
            .collect();
        listed.par_sort_unstable();
        cells.listed = listed;
        Some(cells)
    }

    fn key(&self, p: Vec3) -> [i32; 3] {
        (p / self.cell).floor().as_ivec3().to_array()
    }

    /// Each cell's key and its boxes.
    fn runs(&self) -> Vec<([i32; 3], &[Listed])> {
        self.listed
            .chunk_by(|a, b| a.0 == b.0)
            .map(|run| (run[0].0, run))
            .collect()
    }
}

/// Every pair [a, b], a < b, of `boxes` that overlap and that `keep`
/// accepts, each once (in the cell holding the low corner of the boxes'
/// overlap), in increasing order.
pub fn overlapping_pairs(boxes: &[Aabb], keep: impl Fn(u32, u32) -> bool + Sync) -> Vec<[u32; 2]> {
    let Some(cells) = Cells::new(boxes) else {
        return Vec::new();
    };
    let mut pairs: Vec<[u32; 2]> = cells
        .runs()
        .par_iter()
        .flat_map_iter(|&(key, members)| {
            let (keep, cells) = (&keep, &cells);
            members.iter().enumerate().flat_map(move |(k, &(_, a))| {
                members[k + 1..].iter().filter_map(move |&(_, b)| {
                    let overlap = boxes[a as usize].overlap(&boxes[b as usize])?;
                    let (a, b) = (a.min(b), a.max(b));
                    (cells.key(overlap.lo) == key && keep(a, b)).then_some([a, b])
                })
            })
        })
        .collect();
    pairs.par_sort_unstable();
    pairs
}
