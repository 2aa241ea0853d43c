// Includes: topology, tiles, walk, impact.
// Stage "separate": each cloth vertex's step, from where it started to
// where the solve and the push-out left it, changed where the cloth would
// otherwise pass through itself (issue 23). CPU twin: src/cpu/separate.rs
// (`Within::keep_apart`), which says why; the changes are impact.wgsl's
// (twin src/cpu/impact.rs). Every dispatch after `start` is indirect, sized
// by the `plan_*` kernel before it, so a step whose pairs pass early costs
// only empty dispatches after that.
//
// 1. `start`: each vertex's step d = x − x_start, its zone its own, its
//    sums cleared.
// 2. cpu::separate::DETECTIONS detections, each: `sweep` (the steps it is
//    for), `prepare`, `tiles` (and
//    collide's `supertiles`): each grid cell's swept box (of its corners
//    from x_start to x_start + d), the tile hierarchy refitted to them;
//    `walks`: the near pairs, vertex–triangle and edge–edge pairs sharing
//    no vertex whose swept boxes, the first grown by the floor, overlap
//    and that could fail the relative test. One walk per vertex, for it and
//    the edges it starts (walk.wgsl). A pair lowers its four vertices'
//    least separation (an atomic minimum over the bits of a non-negative
//    f32, which order as the floats do) and joins the pair list
//    (params.self_capacity long: 8 per vertex, or what one binding holds).
//    `plan_walked` sizes the passes over the list (or, where it
//    overflowed, over the walks again, which find the same pairs).
// 3. After each but the last detection, cpu::impact::IMPULSE_ROUNDS rounds
//    of `test_pairs` (failing pairs at each vertex), `plan_tested`,
//    `push_pairs` (each failing pair's push added to its vertices'
//    fixed-point sums) and `apply`; then `plan_phase` and
//    cpu::impact::ZONE_ROUNDS rounds of `hook_pairs` (each failing pair
//    lowers its vertices' next labels),
//    `plan_tested`, `jump` (labels to their labels' next; each zoned vertex
//    adds to its zone's sum or anchor), `spread` (each free zoned vertex
//    takes its zone's step) and `clear`; then `plan_detect`. A detection
//    whose first test finds nothing failing settles the step.
// 4. After the last detection, `test_pairs` and `plan_last`: where pairs
//    still fail, the last resort's cpu::separate::ROUNDS rounds of `round`
//    (or `recheck`), `settle` and `plan`: a pair whose sides' steps differ
//    by more than 2 gamma (s − floor) holds its four vertices (flag bit
//    FLAG_HELD_NEW, folded into FLAG_HELD by `settle`, so a round reads only
//    the last one's result).
// 5. `finish`: the last resort's held vertices each move at most
//    gamma (s − floor) (every vertex in a near pair, when its rounds did not
//    settle); each vertex whose step changed ends at x_start + d, its
//    velocity changed by the change over h; the run's statistics.

// Positions where the step started (integrate.wgsl keeps them).
@group(1) @binding(1) var<storage, read> x_start: array<vec4<f32>>;
// Positions where the solve and push-out left them; changed in `finish`.
@group(1) @binding(2) var<storage, read_write> x: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read_write> v: array<vec4<f32>>;
// Per vertex its words (gpu::constants::separations), then the header
// (gpu::constants::self_header's words; zeroed before the pass).
@group(1) @binding(10) var<storage, read_write> separations: array<atomic<u32>>;
// Per cloth vertex its vertex–face contact slot (collide.wgsl): where the
// body bounds its step.
@group(1) @binding(4) var<storage, read> contacts: array<Contact>;
// Per pair its four vertices (EDGE_PAIR on the first of an edge–edge
// pair); its normal and separation are computed again from x_start.
@group(1) @binding(11) var<storage, read_write> pairs: array<vec4<u32>>;
@group(1) @binding(12) var<storage, read_write> state: StepState;
// The indirect dispatches (the `plan_*` kernels write them).
@group(1) @binding(13) var<storage, read_write> dispatches: array<u32>;

fn header(k: u32) -> u32 {
    return SEP_WORDS * params.n_vertices + k;
}

