// Stage "separate": each cloth vertex's step, from where it started to
// where the solve and the push-out left it, held back where the cloth would
// otherwise pass through itself (issue 23). CPU twin: src/cpu/separate.rs
// (`Within::keep_apart`), which finds the same pairs and holds the same
// vertices.
//
// 1. `prepare`, `tiles` (and collide's `supertiles`): flags cleared, each
//    grid cell's swept box (of its corners from x_start to x), and the tile
//    hierarchy over the cells refitted to them.
// 2. `walks`: the near pairs, vertex–triangle and edge–edge pairs sharing
//    no vertex whose swept boxes, the first grown by the floor, overlap and
//    that could fail the relative test. One walk per vertex, for it and
//    the edges it starts (walk.wgsl), visits the super-tiles and tiles
//    their boxes overlap, then the cells whose swept box they overlap, and
//    tests the cell's two triangles (the vertex) or the edges the cell owns
//    (an edge). A pair lowers the least separation (where the step
//    started) of its four vertices (an atomic minimum over the bits of a
//    non-negative f32, which order as the floats do) and joins the pair
//    list (params.self_capacity long: 8 per vertex, or what one binding
//    holds).
// 3. cpu::separate::ROUNDS rounds of `round` (or, when the list overflowed,
//    `recheck`, which walks again for the same pairs), `settle` and
//    `plan`: a pair whose sides' displacements differ by more than
//    2 gamma (s − floor) holds its four vertices (flag bit 1, folded into
//    bit 0 by `settle`, so a round reads only the last one's result and the
//    order pairs are met in does not matter). `plan` sizes
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
// Per pair its four vertices (EDGE_PAIR on the first of an edge–edge
// pair); its normal and separation are computed again from x_start.
@group(1) @binding(11) var<storage, read_write> pairs: array<vec4<u32>>;
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

// The box vertex i sweeps.
fn swept_lo(i: u32) -> vec3<f32> {
    return min(x_start[i].xyz, x[i].xyz);
}

fn swept_hi(i: u32) -> vec3<f32> {
    return max(x_start[i].xyz, x[i].xyz);
}

// A slab two primitives lie on either side of at the step's start
// (cpu::separate::Slab): unit normal from the second to the first (zero
// where there is none) and width.
struct Slab {
    normal: vec3<f32>,
    width: f32,
}

// The slab normal to `towards` holding first-side point a and second-side
// point b on its faces (Slab::between).
fn slab_between(towards: vec3<f32>, a: vec3<f32>, b: vec3<f32>) -> Slab {
    // As glam's normalize_or_zero: none where 1 / |towards| is not finite.
    let inv = 1.0 / length(towards);
    var normal = vec3<f32>(0.0);
    if inv > 0.0 && inv <= 0x1.fffffep+127f {
        normal = towards * inv;
    }
    let width = dot(normal, a - b);
    if width < 0.0 {
        return Slab(-normal, -width);
    }
    return Slab(normal, width);
}

// A pair as it stands at the step's start (cpu::separate::NearPair::at):
// its separation, the slab along its nearest points' line and the one
// normal to the triangle or to both edges.
struct Gap {
    nearest: Slab,
    plane: Slab,
    separation: f32,
}

fn gap_at_start(p: vec4<u32>, edge: bool) -> Gap {
    let a = x_start[p.x].xyz;
    let b = x_start[p.y].xyz;
    let c = x_start[p.z].xyz;
    let d = x_start[p.w].xyz;
    var near_a = a;
    var near_b: vec3<f32>;
    var plane: Slab;
    if edge {
        let m = closest_between_segments(a, b, c, d);
        near_a = m[0];
        near_b = m[1];
        plane = slab_between(cross(b - a, d - c), a, c);
    } else {
        near_b = closest_on_triangle(a, b, c, d);
        plane = slab_between(cross(c - b, d - b), a, b);
    }
    let gap = near_a - near_b;
    return Gap(slab_between(gap, near_a, near_b), plane, length(gap));
}

fn touching(g: Gap) -> bool {
    return all(g.nearest.normal == vec3<f32>(0.0));
}

// 2 gamma (width − floor).
fn allowance(width: f32) -> f32 {
    return 2.0 * params.self_gamma * max(width - params.self_floor, 0.0);
}

// The most n·(d_b − d_a) over a vertex a of the first side and b of the
// second; with n zero, the most |d_a − d_b|.
fn approach(d: array<vec3<f32>, 4>, edge: bool, n: vec3<f32>) -> f32 {
    let split = select(1u, 2u, edge);
    let none = all(n == vec3<f32>(0.0));
    var most = 0.0;
    for (var a = 0u; a < split; a++) {
        for (var b = split; b < 4u; b++) {
            most = max(most, select(dot(n, d[b] - d[a]), length(d[a] - d[b]), none));
        }
    }
    return most;
}

// Whether displacements d keep the pair above the floor
// (NearPair::passes): across either slab, or touching, by the widest
// difference.
fn passes(d: array<vec3<f32>, 4>, edge: bool, g: Gap) -> bool {
    if touching(g) {
        return approach(d, edge, vec3<f32>(0.0)) <= allowance(g.separation);
    }
    let slabs = array<Slab, 2>(g.nearest, g.plane);
    for (var k = 0u; k < 2u; k++) {
        let s = slabs[k];
        if usable(s, k) && approach(d, edge, s.normal) <= allowance(s.width) {
            return true;
        }
    }
    return false;
}

