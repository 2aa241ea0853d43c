// The PCG solve's per-workgroup partial sums, one segment per quantity,
// each reduced by the next dispatch (shared by pcg.wgsl and
// multigrid.wgsl, whose last up-leg kernel leaves the partial rᵀz).

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
