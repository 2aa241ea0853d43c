// Includes: topology, tiles, walk, response.
// Stage "self_contact": the cloth pushing against itself (issue 23), as
// forces in the implicit solve. CPU twin: src/cpu/self_contact.rs, which
// finds the same contacts and adds the same terms in the same order.
//
// 1. `cells` (then separate's `tiles` and collide's `supertiles`): each
//    grid cell's box at the step's start and the tile hierarchy over them.
// 2. `walks`: each vertex against the triangles, each triangle edge against
//    the edges, of the cells its box grown by the thickness overlaps, in
//    one walk per vertex for it and the edges it starts (walk.wgsl); a
//    vertex projecting inside a triangle, or two edges whose closest
//    points lie inside both, closer than the thickness, sharing no vertex
//    and 2 thickness apart in the flat rest grid, is a contact: appended
//    to the list (up to params.cloth_capacity), each of its vertices'
//    counts raised.
// 3. `link`, per contact: dropped (counted) if one of its vertices is in
//    more than params.cloth_per_vertex contacts; else its eq. 8 normal
//    force, and it joins each vertex's list.
// 4. `sort`, per vertex: its list sorted by the contacts' keys (so the
//    sums do not depend on thread timing) and its friction bound's scale:
//    the load it carried in the last solve (load.wgsl) over its contacts'
//    normal forces now.
// 5. `respond`, per contact: its eqs. 8–9 force and blocks (response.wgsl,
//    as the body's contacts), the friction bound scaled.
// 6. `gather`, per vertex: the diagonal blocks β² B added to A and β rhs
//    to b. The off-diagonal blocks are applied in the solve (pcg.wgsl
//    `couple`).

@group(1) @binding(2) var<storage, read> x: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read> v: array<vec4<f32>>;
// The header (gpu::constants::cloth_header), per vertex its contacts
// found, per vertex its contacts listed, per vertex its list.
@group(1) @binding(14) var<storage, read_write> cloth_lists: array<atomic<u32>>;
@group(1) @binding(15) var<storage, read_write> cloth_pairs: array<ClothPair>;
@group(1) @binding(16) var<storage, read_write> matrix: array<PackedSym3>;
// A solver vector (`b_at`, `b_set`: gpu::shaders::SOLVER_VECTORS).
@group(1) @binding(17) var<storage, read_write> b: array<VectorEntry>;
@group(1) @binding(12) var<storage, read_write> state: StepState;
// Per vertex, the normal load it carried in the last solve (load.wgsl)
// and this step's friction bound scale.
@group(1) @binding(18) var<storage, read_write> cloth_loads: array<vec2<f32>>;

// Vertex i in the flat rest grid (cpu::self_contact::rest_point).
fn rest_point(i: u32) -> vec3<f32> {
    let nx = params.cells_x + 1u;
    return vec3<f32>(f32(i % nx) * params.rest_spacing.x, f32(i / nx) * params.rest_spacing.y, 0.0);
}

// Whether vertices i and j lie within 2 thickness of each other at rest
// (Sheet::near_at_rest).
fn near_at_rest(i: u32, j: u32) -> bool {
    let d = rest_point(i) - rest_point(j);
    let reach = 2.0 * params.cloth_thickness;
    return dot(d, d) < reach * reach;
}

// Whether the grid's neighbours lie within 2 thickness at rest
// (Sheet::neighbours_near); else no vertex is near another, and neither
// shortcut below asks.
fn neighbours_near() -> bool {
    return min(params.rest_spacing.x, params.rest_spacing.y) < 2.0 * params.cloth_thickness;
}

// The cell's corners within 2 thickness at rest of the walk's vertex
// (bits 0 to 3: bottom left, bottom right, top left, top right) and of the
// far end of its edge k (bits 4 + 4k on): no pair across them counts
// (Sheet::refused), so the walk names none (cell_pairs), as the CPU's
// refuses them before their boxes; none where the grid's neighbours are
// not near. In a fine flat cloth, most pairs a walk meets.
fn refused_corners(w: Walk, cell: vec2<u32>) -> u32 {
    if !neighbours_near() {
        return 0u;
    }
    let s = params.rest_spacing;
    // The corners' rest points (rest_point), x and y; z is 0.
    let cx = vec4<f32>(f32(cell.x), f32(cell.x + 1u), f32(cell.x), f32(cell.x + 1u)) * s.x;
    let cy = vec4<f32>(f32(cell.y), f32(cell.y), f32(cell.y + 1u), f32(cell.y + 1u)) * s.y;
    var bits = near_corners(w.a, cx, cy);
    for (var k = 0u; k < 4u; k++) {
        if w.far[k] != NO_TRIANGLE {
            bits |= near_corners(w.far[k], cx, cy) << (4u + 4u * k);
        }
    }
    return bits;
}