// Slab k of a pair that is not touching may be used (NearPair::usable):
// the nearest points' always, the planes' where wider than the floor.
fn usable(s: Slab, k: u32) -> bool {
    return k == 0u || (any(s.normal != vec3<f32>(0.0)) && s.width > params.self_floor);
}

// Whether the pair could fail however its vertices are held
// (NearPair::could_fail): across a slab, max(0, n·d_b) + max(0, −n·d_a)
// at their largest; touching, the longest full step or the widest
// difference.
fn could_fail(p: vec4<u32>, edge: bool, g: Gap) -> bool {
    let d = array<vec3<f32>, 4>(step_of(p.x), step_of(p.y), step_of(p.z), step_of(p.w));
    if touching(g) {
        let longest = max(max(length(d[0]), length(d[1])), max(length(d[2]), length(d[3])));
        return longest > 0.0 || !passes(d, edge, g);
    }
    let split = select(1u, 2u, edge);
    let slabs = array<Slab, 2>(g.nearest, g.plane);
    for (var k = 0u; k < 2u; k++) {
        let n = slabs[k].normal;
        if !usable(slabs[k], k) {
            continue;
        }
        var towards = 0.0;
        var away = 0.0;
        for (var v = 0u; v < 4u; v++) {
            let along = dot(n, d[v]);
            if v < split {
                away = max(away, -along);
            } else {
                towards = max(towards, along);
            }
        }
        if towards + away <= allowance(slabs[k].width) {
            return false;
        }
    }
    return true;
}

// Whether the pair fails with the steps the last round left.
fn fails(p: vec4<u32>, edge: bool, g: Gap) -> bool {
    let d = array<vec3<f32>, 4>(moved(p.x), moved(p.y), moved(p.z), moved(p.w));
    return !passes(d, edge, g);
}

fn hold_pair(p: vec4<u32>) {
    atomicOr(&separations[params.n_vertices + p.x], 2u);
    atomicOr(&separations[params.n_vertices + p.y], 2u);
    atomicOr(&separations[params.n_vertices + p.z], 2u);
    atomicOr(&separations[params.n_vertices + p.w], 2u);
}

// A pair the walk met (walk.wgsl): when it could fail, its separation
// lowers its vertices' least and it joins the list; or (`test`) the pair
// is tested as a round would.
fn pair(vertices: vec4<u32>, edge: bool, test: bool) {
    let g = gap_at_start(vertices, edge);
    if !could_fail(vertices, edge, g) {
        return;
    }
    if test {
        if fails(vertices, edge, g) {
            hold_pair(vertices);
        }
        return;
    }
    let bits = bitcast<u32>(g.separation);
    atomicMin(&separations[vertices.x], bits);
    atomicMin(&separations[vertices.y], bits);
    atomicMin(&separations[vertices.z], bits);
    atomicMin(&separations[vertices.w], bits);
    let k = atomicAdd(&separations[header(SELF_PAIR_COUNT)], 1u);
    if k < capacity() {
        pairs[k] = vec4<u32>(vertices.x | select(0u, EDGE_PAIR, edge), vertices.yzw);
    }
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
        bounds[cell_at(i)] = cell_box(vec2<u32>(i % params.cells_x, i / params.cells_x));
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

// What vertex i sweeps; the walk's queries reach the floor beyond.
fn extent(i: u32) -> Bounds {
    return Bounds(vec4<f32>(swept_lo(i), 0.0), vec4<f32>(swept_hi(i), 0.0));
}

fn growth() -> f32 {
    return params.self_floor;
}

// Every pair sharing no vertex is near when its boxes are.
fn refused_corners(w: Walk, cell: vec2<u32>) -> u32 {
    return 0u;
}

// Vertex i and the edges it starts against what lies near their paths:
// listing the near pairs, or (`test`) a round's test of them when the list
// overflowed.
fn walk_at(i: u32, test: bool) {
    if i < params.n_vertices {
        walk(walk_of(i, test));
    }
}

@compute @workgroup_size(WORKGROUP)
fn walks(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_at(id.x, false);
}

// A round when the list overflowed: the walks again, testing their pairs.
@compute @workgroup_size(WORKGROUP)
fn recheck(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_at(id.x, true);
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
    let first = pairs[k].x;
    let edge = (first & EDGE_PAIR) != 0u;
    let p = vec4<u32>(first & ~EDGE_PAIR, pairs[k].yzw);
    // The normal again from where the step started, as the walk found it.
    if fails(p, edge, gap_at_start(p, edge)) {
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
    set_dispatch(SELF_RECHECK_ARGS, select(0u, groups(params.n_vertices), walked));
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
        // Steps, not substeps: this runs after the clock's advance, and
        // before the next step's first solve clears the flags.
        let flags = state.step_flags;
        let fell_back = first_in_step(flags, fallback, STEP_FALLBACK);
        let overflowed = first_in_step(flags, count > capacity(), STEP_OVERFLOW);
        state.step_flags = flags | fell_back | overflowed;
        state.self_fallbacks += select(0u, 1u, fell_back != 0u);
        state.self_overflows += select(0u, 1u, overflowed != 0u);
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
