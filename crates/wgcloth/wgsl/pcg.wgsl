// Includes: topology, sums, partials.
// Stage "pcg": preconditioned conjugate gradient on A v' = b, pinned rows
// filtered (Baraff & Witkin's modified PCG), preconditioned by Jacobi (the
// thesis's) or by a multigrid V-cycle (wgsl/multigrid.wgsl). CPU twin:
// src/cpu/pcg.rs.
//
// No host round trip: with Jacobi an iteration is `update` (α; x, r,
// z = P⁻¹ r, partial rᵀz and rᵀr) and `next`, which finishes one
// iteration and starts the next: β = δ' / δ and the new scalars,
// p' = z + β p, q = S A p' and partial p'ᵀq. With multigrid, `advance`
// (x, r and partial rᵀr) and the V-cycle, whose last kernel leaves z and
// partial rᵀz, take `update`'s place. The first iteration's q comes from
// `spmv`, and `conclude` finishes the last. Each workgroup reduces the
// previous dispatch's partial sums itself, in the same order, so every one
// sees the same α and β. The scalars and the direction ping-pong between
// two buffers each (`*_in` this iteration's, `*_next` the next one's), and
// the pᵀq partials between two segments, by the iteration count's parity.
// After the scalars, each buffer holds the dispatch sizes of every level
// of the next iteration's indirect dispatches, zero once the solve is
// over, so a converged solve records iterations that cost nothing; `next`
// (one workgroup once the solve is over) and `conclude` carry the scalars.
// `init_scalars` writes the sizes into both buffers, so an iteration that
// goes on copies only its scalars, and kernels read them alone: lavapipe
// executes every branch, masked, for each 8 invocations whether they take
// it or not (Mesa's gallivm pushes a mask for an `if`), and copying the
// sizes too made its iterations 2.5 to 5 times as long.
// For the same reason every way an iteration ends writes its scalars in
// one store, and a stop's sizes are zeroed one per invocation, not in a loop.
// A small cloth preconditioned by multigrid skips the iterations: multigrid's
// `solve` runs them all in one workgroup after `init_scalars`, and
// `correct` adds the correction it leaves to x before `finish`.

// A scalars buffer whole.
struct ScalarsAndSizes {
    scalars: Scalars,
    // [workgroups, 1, 1] per multigrid level (level 0: the cloth).
    groups: array<u32, 3 * MAX_LEVELS>,
    // The same for each level's patch sweeps (multigrid::colour_grid).
    patch_groups: array<u32, 3 * MAX_LEVELS>,
}

// A: its diagonal blocks (one per vertex), then one block per spring.
@group(1) @binding(1) var<storage, read> matrix: array<PackedSym3>;
// The solver's vectors, read and written through `b_at`, `r_set`, ...
// (gpu::shaders::SOLVER_VECTORS); x, the velocities, is a vec4 each.
@group(1) @binding(2) var<storage, read> b: array<VectorEntry>;
@group(1) @binding(3) var<storage, read_write> x: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read_write> r: array<VectorEntry>;
// z = P⁻¹ r, then q = S A p (where multigrid's `solve` runs the whole
// solve, then p and the correction e too).
@group(1) @binding(5) var<storage, read_write> zq: array<VectorEntry>;
// This iteration's direction p, and the next one's.
@group(1) @binding(6) var<storage, read_write> p: array<VectorEntry>;
@group(1) @binding(7) var<storage, read_write> p_next: array<VectorEntry>;
@group(1) @binding(8) var<storage, read_write> inv_diag: array<VectorEntry>;
@group(1) @binding(10) var<storage, read> scalars_in: Scalars;
@group(1) @binding(11) var<storage, read_write> scalars_next: ScalarsAndSizes;
// `init_scalars`: the other buffer, iteration 1's.
@group(1) @binding(15) var<storage, read_write> scalars_spare: ScalarsAndSizes;
@group(1) @binding(12) var<storage, read_write> state: StepState;
// Stage "self_contact"'s lists and contacts: the cloth–cloth couplings C,
// the blocks of A outside the springs' pattern.
@group(1) @binding(13) var<storage, read> cloth_lists: array<u32>;
@group(1) @binding(14) var<storage, read> cloth_pairs: array<ClothPair>;

