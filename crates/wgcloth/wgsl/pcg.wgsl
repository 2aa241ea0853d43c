// Stage "pcg": Jacobi-preconditioned conjugate gradient on A v' = b, pinned
// rows filtered (Baraff & Witkin's modified PCG). CPU twin: src/cpu/pcg.rs.
//
// Per iteration three dispatches, no host round trip: `spmv` (q = S A p
// and partial pᵀq), `update` (x, r, z and partial rᵀz) and `direction`
// (p = z + β p). Each workgroup reduces the previous dispatch's partial
// sums itself, in the same order, so every one sees the same α and β.
// The scalars ping-pong between two buffers (`scalars_in` is last
// iteration's, `scalars_out` this one's); once converged every kernel
// returns at once and `direction` carries the scalars over.

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
@group(1) @binding(5) var<storage, read_write> z: array<vec4<f32>>;
@group(1) @binding(6) var<storage, read_write> p: array<vec4<f32>>;
@group(1) @binding(7) var<storage, read_write> q: array<vec4<f32>>;
@group(1) @binding(8) var<storage, read_write> inv_diag: array<vec4<f32>>;
// Per-workgroup partial sums, three segments: pᵀq, rᵀz, bᵀP⁻¹b.
@group(1) @binding(9) var<storage, read_write> partials: array<f32>;
@group(1) @binding(10) var<storage, read> scalars_in: Scalars;
@group(1) @binding(11) var<storage, read_write> scalars_out: Scalars;
@group(1) @binding(12) var<storage, read_write> state: StepState;

const PQ: u32 = 0u;
const RZ: u32 = 1u;
const BB: u32 = 2u;

// Row i of A x and of A p (WGSL cannot pass storage pointers).
fn row_x(i: u32) -> vec3<f32> {
    var acc = sym_mul(matrix[i], x[i].xyz);
    for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
        acc += sym_mul(matrix[params.n_vertices + adjacent_spring(k)], x[adjacent_vertex(k)].xyz);
    }
    return acc;
}

fn row_p(i: u32) -> vec3<f32> {
    var acc = sym_mul(matrix[i], p[i].xyz);
    for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
        acc += sym_mul(matrix[params.n_vertices + adjacent_spring(k)], p[adjacent_vertex(k)].xyz);
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

// r = S (b − A x), p = P⁻¹ r, with partial rᵀp and bᵀP⁻¹b.
@compute @workgroup_size(WORKGROUP)
fn init(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32,
        @builtin(workgroup_id) wg: vec3<u32>) {
    let i = id.x;
    var rp = 0.0;
    var bb = 0.0;
    if i < params.n_vertices {
        let free = !is_pinned(i);
        let m = select(vec3<f32>(0.0), 1.0 / sym_diag(matrix[i]), free);
        inv_diag[i] = vec4<f32>(m, 0.0);
        let ri = select(vec3<f32>(0.0), b[i].xyz - row_x(i), free);
        r[i] = vec4<f32>(ri, 0.0);
        p[i] = vec4<f32>(m * ri, 0.0);
        rp = dot(ri, m * ri);
        bb = dot(b[i].xyz, m * b[i].xyz);
    }
    let s_rp = workgroup_sum(lid, rp);
    let s_bb = workgroup_sum(lid, bb);
    if lid == 0u {
        store_partial(RZ, wg.x, s_rp);
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
        scalars_out = Scalars(delta, delta0, threshold, 0u, u32(!(delta > threshold && delta > 0.0)), 0u, 0u, 0u);
    }
}

// q = S A p and partial pᵀq.
@compute @workgroup_size(WORKGROUP)
fn spmv(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32,
        @builtin(workgroup_id) wg: vec3<u32>) {
    if scalars_in.done != 0u {
        return;
    }
    let i = id.x;
    var pq = 0.0;
    if i < params.n_vertices {
        let qi = select(vec3<f32>(0.0), row_p(i), !is_pinned(i));
        q[i] = vec4<f32>(qi, 0.0);
        pq = dot(p[i].xyz, qi);
    }
    let s = workgroup_sum(lid, pq);
    if lid == 0u {
        store_partial(PQ, wg.x, s);
    }
}

// α = δ / pᵀq; x += α p; r −= α q; z = P⁻¹ r; partial rᵀz.
@compute @workgroup_size(WORKGROUP)
fn update(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32,
          @builtin(workgroup_id) wg: vec3<u32>) {
    if scalars_in.done != 0u {
        return;
    }
    let pq = total(lid, PQ);
    if !(pq > 0.0) {
        return; // breakdown: `direction` records it
    }
    let alpha = scalars_in.delta / pq;
    let i = id.x;
    var rz = 0.0;
    if i < params.n_vertices {
        x[i] = vec4<f32>(x[i].xyz + alpha * p[i].xyz, x[i].w);
        let ri = r[i].xyz - alpha * q[i].xyz;
        r[i] = vec4<f32>(ri, 0.0);
        let zi = inv_diag[i].xyz * ri;
        z[i] = vec4<f32>(zi, 0.0);
        rz = dot(ri, zi);
    }
    let s = workgroup_sum(lid, rz);
    if lid == 0u {
        store_partial(RZ, wg.x, s);
    }
}

// β = δ' / δ; p = z + β p; the next scalars.
@compute @workgroup_size(WORKGROUP)
fn direction(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32,
             @builtin(workgroup_id) wg: vec3<u32>) {
    let leader = lid == 0u && wg.x == 0u;
    if scalars_in.done != 0u {
        if leader {
            scalars_out = scalars_in;
        }
        return;
    }
    let pq = total(lid, PQ);
    if !(pq > 0.0) {
        if leader {
            scalars_out = scalars_in;
            scalars_out.done = 1u;
            scalars_out.breakdown = 1u;
        }
        return;
    }
    let delta = total(lid, RZ);
    let beta = delta / scalars_in.delta;
    let i = id.x;
    if i < params.n_vertices {
        p[i] = vec4<f32>(z[i].xyz + beta * p[i].xyz, 0.0);
    }
    if leader {
        let converged = !(delta > scalars_in.threshold && delta > 0.0);
        scalars_out = Scalars(delta, scalars_in.delta0, scalars_in.threshold, scalars_in.iterations + 1u,
                              u32(converged), u32(!(delta == delta)), 0u, 0u);
    }
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
