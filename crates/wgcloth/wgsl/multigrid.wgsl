// Includes: topology, sums, partials.
// Stage "pcg", its multigrid preconditioner: one symmetric V(1,1)-cycle on
// the cloth grid's hierarchy (src/multigrid.rs), the Galerkin coarse
// operators Pᵀ A P rebuilt every step, each level but the coarsest smoothed
// by the patch smoother (block Gauss-Seidel over 2 × 2-node patches in four
// colours, `patch_down` and `patch_up`) or damped block Jacobi. CPU twin:
// src/cpu/multigrid.rs, function by function.
//
// Each dispatch works between two levels, `hop.fine` and `hop.coarse`,
// bound per dispatch, except `tail`, which takes the coarsest levels in one
// workgroup, a barrier where the per-level kernels take a dispatch (each
// costs more than those levels' work), and `solve`, which runs the whole
// PCG solve with its V-cycles in one workgroup on a small cloth; level 0
// is the cloth, whose operator is A itself
// (diagonal blocks and spring blocks), its pinned vertices filtered out of
// the interpolation (P̃ = S P). With block Jacobi no level stores its
// pre-smoothing a = ω D⁻¹ r (the residual kernel recomputes it where it
// reads it, nine loads against a stored vector's three plus a dispatch);
// the residual and the guess are stored in the work vector, since every
// node's is read by up to nine others. The patch smoother keeps its level's
// smoothed vector in place (`smoothed`), from the pre-smoothing through the
// guess to the result.

// One level's grid and where its data lives.
struct Grid {
    level: u32,
    nx: u32,
    ny: u32,
    // ω D⁻¹ blocks, one per node, in `operators`; none on a level the patch
    // smoother smooths (`patches_at` set).
    smoothers_at: u32,
    // STORED_STENCIL blocks per node (coarse levels), in `operators`: the
    // upper half of its stencil (`stencil_block`).
    stencil_at: u32,
    // Right-hand side and correction, one vec4 per node each, in `vectors`.
    rhs_at: u32,
    correction_at: u32,
    // The work vector (residual down, guess up), one region for all levels.
    work_at: u32,
    // PATCH_BLOCKS blocks per patch in `operators`, each patch's inverse
    // (`upper`), or NO_PATCHES where block Jacobi smooths.
    patches_at: u32,
}

struct Hop {
    fine: Grid,
    coarse: Grid,
    // The patches a patch sweep of `fine` solves.
    colour: u32,
}

@group(1) @binding(0) var<storage, read> bound_hop: Hop;
// Every level's hop (the coarsest level's `fine` is itself), for `tail`.
@group(1) @binding(6) var<storage, read> hop_list: array<Hop>;
// The hop being worked on: the bound one, or the one `tail` is at.
var<private> hop: Hop;

// The kind of level a pipeline's dispatches work on, set when it is made
// (gpu::kernels::LevelKind): lavapipe runs every branch of a kernel, masked,
// for every 8 invocations, so a kernel that read the kind from its hop paid
// at every node for the cloth's rows and the coarse stencils both, and for
// both smoothers. LEVEL_ANY reads the level from the hop, as `solve` must,
// whose V-cycle starts at the cloth. Every level above the coarsest is smoothed
// alike (`tail` smooths the coarsest with its own code).
override LEVEL: u32;
override PATCHES: bool;

// Whether the fine level is the cloth.
fn on_cloth() -> bool {
    if LEVEL == LEVEL_ANY {
        return hop.fine.level == 0u;
    }
    return LEVEL == LEVEL_CLOTH;
}
// A of the cloth: its diagonal blocks (one per vertex), then one per spring.
@group(1) @binding(1) var<storage, read> matrix: array<PackedSym3>;
// Every level's smoother blocks and every coarse level's stencils.
@group(1) @binding(2) var<storage, read_write> operators: array<PackedSym3>;
// Every coarse level's right-hand side and correction, and the work
// vector. It, r and zq are solver vectors, read and written through
// `vectors_at`, `vectors_set`, ... (gpu::shaders::SOLVER_VECTORS).
@group(1) @binding(3) var<storage, read_write> vectors: array<VectorEntry>;
// The PCG residual, level 0's right-hand side (which `solve` updates).
@group(1) @binding(4) var<storage, read_write> r: array<VectorEntry>;
// z = P⁻¹ r, the V-cycle's result (and q, which it leaves alone; `solve`
// keeps p and its correction e after them).
@group(1) @binding(5) var<storage, read_write> zq: array<VectorEntry>;
// The PCG scalars `solve` starts from and leaves.
@group(1) @binding(7) var<storage, read_write> scalars: Scalars;

fn nodes(g: Grid) -> u32 {
    return g.nx * g.ny;
}

fn coords(g: Grid, i: u32) -> vec2<u32> {
    return vec2<u32>(i % g.nx, i / g.nx);
}

// Index of the node at `c` + (dx, dy), or -1 outside the grid.
fn neighbour(g: Grid, c: vec2<u32>, dx: i32, dy: i32) -> i32 {
    let x = i32(c.x) + dx;
    let y = i32(c.y) + dy;
    if x < 0 || y < 0 || x >= i32(g.nx) || y >= i32(g.ny) {
        return -1;
    }
    return y * i32(g.nx) + x;
}

fn stencil_slot(dx: i32, dy: i32) -> u32 {
    return u32((dy + 2) * 5 + dx + 2);
}