// The pᵀq segment of iteration `iteration`.
fn pq_segment(iteration: u32) -> u32 {
    return PQ + iteration % 2u;
}

fn z(i: u32) -> vec3<f32> {
    return zq_at(i);
}

fn q(i: u32) -> vec3<f32> {
    return zq_at(params.n_vertices + i);
}

fn store_q(i: u32, value: vec3<f32>) {
    zq_set(params.n_vertices + i, value);
}

// Row i of A x and of A p (WGSL cannot pass storage pointers).
fn row_x(i: u32) -> vec3<f32> {
    var acc = sym_mul(sym_unpack(matrix_at(i)), x[i].xyz);
    for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
        acc += sym_mul(sym_unpack(matrix_at(params.n_vertices + adjacent_spring(k))), x[adjacent_vertex(k)].xyz);
    }
    return acc;
}

// The next direction at vertex j, z + β p, as `next` also stores it; the
// first iteration's (β = 0) is z alone, as p is being written then.
fn next_direction(j: u32, beta: f32) -> vec3<f32> {
    if beta == 0.0 {
        return z(j);
    }
    return z(j) + beta * p_at(j);
}

// Row i of A p' for p' = next_direction(·, β).
fn row_next(i: u32, beta: f32) -> vec3<f32> {
    var acc = sym_mul(sym_unpack(matrix_at(i)), next_direction(i, beta));
    for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
        acc += sym_mul(sym_unpack(matrix_at(params.n_vertices + adjacent_spring(k))),
                       next_direction(adjacent_vertex(k), beta));
    }
    return acc;
}

// r = S (b − A x), Jacobi's z = P⁻¹ r (the V-cycle overwrites it), with
// partial rᵀz, |S b|² and rᵀr.
@compute @workgroup_size(WORKGROUP)
fn init(@builtin(global_invocation_id) id: vec3<u32>, lane: Lane,
        @builtin(workgroup_id) wg: vec3<u32>) {
    let i = id.x;
    var rz = 0.0;
    var bb = 0.0;
    var rr = 0.0;
    if i < params.n_vertices {
        let free = !is_pinned(i);
        let m = select(vec3<f32>(0.0), 1.0 / sym_diag(sym_unpack(matrix_at(i))), free);
        inv_diag_set(i, m);
        let bi = b_at(i);
        let ri = select(vec3<f32>(0.0), bi - row_x(i), free);
        r_set(i, ri);
        let zi = m * ri;
        zq_set(i, zi);
        rz = dot(ri, zi);
        bb = select(0.0, dot(bi, bi), free);
        rr = dot(ri, ri);
    }
    let sums = workgroup_sums(lane, vec4<f32>(rz, bb, rr, 0.0));
    if lane.index == 0u {
        store_partial(RZ, wg.x, sums.x);
        store_partial(BB, wg.x, sums.y);
        store_partial(RR, wg.x, sums.z);
    }
}

// Once the solve is over, later iterations dispatch no workgroups: level l's
// sizes zeroed by invocation l of the first workgroup, one store each where
// a loop in the leader cost lavapipe 48 masked stores in every 8 invocations
// of every workgroup (about a tenth of a Jacobi iteration at 256²).
fn stop_levels(lane: Lane, wg: u32) {
    if wg == 0u && lane.index < MAX_LEVELS {
        scalars_next.groups[3u * lane.index] = 0u;
        scalars_next.patch_groups[3u * lane.index] = 0u;
    }
}

