// The walk over the tile hierarchy's cells that stages "separate" and
// "self_contact" share. One walk per vertex, for the vertex and the
// triangle edges it starts (as cpu::separate::candidates walks the BVH
// once for them), visits the cells the union of their boxes overlaps, and
// hands the stage every pair of the vertex and a cell's triangle, or of
// one of its edges and an edge the cell owns, whose boxes overlap and that
// shares no vertex. Prepended to those stages after tiles.wgsl
// (gpu::shaders::INCLUDES).
//
// The stage gives `extent(i)`, vertex i's own box (separate: what it
// sweeps; self_contact: where it is), `growth()`, how far a query's box
// reaches beyond its vertices' (the floor; the thickness),
// `refused_corners(w, cell)`, the cell's corners across which no pair of
// the walk's vertex (bits 0 to 3) or of the far end of its edge k (bits
// 4 + 4k on) counts (self_contact: those near it at rest; separate: none),
// and `pair(p, edge, mode)`, its test of a pair: vertex p.x against
// triangle p.yzw, or (edge) edge p.xy against edge p.zw, lower ends first.
//
// Lavapipe runs every branch, taken or not, masked, for each 8 invocations,
// and every loop's body at least once, so a test nested in the hierarchy's
// loops would run at every box they test. Hence three flat steps: a loop
// finds the next cell the walk's box overlaps, one box test an iteration
// (`next_cell`); box tests alone find the cell's pairs, as bits
// (`cell_pairs`); the stage's test runs once per bit set.

// A walk: vertex `a`'s box, the far ends of the edges it starts
// (NO_TRIANGLE where none) and their boxes, component by component (a
// vector, not an array, so that no walk needs function-local memory), and
// the union of them all, which the hierarchy is walked for; `mode` is
// separate's (the pass the walk's pairs are met in: listed, or tested).
struct Walk {
    lo: vec3<f32>,
    a: u32,
    hi: vec3<f32>,
    mode: u32,
    vertex: Bounds,
    far: vec4<u32>,
    lo_x: vec4<f32>,
    lo_y: vec4<f32>,
    lo_z: vec4<f32>,
    hi_x: vec4<f32>,
    hi_y: vec4<f32>,
    hi_z: vec4<f32>,
}

// Vertex i's box grown by the stage's reach.
fn reach(i: u32) -> Bounds {
    let e = extent(i);
    let g = vec4<f32>(vec3<f32>(growth()), 0.0);
    return Bounds(e.lo - g, e.hi + g);
}

fn union_of(a: Bounds, b: Bounds) -> Bounds {
    return Bounds(min(a.lo, b.lo), max(a.hi, b.hi));
}

fn overlaps(lo: vec3<f32>, hi: vec3<f32>, b: Bounds) -> bool {
    return all(lo <= b.hi.xyz) && all(b.lo.xyz <= hi);
}

// The far ends of the triangle edges vertex a starts (it is their lower
// end): right, up, and where x + y is odd the diagonals of the cells to
// its upper right and upper left (`owned_edge`'s alternation, as
// scene::cloth lays the triangles); NO_TRIANGLE where the grid ends.
fn started_edges(a: u32) -> vec4<u32> {
    let nx = params.cells_x + 1u;
    let x = a % nx;
    let y = a / nx;
    let right = x < params.cells_x;
    let up = y < params.cells_y;
    let odd = (x + y) % 2u == 1u;
    return vec4<u32>(
        select(NO_TRIANGLE, a + 1u, right),
        select(NO_TRIANGLE, a + nx, up),
        select(NO_TRIANGLE, a + nx + 1u, right && up && odd),
        select(NO_TRIANGLE, a + nx - 1u, x > 0u && up && odd),
    );
}

// Edge (a, far)'s box: the union of its ends' reach; empty (nothing
// overlaps it) where there is no such edge.
fn edge_reach(own: Bounds, far: u32) -> Bounds {
    if far == NO_TRIANGLE {
        return Bounds(vec4<f32>(3.4e38), vec4<f32>(-3.4e38));
    }
    return union_of(own, reach(far));
}

fn walk_of(a: u32, mode: u32) -> Walk {
    let own = reach(a);
    let far = started_edges(a);
    let e0 = edge_reach(own, far.x);
    let e1 = edge_reach(own, far.y);
    let e2 = edge_reach(own, far.z);
    let e3 = edge_reach(own, far.w);
    let all = union_of(own, union_of(union_of(e0, e1), union_of(e2, e3)));
    return Walk(
        all.lo.xyz, a, all.hi.xyz, mode, own, far,
        vec4<f32>(e0.lo.x, e1.lo.x, e2.lo.x, e3.lo.x),
        vec4<f32>(e0.lo.y, e1.lo.y, e2.lo.y, e3.lo.y),
        vec4<f32>(e0.lo.z, e1.lo.z, e2.lo.z, e3.lo.z),
        vec4<f32>(e0.hi.x, e1.hi.x, e2.hi.x, e3.hi.x),
        vec4<f32>(e0.hi.y, e1.hi.y, e2.hi.y, e3.hi.y),
        vec4<f32>(e0.hi.z, e1.hi.z, e2.hi.z, e3.hi.z),
    );
}

