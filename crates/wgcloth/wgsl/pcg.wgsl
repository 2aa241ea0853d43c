// Stage "pcg": Jacobi-preconditioned conjugate gradient on A v' = b, pinned
// rows filtered (Baraff & Witkin's modified PCG). CPU twin: src/cpu/pcg.rs.
//
// Two dispatches per iteration, no host round trip: `update` (α; x, r,
// z = P⁻¹ r and partial rᵀz) and `next`, which finishes one iteration and
// starts the next: β = δ' / δ and the new scalars, p' = z + β p, q = S A p'
// and partial p'ᵀq. The first iteration's q comes from `spmv`, and
// `conclude` finishes the last. Each workgroup reduces the previous
// dispatch's partial sums itself, in the same order, so every one sees the
// same α and β. The scalars and the direction ping-pong between two
// buffers each (`*_in` this iteration's, `*_next` the next one's), and the
// pᵀq partials between two segments, by the iteration count's parity;
// once converged every kernel returns at once and carries the scalars.

struct Scalars {
    delta: f32,
    delta0: f32,
    threshold: f32,
    iterations: u32,
    done: u32,
    breakdown: u32,
    pad0: u32,
    pad1: u32,
}

// A: its diagonal blocks (one per vertex), then one block per spring.
@group(1) @binding(1) var<storage, read> matrix: array<Sym3>;
@group(1) @binding(2) var<storage, read> b: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read_write> x: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read_write> r: array<vec4<f32>>;
// z = P⁻¹ r, then q = S A p: one vec4 per vertex each.
@group(1) @binding(5) var<storage, read_write> zq: array<vec4<f32>>;
// This iteration's direction p, and the next one's.
@group(1) @binding(6) var<storage, read_write> p: array<vec4<f32>>;
@group(1) @binding(7) var<storage, read_write> p_next: array<vec4<f32>>;
@group(1) @binding(8) var<storage, read_write> inv_diag: array<vec4<f32>>;
// Per-workgroup partial sums, four segments: pᵀq of even and of odd
// iterations, rᵀz, bᵀP⁻¹b.
@group(1) @binding(9) var<storage, read_write> partials: array<f32>;
@group(1) @binding(10) var<storage, read> scalars_in: Scalars;
@group(1) @binding(11) var<storage, read_write> scalars_next: Scalars;
@group(1) @binding(12) var<storage, read_write> state: StepState;

// Segments of `partials`: PQ + (iteration parity), RZ, BB.
const PQ: u32 = 0u;
const RZ: u32 = 2u;
const BB: u32 = 3u;

// The pᵀq segment of iteration `iteration`.
fn pq_segment(iteration: u32) -> u32 {
    return PQ + iteration % 2u;
}

fn z(i: u32) -> vec3<f32> {
    return zq[i].xyz;
}

fn q(i: u32) -> vec3<f32> {
    return zq[params.n_vertices + i].xyz;
}

fn store_q(i: u32, value: vec3<f32>) {
    zq[params.n_vertices + i] = vec4<f32>(value, 0.0);
}

// Row i of A x and of A p (WGSL cannot pass storage pointers).
fn row_x(i: u32) -> vec3<f32> {
    var acc = sym_mul(matrix[i], x[i].xyz);
    for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
        acc += sym_mul(matrix[params.n_vertices + adjacent_spring(k)], x[adjacent_vertex(k)].xyz);
    }
    return acc;
}

// The next direction at vertex j, z + β p, as `next` also stores it; the
// first iteration's (β = 0) is z alone, as p is being written then.
fn next_direction(j: u32, beta: f32) -> vec3<f32> {
    if beta == 0.0 {
        return z(j);
    }
    return z(j) + beta * p[j].xyz;
}

// Row i of A p' for p' = next_direction(·, β).
fn row_next(i: u32, beta: f32) -> vec3<f32> {
    var acc = sym_mul(matrix[i], next_direction(i, beta));
    for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
        acc += sym_mul(matrix[params.n_vertices + adjacent_spring(k)],
                       next_direction(adjacent_vertex(k), beta));
    }
    return acc;
}

fn partial_count() -> u32 {
    return (params.n_vertices + WORKGROUP - 1u) / WORKGROUP;
}

fn store_partial(segment: u32, wg: u32, value: f32) {
    partials[segment * partial_count() + wg] = value;
}

// Σ of a segment's partials over all workgroups of the previous dispatch.
fn total(lid: u32, segment: u32) -> f32 {
    var s = 0.0;
    for (var k = lid; k < partial_count(); k += WORKGROUP) {
        s += partials[segment * partial_count() + k];
    }
    return workgroup_sum(lid, s);
}

// r = S (b − A x), z = P⁻¹ r, with partial rᵀz and bᵀP⁻¹b.
@compute @workgroup_size(WORKGROUP)
fn init(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32,
        @builtin(workgroup_id) wg: vec3<u32>) {
    let i = id.x;
    var rz = 0.0;
    var bb = 0.0;
    if i < params.n_vertices {
        let free = !is_pinned(i);
        let m = select(vec3<f32>(0.0), 1.0 / sym_diag(matrix[i]), free);
        inv_diag[i] = vec4<f32>(m, 0.0);
        let ri = select(vec3<f32>(0.0), b[i].xyz - row_x(i), free);
        r[i] = vec4<f32>(ri, 0.0);
        let zi = m * ri;
        zq[i] = vec4<f32>(zi, 0.0);
        rz = dot(ri, zi);
        bb = dot(b[i].xyz, m * b[i].xyz);
    }
    let s_rz = workgroup_sum(lid, rz);
    let s_bb = workgroup_sum(lid, bb);
    if lid == 0u {
        store_partial(RZ, wg.x, s_rz);
        store_partial(BB, wg.x, s_bb);
    }
}