// Block (i, j) of coarse level g, j at (dx, dy) from i. Blocks and A are
// symmetric, so a node stores the centre and the offsets after it, and the
// others are its neighbours' (multigrid::stored_at).
// One load whichever node stores it: lavapipe runs both sides of a branch.
fn stencil_block(g: Grid, i: u32, j: u32, dx: i32, dy: i32) -> Sym3 {
    let slot = stencil_slot(dx, dy);
    let centre = STENCIL / 2u;
    let mine = slot >= centre;
    let at = select(j * STORED_STENCIL + centre - slot, i * STORED_STENCIL + slot - centre, mine);
    return sym_unpack(operators_at(g.stencil_at + at));
}

// The coarse parents of fine coordinate c and their weights (multigrid::parents).
struct Parents {
    at: vec2<u32>,
    w: vec2<f32>,
}

fn parents(c: u32, n_coarse: u32) -> Parents {
    let left = c / 2u;
    if c % 2u == 0u {
        return Parents(vec2<u32>(left), vec2<f32>(1.0, 0.0));
    }
    if left + 1u < n_coarse {
        return Parents(vec2<u32>(left, left + 1u), vec2<f32>(0.5));
    }
    return Parents(vec2<u32>(left), vec2<f32>(1.0, 0.0));
}

fn axis_weight(c: u32, coarse: u32, n_coarse: u32) -> f32 {
    let p = parents(c, n_coarse);
    return select(0.0, p.w.x, p.at.x == coarse) + select(0.0, p.w.y, p.at.y == coarse);
}

// Whether node i of `hop.fine` is a pinned cloth vertex.
fn filtered(i: u32) -> bool {
    return on_cloth() && is_pinned(i);
}

// The weight of fine node i in coarse node `cc` (0 at a pinned vertex).
fn fine_weight(i: u32, cc: vec2<u32>) -> f32 {
    if filtered(i) {
        return 0.0;
    }
    let c = coords(hop.fine, i);
    return axis_weight(c.x, cc.x, hop.coarse.nx) * axis_weight(c.y, cc.y, hop.coarse.ny);
}

// D⁻¹ of a diagonal block, zero if D is singular.
fn inverse(d: Sym3) -> Sym3 {
    let a = d.a;
    let b = d.b;
    // Cofactors of [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]].
    let cxx = a.y * a.z - b.y * b.y;
    let cyy = a.x * a.z - b.x * b.x;
    let czz = a.x * a.y - a.w * a.w;
    let cxy = b.x * b.y - a.w * a.z;
    let cxz = a.w * b.y - a.y * b.x;
    let cyz = a.w * b.x - a.x * b.y;
    let det = a.x * cxx + a.w * cxy + b.x * cxz;
    if !(abs(det) > 1.17549435e-38 && abs(det) < 3.0e38) {
        return sym_zero();
    }
    return Sym3(vec4<f32>(cxx, cyy, czz, cxy) / det, vec4<f32>(cxz, cyz, 0.0, 0.0) / det);
}

// |D⁻¹ B| (Frobenius) for symmetric B, column by column.
fn scaled_norm(inverse: Sym3, block: Sym3) -> f32 {
    let c0 = sym_mul(inverse, vec3<f32>(block.a.x, block.a.w, block.b.x));
    let c1 = sym_mul(inverse, vec3<f32>(block.a.w, block.a.y, block.b.y));
    let c2 = sym_mul(inverse, vec3<f32>(block.b.x, block.b.y, block.a.z));
    return sqrt(dot(c0, c0) + dot(c1, c1) + dot(c2, c2));
}

// ω_i D⁻¹ from D⁻¹ and s_i = Σ_j |D_i⁻¹ A_ij| (multigrid::row_weight).
fn smoother(inverse: Sym3, spread: f32) -> Sym3 {
    return sym_scale(inverse, min(SMOOTH_WEIGHT, 2.0 * SMOOTH_MARGIN / (1.0 + spread)));
}

fn fine_rhs(j: u32) -> vec3<f32> {
    if on_cloth() {
        return r_at(j);
    }
    return vectors_at(hop.fine.rhs_at + j);
}

// The interpolated coarse correction at fine node j.
fn interpolate(j: u32) -> vec3<f32> {
    if filtered(j) {
        return vec3<f32>(0.0);
    }
    let c = coords(hop.fine, j);
    let px = parents(c.x, hop.coarse.nx);
    let py = parents(c.y, hop.coarse.ny);
    var acc = vec3<f32>(0.0);
    for (var b = 0u; b < 2u; b++) {
        for (var a = 0u; a < 2u; a++) {
            let at = py.at[b] * hop.coarse.nx + px.at[a];
            acc += (px.w[a] * py.w[b]) * vectors_at(hop.coarse.correction_at + at);
        }
    }
    return acc;
}

// The fine level's pre-smoothing ω D⁻¹ r at node j.
fn pre(j: u32) -> vec3<f32> {
    return sym_mul(sym_unpack(operators_at(hop.fine.smoothers_at + j)), fine_rhs(j));
}

fn work(j: u32) -> vec3<f32> {
    return vectors_at(hop.fine.work_at + j);
}

// Whether the patch smoother smooths the fine level.
fn patched() -> bool {
    return PATCHES;
}

