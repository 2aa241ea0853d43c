// The tile hierarchy over the cloth grid (collide.wgsl refits it around the
// positions, separate.wgsl around what a step sweeps): tiles of TILE×TILE
// cells, super-tiles of TILE×TILE tiles, their boxes in one array.
// Prepended to the stages that list it (gpu::shaders::INCLUDES).

// The tiles' boxes, then the super-tiles' (then, with self-contact, each
// cell's swept box: separate.wgsl).
@group(1) @binding(6) var<storage, read_write> bounds: array<Bounds>;

// The union of the boxes of block (bx, by) of TILE×TILE entries of a
// `cols`×`rows` grid of boxes starting at bounds[first].
fn block_bounds(first: u32, cols: u32, rows: u32, bx: u32, by: u32) -> Bounds {
    var lo = vec4<f32>(3.4e38);
    var hi = vec4<f32>(-3.4e38);
    for (var y = by * TILE; y < min(by * TILE + TILE, rows); y++) {
        for (var x = bx * TILE; x < min(bx * TILE + TILE, cols); x++) {
            let b = bounds[first + y * cols + x];
            lo = min(lo, b.lo);
            hi = max(hi, b.hi);
        }
    }
    return Bounds(lo, hi);
}
