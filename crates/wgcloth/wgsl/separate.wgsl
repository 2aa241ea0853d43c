// Stage "separate": each cloth vertex's step, from where it started to
// where the solve and the push-out left it, held back where the cloth would
// otherwise pass through itself (issue 23). CPU twin: src/cpu/separate.rs
// (`Within::keep_apart`), which finds the same pairs and holds the same
// vertices.
//
// 1. `prepare`, `tiles` (and collide's `supertiles`): flags cleared, each
//    grid cell's swept box (of its corners from x_start to x), and the tile
//    hierarchy over the cells refitted to them.
// 2. `vertices`, `edges`: the near pairs, vertex–triangle and edge–edge
//    pairs sharing no vertex whose swept boxes, the first grown by the
//    floor, overlap and that could fail the relative test. A query box
//    walks the super-tiles and tiles it overlaps, then the cells whose
//    swept box it overlaps, and tests the cell's two triangles (a vertex)
//    or the edges the cell owns (an edge). A pair lowers the least separation (where the step
//    started) of its four vertices (an atomic minimum over the bits of a
//    non-negative f32, which order as the floats do) and joins the pair
//    list (params.self_capacity long: 8 per vertex, or what one binding
//    holds).
// 3. cpu::separate::ROUNDS rounds of `round` (or, when the list overflowed,
//    `recheck_vertices` and `recheck_edges`, which walk again for the same
//    pairs), `settle` and `plan`: a pair whose sides' displacements differ
//    by more than 2 gamma (s − floor) holds its four vertices (flag bit 1,
//    folded into bit 0 by `settle`, so a round reads only the last one's
//    result and the order pairs are met in does not matter). `plan` sizes
//    the next round's indirect dispatches: none once a round holds nothing
//    new.
// 4. `finish`: each held vertex moves at most gamma (s − floor); if the
//    last round still held new vertices, every vertex in a near pair is.

// Positions where the step started (integrate.wgsl keeps them).
@group(1) @binding(1) var<storage, read> x_start: array<vec4<f32>>;
// Positions where the solve and push-out left them; held back in `finish`.
@group(1) @binding(2) var<storage, read_write> x: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read_write> v: array<vec4<f32>>;
// Per vertex its least separation's bits, then per vertex its flags, then
// the header (gpu::constants::self_header's words, at 2 n; zeroed before
// the pass).
@group(1) @binding(10) var<storage, read_write> separations: array<atomic<u32>>;
// Per pair five words: its four vertices (EDGE_PAIR on the first of an
// edge–edge pair) and its separation's bits.
@group(1) @binding(11) var<storage, read_write> pairs: array<u32>;
@group(1) @binding(12) var<storage, read_write> state: StepState;
// The next round's indirect dispatches (`plan` writes them).
@group(1) @binding(13) var<storage, read_write> dispatches: array<u32>;

fn header(k: u32) -> u32 {
    return 2u * params.n_vertices + k;
}

fn capacity() -> u32 {
    return params.self_capacity;
}

fn step_of(i: u32) -> vec3<f32> {
    return x[i].xyz - x_start[i].xyz;
}

fn overlaps(lo: vec3<f32>, hi: vec3<f32>, b_lo: vec3<f32>, b_hi: vec3<f32>) -> bool {
    return all(lo <= b_hi) && all(b_lo <= hi);
}

// A query: vertex `a` (edge false) or the edge (a, b), a < b, the box it
// sweeps grown by the floor, and whether it lists its pairs (false) or
// tests them as a round does (true).
struct Query {
    lo: vec3<f32>,
    a: u32,
    hi: vec3<f32>,
    b: u32,
    edge: bool,
    test: bool,
}

// The box vertex i sweeps.
fn swept_lo(i: u32) -> vec3<f32> {
    return min(x_start[i].xyz, x[i].xyz);
}

fn swept_hi(i: u32) -> vec3<f32> {
    return max(x_start[i].xyz, x[i].xyz);
}