// The corners at (cx, cy) within 2 thickness of vertex i at rest
// (near_at_rest), as bits.
fn near_corners(i: u32, cx: vec4<f32>, cy: vec4<f32>) -> u32 {
    let p = rest_point(i);
    let dx = p.x - cx;
    let dy = p.y - cy;
    let reach = 2.0 * params.cloth_thickness;
    let near = dx * dx + dy * dy < vec4<f32>(reach * reach);
    return dot(select(vec4<u32>(0u), vec4<u32>(1u, 2u, 4u, 8u), near), vec4<u32>(1u));
}

// Whether a vertex of the pair's first side lies within 2 thickness of one
// of its second side's at rest, so that it is not apart at rest
// (Sheet::vertices_near_at_rest): tested before any geometry. The walk
// names no such pair (refused_corners), but lavapipe ran the stage about
// 5 % slower without this test.
fn vertices_near_at_rest(p: vec4<u32>, edge: bool) -> bool {
    if !neighbours_near() {
        return false;
    }
    let near = near_at_rest(p.x, p.z) || near_at_rest(p.x, p.w);
    if edge {
        return near || near_at_rest(p.y, p.z) || near_at_rest(p.y, p.w);
    }
    return near || near_at_rest(p.x, p.y);
}

// Whether the two sides lie 2 thickness apart at rest (Sheet::apart_at_rest).
fn apart_at_rest(p: vec4<u32>, edge: bool) -> bool {
    let a = rest_point(p.x);
    let b = rest_point(p.y);
    let c = rest_point(p.z);
    let d = rest_point(p.w);
    var gap: vec3<f32>;
    if edge {
        let m = closest_between_segments(a, b, c, d);
        gap = m[0] - m[1];
    } else {
        gap = a - closest_on_triangle(a, b, c, d);
    }
    return length(gap) >= 2.0 * params.cloth_thickness;
}

// A contact joins the list; its vertices count it.
fn note(key: vec4<u32>, beta: vec4<f32>) {
    let k = atomicAdd(&cloth_lists[CLOTH_COUNT], 1u);
    if k >= params.cloth_capacity {
        return;
    }
    let none = PackedSym3(vec2<f32>(0.0), vec2<f32>(0.0), vec2<f32>(0.0));
    cloth_pairs[k] = ClothPair(key, beta, vec3<f32>(0.0), 1u, none, 0.0, 0u);
    for (var s = 0u; s < 4u; s++) {
        atomicAdd(&cloth_lists[found_at(pair_vertex(key, s))], 1u);
    }
}

// Vertex p.x against triangle p.yzw (Sheet::vertex_pair).
fn vertex_pair(p: vec4<u32>) {
    if vertices_near_at_rest(p, false) {
        return;
    }
    let a = x[p.y].xyz;
    let b = x[p.z].xyz;
    let c = x[p.w].xyz;
    let cr = cross(b - a, c - a);
    let len = length(cr);
    if len == 0.0 {
        return;
    }
    let eps = params.cloth_thickness;
    let hit = point_triangle(x[p.x].xyz, a, b, c, cr * (1.0 / len), eps, eps);
    if found(hit) && hit.x != 0.0 && apart_at_rest(p, false) {
        note(p, vec4<f32>(1.0, -hit.yzw));
    }
}

// Edge p.xy against edge p.zw (Sheet::edge_pair).
fn edge_pair(p: vec4<u32>) {
    if vertices_near_at_rest(p, true) {
        return;
    }
    let e0 = x[p.x].xyz;
    let e1 = x[p.y].xyz;
    let f0 = x[p.z].xyz;
    let f1 = x[p.w].xyz;
    let st = segment_parameters(e0, e1, f0, f1);
    if !(st.x > 0.0 && st.x < 1.0 && st.y > 0.0 && st.y < 1.0) {
        return;
    }
    let gap = (e0 + (e1 - e0) * st.x) - (f0 + (f1 - f0) * st.y);
    let distance = length(gap);
    if distance > 0.0 && distance < params.cloth_thickness && apart_at_rest(p, true) {
        note(vec4<u32>(p.x | EDGE_PAIR, p.yzw), vec4<f32>(1.0 - st.x, st.x, st.y - 1.0, -st.y));
    }
}