// The fine level's smoothed vector, which the patch smoother keeps in
// place: z on the cloth, the correction on a coarse level.
fn smoothed(j: u32) -> vec3<f32> {
    if on_cloth() {
        return zq_at(j);
    }
    return vectors_at(hop.fine.correction_at + j);
}

fn set_smoothed(j: u32, value: vec3<f32>) {
    if on_cloth() {
        zq_set(j, value);
    } else {
        vectors_set(hop.fine.correction_at + j, value);
    }
}

// The fine level's guess at node j: its pre-smoothing on the way down, the
// stored guess (pre-smoothing plus coarse correction) on the way up; with
// patches, the smoothed vector, which holds each.
fn guess(j: u32, up: bool) -> vec3<f32> {
    if patched() {
        return smoothed(j);
    }
    if up {
        return work(j);
    }
    return pre(j);
}

// The patch colour of the node at `c` (multigrid::node_colour).
fn colour_of(c: vec2<u32>) -> u32 {
    return (c.x / 2u) % 2u + 2u * ((c.y / 2u) % 2u);
}

// Every patch colour, as a range for `counted`.
const ALL_COLOURS = vec2<u32>(0u, PATCH_COLOURS);

// Whether the fine level's node at `c` is of the colours `colours.x` up
// to `colours.y` (not included), which a row product takes.
fn counted(c: vec2<i32>, colours: vec2<u32>) -> bool {
    let k = colour_of(vec2<u32>(c));
    return k >= colours.x && k < colours.y;
}

// Grid offset (dx, dy) of cloth vertex j from vertex i, a spring apart: a
// spring reaches at most two nodes along each axis, so j − i = dy nx + dx
// falls in one of five ranges that do not overlap on a grid at least five
// wide, told apart by comparisons; no division per neighbour.
fn spring_offset(g: Grid, i: u32, j: u32) -> vec2<i32> {
    if g.nx < 5u {
        return vec2<i32>(coords(g, j)) - vec2<i32>(coords(g, i));
    }
    let d = i32(j) - i32(i);
    let n = i32(g.nx);
    let dy = i32(d > 2 - 2 * n) + i32(d > 2 - n) + i32(d > 2) + i32(d > n + 2) - 2;
    return vec2<i32>(d - dy * n, dy);
}

// Row i of the fine level's operator times its guess, over the nodes of
// `colours` (a forward patch sweep's later colours are still zero).
fn row_guess(i: u32, up: bool, colours: vec2<u32>) -> vec3<f32> {
    let g = hop.fine;
    let every = all(colours == ALL_COLOURS);
    let c = coords(g, i);
    var acc = vec3<f32>(0.0);
    if on_cloth() {
        if every || counted(vec2<i32>(c), colours) {
            acc = sym_mul(sym_unpack(matrix_at(i)), guess(i, up));
        }
        for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
            let j = adjacent_vertex(k);
            if every || counted(vec2<i32>(c) + spring_offset(g, i, j), colours) {
                acc += sym_mul(sym_unpack(matrix_at(params.n_vertices + adjacent_spring(k))), guess(j, up));
            }
        }
        return acc;
    }
    for (var dy = -2; dy <= 2; dy++) {
        for (var dx = -2; dx <= 2; dx++) {
            let j = neighbour(g, c, dx, dy);
            if j >= 0 && (every || counted(vec2<i32>(c) + vec2<i32>(dx, dy), colours)) {
                acc += sym_mul(stencil_block(g, i, u32(j), dx, dy), guess(u32(j), up));
            }
        }
    }
    return acc;
}

// The fine nodes coarse node cc gathers from: 2 cc − 1 ..= 2 cc + 1 per
// axis, within the grid (as `first`, `end`).
fn children(cc: u32, n_fine: u32) -> vec2<u32> {
    return vec2<u32>(max(2u * cc, 1u) - 1u, min(2u * cc + 2u, n_fine));
}

var<private> acc: array<Sym3, STENCIL>;

// Whether `galerkin` sums each coarse row whole, for its block-Jacobi
// smoother; a level the patch smoother smooths needs only the stored half.
fn whole_rows() -> bool {
    return hop.coarse.patches_at == NO_PATCHES;
}

// Adds w_i A_ij w_j to the coarse stencil of node cc for every parent of
// fine node j.
fn add_entry(cc: vec2<u32>, wi: f32, j: u32, block: Sym3) {
    if filtered(j) {
        return;
    }
    let c = coords(hop.fine, j);
    let px = parents(c.x, hop.coarse.nx);
    let py = parents(c.y, hop.coarse.ny);
    for (var b = 0u; b < 2u; b++) {
        for (var a = 0u; a < 2u; a++) {
            let w = wi * px.w[a] * py.w[b];
            let slot = stencil_slot(i32(px.at[a]) - i32(cc.x), i32(py.at[b]) - i32(cc.y));
            if w != 0.0 && (whole_rows() || slot >= STENCIL / 2u) {
                acc[slot] = sym_add(acc[slot], sym_scale(block, w));
            }
        }
    }
}