// The starting scalars (one workgroup).
@compute @workgroup_size(WORKGROUP)
fn init_scalars(@builtin(local_invocation_index) lid: u32) {
    let delta = total(lid, RZ);
    let delta0 = total(lid, BB);
    if lid == 0u {
        let threshold = params.cg_tol * params.cg_tol * delta0;
        scalars_next = Scalars(delta, delta0, threshold, 0u, u32(!(delta > threshold && delta > 0.0)), 0u, 0u, 0u);
    }
}

// The first iteration's direction p = z, q = S A p and partial pᵀq.
@compute @workgroup_size(WORKGROUP)
fn spmv(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32,
        @builtin(workgroup_id) wg: vec3<u32>) {
    if scalars_in.done != 0u {
        return;
    }
    let i = id.x;
    var pq = 0.0;
    if i < params.n_vertices {
        let pi = z(i);
        p[i] = vec4<f32>(pi, 0.0);
        let qi = select(vec3<f32>(0.0), row_next(i, 0.0), !is_pinned(i));
        store_q(i, qi);
        pq = dot(pi, qi);
    }
    let s = workgroup_sum(lid, pq);
    if lid == 0u {
        store_partial(pq_segment(scalars_in.iterations), wg.x, s);
    }
}

// α = δ / pᵀq; x += α p; r −= α q; z = P⁻¹ r; partial rᵀz.
@compute @workgroup_size(WORKGROUP)
fn update(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32,
          @builtin(workgroup_id) wg: vec3<u32>) {
    if scalars_in.done != 0u {
        return;
    }
    let pq = total(lid, pq_segment(scalars_in.iterations));
    if !(pq > 0.0) {
        return; // breakdown: `next` or `conclude` records it
    }
    let alpha = scalars_in.delta / pq;
    let i = id.x;
    var rz = 0.0;
    if i < params.n_vertices {
        x[i] = vec4<f32>(x[i].xyz + alpha * p[i].xyz, x[i].w);
        let ri = r[i].xyz - alpha * q(i);
        r[i] = vec4<f32>(ri, 0.0);
        let zi = inv_diag[i].xyz * ri;
        zq[i] = vec4<f32>(zi, 0.0);
        rz = dot(ri, zi);
    }
    let s = workgroup_sum(lid, rz);
    if lid == 0u {
        store_partial(RZ, wg.x, s);
    }
}

// The end of an iteration, by every workgroup alike: the scalars it leaves
// (the leader writes them), and whether the solve goes on.
struct Ending {
    going_on: bool,
    beta: f32,
}

fn end_iteration(lid: u32, wg: u32) -> Ending {
    let leader = lid == 0u && wg == 0u;
    if scalars_in.done != 0u {
        if leader {
            scalars_next = scalars_in;
        }
        return Ending(false, 0.0);
    }
    let pq = total(lid, pq_segment(scalars_in.iterations));
    if !(pq > 0.0) {
        if leader {
            scalars_next = scalars_in;
            scalars_next.done = 1u;
            scalars_next.breakdown = 1u;
        }
        return Ending(false, 0.0);
    }
    let delta = total(lid, RZ);
    let converged = !(delta > scalars_in.threshold && delta > 0.0);
    if leader {
        scalars_next = Scalars(delta, scalars_in.delta0, scalars_in.threshold, scalars_in.iterations + 1u,
                               u32(converged), u32(!(delta == delta)), 0u, 0u);
    }
    return Ending(!converged, delta / scalars_in.delta);
}

// Ends this iteration and starts the next: p' = z + β p, q = S A p' and
// partial p'ᵀq (p' recomputed at the neighbours rather than read, as
// every workgroup writes its own part of it in this dispatch).
@compute @workgroup_size(WORKGROUP)
fn next(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32,
        @builtin(workgroup_id) wg: vec3<u32>) {
    let ending = end_iteration(lid, wg.x);
    if !ending.going_on {
        return;
    }
    let i = id.x;
    var pq = 0.0;
    if i < params.n_vertices {
        let pi = next_direction(i, ending.beta);
        p_next[i] = vec4<f32>(pi, 0.0);
        let qi = select(vec3<f32>(0.0), row_next(i, ending.beta), !is_pinned(i));
        store_q(i, qi);
        pq = dot(pi, qi);
    }
    let s = workgroup_sum(lid, pq);
    if lid == 0u {
        store_partial(pq_segment(scalars_in.iterations + 1u), wg.x, s);
    }
}

// Ends the last iteration: its scalars alone (one workgroup).
@compute @workgroup_size(WORKGROUP)
fn conclude(@builtin(local_invocation_index) lid: u32) {
    _ = end_iteration(lid, 0u);
}

// Folds the solve's outcome into the run statistics (one invocation).
@compute @workgroup_size(1)
fn finish() {
    let s = scalars_in;
    var residual = 0.0;
    if s.delta0 > 0.0 {
        residual = sqrt(max(s.delta, 0.0) / s.delta0);
    }
    state.last_iterations = s.iterations;
    state.last_residual = residual;
    state.cg_iterations_total += s.iterations;
    state.cg_breakdowns += s.breakdown;
    state.cg_residual_max = max(state.cg_residual_max, residual);
}