fn read_header(k: u32) -> u32 {
    return atomicLoad(&separations[header(k)]);
}

fn write_header(k: u32, value: u32) {
    atomicStore(&separations[header(k)], value);
}

fn capacity() -> u32 {
    return params.self_capacity;
}

// Where vertex i's step ends, as the current detection found it.
fn end_of(i: u32) -> vec3<f32> {
    return x_start[i].xyz + swept_step(i);
}

// The box vertex i sweeps.
fn swept_lo(i: u32) -> vec3<f32> {
    return min(x_start[i].xyz, end_of(i));
}

fn swept_hi(i: u32) -> vec3<f32> {
    return max(x_start[i].xyz, end_of(i));
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
    let d = array<vec3<f32>, 4>(swept_step(p.x), swept_step(p.y), swept_step(p.z), swept_step(p.w));
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

// The pass a walk or a listed pair is met in (walk.wgsl's `mode`).
const LISTING: u32 = 0u;
const COUNTING: u32 = 1u;
const PUSHING: u32 = 2u;
const HOOKING: u32 = 3u;
const HOLDING: u32 = 4u;

fn steps_of(p: vec4<u32>) -> array<vec3<f32>, 4> {
    return array<vec3<f32>, 4>(step_of(p.x), step_of(p.y), step_of(p.z), step_of(p.w));
}

// Whether the pair fails with the steps as they stand.
fn failing(p: vec4<u32>, edge: bool, g: Gap) -> bool {
    return !passes(steps_of(p), edge, g);
}

fn hold_pair(p: vec4<u32>) {
    atomicOr(&separations[vertex_word(SEP_FLAGS, p.x)], FLAG_HELD_NEW);
    atomicOr(&separations[vertex_word(SEP_FLAGS, p.y)], FLAG_HELD_NEW);
    atomicOr(&separations[vertex_word(SEP_FLAGS, p.z)], FLAG_HELD_NEW);
    atomicOr(&separations[vertex_word(SEP_FLAGS, p.w)], FLAG_HELD_NEW);
}

// A test's failing pair: its vertices' counts.
fn count_pair(p: vec4<u32>) {
    atomicAdd(&separations[header(SELF_FAILING)], 1u);
    atomicAdd(&separations[vertex_word(SEP_COUNT, p.x)], 1u);
    atomicAdd(&separations[vertex_word(SEP_COUNT, p.y)], 1u);
    atomicAdd(&separations[vertex_word(SEP_COUNT, p.z)], 1u);
    atomicAdd(&separations[vertex_word(SEP_COUNT, p.w)], 1u);
}

// A zone round's failing pair: its vertices' next labels lowered to the
// least of their labels, and each marked zoned (Impact::zone_rounds).
fn hook_pair(p: vec4<u32>) {
    atomicAdd(&separations[header(SELF_FAILING)], 1u);
    let ids = array<u32, 4>(p.x, p.y, p.z, p.w);
    var least = 0xffffffffu;
    for (var k = 0u; k < 4u; k++) {
        least = min(least, atomicLoad(&separations[vertex_word(SEP_LABEL, ids[k])]));
    }
    for (var k = 0u; k < 4u; k++) {
        atomicMin(&separations[vertex_word(SEP_NEXT, ids[k])], least);
        atomicOr(&separations[vertex_word(SEP_FLAGS, ids[k])], FLAG_ZONED);
    }
}

// A pair the walk met (walk.wgsl), or a listed one, in a pass's `mode`:
// listed when it could fail (LISTING), else tested as the pass tests it.
fn pair(vertices: vec4<u32>, edge: bool, mode: u32) {
    let g = gap_at_start(vertices, edge);
    if !could_fail(vertices, edge, g) {
        return;
    }
    switch mode {
        case LISTING: {
            let bits = bitcast<u32>(g.separation);
            atomicMin(&separations[vertex_word(SEP_LEAST, vertices.x)], bits);
            atomicMin(&separations[vertex_word(SEP_LEAST, vertices.y)], bits);
            atomicMin(&separations[vertex_word(SEP_LEAST, vertices.z)], bits);
            atomicMin(&separations[vertex_word(SEP_LEAST, vertices.w)], bits);
            let k = atomicAdd(&separations[header(SELF_PAIR_COUNT)], 1u);
            if k < capacity() {
                pairs[k] = vec4<u32>(vertices.x | select(0u, EDGE_PAIR, edge), vertices.yzw);
            }
        }
        case COUNTING: {
            if failing(vertices, edge, g) {
                count_pair(vertices);
            }
        }
        case PUSHING: {
            if failing(vertices, edge, g) {
                let push = push_of(vertices, edge, g);
                if push.valid {
                    add_shares(vertices, edge, push);
                }
            }
        }
        case HOOKING: {
            if failing(vertices, edge, g) {
                hook_pair(vertices);
            }
        }
        default: {
            if fails(vertices, edge, g) {
                hold_pair(vertices);
            }
        }
    }
}

// Each vertex's step from the solve, its zone its own, nothing summed.
@compute @workgroup_size(WORKGROUP)
fn start(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    set_step(i, x[i].xyz - x_start[i].xyz);
    atomicStore(&separations[vertex_word(SEP_COUNT, i)], 0u);
    atomicStore(&separations[vertex_word(SEP_LABEL, i)], i);
    atomicStore(&separations[vertex_word(SEP_NEXT, i)], i);
    atomicStore(&separations[vertex_word(SEP_ANCHOR, i)], 0xffffffffu);
    clear_sum(i);
}

// A detection's steps: each vertex's as its boxes and near pairs are found
// for, which every pass over them walks for again when the list
// overflowed (so they meet the same pairs).
@compute @workgroup_size(WORKGROUP)
fn sweep(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    let d = step_of(i);
    atomicStore(&separations[swept_word(i, 0u)], bitcast<u32>(d.x));
    atomicStore(&separations[swept_word(i, 1u)], bitcast<u32>(d.y));
    atomicStore(&separations[swept_word(i, 2u)], bitcast<u32>(d.z));
}

// A detection: nothing near any vertex yet (+∞), none held; the box cell
// i sweeps.
@compute @workgroup_size(WORKGROUP)
fn prepare(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i == 0u {
        write_header(SELF_PAIR_COUNT, 0u);
    }
    if i < params.n_vertices {
        atomicStore(&separations[vertex_word(SEP_LEAST, i)], 0x7f800000u);
        atomicAnd(&separations[vertex_word(SEP_FLAGS, i)], ~(FLAG_HELD | FLAG_HELD_NEW));
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

// Vertex i and the edges it starts against what lies near their paths, in
// a pass's mode.
fn walk_at(i: u32, mode: u32) {
    if i < params.n_vertices {
        walk(walk_of(i, mode));
    }
}

fn listed_pair(k: u32, mode: u32) {
    if k >= min(read_header(SELF_PAIR_COUNT), capacity()) {
        return;
    }
    let first = pairs[k].x;
    let edge = (first & EDGE_PAIR) != 0u;
    pair(vec4<u32>(first & ~EDGE_PAIR, pairs[k].yzw), edge, mode);
}

// Each vertex and the edges it starts against the cloth near their paths,
// listing the near pairs.
@compute @workgroup_size(WORKGROUP)
fn walks(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_at(id.x, LISTING);
}

// A test: failing pairs counted at their vertices, over the list or
// (`test_walks`) the walks again.
@compute @workgroup_size(WORKGROUP)
fn test_pairs(@builtin(global_invocation_id) id: vec3<u32>) {
    listed_pair(id.x, COUNTING);
}

// A test over the walks, when the list overflowed.
@compute @workgroup_size(WORKGROUP)
fn test_walks(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_at(id.x, COUNTING);
}

// An impulse round's pushes.
@compute @workgroup_size(WORKGROUP)
fn push_pairs(@builtin(global_invocation_id) id: vec3<u32>) {
    listed_pair(id.x, PUSHING);
}

// An impulse round's pushes over the walks, when the list overflowed.
@compute @workgroup_size(WORKGROUP)
fn push_walks(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_at(id.x, PUSHING);
}

// Each vertex's step changed by its sum, which is cleared with its count.
@compute @workgroup_size(WORKGROUP)
fn apply(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    var summed = false;
    for (var k = 0u; k < 6u; k++) {
        summed = summed || atomicLoad(&separations[SEP_SUM * params.n_vertices + 6u * i + k]) != 0u;
    }
    if summed {
        set_step(i, clip(i, step_of(i) + sum_of(i)));
        atomicOr(&separations[vertex_word(SEP_FLAGS, i)], FLAG_PUSHED);
        clear_sum(i);
    }
    atomicStore(&separations[vertex_word(SEP_COUNT, i)], 0u);
}

// A zone round's hooks.
@compute @workgroup_size(WORKGROUP)
fn hook_pairs(@builtin(global_invocation_id) id: vec3<u32>) {
    listed_pair(id.x, HOOKING);
}

// A zone round's hooks over the walks, when the list overflowed.
@compute @workgroup_size(WORKGROUP)
fn hook_walks(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_at(id.x, HOOKING);
}

// Each label becomes its label's next; a zoned vertex the failsafe may not
// move offers itself as its zone's anchor; any other adds its step to its
// zone's sum, and offers itself as its body anchor (ANCHOR_BODY, which a
// fixed one's index is below) where it is stopped against the body.
@compute @workgroup_size(WORKGROUP)
fn jump(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    let next = atomicLoad(&separations[vertex_word(SEP_NEXT, i)]);
    let zone = atomicLoad(&separations[vertex_word(SEP_NEXT, next)]);
    atomicStore(&separations[vertex_word(SEP_LABEL, i)], zone);
    if (flags(i) & FLAG_ZONED) == 0u {
        return;
    }
    if is_fixed(i) {
        atomicMin(&separations[vertex_word(SEP_ANCHOR, zone)], i);
        return;
    }
    if (flags(i) & FLAG_BODY) != 0u {
        atomicMin(&separations[vertex_word(SEP_ANCHOR, zone)], i | ANCHOR_BODY);
    }
    let d = step_of(i);
    add_fixed3(zone, array<vec2<u32>, 3>(to_fixed(d.x), to_fixed(d.y), to_fixed(d.z)));
    atomicAdd(&separations[vertex_word(SEP_COUNT, zone)], 1u);
}

// Each zoned vertex that is not fixed takes its zone's anchor's step; else,
// with a body anchor, the body's step there; else its zone's mean.
@compute @workgroup_size(WORKGROUP)
fn spread(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices || (flags(i) & FLAG_ZONED) == 0u || is_fixed(i) {
        return;
    }
    let zone = atomicLoad(&separations[vertex_word(SEP_LABEL, i)]);
    let anchor = atomicLoad(&separations[vertex_word(SEP_ANCHOR, zone)]);
    var d: vec3<f32>;
    if anchor < ANCHOR_BODY {
        d = step_of(anchor);
    } else if anchor != 0xffffffffu {
        d = -contacts[anchor & ~ANCHOR_BODY].offset * params.dt;
    } else {
        let count = atomicLoad(&separations[vertex_word(SEP_COUNT, zone)]);
        d = sum_of(zone) / f32(count);
    }
    set_step(i, clip(i, d));
}

// The zone sums cleared, and each next label its label.
@compute @workgroup_size(WORKGROUP)
fn clear(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    clear_sum(i);
    atomicStore(&separations[vertex_word(SEP_COUNT, i)], 0u);
    atomicStore(&separations[vertex_word(SEP_ANCHOR, i)], 0xffffffffu);
    let label = atomicLoad(&separations[vertex_word(SEP_LABEL, i)]);
    atomicStore(&separations[vertex_word(SEP_NEXT, i)], label);
}

fn set_dispatch(at: u32, groups: u32) {
    dispatches[at] = groups;
    dispatches[at + 1u] = 1u;
    dispatches[at + 2u] = 1u;
}

fn groups(n: u32) -> u32 {
    return (n + WORKGROUP - 1u) / WORKGROUP;
}

fn settled() -> bool {
    return read_header(SELF_SETTLED) != 0u;
}

// The passes over the pairs on (over the list, or the walks where it
// overflowed) unless the step has settled, the vertex passes off.
fn plan_pairs() {
    let on = !settled();
    let count = read_header(SELF_PAIR_COUNT);
    set_dispatch(SELF_LIST_ARGS, select(0u, groups(count), on && count <= capacity()));
    set_dispatch(SELF_RETEST_ARGS, select(0u, groups(params.n_vertices), on && count > capacity()));
    set_dispatch(SELF_VERTEX_ARGS, 0u);
}

// After a detection's walks: its pairs counted, and its first test next.
@compute @workgroup_size(1)
fn plan_walked() {
    if !settled() {
        let count = read_header(SELF_PAIR_COUNT);
        write_header(SELF_MOST_PAIRS, max(read_header(SELF_MOST_PAIRS), count));
        write_header(SELF_DETECTED, read_header(SELF_DETECTED) + 1u);
        write_header(SELF_FIRST, 1u);
        // Steps, not substeps (the flags are cleared by a step's first solve).
        let step_flags = state.step_flags;
        let overflowed = first_in_step(step_flags, count > capacity(), STEP_OVERFLOW);
        state.step_flags = step_flags | overflowed;
        state.self_overflows += select(0u, 1u, overflowed != 0u);
    }
    plan_pairs();
}

// Between a detection's impulse and zone rounds.
@compute @workgroup_size(1)
fn plan_phase() {
    plan_pairs();
}

// After a test (`test_pairs` or `hook_pairs`): nothing failing ends the rounds, and
// settles the step where it was the detection's first test; else the
// round goes on.
@compute @workgroup_size(1)
fn plan_tested() {
    let failing = read_header(SELF_FAILING);
    write_header(SELF_FAILING, 0u);
    if failing == 0u && read_header(SELF_FIRST) != 0u {
        write_header(SELF_SETTLED, 1u);
    }
    write_header(SELF_FIRST, 0u);
    if failing == 0u || settled() {
        set_dispatch(SELF_LIST_ARGS, 0u);
        set_dispatch(SELF_RETEST_ARGS, 0u);
        set_dispatch(SELF_VERTEX_ARGS, 0u);
    } else {
        set_dispatch(SELF_VERTEX_ARGS, groups(params.n_vertices));
    }
}

// Before a detection: its passes, unless the step has settled.
@compute @workgroup_size(1)
fn plan_detect() {
    let on = !settled();
    let cells = params.cells_x * params.cells_y;
    set_dispatch(SELF_PREPARE_ARGS, select(0u, groups(max(params.n_vertices, cells)), on));
    set_dispatch(SELF_TILES_ARGS, select(0u, groups(params.tiles_x * params.tiles_y), on));
    set_dispatch(SELF_SUPERTILES_ARGS, select(0u, groups(params.supertiles_x * params.supertiles_y), on));
    set_dispatch(SELF_WALKS_ARGS, select(0u, groups(params.n_vertices), on));
}

// After the last detection's test: where pairs still fail, the last
// resort's first round.
@compute @workgroup_size(1)
fn plan_last() {
    let failing = read_header(SELF_FAILING);
    write_header(SELF_FAILING, 0u);
    write_header(SELF_FIRST, 0u);
    let last = failing != 0u && !settled();
    write_header(SELF_LAST_RESORT, select(0u, 1u, last));
    write_header(SELF_CHANGED, select(0u, 1u, last));
    plan_hold();
}

// The last resort's next round: none once it held nothing new; its round
// over the list, or its walks again where the list overflowed.
fn plan_hold() {
    let unsettled = read_header(SELF_CHANGED) > 0u;
    write_header(SELF_CHANGED, 0u);
    write_header(SELF_UNSETTLED, select(0u, 1u, unsettled));
    let count = read_header(SELF_PAIR_COUNT);
    let listed = unsettled && count <= capacity();
    let walked = unsettled && count > capacity();
    set_dispatch(SELF_ROUND_ARGS, select(0u, groups(count), listed));
    set_dispatch(SELF_RECHECK_ARGS, select(0u, groups(params.n_vertices), walked));
    set_dispatch(SELF_SETTLE_ARGS, select(0u, groups(params.n_vertices), unsettled));
}

// After a round of the last resort: the next round's dispatches.
@compute @workgroup_size(1)
fn plan() {
    plan_hold();
}

// How far vertex i may move when held (cpu::separate::displacement_bound
// of its least separation).
fn bound(i: u32) -> f32 {
    let s = bitcast<f32>(atomicLoad(&separations[vertex_word(SEP_LEAST, i)]));
    return params.self_gamma * max(s - params.self_floor, 0.0);
}

fn held(i: u32) -> bool {
    return (flags(i) & FLAG_HELD) != 0u;
}

// The step a vertex takes as the last resort's last round left it.
fn moved(i: u32) -> vec3<f32> {
    let d = step_of(i);
    let b = bound(i);
    let length = length(d);
    if held(i) && length > b {
        return d * (b / length);
    }
    return d;
}

// The last resort's round over the listed pairs: a pair failing with the
// steps of the round before holds its four vertices from the next round on.
@compute @workgroup_size(WORKGROUP)
fn round(@builtin(global_invocation_id) id: vec3<u32>) {
    listed_pair(id.x, HOLDING);
}

// Its round when the list overflowed: the walks again, testing their pairs.
@compute @workgroup_size(WORKGROUP)
fn recheck(@builtin(global_invocation_id) id: vec3<u32>) {
    walk_at(id.x, HOLDING);
}

// A vertex the round held for the first time counts as a change; the new
// hold folds into the held flag.
@compute @workgroup_size(WORKGROUP)
fn settle(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    let f = flags(i);
    if (f & (FLAG_HELD | FLAG_HELD_NEW)) == FLAG_HELD_NEW {
        atomicAdd(&separations[header(SELF_CHANGED)], 1u);
    }
    if (f & FLAG_HELD_NEW) != 0u {
        atomicStore(&separations[vertex_word(SEP_FLAGS, i)], (f | FLAG_HELD) & ~FLAG_HELD_NEW);
    }
}

// The last resort's holds (every vertex in a near pair, when its rounds did
// not settle); each vertex whose step changed moved to its end and its
// velocity changed with it; the run's statistics, and the flags cleared.
@compute @workgroup_size(WORKGROUP)
fn finish(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    let last_resort = read_header(SELF_LAST_RESORT) != 0u;
    if i == 0u {
        state.self_pairs_max = max(state.self_pairs_max, read_header(SELF_MOST_PAIRS));
        state.self_detections_total += read_header(SELF_DETECTED);
        // Steps, not substeps: this runs after the clock's advance, and
        // before the next step's first solve clears the flags.
        let step_flags = state.step_flags;
        let fell_back = first_in_step(step_flags, last_resort, STEP_FALLBACK);
        state.step_flags = step_flags | fell_back;
        state.self_fallbacks += select(0u, 1u, fell_back != 0u);
    }
    if i >= params.n_vertices {
        return;
    }
    let f = flags(i);
    var d = step_of(i);
    if last_resort {
        let near = atomicLoad(&separations[vertex_word(SEP_LEAST, i)]) != 0x7f800000u;
        let hold = select((f & FLAG_HELD) != 0u, near, read_header(SELF_UNSETTLED) != 0u);
        let b = bound(i);
        let length = length(d);
        if hold && length > b {
            d = d * (b / length);
            atomicAdd(&state.self_held_total, 1u);
        }
    }
    atomicStore(&separations[vertex_word(SEP_FLAGS, i)], 0u);
    if (f & FLAG_PUSHED) != 0u {
        atomicAdd(&state.self_pushed_total, 1u);
    }
    if (f & FLAG_ZONED) != 0u {
        atomicAdd(&state.self_zoned_total, 1u);
    }
    if (f & FLAG_BODY) != 0u {
        atomicAdd(&state.self_stopped_total, 1u);
    }
    let solved = x[i].xyz - x_start[i].xyz;
    var vi = v[i].xyz;
    if any(d != solved) {
        x[i] = vec4<f32>(x_start[i].xyz + d, 1.0);
        vi += (d - solved) / params.dt;
        atomicAdd(&state.self_changed_total, 1u);
    }
    // The push-out's mark cleared.
    v[i] = vec4<f32>(vi, 0.0);
}