// The coarse level's stencil and smoother, per coarse node: the Galerkin
// product gathered over its children's rows. On the first hop, with block
// Jacobi, it also writes the smoothers of the cloth vertices it owns,
// (2 cc + {0, 1}).
@compute @workgroup_size(WORKGROUP)
fn galerkin(@builtin(global_invocation_id) id: vec3<u32>) {
    hop = bound_hop;
    let I = id.x;
    if I >= nodes(hop.coarse) {
        return;
    }
    let g = hop.fine;
    let cc = coords(hop.coarse, I);
    for (var k = 0u; k < STENCIL; k++) {
        acc[k] = sym_zero();
    }
    let xs = children(cc.x, g.nx);
    let ys = children(cc.y, g.ny);
    for (var y = ys.x; y < ys.y; y++) {
        for (var x = xs.x; x < xs.y; x++) {
            let i = y * g.nx + x;
            let wi = fine_weight(i, cc);
            if wi == 0.0 {
                continue;
            }
            if on_cloth() {
                add_entry(cc, wi, i, sym_unpack(matrix_at(i)));
                for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
                    add_entry(cc, wi, adjacent_vertex(k), sym_unpack(matrix_at(params.n_vertices + adjacent_spring(k))));
                }
            } else {
                let c = vec2<u32>(x, y);
                for (var dy = -2; dy <= 2; dy++) {
                    for (var dx = -2; dx <= 2; dx++) {
                        let j = neighbour(g, c, dx, dy);
                        if j >= 0 {
                            add_entry(cc, wi, u32(j), stencil_block(g, i, u32(j), dx, dy));
                        }
                    }
                }
            }
        }
    }
    // The whole row gives the smoother; the upper half is kept.
    for (var k = 0u; k < STORED_STENCIL; k++) {
        operators_set(hop.coarse.stencil_at + I * STORED_STENCIL + k, sym_pack(acc[STENCIL / 2u + k]));
    }
    if whole_rows() {
        let centre = inverse(acc[stencil_slot(0, 0)]);
        var spread = 0.0;
        for (var k = 0u; k < STENCIL; k++) {
            if k != stencil_slot(0, 0) {
                spread += scaled_norm(centre, acc[k]);
            }
        }
        operators_set(hop.coarse.smoothers_at + I, sym_pack(smoother(centre, spread)));
    }
    // The patch smoother needs no cloth smoother: a pass over A saved.
    if on_cloth() && !patched() {
        for (var y = 2u * cc.y; y < min(2u * cc.y + 2u, g.ny); y++) {
            for (var x = 2u * cc.x; x < min(2u * cc.x + 2u, g.nx); x++) {
                let i = y * g.nx + x;
                var m = sym_zero();
                if !is_pinned(i) {
                    let d = inverse(sym_unpack(matrix_at(i)));
                    var spread = 0.0;
                    for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
                        spread += scaled_norm(d, sym_unpack(matrix_at(params.n_vertices + adjacent_spring(k))));
                    }
                    m = smoother(d, spread);
                }
                operators_set(g.smoothers_at + i, sym_pack(m));
            }
        }
    }
}

// The fine level's residual after its pre-smoothing, r − A ω D⁻¹ r (with
// patches r − A s, s the forward sweeps' result, from the later colours
// alone), into the work vector.
@compute @workgroup_size(WORKGROUP)
fn residual(@builtin(global_invocation_id) id: vec3<u32>) {
    hop = bound_hop;
    if id.x < nodes(hop.fine) {
        residual_at(id.x);
    }
}

fn residual_at(i: u32) {
    var res = vec3<f32>(0.0);
    if patched() {
        // The forward sweep solved each patch exactly for the colours
        // before it, the later ones zero: what is left at a node is the
        // later colours' part (none at the last colour's).
        let later = vec2<u32>(colour_of(coords(hop.fine, i)) + 1u, PATCH_COLOURS);
        if later.x < PATCH_COLOURS {
            res = -row_guess(i, false, later);
        }
    } else {
        res = fine_rhs(i) - row_guess(i, false, ALL_COLOURS);
    }
    vectors_set(hop.fine.work_at + i, res);
}

// Down one level: the coarse right-hand side is the restricted residual,
// Pᵀ (r − A ω D⁻¹ r).
@compute @workgroup_size(WORKGROUP)
fn down(@builtin(global_invocation_id) id: vec3<u32>) {
    hop = bound_hop;
    if id.x < nodes(hop.coarse) {
        down_at(id.x);
    }
}

fn down_at(I: u32) {
    let g = hop.fine;
    let cc = coords(hop.coarse, I);
    let xs = children(cc.x, g.nx);
    let ys = children(cc.y, g.ny);
    var sum = vec3<f32>(0.0);
    for (var y = ys.x; y < ys.y; y++) {
        for (var x = xs.x; x < xs.y; x++) {
            let i = y * g.nx + x;
            let w = fine_weight(i, cc);
            if w != 0.0 {
                sum += w * work(i);
            }
        }
    }
    vectors_set(hop.coarse.rhs_at + I, sum);
}

var<workgroup> sweep: array<vec4<f32>, COARSEST_NODES>;

// The levels from `bound_hop.fine` down, in one workgroup. It starts
// below the cloth (level 0 leaves PCG's partial rᵀz, one per workgroup of
// the cloth's dispatches).
@compute @workgroup_size(WORKGROUP)
fn tail(@builtin(local_invocation_index) lid: u32) {
    cycle(lid, bound_hop.fine.level);
}