// The most a displacement of one side of a pair differs from one of the
// other's (cpu::separate::NearPair::apart): the vertex and the triangle,
// or the two edges.
fn apart(d: array<vec3<f32>, 4>, edge: bool) -> f32 {
    let split = select(1u, 2u, edge);
    var most = 0.0;
    for (var a = 0u; a < split; a++) {
        for (var b = split; b < 4u; b++) {
            most = max(most, length(d[a] - d[b]));
        }
    }
    return most;
}

// 2 gamma (s − floor).
fn allowance(s: f32) -> f32 {
    return 2.0 * params.self_gamma * max(s - params.self_floor, 0.0);
}

// Whether the pair could fail however its vertices are held
// (NearPair::could_fail): the longest full step or the widest difference.
fn could_fail(p: vec4<u32>, edge: bool, s: f32) -> bool {
    let d = array<vec3<f32>, 4>(step_of(p.x), step_of(p.y), step_of(p.z), step_of(p.w));
    let longest = max(max(length(d[0]), length(d[1])), max(length(d[2]), length(d[3])));
    return max(longest, apart(d, edge)) > allowance(s);
}

// Whether the pair fails with the steps the last round left.
fn fails(p: vec4<u32>, edge: bool, s: f32) -> bool {
    let d = array<vec3<f32>, 4>(moved(p.x), moved(p.y), moved(p.z), moved(p.w));
    return apart(d, edge) > allowance(s);
}

fn hold_pair(p: vec4<u32>) {
    atomicOr(&separations[params.n_vertices + p.x], 2u);
    atomicOr(&separations[params.n_vertices + p.y], 2u);
    atomicOr(&separations[params.n_vertices + p.z], 2u);
    atomicOr(&separations[params.n_vertices + p.w], 2u);
}

fn note(q: Query, vertices: vec4<u32>, s: f32) {
    if !could_fail(vertices, q.edge, s) {
        return;
    }
    if q.test {
        if fails(vertices, q.edge, s) {
            hold_pair(vertices);
        }
        return;
    }
    let bits = bitcast<u32>(s);
    atomicMin(&separations[vertices.x], bits);
    atomicMin(&separations[vertices.y], bits);
    atomicMin(&separations[vertices.z], bits);
    atomicMin(&separations[vertices.w], bits);
    let k = atomicAdd(&separations[header(SELF_PAIR_COUNT)], 1u);
    if k < capacity() {
        pairs[5u * k] = vertices.x | select(0u, EDGE_PAIR, q.edge);
        pairs[5u * k + 1u] = vertices.y;
        pairs[5u * k + 2u] = vertices.z;
        pairs[5u * k + 3u] = vertices.w;
        pairs[5u * k + 4u] = bits;
    }
}

// The vertex against cloth triangle t.
fn vertex_against(q: Query, t: u32) {
    let tri = vec3<u32>(cloth_index(3u * t), cloth_index(3u * t + 1u), cloth_index(3u * t + 2u));
    if any(tri == vec3<u32>(q.a)) {
        return;
    }
    let lo = min(min(swept_lo(tri.x), swept_lo(tri.y)), swept_lo(tri.z));
    let hi = max(max(swept_hi(tri.x), swept_hi(tri.y)), swept_hi(tri.z));
    if !overlaps(q.lo, q.hi, lo, hi) {
        return;
    }
    let p = x_start[q.a].xyz;
    let c = closest_on_triangle(p, x_start[tri.x].xyz, x_start[tri.y].xyz, x_start[tri.z].xyz);
    note(q, vec4<u32>(q.a, tri), length(p - c));
}