// Where cell c's box is in `bounds`.
fn cell_at(c: u32) -> u32 {
    return params.tiles_x * params.tiles_y + params.supertiles_x * params.supertiles_y + c;
}

// Where a walk's search for its next cell stands: super-tile `s`, tile
// `tile` of its TILE × TILE and cell `cell` of that tile's (row-major), and
// which of the three `level` tests next.
struct Cursor {
    s: u32,
    tile: u32,
    cell: u32,
    level: u32,
}

// The next cell (x, y) whose box the walk's overlaps, within tiles and
// super-tiles whose boxes it overlaps; x is NO_TRIANGLE once there is none.
// Each iteration loads the one box its level tests and moves on by
// selects (lavapipe would run a load in each branch).
fn next_cell(w: Walk, at: ptr<function, Cursor>) -> vec2<u32> {
    let tiles = params.tiles_x * params.tiles_y;
    let supertiles = params.supertiles_x * params.supertiles_y;
    let children = TILE * TILE;
    loop {
        let c = *at;
        if c.s == supertiles {
            return vec2<u32>(NO_TRIANGLE);
        }
        let tx = (c.s % params.supertiles_x) * TILE + c.tile % TILE;
        let ty = (c.s / params.supertiles_x) * TILE + c.tile / TILE;
        let cx = tx * TILE + c.cell % TILE;
        let cy = ty * TILE + c.cell / TILE;
        let has_tile = c.tile < children && tx < params.tiles_x && ty < params.tiles_y;
        let has_cell = c.cell < children && cx < params.cells_x && cy < params.cells_y;
        let box_at = select(select(cell_at(cy * params.cells_x + cx), ty * params.tiles_x + tx, c.level == 1u), tiles + c.s, c.level == 0u);
        let exists = select(select(has_cell, has_tile, c.level == 1u), true, c.level == 0u);
        let hit = exists && overlaps(w.lo, w.hi, bounds[select(0u, box_at, exists)]);
        // A hit descends (or, a cell, is returned); a miss moves to the
        // next sibling; past the last child, up to the parent's next.
        let done = select(c.tile == children, c.cell == children, c.level == 2u) && c.level != 0u;
        let level = select(select(c.level, c.level + 1u, hit && c.level < 2u), c.level - 1u, done);
        let s = c.s + select(0u, 1u, (c.level == 0u && !hit) || (c.level == 1u && done));
        let tile = select(c.tile, c.tile + 1u, (c.level == 1u && !hit && !done) || (c.level == 2u && done));
        let cell = select(c.cell + 1u, 0u, c.level < 2u || done);
        *at = Cursor(s, select(tile, 0u, level == 0u), cell, level);
        if c.level == 2u && hit {
            return vec2<u32>(cx, cy);
        }
    }
    // Not reached; naga asks for a return after the loop.
    return vec2<u32>(NO_TRIANGLE);
}

// A cell's corners: the lower left `a` (then a + 1, a + nx, a + nx + 1)
// and their extents.
struct Corners {
    a: u32,
    e0: Bounds,
    e1: Bounds,
    e2: Bounds,
    e3: Bounds,
}

fn corners(cell: vec2<u32>) -> Corners {
    let nx = params.cells_x + 1u;
    let a = cell.y * nx + cell.x;
    return Corners(a, extent(a), extent(a + 1u), extent(a + nx), extent(a + nx + 1u));
}

// The cell's box, the union of its corners' extents: what the stage
// stores after the tiles' in `bounds` for the walks.
fn cell_box(cell: vec2<u32>) -> Bounds {
    let k = corners(cell);
    let b = union_of(union_of(k.e0, k.e1), union_of(k.e2, k.e3));
    return Bounds(vec4<f32>(b.lo.xyz, 0.0), vec4<f32>(b.hi.xyz, 0.0));
}

// The extent of corner v of the cell.
fn corner_extent(k: Corners, v: u32) -> Bounds {
    let nx = params.cells_x + 1u;
    let lo = select(select(select(k.e3.lo, k.e2.lo, v == k.a + nx), k.e1.lo, v == k.a + 1u), k.e0.lo, v == k.a);
    let hi = select(select(select(k.e3.hi, k.e2.hi, v == k.a + nx), k.e1.hi, v == k.a + 1u), k.e0.hi, v == k.a);
    return Bounds(lo, hi);
}

// The cell's triangle t (0 or 1), as scene::cloth lists it.
fn cell_triangle(cell: vec2<u32>, t: u32) -> vec3<u32> {
    let k = 3u * (2u * (cell.y * params.cells_x + cell.x) + t);
    return vec3<u32>(cloth_index(k), cloth_index(k + 1u), cloth_index(k + 2u));
}