// The V-cycle from level `first` down, by one workgroup: each level's
// residual and restriction, the coarsest level's sweeps, then each one's
// guess and correction back up; the per-level kernels' work, node by node.
fn cycle(lid: u32, first: u32) {
    let coarsest = arrayLength(&hop_list) - 1u;
    for (var l = first; l < coarsest; l++) {
        hop = hop_list[l];
        if hop_list[l].fine.patches_at != NO_PATCHES {
            tail_sweeps(lid, l, true);
        }
        for (var i = lid; i < nodes(hop.fine); i += WORKGROUP) {
            residual_at(i);
        }
        storageBarrier();
        for (var i = lid; i < nodes(hop.coarse); i += WORKGROUP) {
            down_at(i);
        }
        storageBarrier();
    }
    hop = hop_list[coarsest];
    coarse(lid);
    storageBarrier();
    for (var l = coarsest; l > first; l--) {
        hop = hop_list[l - 1u];
        for (var i = lid; i < nodes(hop.fine); i += WORKGROUP) {
            guess_at(i);
        }
        storageBarrier();
        if hop_list[l - 1u].fine.patches_at != NO_PATCHES {
            tail_sweeps(lid, l - 1u, false);
        } else {
            for (var i = lid; i < nodes(hop.fine); i += WORKGROUP) {
                _ = up_at(i);
            }
            storageBarrier();
        }
    }
}

// The whole solve in one workgroup (issue 67's short step), for a cloth
// small enough that one workgroup's passes over it cost less than a chain
// of dispatches per iteration (`gpu::buffers::solved_whole`): PCG's
// iterations as pcg.wgsl's kernels take them (`spmv`, `advance`, the
// V-cycle, `next`; CPU twin cpu/pcg.rs), one after another with a barrier
// where those take a dispatch, and the V-cycle `cycle` from the cloth. It
// solves for the correction e = x' − x from r = S (b − A x) and the
// starting |S b|², rᵀr and threshold, which `init` and `init_scalars`
// leave, and leaves e for pcg's `correct` and its scalars for `finish`; it
// stops at convergence or `params.cg_max_iters`, so the step records one
// dispatch whatever the iterations. zq holds z, q, p and e, n each. It
// binds 8 storage buffers, WebGPU's default; cloth–cloth couplings would
// take two more, so a scene with them keeps the chain.
@compute @workgroup_size(WORKGROUP)
fn solve(lane: Lane) {
    let lid = lane.index;
    let n = params.n_vertices;
    // The scalars as one value for the whole workgroup, which it branches on.
    if lid == 0u {
        solve_start = scalars;
    }
    var s = workgroupUniformLoad(&solve_start);
    for (var i = lid; i < n; i += WORKGROUP) {
        zq_set(3u * n + i, vec3<f32>(0.0));
    }
    // The starting δ, and whether the solve goes on, are the V-cycle's, as
    // in the chain, whatever `init`'s Jacobi rᵀz told `init_scalars`.
    var delta = precondition(lane);
    s.delta = delta;
    s.done = u32(!going_on(s.rr, delta, s.threshold));
    s.breakdown = u32(stalled(s.rr, delta, s.threshold));
    var beta = 0.0;
    while s.done == 0u && s.iterations < params.cg_max_iters {
        // p = z + β p, q = S A p and pᵀq.
        // The first p is z alone, whatever the last solve left in p.
        for (var i = lid; i < n; i += WORKGROUP) {
            zq_set(2u * n + i, select(zq_at(i) + beta * zq_at(2u * n + i), zq_at(i), beta == 0.0));
        }
        storageBarrier();
        var pq = 0.0;
        for (var i = lid; i < n; i += WORKGROUP) {
            let qi = cloth_row(i, 2u * n);
            zq_set(n + i, qi);
            pq += dot(zq_at(2u * n + i), qi);
        }
        pq = workgroup_sum(lane, pq);
        if !usable(pq) {
            s.breakdown = 1u;
            s.done = 1u;
            break;
        }
        // e += α p, r −= α q and rᵀr.
        let alpha = s.delta / pq;
        var rr = 0.0;
        for (var i = lid; i < n; i += WORKGROUP) {
            zq_set(3u * n + i, zq_at(3u * n + i) + alpha * zq_at(2u * n + i));
            let ri = r_at(i) - alpha * zq_at(n + i);
            r_set(i, ri);
            rr += dot(ri, ri);
        }
        rr = workgroup_sum(lane, rr);
        storageBarrier();
        delta = precondition(lane);
        s.iterations += 1u;
        s.rr = rr;
        beta = delta / s.delta;
        s.delta = delta;
        s.done = u32(!going_on(rr, delta, s.threshold));
        s.breakdown = u32(stalled(rr, delta, s.threshold));
    }
    if lid == 0u {
        scalars = s;
    }
}

// The starting scalars `solve` reads, made uniform across its workgroup.
var<workgroup> solve_start: Scalars;

// z = P⁻¹ r by the V-cycle from the cloth, returning rᵀz.
fn precondition(lane: Lane) -> f32 {
    cycle(lane.index, 0u);
    var rz = 0.0;
    for (var i = lane.index; i < params.n_vertices; i += WORKGROUP) {
        rz += dot(r_at(i), zq_at(i));
    }
    return workgroup_sum(lane, rz);
}

// Row i of S A times zq's vector from `at` (0 at a pinned vertex).
fn cloth_row(i: u32, at: u32) -> vec3<f32> {
    if is_pinned(i) {
        return vec3<f32>(0.0);
    }
    var acc = sym_mul(sym_unpack(matrix_at(i)), zq_at(at + i));
    for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
        acc += sym_mul(sym_unpack(matrix_at(params.n_vertices + adjacent_spring(k))),
                       zq_at(at + adjacent_vertex(k)));
    }
    return acc;
}

