// The PCG solve's scalars, the tests on them, and its per-workgroup
// partial sums, one segment per quantity, each reduced by the next
// dispatch (shared by pcg.wgsl and multigrid.wgsl, whose last up-leg
// kernel leaves the partial rᵀz, and whose `solve` runs the whole solve).

struct Scalars {
    delta: f32,
    bb: f32,
    threshold: f32,
    iterations: u32,
    done: u32,
    breakdown: u32,
    rr: f32,
    pad: u32,
    // `next`'s [workgroups, 1, 1]: the cloth's while the solve goes on, one
    // (to carry the scalars) once it is over.
    next_groups: array<u32, 3>,
}

// Whether the solve goes on from residual rᵀr = rr and δ = rᵀz.
fn going_on(rr: f32, delta: f32, threshold: f32) -> bool {
    return rr > threshold && delta > 0.0;
}

// A non-finite scalar, or rᵀz ≤ 0 above the goal (a preconditioner that is
// not positive definite): a breakdown, never convergence.
fn stalled(rr: f32, delta: f32, threshold: f32) -> bool {
    return !(delta == delta && rr == rr) || (rr > threshold && !(delta > 0.0));
}

// pᵀq > 0 and finite (as the CPU twin asks); anything else is a breakdown.
// The bound is f32's largest finite value written exactly: browsers' WGSL
// compilers (Tint) read the decimal 3.4028235e38 as just above it, and
// refuse it.
fn usable(pq: f32) -> bool {
    return pq > 0.0 && pq <= 0x1.fffffep+127f;
}

@group(1) @binding(41) var<storage, read_write> partials: array<f32>;

// Segments: pᵀq of even and of odd iterations, rᵀz, |S b|², rᵀr.
const PQ: u32 = 0u;
const RZ: u32 = 2u;
const BB: u32 = 3u;
const RR: u32 = 4u;

fn partial_count() -> u32 {
    return (params.n_vertices + WORKGROUP - 1u) / WORKGROUP;
}

fn store_partial(segment: u32, wg: u32, value: f32) {
    partials[segment * partial_count() + wg] = value;
}

fn workgroup_sum(lane: Lane, value: f32) -> f32 {
    return workgroup_sums(lane, vec4<f32>(value, 0.0, 0.0, 0.0)).x;
}

// Σ of a segment's partials over all workgroups of the previous dispatch.
fn total(lane: Lane, segment: u32) -> f32 {
    var s = 0.0;
    for (var k = lane.index; k < partial_count(); k += WORKGROUP) {
        s += partials[segment * partial_count() + k];
    }
    return workgroup_sum(lane, s);
}

// `total` of three segments at once, in one workgroup sum.
fn totals(lane: Lane, segments: vec3<u32>) -> vec3<f32> {
    let n = partial_count();
    var s = vec3<f32>(0.0);
    for (var k = lane.index; k < n; k += WORKGROUP) {
        s += vec3<f32>(partials[segments.x * n + k], partials[segments.y * n + k],
                       partials[segments.z * n + k]);
    }
    return workgroup_sums(lane, vec4<f32>(s, 0.0)).xyz;
}