// The starting scalars (one workgroup), and every level's dispatch size
// (the levels of multigrid::levels, halving from the cloth's grid).
@compute @workgroup_size(WORKGROUP)
fn init_scalars(lane: Lane) {
    let sums = totals(lane, vec3<u32>(RZ, BB, RR));
    let delta = sums.x;
    let bb = sums.y;
    let rr = sums.z;
    if lane.index == 0u {
        var s: Scalars;
        s.delta = delta;
        s.bb = bb;
        s.rr = rr;
        s.threshold = params.cg_tol * params.cg_tol * bb;
        let on = going_on(rr, delta, s.threshold);
        s.done = u32(!on);
        s.breakdown = u32(stalled(rr, delta, s.threshold));
        var nx = params.cells_x + 1u;
        var ny = params.cells_y + 1u;
        s.next_groups = array<u32, 3>(select(1u, (nx * ny + WORKGROUP - 1u) / WORKGROUP, on), 1u, 1u);
        var sizes: ScalarsAndSizes;
        sizes.scalars = s;
        for (var l = 0u; l < MAX_LEVELS; l++) {
            sizes.groups[3u * l] = select(0u, (nx * ny + WORKGROUP - 1u) / WORKGROUP, on);
            sizes.groups[3u * l + 1u] = 1u;
            sizes.groups[3u * l + 2u] = 1u;
            let threads = patch_threads(nx, ny);
            sizes.patch_groups[3u * l] = select(0u, (threads + WORKGROUP - 1u) / WORKGROUP, on);
            sizes.patch_groups[3u * l + 1u] = 1u;
            sizes.patch_groups[3u * l + 2u] = 1u;
            nx = (nx + 1u) / 2u;
            ny = (ny + 1u) / 2u;
        }
        scalars_next = sizes;
        scalars_spare = sizes;
    }
}

// The first iteration's direction p = z, q = S A p and partial pᵀq.
@compute @workgroup_size(WORKGROUP)
fn spmv(@builtin(global_invocation_id) id: vec3<u32>, lane: Lane,
        @builtin(workgroup_id) wg: vec3<u32>) {
    if scalars_in.done != 0u {
        return;
    }
    let i = id.x;
    var pq = 0.0;
    if i < params.n_vertices {
        let pi = z(i);
        p_set(i, pi);
        let qi = select(vec3<f32>(0.0), row_next(i, 0.0), !is_pinned(i));
        store_q(i, qi);
        pq = dot(pi, qi);
    }
    let s = workgroup_sum(lane, pq);
    if lane.index == 0u {
        store_partial(pq_segment(scalars_in.iterations), wg.x, s);
    }
}

// α = δ / pᵀq, or 0 at a breakdown (which `next` or `conclude` records).
fn step_length(lane: Lane) -> f32 {
    let pq = total(lane, pq_segment(scalars_in.iterations));
    return select(0.0, scalars_in.delta / pq, usable(pq));
}

// x += α p; r −= α q at vertex i, returning the new r.
fn advance_vertex(i: u32, alpha: f32) -> vec3<f32> {
    x[i] = vec4<f32>(x[i].xyz + alpha * p_at(i), x[i].w);
    let ri = r_at(i) - alpha * q(i);
    r_set(i, ri);
    return ri;
}

// Jacobi: x += α p; r −= α q; z = P⁻¹ r; partial rᵀz and rᵀr.
@compute @workgroup_size(WORKGROUP)
fn update(@builtin(global_invocation_id) id: vec3<u32>, lane: Lane,
          @builtin(workgroup_id) wg: vec3<u32>) {
    let alpha = step_length(lane);
    let i = id.x;
    var sums = vec2<f32>(0.0);
    if i < params.n_vertices && alpha != 0.0 {
        sums = jacobi_z(i, advance_vertex(i, alpha));
    }
    store_rz_rr(lane, wg.x, sums);
}

// Jacobi's z = P⁻¹ r at vertex i, returning (rᵀz, rᵀr) there.
fn jacobi_z(i: u32, ri: vec3<f32>) -> vec2<f32> {
    let zi = inv_diag_at(i) * ri;
    zq_set(i, zi);
    return vec2<f32>(dot(ri, zi), dot(ri, ri));
}

