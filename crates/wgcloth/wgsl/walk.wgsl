// The walk over the tile hierarchy's cells that stages "separate" and
// "self_contact" share: a query box visits the super-tiles, tiles and
// cells (their boxes after the tiles' in `bounds`) it overlaps, and calls
// the stage's own `vertex_against(q, t)` (a vertex query, each of the
// cell's two triangles) or `edge_against(q, u, w)` (an edge query, each
// edge the cell owns). Prepended to those stages after tiles.wgsl
// (gpu::shaders::INCLUDES).

// A query: vertex `a` (edge false) or the edge (a, b), a < b, and its box
// (separate: what it sweeps grown by the floor; self_contact: where it is
// grown by the thickness); `test` is separate's (a round's test rather
// than listing).
struct Query {
    lo: vec3<f32>,
    a: u32,
    hi: vec3<f32>,
    b: u32,
    edge: bool,
    test: bool,
}

// Spring s's ends, lower first, when it runs along a triangle (the edges
// the walks test); else vec2(NO_TRIANGLE).
fn walked_edge(s: u32) -> vec2<u32> {
    if s >= params.n_springs || spring_triangles(s).x == NO_TRIANGLE {
        return vec2<u32>(NO_TRIANGLE);
    }
    let ends = spring_ends(s);
    return vec2<u32>(min(ends.x, ends.y), max(ends.x, ends.y));
}

// Edge (u, w), lower end first, when an edge query tests it: above the
// query's edge (each pair from its lower edge, as on the CPU) and sharing
// no vertex with it; else vec2(NO_TRIANGLE).
fn met_edge(q: Query, u: u32, w: u32) -> vec2<u32> {
    let f = vec2<u32>(min(u, w), max(u, w));
    let above = f.x > q.a || (f.x == q.a && f.y > q.b);
    let apart = f.x != q.a && f.x != q.b && f.y != q.a && f.y != q.b;
    return select(vec2<u32>(NO_TRIANGLE), f, above && apart);
}

fn overlaps(lo: vec3<f32>, hi: vec3<f32>, b_lo: vec3<f32>, b_hi: vec3<f32>) -> bool {
    return all(lo <= b_hi) && all(b_lo <= hi);
}

// The query against grid cell (cx, cy): a vertex against its two
// triangles; an edge against the edges the cell owns, so that each is met
// once: its bottom, its left and its diagonal (alternating as
// scene::cloth lays them), and its right and top on the grid's last column
// and row. An edge near the query lies in every cell that holds it, and
// those cells' boxes hold its box, so its owner is walked.
fn against(q: Query, cx: u32, cy: u32) {
    let c = cy * params.cells_x + cx;
    if !q.edge {
        vertex_against(q, 2u * c);
        vertex_against(q, 2u * c + 1u);
        return;
    }
    let nx = params.cells_x + 1u;
    let a = cy * nx + cx;
    let b = a + 1u;
    let up = a + nx;
    let d = up + 1u;
    let diagonal = select(vec2<u32>(a, d), vec2<u32>(b, up), (cx + cy) % 2u == 0u);
    // Bottom, left, diagonal, then right and top where the grid ends (one
    // call site, so the segment test is compiled once).
    let owned = array<vec2<u32>, 5>(vec2<u32>(a, b), vec2<u32>(a, up), diagonal, vec2<u32>(b, d), vec2<u32>(up, d));
    let last = 3u + select(0u, 1u, cx + 1u == params.cells_x);
    for (var k = 0u; k < 5u; k++) {
        if k < last || (k == 4u && cy + 1u == params.cells_y) {
            edge_against(q, owned[k].x, owned[k].y);
        }
    }
}

// Every grid cell whose box the query's overlaps.
fn walk(q: Query) {
    let tiles = params.tiles_x * params.tiles_y;
    for (var s = 0u; s < params.supertiles_x * params.supertiles_y; s++) {
        let sb = bounds[tiles + s];
        if !overlaps(q.lo, q.hi, sb.lo.xyz, sb.hi.xyz) {
            continue;
        }
        let sx = s % params.supertiles_x;
        let sy = s / params.supertiles_x;
        for (var ty = sy * TILE; ty < min(sy * TILE + TILE, params.tiles_y); ty++) {
            for (var tx = sx * TILE; tx < min(sx * TILE + TILE, params.tiles_x); tx++) {
                let tb = bounds[ty * params.tiles_x + tx];
                if !overlaps(q.lo, q.hi, tb.lo.xyz, tb.hi.xyz) {
                    continue;
                }
                for (var cy = ty * TILE; cy < min(ty * TILE + TILE, params.cells_y); cy++) {
                    for (var cx = tx * TILE; cx < min(tx * TILE + TILE, params.cells_x); cx++) {
                        let c = cy * params.cells_x + cx;
                        let cb = bounds[cell_at(c)];
                        if overlaps(q.lo, q.hi, cb.lo.xyz, cb.hi.xyz) {
                            against(q, cx, cy);
                        }
                    }
                }
            }
        }
    }
}

// Where cell c's box is in `bounds`.
fn cell_at(c: u32) -> u32 {
    return params.tiles_x * params.tiles_y + params.supertiles_x * params.supertiles_y + c;
}
