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

// Σ of a segment's partials over all workgroups of the previous dispatch.
fn total(lid: u32, segment: u32) -> f32 {
    var s = 0.0;
    for (var k = lid; k < partial_count(); k += WORKGROUP) {
        s += partials[segment * partial_count() + k];
    }
    return workgroup_sum(lid, s);
}