// The workgroup's partial rᵀz and rᵀr.
fn store_rz_rr(lane: Lane, wg: u32, sums: vec2<f32>) {
    let s = workgroup_sums(lane, vec4<f32>(sums, 0.0, 0.0));
    if lane.index == 0u {
        store_partial(RZ, wg, s.x);
        store_partial(RR, wg, s.y);
    }
}

// Multigrid: x += α p; r −= α q; partial rᵀr (the V-cycle follows).
@compute @workgroup_size(WORKGROUP)
fn advance(@builtin(global_invocation_id) id: vec3<u32>, lane: Lane,
           @builtin(workgroup_id) wg: vec3<u32>) {
    let alpha = step_length(lane);
    let i = id.x;
    var rr = 0.0;
    if i < params.n_vertices && alpha != 0.0 {
        let ri = advance_vertex(i, alpha);
        rr = dot(ri, ri);
    }
    let s = workgroup_sum(lane, rr);
    if lane.index == 0u {
        store_partial(RR, wg.x, s);
    }
}

// The end of an iteration, by every workgroup alike: the scalars it leaves
// (the leader writes them), and whether the solve goes on.
struct Ending {
    going_on: bool,
    beta: f32,
}

fn end_iteration(lane: Lane, wg: u32) -> Ending {
    let leader = lane.index == 0u && wg == 0u;
    // Once done, the one workgroup left only carries the scalars on.
    let done = scalars_in.done != 0u;
    var sums = vec3<f32>(0.0);
    if !done {
        sums = totals(lane, vec3<u32>(pq_segment(scalars_in.iterations), RZ, RR));
    }
    let pq = sums.x;
    let delta = sums.y;
    let rr = sums.z;
    let broke = !done && !usable(pq);
    let ended = !done && !broke;
    let on = ended && going_on(rr, delta, scalars_in.threshold);
    // The next scalars for the four ways an iteration ends (it goes on, the
    // solve was over before, a breakdown, the goal reached or a stall),
    // written in one store by the leader.
    var s = scalars_in;
    s.delta = select(s.delta, delta, ended);
    s.rr = select(s.rr, rr, ended);
    s.iterations += u32(ended);
    if !on {
        let stalls = u32(stalled(rr, delta, scalars_in.threshold));
        s.breakdown = select(select(s.breakdown, 1u, broke), stalls, ended);
        s.done = 1u;
        s.next_groups[0] = 1u;
    }
    if leader {
        scalars_next.scalars = s;
    }
    if !on {
        stop_levels(lane, wg);
    }
    return Ending(on, delta / scalars_in.delta);
}

// Ends this iteration and starts the next: p' = z + β p, q = S A p' and
// partial p'ᵀq (p' recomputed at the neighbours rather than read, as
// every workgroup writes its own part of it in this dispatch).
@compute @workgroup_size(WORKGROUP)
fn next(@builtin(global_invocation_id) id: vec3<u32>, lane: Lane,
        @builtin(workgroup_id) wg: vec3<u32>) {
    let ending = end_iteration(lane, wg.x);
    if !ending.going_on {
        return;
    }
    let i = id.x;
    var pq = 0.0;
    if i < params.n_vertices {
        let pi = next_direction(i, ending.beta);
        p_next_set(i, pi);
        let qi = select(vec3<f32>(0.0), row_next(i, ending.beta), !is_pinned(i));
        store_q(i, qi);
        pq = dot(pi, qi);
    }
    let s = workgroup_sum(lane, pq);
    if lane.index == 0u {
        store_partial(pq_segment(scalars_in.iterations + 1u), wg.x, s);
    }
}