// Level l's four patch sweeps in the tail's workgroup (`hop` is level l's),
// in colour order forward, else backward; WORKGROUP threads of a colour's
// at a time.
fn tail_sweeps(lid: u32, l: u32, forward: bool) {
    let g = hop_list[l].fine;
    let threads = patch_threads(g.nx, g.ny);
    for (var k = 0u; k < PATCH_COLOURS; k++) {
        let colour = select(PATCH_COLOURS - 1u - k, k, forward);
        for (var t = 0u; t < threads; t += WORKGROUP) {
            patch_sweep_at(t + lid, lid, colour, forward);
            // Its patch's residuals are read before the next overwrites them.
            workgroupBarrier();
        }
        storageBarrier();
    }
}

// The coarsest level (`hop.fine`, at most COARSEST_NODES nodes), by one
// workgroup: COARSE_SWEEPS damped Jacobi sweeps from zero.
fn coarse(lid: u32) {
    let g = hop.fine;
    let mine = lid < nodes(g);
    var e = vec3<f32>(0.0);
    if mine {
        e = sym_mul(sym_unpack(operators_at(g.smoothers_at + lid)), vectors_at(g.rhs_at + lid));
        sweep[lid] = vec4<f32>(e, 0.0);
    }
    workgroupBarrier();
    for (var k = 1u; k < COARSE_SWEEPS; k++) {
        if mine {
            let c = coords(g, lid);
            var row = vec3<f32>(0.0);
            for (var dy = -2; dy <= 2; dy++) {
                for (var dx = -2; dx <= 2; dx++) {
                    let j = neighbour(g, c, dx, dy);
                    if j >= 0 {
                        row += sym_mul(stencil_block(g, lid, u32(j), dx, dy), sweep[j].xyz);
                    }
                }
            }
            e += sym_mul(sym_unpack(operators_at(g.smoothers_at + lid)), vectors_at(g.rhs_at + lid) - row);
        }
        workgroupBarrier();
        if mine {
            sweep[lid] = vec4<f32>(e, 0.0);
        }
        workgroupBarrier();
    }
    if mine {
        vectors_set(g.correction_at + lid, e);
    }
}

// The fine level's guess, its pre-smoothing plus the interpolated coarse
// correction, into the work vector.
@compute @workgroup_size(WORKGROUP)
fn guess_up(@builtin(global_invocation_id) id: vec3<u32>) {
    hop = bound_hop;
    if id.x < nodes(hop.fine) {
        guess_at(id.x);
    }
}

fn guess_at(i: u32) {
    if patched() {
        set_smoothed(i, smoothed(i) + interpolate(i));
        return;
    }
    vectors_set(hop.fine.work_at + i, pre(i) + interpolate(i));
}

// Up one level: one more damped Jacobi sweep from the stored guess. On the
// cloth this is z = P⁻¹ r, with its partial rᵀz for PCG; with patches, the
// backward sweeps left z, and this is its rᵀz alone.
@compute @workgroup_size(WORKGROUP)
fn up(@builtin(global_invocation_id) id: vec3<u32>, lane: Lane,
      @builtin(workgroup_id) wg: vec3<u32>) {
    hop = bound_hop;
    var rz = 0.0;
    if id.x < nodes(hop.fine) {
        rz = up_at(id.x);
    }
    // Only the cloth's rᵀz is PCG's: coarser levels sum nothing (`up` is
    // bound to one level, so the branch is the pipeline's, uniform).
    if LEVEL == LEVEL_CLOTH {
        let s = workgroup_sum(lane, rz);
        if lane.index == 0u {
            store_partial(RZ, wg.x, s);
        }
    }
}

// Node i's corrected guess, z on the cloth (returning rᵀz there, else 0).
fn up_at(i: u32) -> f32 {
    let g = hop.fine;
    let ri = fine_rhs(i);
    if patched() {
        return dot(ri, smoothed(i));
    }
    let zi = work(i) + sym_mul(sym_unpack(operators_at(g.smoothers_at + i)), ri - row_guess(i, true, ALL_COLOURS));
    if on_cloth() {
        zq_set(i, zi);
        return dot(ri, zi);
    }
    vectors_set(g.correction_at + i, zi);
    return 0.0;
}

// The patch smoother. Patch (pc, pr) holds nodes 2 pc..2 pc + 2 ×
// 2 pr..2 pr + 2 of its level, local node k at (k % 2, k / 2); its inverse
// among those unknowns is built once a step (`patches`), and a sweep of
// one colour solves each of that colour's patches for its residual, four
// threads to a patch.

// Each patch's matrix, then its Cholesky factor L (in its lower half), in
// `patches`; W = L⁻¹.
var<private> patch_m: array<array<f32, 12>, 12>;
var<private> patch_w: array<array<f32, 12>, 12>;

// Sets block (k, b) of `patch_m` to `block`.
fn set_patch_block(k: u32, b: u32, block: Sym3) {
    for (var c = 0u; c < 3u; c++) {
        var unit = vec3<f32>(0.0);
        unit[c] = 1.0;
        let column = sym_mul(block, unit);
        for (var r = 0u; r < 3u; r++) {
            patch_m[3u * k + r][3u * b + c] = column[r];
        }
    }
}