// A pair the walk met (walk.wgsl), whose boxes overlap.
fn pair(p: vec4<u32>, edge: bool, mode: u32) {
    if edge {
        edge_pair(p);
    } else {
        vertex_pair(p);
    }
}

// Each grid cell's box at the step's start, where the walks look.
@compute @workgroup_size(WORKGROUP)
fn cells(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.cells_x * params.cells_y {
        return;
    }
    bounds[cell_at(i)] = cell_box(vec2<u32>(i % params.cells_x, i / params.cells_x));
}

// Where vertex i is; the walk's queries reach the thickness beyond.
fn extent(i: u32) -> Bounds {
    return Bounds(x[i], x[i]);
}

fn growth() -> f32 {
    return params.cloth_thickness;
}

// Vertex i and the edges it starts against what lies near them.
@compute @workgroup_size(WORKGROUP)
fn walks(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < params.n_vertices {
        walk(walk_of(id.x, 0u));
    }
}

// The coefficients of a contact whose most crowded vertex is in `most`
// (Band::coefficients): h² k_n, h k_d, h k_t at most limit / most.
fn coefficients(most: u32) -> Coefficients {
    let h = params.dt;
    let share = params.cloth_limit / f32(most);
    return Coefficients(min(params.kn, share / (h * h)), min(params.kd, share / h), min(params.kt, share / h), params.mu);
}

// The state of contact k at the step's start: v_rel, the gap from the
// surface to the penetrating point (Pair::gap), the most contacts found at
// one of its vertices and Σ β² of each vertex's count (Band::inertia).
struct Start {
    v_rel: vec3<f32>,
    gap: vec3<f32>,
    most: u32,
    spread: f32,
}

fn start_of(pair: ClothPair) -> Start {
    var s = Start(vec3<f32>(0.0), vec3<f32>(0.0), 1u, 0.0);
    for (var k = 0u; k < 4u; k++) {
        let i = pair_vertex(pair.key, k);
        let found = atomicLoad(&cloth_lists[found_at(i)]);
        s.most = max(s.most, found);
        s.spread += pair.beta[k] * pair.beta[k] * f32(found);
        s.v_rel += pair.beta[k] * v[i].xyz;
        s.gap += pair.beta[k] * x[i].xyz;
    }
    return s;
}

// Pair::normal_depth: n, and c = d̃ n with d̃ at most 0, so the band's edge
// never pulls; no force where the gap rounds to nothing.
fn normal_of(gap: vec3<f32>) -> vec3<f32> {
    let distance = length(gap);
    return select(vec3<f32>(0.0), gap / distance, distance > 0.0);
}

fn depth_of(gap: vec3<f32>) -> f32 {
    let distance = length(gap);
    return select(0.0, min(distance - params.cloth_thickness, 0.0), distance > 0.0);
}

// Contact k: dropped at a crowded vertex, else its normal force and a
// place in each vertex's list.
@compute @workgroup_size(WORKGROUP)
fn link(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= min(atomicLoad(&cloth_lists[CLOTH_COUNT]), params.cloth_capacity) {
        return;
    }
    let pair = cloth_pairs[k];
    let s = start_of(pair);
    if s.most > params.cloth_per_vertex {
        cloth_pairs[k].applied = 0u;
        atomicAdd(&cloth_lists[CLOTH_DROPPED], 1u);
        return;
    }
    let c = normal_of(s.gap) * depth_of(s.gap);
    cloth_pairs[k].pushes = normal_force(c, s.v_rel, coefficients(s.most));
    for (var t = 0u; t < 4u; t++) {
        let i = pair_vertex(pair.key, t);
        let at = atomicAdd(&cloth_lists[listed_at(i)], 1u);
        atomicStore(&cloth_lists[entry_at(i, at)], 4u * k + t);
    }
}

