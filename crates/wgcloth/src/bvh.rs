//! Bounding-volume hierarchy over triangle AABBs: the broad phase of
//! collision detection (DESIGN "collision detection"). Built once per mesh;
//! the cloth's is refitted every step with the same topology, the rigid
//! body's lives in body space and never changes.
//!
//! Nodes are stored level by level, root first, both children of a node
//! a consecutive pair on the next level: a refit runs the levels from the
//! deepest up, each in parallel; the flat layout is what a GPU traversal
//! reads too.

use std::collections::VecDeque;

use glam::Vec3;
use rayon::prelude::*;

use crate::parallel::GRAIN;

/// An axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// The corner with the smallest coordinates.
    pub min: Vec3,
    /// The corner with the largest coordinates.
    pub max: Vec3,
}

impl Aabb {
    /// The empty box (min +∞, max −∞): growing it by a point gives that point.
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// The smallest box holding every point; [`Aabb::EMPTY`] for none.
    pub fn of_points(points: &[Vec3]) -> Aabb {
        points.iter().fold(Aabb::EMPTY, |b, p| b.grow(*p))
    }

    /// This box extended to hold `p`.
    pub fn grow(self, p: Vec3) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box holding both.
    pub fn union(self, o: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// The box's centre.
    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    /// Whether the two boxes overlap (touching counts).
    pub fn overlaps(&self, o: &Aabb) -> bool {
        self.min.cmple(o.max).all() && o.min.cmple(self.max).all()
    }

    /// This box grown by `r` on every side.
    pub fn grown(&self, r: f32) -> Aabb {
        Aabb {
            min: self.min - r,
            max: self.max + r,
        }
    }

    /// Whether a box of half-size `r` around `p` overlaps this one.
    pub fn near(&self, p: Vec3, r: f32) -> bool {
        (p + r).cmpge(self.min).all() && (p - r).cmple(self.max).all()
    }
}

/// A node of the hierarchy: a leaf (`count` > 0) or an internal node with
/// two children.
#[derive(Clone, Copy, Debug)]
pub struct Node {
    /// The union of the boxes of every primitive below it.
    pub bounds: Aabb,
    /// Leaf: first index into `Bvh::order`; internal: index of the left child
    /// (the right one is `first + 1`).
    pub first: u32,
    /// Primitives in a leaf; 0 for an internal node.
    pub count: u32,
}

/// A bounding-volume hierarchy, stored flat (see the module docs).
#[derive(Clone, Debug)]
pub struct Bvh {
    /// The nodes, the root first; children follow their parent as a pair.
    pub nodes: Vec<Node>,
    /// Primitive indices in leaf order.
    pub order: Vec<u32>,
    /// Where each level's nodes start, then the node count: level l is
    /// `nodes[levels[l]..levels[l + 1]]`.
    pub levels: Vec<u32>,
}

const LEAF_SIZE: usize = 4;

impl Bvh {
    /// Median split on the longest axis of the centroid bounds.
    pub fn build(boxes: &[Aabb]) -> Bvh {
        let mut order: Vec<u32> = (0..boxes.len() as u32).collect();
        let mut nodes = vec![Node {
            bounds: Aabb::EMPTY,
            first: 0,
            count: boxes.len() as u32,
        }];
        let mut levels = Vec::new();
        // Breadth first: nodes are numbered, and taken, level by level.
        let mut todo = VecDeque::from([(0usize, 0usize, boxes.len(), 0usize)]);
        while let Some((node, start, end, depth)) = todo.pop_front() {
            if depth == levels.len() {
                levels.push(node as u32);
            }
            let prims = &mut order[start..end];
            let bounds = prims
                .iter()
                .fold(Aabb::EMPTY, |b, &i| b.union(boxes[i as usize]));
            nodes[node].bounds = bounds;
            if prims.len() <= LEAF_SIZE {
                nodes[node].first = start as u32;
                nodes[node].count = prims.len() as u32;
                continue;
            }
            let centers = prims
                .iter()
                .fold(Aabb::EMPTY, |b, &i| b.grow(boxes[i as usize].center()));
            let extent = centers.max - centers.min;
            let axis = if extent.x >= extent.y && extent.x >= extent.z {
                0
            } else if extent.y >= extent.z {
                1
            } else {
                2
            };
            let mid = prims.len() / 2;
            prims.select_nth_unstable_by(mid, |&a, &b| {
                let ca = boxes[a as usize].center()[axis];
                let cb = boxes[b as usize].center()[axis];
                ca.total_cmp(&cb).then(a.cmp(&b))
            });
            let left = nodes.len();
            nodes.push(Node {
                bounds: Aabb::EMPTY,
                first: 0,
                count: 0,
            });
            nodes.push(nodes[left]);
            nodes[node].first = left as u32;
            nodes[node].count = 0;
            todo.push_back((left, start, start + mid, depth + 1));
            todo.push_back((left + 1, start + mid, end, depth + 1));
        }
        levels.push(nodes.len() as u32);
        Bvh {
            nodes,
            order,
            levels,
        }
    }