// The edge against edge (u, w) when it is above it (each pair from its
// lower edge, as on the CPU).
fn edge_against(q: Query, u: u32, w: u32) {
    let f = vec2<u32>(min(u, w), max(u, w));
    let above = f.x > q.a || (f.x == q.a && f.y > q.b);
    let apart = f.x != q.a && f.x != q.b && f.y != q.a && f.y != q.b;
    if !(above && apart) {
        return;
    }
    let lo = min(swept_lo(f.x), swept_lo(f.y));
    let hi = max(swept_hi(f.x), swept_hi(f.y));
    if overlaps(q.lo, q.hi, lo, hi) {
        let m = closest_between_segments(x_start[q.a].xyz, x_start[q.b].xyz, x_start[f.x].xyz,
                                         x_start[f.y].xyz);
        note(q, vec4<u32>(q.a, q.b, f), length(m[0] - m[1]));
    }
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

// Every grid cell whose swept box the query's overlaps.
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

// Where cell c's swept box is in `bounds`.
fn cell_at(c: u32) -> u32 {
    return params.tiles_x * params.tiles_y + params.supertiles_x * params.supertiles_y + c;
}

// Nothing near any vertex yet (+∞), none held, `plan` reading its first
// round as changed; the box cell i sweeps.
@compute @workgroup_size(WORKGROUP)
fn prepare(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i == 0u {
        atomicStore(&separations[header(SELF_CHANGED)], 1u);
    }
    if i < params.n_vertices {
        atomicStore(&separations[i], 0x7f800000u);
        atomicStore(&separations[params.n_vertices + i], 0u);
    }
    if i < params.cells_x * params.cells_y {
        let nx = params.cells_x + 1u;
        let k = (i / params.cells_x) * nx + i % params.cells_x;
        let lo = min(min(swept_lo(k), swept_lo(k + 1u)), min(swept_lo(k + nx), swept_lo(k + nx + 1u)));
        let hi = max(max(swept_hi(k), swept_hi(k + 1u)), max(swept_hi(k + nx), swept_hi(k + nx + 1u)));
        bounds[cell_at(i)] = Bounds(vec4<f32>(lo, 0.0), vec4<f32>(hi, 0.0));
    }
}

// The box tile k (collide.wgsl's `tiles`: cells [8 tx, 8 tx + 8)) sweeps:
// the union of its cells' (tiles.wgsl).
@compute @workgroup_size(WORKGROUP)
fn tiles(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= params.tiles_x * params.tiles_y {
        return;
    }
    let tx = k % params.tiles_x;
    let ty = k / params.tiles_x;
    bounds[k] = block_bounds(cell_at(0u), params.cells_x, params.cells_y, tx, ty);
}

// Vertex i against the triangles near its path.
fn walk_vertex(i: u32, test: bool) {
    if i >= params.n_vertices {
        return;
    }
    let f = params.self_floor;
    walk(Query(swept_lo(i) - f, i, swept_hi(i) + f, i, false, test));
}

// Spring s, if along a triangle, against the edges near its path.
fn walk_edge(s: u32, test: bool) {
    if s >= params.n_springs || spring_triangles(s).x == NO_TRIANGLE {
        return;
    }
    let ends = spring_ends(s);
    let a = min(ends.x, ends.y);
    let b = max(ends.x, ends.y);
    let f = params.self_floor;
    let lo = min(swept_lo(a), swept_lo(b)) - f;
    let hi = max(swept_hi(a), swept_hi(b)) + f;
    walk(Query(lo, a, hi, b, true, test));
}

@compute @workgroup_size(WORKGROUP)
fn vertices(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_vertex(id.x, false);
}

@compute @workgroup_size(WORKGROUP)
fn edges(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_edge(id.x, false);
}

// A round when the list overflowed: the walks again, testing their pairs.
@compute @workgroup_size(WORKGROUP)
fn recheck_vertices(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_vertex(id.x, true);
}

@compute @workgroup_size(WORKGROUP)
fn recheck_edges(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_edge(id.x, true);
}

// How far vertex i may move when held (cpu::separate::displacement_bound
// of its least separation).
fn bound(i: u32) -> f32 {
    let s = bitcast<f32>(atomicLoad(&separations[i]));
    return params.self_gamma * max(s - params.self_floor, 0.0);
}

fn held(i: u32) -> bool {
    return (atomicLoad(&separations[params.n_vertices + i]) & 1u) != 0u;
}

// The step a vertex takes as the last round left it.
fn moved(i: u32) -> vec3<f32> {
    let d = step_of(i);
    let b = bound(i);
    let length = length(d);
    if held(i) && length > b {
        return d * (b / length);
    }
    return d;
}

// One listed pair: when its two sides' displacements differ by more than
// 2 gamma (s − floor), its four vertices are held from the next round on.
@compute @workgroup_size(WORKGROUP)
fn round(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= min(atomicLoad(&separations[header(SELF_PAIR_COUNT)]), capacity()) {
        return;
    }
    let first = pairs[5u * k];
    let edge = (first & EDGE_PAIR) != 0u;
    let p = vec4<u32>(first & ~EDGE_PAIR, pairs[5u * k + 1u], pairs[5u * k + 2u], pairs[5u * k + 3u]);
    if fails(p, edge, bitcast<f32>(pairs[5u * k + 4u])) {
        hold_pair(p);
    }
}

// A vertex the round held for the first time counts as a change; bit 1
// folds into bit 0.
@compute @workgroup_size(WORKGROUP)
fn settle(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    let f = atomicLoad(&separations[params.n_vertices + i]);
    if f == 2u {
        atomicAdd(&separations[header(SELF_CHANGED)], 1u);
    }
    atomicStore(&separations[params.n_vertices + i], (f | (f >> 1u)) & 1u);
}

fn set_dispatch(at: u32, groups: u32) {
    dispatches[at] = groups;
    dispatches[at + 1u] = 1u;
    dispatches[at + 2u] = 1u;
}

fn groups(n: u32) -> u32 {
    return (n + WORKGROUP - 1u) / WORKGROUP;
}

// One invocation: whether the last round held anything new, and the next
// round's dispatches: none once it did not; the list's round, or the
// walks again when it overflowed.
@compute @workgroup_size(1)
fn plan() {
    let unsettled = atomicLoad(&separations[header(SELF_CHANGED)]) > 0u;
    atomicStore(&separations[header(SELF_CHANGED)], 0u);
    atomicStore(&separations[header(SELF_UNSETTLED)], select(0u, 1u, unsettled));
    let count = atomicLoad(&separations[header(SELF_PAIR_COUNT)]);
    let listed = unsettled && count <= capacity();
    let walked = unsettled && count > capacity();
    set_dispatch(SELF_ROUND_ARGS, select(0u, groups(count), listed));
    set_dispatch(SELF_RECHECK_VERTEX_ARGS, select(0u, groups(params.n_vertices), walked));
    set_dispatch(SELF_RECHECK_EDGE_ARGS, select(0u, groups(params.n_springs), walked));
    set_dispatch(SELF_SETTLE_ARGS, select(0u, groups(params.n_vertices), unsettled));
}

// Each held vertex (every vertex in a near pair, when the rounds did not
// settle) moved at most its bound along its step, its velocity the step it
// took over h; the run's statistics.
@compute @workgroup_size(WORKGROUP)
fn finish(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let count = atomicLoad(&separations[header(SELF_PAIR_COUNT)]);
    let fallback = atomicLoad(&separations[header(SELF_UNSETTLED)]) != 0u;
    if i == 0u {
        state.self_pairs_max = max(state.self_pairs_max, count);
        state.self_fallbacks += select(0u, 1u, fallback);
        state.self_overflows += select(0u, 1u, count > capacity());
    }
    if i >= params.n_vertices {
        return;
    }
    let near = atomicLoad(&separations[i]) != 0x7f800000u;
    let hold = select(held(i), near, fallback);
    let d = step_of(i);
    let b = bound(i);
    let length = length(d);
    if hold && length > b {
        let kept = d * (b / length);
        x[i] = vec4<f32>(x_start[i].xyz + kept, 1.0);
        v[i] = vec4<f32>(kept / params.dt, 0.0);
        atomicAdd(&state.self_held_total, 1u);
    }
}