// Index among a patch's six blocks above the diagonal of block (k, b), k < b
// (multigrid::upper_block), and its inverse.
fn upper_block(k: u32, b: u32) -> u32 {
    // k (k − 1) wraps at k = 0, times 0.
    return 3u * k - k * (k - 1u) / 2u + b - k - 1u;
}

fn upper_pair(m: u32) -> vec2<u32> {
    if m < 3u {
        return vec2<u32>(0u, m + 1u);
    }
    if m < 5u {
        return vec2<u32>(1u, m - 1u);
    }
    return vec2<u32>(2u, 3u);
}

// Float f of a patch's packed inverse (multigrid::PATCH_BLOCKS): the four
// diagonal blocks as PackedSym3 (xx, yy, zz, xy, xz, yz), then the six
// blocks above them, 9 floats each, column-major. Entry (i, j), i ≥ j, of
// M⁻¹ = Wᵀ W.
fn inverse_float(f: u32) -> f32 {
    var i: u32;
    var j: u32;
    if f < 24u {
        let k = f / 6u;
        let e = f % 6u;
        var rows = array<u32, 6>(0u, 1u, 2u, 0u, 0u, 1u);
        var cols = array<u32, 6>(0u, 1u, 2u, 1u, 2u, 2u);
        i = 3u * k + rows[e];
        j = 3u * k + cols[e];
    } else {
        let g = f - 24u;
        let pair = upper_pair(g / 9u);
        i = 3u * pair.x + g % 3u;
        j = 3u * pair.y + (g % 9u) / 3u;
    }
    let hi = max(i, j);
    let lo = min(i, j);
    var s = 0.0;
    for (var k = hi; k < 12u; k++) {
        s += patch_w[k][hi] * patch_w[k][lo];
    }
    return s;
}

// The inverse of `patch_m` (SPD) into `patch_w`'s W = L⁻¹, by Cholesky, as
// multigrid::patch_inverse does it; false if it is not positive definite.
// `patch_m` keeps L below its diagonal and 1 / L_jj on it.
fn patch_factor() -> bool {
    for (var j = 0u; j < 12u; j++) {
        var d = patch_m[j][j];
        for (var k = 0u; k < j; k++) {
            d -= patch_m[j][k] * patch_m[j][k];
        }
        if !(d > 0.0 && d < 3.0e38) {
            return false;
        }
        patch_m[j][j] = 1.0 / sqrt(d);
        for (var i = j + 1u; i < 12u; i++) {
            var s = patch_m[i][j];
            for (var k = 0u; k < j; k++) {
                s -= patch_m[i][k] * patch_m[j][k];
            }
            patch_m[i][j] = s * patch_m[j][j];
        }
    }
    for (var c = 0u; c < 12u; c++) {
        for (var i = 0u; i < 12u; i++) {
            patch_w[i][c] = 0.0;
        }
        patch_w[c][c] = patch_m[c][c];
        for (var i = c + 1u; i < 12u; i++) {
            var s = 0.0;
            for (var k = c; k < i; k++) {
                s += patch_m[i][k] * patch_w[k][c];
            }
            patch_w[i][c] = -s * patch_m[i][i];
        }
    }
    return true;
}

// Node i's diagonal block of the fine level's operator.
fn diagonal(i: u32) -> Sym3 {
    if on_cloth() {
        return sym_unpack(matrix_at(i));
    }
    return stencil_block(hop.fine, i, i, 0, 0);
}

// Whether the node at `c` of the fine level is held at zero in its patch:
// past the grid, a pinned vertex, or a coarse node of pinned vertices
// alone (a zero row).
fn held(c: vec2<u32>) -> bool {
    let g = hop.fine;
    if c.x >= g.nx || c.y >= g.ny {
        return true;
    }
    let i = c.y * g.nx + c.x;
    let d = diagonal(i);
    return filtered(i) || (all(d.a == vec4<f32>(0.0)) && all(d.b == vec4<f32>(0.0)));
}

// Each patch's inverse of the fine level's operator among its unknowns,
// one thread per patch (held nodes' unknowns at zero: identity rows). A
// patch that is not positive definite (only when A is not) gets a zero
// inverse and is left alone.
@compute @workgroup_size(WORKGROUP)
fn patches(@builtin(global_invocation_id) id: vec3<u32>) {
    hop = bound_hop;
    let g = hop.fine;
    let px = (g.nx + 1u) / 2u;
    let p = id.x;
    if p >= px * ((g.ny + 1u) / 2u) {
        return;
    }
    let first = 2u * vec2<u32>(p % px, p / px);
    for (var i = 0u; i < 12u; i++) {
        for (var j = 0u; j < 12u; j++) {
            patch_m[i][j] = 0.0;
        }
    }
    for (var k = 0u; k < PATCH; k++) {
        let c = first + vec2<u32>(k % 2u, k / 2u);
        let i = c.y * g.nx + c.x;
        if held(c) {
            set_patch_block(k, k, Sym3(vec4<f32>(1.0, 1.0, 1.0, 0.0), vec4<f32>(0.0)));
            continue;
        }
        set_patch_block(k, k, diagonal(i));
        for (var b = 0u; b < PATCH; b++) {
            let cb = first + vec2<u32>(b % 2u, b / 2u);
            if b != k && !on_cloth() && !held(cb) {
                let d = vec2<i32>(cb) - vec2<i32>(c);
                set_patch_block(k, b, stencil_block(g, i, cb.y * g.nx + cb.x, d.x, d.y));
            }
        }
        if on_cloth() {
            for (var a = adjacency_begin(i); a < adjacency_begin(i + 1u); a++) {
                let cj = vec2<u32>(vec2<i32>(c) + spring_offset(g, i, adjacent_vertex(a)));
                if cj.x >= first.x && cj.x < first.x + 2u && cj.y >= first.y && cj.y < first.y + 2u && !held(cj) {
                    let b = (cj.x - first.x) + 2u * (cj.y - first.y);
                    set_patch_block(k, b, sym_unpack(matrix_at(params.n_vertices + adjacent_spring(a))));
                }
            }
        }
    }
    let ok = patch_factor();
    let at = g.patches_at + p * PATCH_BLOCKS;
    for (var s = 0u; s < PATCH_BLOCKS; s++) {
        var f: array<f32, 6>;
        for (var e = 0u; e < 6u; e++) {
            f[e] = select(0.0, inverse_float(6u * s + e), ok);
        }
        operators_set(at + s, PackedSym3(vec2<f32>(f[0], f[1]), vec2<f32>(f[2], f[3]), vec2<f32>(f[4], f[5])));
    }
}