fn key_below(a: vec4<u32>, b: vec4<u32>) -> bool {
    for (var k = 0u; k < 4u; k++) {
        if a[k] != b[k] {
            return a[k] < b[k];
        }
    }
    return false;
}

fn entry_key(e: u32) -> vec4<u32> {
    return cloth_pairs[e / 4u].key;
}

// Vertex i's list sorted by key; its friction bound's scale
// (self_contact::bound_scales): the load it carried in the last solve over
// Σ |β| F_c of its contacts now, 1 where either is 0.
@compute @workgroup_size(WORKGROUP)
fn sort(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    let listed = atomicLoad(&cloth_lists[listed_at(i)]);
    for (var a = 1u; a < listed; a++) {
        let e = atomicLoad(&cloth_lists[entry_at(i, a)]);
        let key = entry_key(e);
        var j = a;
        while j > 0u {
            let before = atomicLoad(&cloth_lists[entry_at(i, j - 1u)]);
            if !key_below(key, entry_key(before)) {
                break;
            }
            atomicStore(&cloth_lists[entry_at(i, j)], before);
            j--;
        }
        atomicStore(&cloth_lists[entry_at(i, j)], e);
    }
    var pushed = 0.0;
    for (var a = 0u; a < listed; a++) {
        let e = atomicLoad(&cloth_lists[entry_at(i, a)]);
        let pair = cloth_pairs[e / 4u];
        pushed += abs(pair.beta[e % 4u]) * pair.pushes;
    }
    let carried = cloth_loads[i].x;
    cloth_loads[i].y = select(1.0, carried / pushed, pushed > 0.0 && carried > 0.0);
}

// Contact k's eqs. 8–9 force and blocks (cpu::self_contact::respond), its
// friction bound scaled by its vertices' scales weighted by β²
// (Pair::bound_scale).
@compute @workgroup_size(WORKGROUP)
fn respond(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= min(atomicLoad(&cloth_lists[CLOTH_COUNT]), params.cloth_capacity) {
        return;
    }
    let pair = cloth_pairs[k];
    if pair.applied == 0u {
        return;
    }
    let s = start_of(pair);
    var scaled = 0.0;
    var weight = 0.0;
    for (var t = 0u; t < 4u; t++) {
        let b2 = pair.beta[t] * pair.beta[t];
        scaled += b2 * cloth_loads[pair_vertex(pair.key, t)].y;
        weight += b2;
    }
    var k_c = coefficients(s.most);
    k_c.mu *= scaled / weight;
    let n = normal_of(s.gap);
    // Band::inertia: each vertex's mass shared among the pairs found at it.
    let inertia = params.vertex_mass / (params.dt * s.spread);
    let r = response(friction(n * depth_of(s.gap), s.v_rel, k_c), n, s.v_rel, inertia);
    cloth_pairs[k].block = sym_pack(contact_block(r, n));
    cloth_pairs[k].rhs = params.dt * (r.force - sym_mul(sym_unpack(r.damping), s.v_rel));
}

// β² B of vertex i's contacts into its diagonal block, β rhs into b, in
// key order (cpu::self_contact::add_to_system); the run's statistics.
@compute @workgroup_size(WORKGROUP)
fn gather(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i == 0u {
        let count = atomicLoad(&cloth_lists[CLOTH_COUNT]);
        let kept = min(count, params.cloth_capacity);
        let crowded = atomicLoad(&cloth_lists[CLOTH_DROPPED]);
        state.cloth_contacts_max = max(state.cloth_contacts_max, kept - crowded);
        state.cloth_contacts_dropped += crowded + count - kept;
    }
    if i >= params.n_vertices {
        return;
    }
    let listed = atomicLoad(&cloth_lists[listed_at(i)]);
    if listed == 0u {
        return;
    }
    var diag = sym_unpack(matrix_at(i));
    var rhs = b_at(i);
    for (var a = 0u; a < listed; a++) {
        let e = atomicLoad(&cloth_lists[entry_at(i, a)]);
        let pair = cloth_pairs[e / 4u];
        let beta = pair.beta[e % 4u];
        diag = sym_add(diag, sym_scale(sym_unpack(pair.block), beta * beta));
        rhs += beta * pair.rhs;
    }
    matrix_set(i, sym_pack(diag));
    b_set(i, rhs);
}