// Edge m (0 to 4) of those the cell owns, lower end first, so that each is
// met once: its bottom, its left and its diagonal (alternating as
// scene::cloth lays them), and its right and top on the grid's last column
// and row; NO_TRIANGLE where it owns no such edge. An edge near a query
// lies in every cell that holds it, and those cells' boxes hold its box, so
// its owner is walked.
fn owned_edge(cell: vec2<u32>, m: u32) -> vec2<u32> {
    let nx = params.cells_x + 1u;
    let a = cell.y * nx + cell.x;
    let up = a + nx;
    let diagonal = select(vec2<u32>(a, up + 1u), vec2<u32>(a + 1u, up), (cell.x + cell.y) % 2u == 0u);
    // Selects, not an array: lavapipe would keep an array in memory.
    let top_or_right = select(vec2<u32>(up, up + 1u), vec2<u32>(a + 1u, up + 1u), m == 3u);
    let e = select(select(select(top_or_right, diagonal, m == 2u), vec2<u32>(a, up), m == 1u), vec2<u32>(a, a + 1u), m == 0u);
    let owned = m < 3u || (m == 3u && cell.x + 1u == params.cells_x) || (m == 4u && cell.y + 1u == params.cells_y);
    return select(vec2<u32>(NO_TRIANGLE), e, owned);
}

// Corner vertex v's bit among the cell's corners (`refused_corners`'
// order: bottom left, bottom right, top left, top right).
fn corner_bit(k: Corners, v: u32) -> u32 {
    let nx = params.cells_x + 1u;
    return select(select(select(8u, 4u, v == k.a + nx), 2u, v == k.a + 1u), 1u, v == k.a);
}

// The cell's pairs for the walk, as bits: bit t (0, 1) the vertex against
// its triangle t, bit 2 + 4 m + k the walk's edge k against its edge m
// (each edge pair from its lower edge, as on the CPU); each where the
// two boxes overlap, the pair shares no vertex and no vertex of one side
// is refused with one of the other's (`refused`, from
// `refused_corners`), which the boxes are not tested for.
fn cell_pairs(w: Walk, cell: vec2<u32>, refused: u32) -> u32 {
    let k = corners(cell);
    let by_a = refused & 15u;
    let by_far = vec4<u32>(refused >> 4u, refused >> 8u, refused >> 12u, refused >> 16u) & vec4<u32>(15u);
    var bits = 0u;
    for (var t = 0u; t < 2u; t++) {
        let tri = cell_triangle(cell, t);
        let b = union_of(union_of(corner_extent(k, tri.x), corner_extent(k, tri.y)), corner_extent(k, tri.z));
        let kept = (by_a & (corner_bit(k, tri.x) | corner_bit(k, tri.y) | corner_bit(k, tri.z))) == 0u;
        if !any(tri == vec3<u32>(w.a)) && kept && overlaps(w.vertex.lo.xyz, w.vertex.hi.xyz, b) {
            bits |= 1u << t;
        }
    }
    for (var m = 0u; m < 5u; m++) {
        let f = owned_edge(cell, m);
        let b = union_of(corner_extent(k, f.x), corner_extent(k, f.y));
        // Parenthesised: WGSL (Tint) refuses a comparison mixed with `&`.
        let near = (w.lo_x <= vec4<f32>(b.hi.x)) & (vec4<f32>(b.lo.x) <= w.hi_x)
            & (w.lo_y <= vec4<f32>(b.hi.y)) & (vec4<f32>(b.lo.y) <= w.hi_y)
            & (w.lo_z <= vec4<f32>(b.hi.z)) & (vec4<f32>(b.lo.z) <= w.hi_z);
        let above = vec4<bool>(f.x > w.a) | (vec4<bool>(f.x == w.a) & (vec4<u32>(f.y) > w.far));
        let apart = vec4<bool>(f.x != w.a && f.y != w.a) & (vec4<u32>(f.x) != w.far) & (vec4<u32>(f.y) != w.far);
        let ends = vec4<u32>(corner_bit(k, f.x) | corner_bit(k, f.y));
        let kept = ((by_far | vec4<u32>(by_a)) & ends) == vec4<u32>(0u);
        let met = select(vec4<u32>(0u), vec4<u32>(1u, 2u, 4u, 8u), near & above & apart & kept & vec4<bool>(f.x != NO_TRIANGLE));
        bits |= (met.x | met.y | met.z | met.w) << (2u + 4u * m);
    }
    return bits;
}

// The pair bit j of `cell_pairs` names.
fn pair_at(w: Walk, cell: vec2<u32>, j: u32) -> vec4<u32> {
    if j < 2u {
        return vec4<u32>(w.a, cell_triangle(cell, j));
    }
    return vec4<u32>(w.a, w.far[(j - 2u) % 4u], owned_edge(cell, (j - 2u) / 4u));
}

// Every pair of the walk, to the stage's test.
fn walk(w: Walk) {
    var at = Cursor(0u, 0u, 0u, 0u);
    loop {
        let cell = next_cell(w, &at);
        if cell.x == NO_TRIANGLE {
            break;
        }
        var found = cell_pairs(w, cell, refused_corners(w, cell));
        while found != 0u {
            let j = firstTrailingBit(found);
            found &= found - 1u;
            pair(pair_at(w, cell, j), j >= 2u, w.mode);
        }
    }
}