// Row i of C p (cpu::self_contact::Couplings::row): over vertex i's
// contacts, in key order, β_k B Σ_{l ≠ k} β_l p_l.
fn coupled(i: u32) -> vec3<f32> {
    var acc = vec3<f32>(0.0);
    for (var a = 0u; a < cloth_lists[listed_at(i)]; a++) {
        let e = cloth_lists[entry_at(i, a)];
        let pair = cloth_pairs[e / 4u];
        let slot = e % 4u;
        var others = vec3<f32>(0.0);
        for (var l = 0u; l < 4u; l++) {
            if l != slot {
                others += pair.beta[l] * p_at(pair_vertex(pair.key, l));
            }
        }
        acc += pair.beta[slot] * sym_mul(sym_unpack(pair.block), others);
    }
    return acc;
}

// With cloth–cloth contacts, before `couple_init`: p = x, which the first
// direction overwrites (`spmv`).
@compute @workgroup_size(WORKGROUP)
fn couple_start(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i < params.n_vertices {
        p_set(i, x[i].xyz);
    }
}

// After `init`, with cloth–cloth contacts: r −= S C x (x in p, from
// `couple_start`), Jacobi's z = P⁻¹ r, and the partial rᵀz and rᵀr again.
@compute @workgroup_size(WORKGROUP)
fn couple_init(@builtin(global_invocation_id) id: vec3<u32>, lane: Lane,
               @builtin(workgroup_id) wg: vec3<u32>) {
    let i = id.x;
    var sums = vec2<f32>(0.0);
    if i < params.n_vertices {
        var ri = r_at(i);
        if !is_pinned(i) {
            ri -= coupled(i);
        }
        r_set(i, ri);
        sums = jacobi_z(i, ri);
    }
    store_rz_rr(lane, wg.x, sums);
}

// After `spmv` or `next`, with cloth–cloth contacts: q += S C p for the
// direction just written, and its partial pᵀq again (`scalars_in` bound
// to the scalars of that iteration).
@compute @workgroup_size(WORKGROUP)
fn couple(@builtin(global_invocation_id) id: vec3<u32>, lane: Lane,
          @builtin(workgroup_id) wg: vec3<u32>) {
    if scalars_in.done != 0u {
        return;
    }
    let i = id.x;
    var pq = 0.0;
    if i < params.n_vertices {
        var qi = q(i);
        if !is_pinned(i) {
            qi += coupled(i);
            store_q(i, qi);
        }
        pq = dot(p_at(i), qi);
    }
    let s = workgroup_sum(lane, pq);
    if lane.index == 0u {
        store_partial(pq_segment(scalars_in.iterations), wg.x, s);
    }
}

// Ends the last iteration: its scalars alone (one workgroup).
@compute @workgroup_size(WORKGROUP)
fn conclude(lane: Lane) {
    _ = end_iteration(lane, 0u);
}

// After multigrid's `solve`: x += e, the correction it left in zq's
// fourth vector.
@compute @workgroup_size(WORKGROUP)
fn correct(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i < params.n_vertices {
        x[i] = vec4<f32>(x[i].xyz + zq_at(3u * params.n_vertices + i), x[i].w);
    }
}

// Folds the solve's outcome into the run statistics (one invocation).
@compute @workgroup_size(1)
fn finish() {
    let s = scalars_in;
    var residual = 0.0;
    if s.bb > 0.0 {
        residual = sqrt(max(s.rr, 0.0) / s.bb);
    }
    // The step's most and worst over its substeps; the clock counts
    // substeps, and integrate advances it after this pass.
    if state.clock % params.substeps == 0u {
        state.last_iterations = s.iterations;
        state.last_residual = residual;
        state.step_flags = 0u;
    } else {
        state.last_iterations = max(state.last_iterations, s.iterations);
        state.last_residual = max(state.last_residual, residual);
    }
    state.cg_iterations_total += s.iterations;
    let broke = first_in_step(state.step_flags, s.breakdown != 0u, STEP_BREAKDOWN);
    state.step_flags |= broke;
    state.cg_breakdowns += select(0u, 1u, broke != 0u);
    state.cg_residual_max = max(state.cg_residual_max, residual);
}