    /// Recompute every node's bounds from new primitive boxes,
    /// `prim_box(i)` for primitive i (same topology), level by level from
    /// the deepest, each level's nodes in parallel where there are enough
    /// of them. The boxes are made where they are read: a step that
    /// allocated them as an array faulted its pages in every time.
    pub fn refit(&mut self, prim_box: impl Fn(u32) -> Aabb + Sync) {
        if self.order.is_empty() {
            return;
        }
        let order = &self.order;
        for l in (0..self.levels.len() - 1).rev() {
            let (start, next) = (self.levels[l] as usize, self.levels[l + 1] as usize);
            let (above, below) = self.nodes.split_at_mut(next);
            let fit = |node: &mut Node| {
                node.bounds = if node.count > 0 {
                    let range = node.first as usize..(node.first + node.count) as usize;
                    order[range]
                        .iter()
                        .fold(Aabb::EMPTY, |b, &i| b.union(prim_box(i)))
                } else {
                    let c = node.first as usize - next;
                    below[c].bounds.union(below[c + 1].bounds)
                };
            };
            let level = &mut above[start..];
            if level.len() > GRAIN {
                level.par_iter_mut().with_min_len(GRAIN).for_each(fit);
            } else {
                level.iter_mut().for_each(fit);
            }
        }
    }

    /// Calls `visit` for every primitive whose box overlaps the box of
    /// half-size `r` around `p`.
    pub fn query(&self, p: Vec3, r: f32, visit: impl FnMut(u32)) {
        self.traverse(|b| b.near(p, r), visit);
    }

    /// Calls `visit` for every primitive whose box overlaps `b`.
    pub fn query_box(&self, b: Aabb, visit: impl FnMut(u32)) {
        self.traverse(
            |n| b.min.cmple(n.max).all() && n.min.cmple(b.max).all(),
            visit,
        );
    }

    /// Calls `visit` for every primitive whose box the ray o + t x̂ (t ≥ 0)
    /// meets, its faces and edges included: exact comparisons.
    pub fn query_x_ray(&self, origin: Vec3, visit: impl FnMut(u32)) {
        let Vec3 { x, y, z } = origin;
        self.traverse(
            |b| {
                b.max.x >= x && (b.min.y..=b.max.y).contains(&y) && (b.min.z..=b.max.z).contains(&z)
            },
            visit,
        );
    }

    /// Depth-first walk of the nodes whose bounds pass `overlaps`. Always
    /// inlined: called through a function, the per-primitive `visit` is
    /// too, which made the face–vertex search half again as slow.
    #[inline(always)]
    fn traverse(&self, overlaps: impl Fn(&Aabb) -> bool, mut visit: impl FnMut(u32)) {
        if self.order.is_empty() {
            return;
        }
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            if !overlaps(&node.bounds) {
                continue;
            }
            if node.count > 0 {
                for &i in &self.order[node.first as usize..(node.first + node.count) as usize] {
                    visit(i);
                }
            } else {
                stack[top] = node.first;
                stack[top + 1] = node.first + 1;
                top += 2;
            }
        }
    }
}

/// The bounding box of each triangle.
pub fn triangle_boxes(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Aabb> {
    triangles
        .iter()
        .map(|t| Aabb::of_points(&t.map(|i| positions[i as usize])))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Boxes along a wavy strip, `shift` moving each differently.
    fn boxes(n: usize, shift: f32) -> Vec<Aabb> {
        (0..n)
            .map(|i| {
                let t = i as f32 * 0.37;
                let p = Vec3::new(t.sin(), (t * shift).cos(), t * 0.01);
                Aabb::of_points(&[p, p + Vec3::splat(0.05 + 0.02 * (t * 3.1).sin().abs())])
            })
            .collect()
    }

    /// A leaf's bounds are the union of its primitives' boxes, an internal
    /// node's the union of its children's, which lie on the next level: so
    /// every node's are its subtree's.
    fn check(bvh: &Bvh, boxes: &[Aabb]) {
        for l in 0..bvh.levels.len() - 1 {
            let (start, end) = (bvh.levels[l] as usize, bvh.levels[l + 1] as usize);
            assert!(start < end, "level {l} is empty");
            let next = bvh.levels.get(l + 2).map_or(end, |&e| e as usize);
            for node in &bvh.nodes[start..end] {
                let first = node.first as usize;
                let union = if node.count > 0 {
                    (bvh.order[first..first + node.count as usize].iter())
                        .fold(Aabb::EMPTY, |b, &i| b.union(boxes[i as usize]))
                } else {
                    assert!(
                        (end..next - 1).contains(&first),
                        "children not a level down"
                    );
                    bvh.nodes[first].bounds.union(bvh.nodes[first + 1].bounds)
                };
                assert_eq!(node.bounds, union);
            }
        }
        assert_eq!(*bvh.levels.last().unwrap() as usize, bvh.nodes.len());
    }

    #[test]
    fn a_refit_bounds_every_node_as_a_build_does_and_keeps_the_levels() {
        // More nodes on a level than a parallel level takes.
        for n in [1, 5, 1000, 4 * GRAIN] {
            let mut bvh = Bvh::build(&boxes(n, 1.0));
            check(&bvh, &boxes(n, 1.0));
            let moved = boxes(n, 1.7);
            bvh.refit(|i| moved[i as usize]);
            check(&bvh, &moved);
        }
    }
}