// Block m above the diagonal of the patch inverse at `at` (see
// `inverse_float`): 9 floats from float 24 + 9 m, so from block
// 4 + ⌊3 m / 2⌋, at its first or fourth float.
fn upper(at: u32, m: u32) -> mat3x3<f32> {
    let s = at + 4u + 3u * m / 2u;
    let a = operators_at(s);
    let b = operators_at(s + 1u);
    if m % 2u == 0u {
        return mat3x3<f32>(vec3<f32>(a.xx_yy, a.zz_xy.x), vec3<f32>(a.zz_xy.y, a.xz_yz), vec3<f32>(b.xx_yy, b.zz_xy.x));
    }
    return mat3x3<f32>(vec3<f32>(a.zz_xy.y, a.xz_yz), vec3<f32>(b.xx_yy, b.zz_xy.x), vec3<f32>(b.zz_xy.y, b.xz_yz));
}

// A patch sweep's thread t: node k = t % 4 of the (t / 4)-th patch of its
// colour (multigrid::colour_grid), `inside` the grid or not, and whether
// it is free (not a pinned vertex).
struct PatchNode {
    index: u32,
    k: u32,
    node: u32,
    inside: bool,
    free: bool,
}

fn patch_node(t: u32, colour: u32) -> PatchNode {
    let g = hop.fine;
    let px = (g.nx + 1u) / 2u;
    let per_row = (px + 1u) / 2u;
    let q = t / PATCH;
    let k = t % PATCH;
    let pc = colour % 2u + 2u * (q % per_row);
    let pr = colour / 2u + 2u * (q / per_row);
    let c = 2u * vec2<u32>(pc, pr) + vec2<u32>(k % 2u, k / 2u);
    let inside = pc < px && c.x < g.nx && c.y < g.ny;
    let node = c.y * g.nx + c.x;
    return PatchNode(pr * px + pc, k, node, inside, inside && !filtered(node));
}

var<workgroup> patch_residual: array<vec4<f32>, WORKGROUP>;

// Thread t's part of a patch sweep of `colour` (at `lid` in a workgroup
// that holds its patch's four threads): its node's residual, shared with
// its patch, then its node's part of the patch's solve. Forward (down,
// from zero) the colours below this one are smoothed and the rest zero,
// and it sets the node's value; backward (up) every node holds its guess,
// and it corrects the node's value.
fn patch_sweep_at(t: u32, lid: u32, colour: u32, forward: bool) {
    let n = patch_node(t, colour);
    var res = vec3<f32>(0.0);
    if n.free {
        let earlier = vec2<u32>(0u, select(PATCH_COLOURS, colour, forward));
        res = fine_rhs(n.node) - row_guess(n.node, !forward, earlier);
    }
    patch_residual[lid] = vec4<f32>(res, 0.0);
    workgroupBarrier();
    if n.inside {
        // Node k's rows of M⁻¹ res; a pinned vertex's are zero off its own
        // (identity) block, and its residual zero.
        let first = lid - n.k;
        let at = hop.fine.patches_at + n.index * PATCH_BLOCKS;
        var d = sym_mul(sym_unpack(operators_at(at + n.k)), patch_residual[lid].xyz);
        for (var b = 0u; b < PATCH; b++) {
            let rb = patch_residual[first + b].xyz;
            if b < n.k {
                d += transpose(upper(at, upper_block(b, n.k))) * rb;
            } else if b > n.k {
                d += upper(at, upper_block(n.k, b)) * rb;
            }
        }
        if forward {
            set_smoothed(n.node, d);
        } else {
            set_smoothed(n.node, smoothed(n.node) + d);
        }
    }
}

// A forward sweep of `hop.colour`'s patches, down.
@compute @workgroup_size(WORKGROUP)
fn patch_down(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    hop = bound_hop;
    patch_sweep_at(id.x, lid, hop.colour, true);
}

// A backward sweep of `hop.colour`'s patches, up.
@compute @workgroup_size(WORKGROUP)
fn patch_up(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    hop = bound_hop;
    patch_sweep_at(id.x, lid, hop.colour, false);
}
