// Workgroup sums through workgroup memory alone, for a device without
// subgroup operations (sums_subgroup.wgsl is the other). The kernels that
// sum take a `Lane`, so both files serve the same entry points.

struct Lane {
    @builtin(local_invocation_index) index: u32,
}

var<workgroup> scratch: array<vec4<f32>, WORKGROUP>;

// Sum of `value` over the workgroup, each component in a fixed order
// (deterministic), as a uniform value the workgroup may branch on. Every
// invocation must call it. Up to four sums in one costs what one does.
// SUM_LANES lanes each sum a stride of the values, then one sums theirs:
// two rounds, not a tree's log₂ WORKGROUP. lavapipe runs each round's code
// for every 8 lanes of the workgroup, active or not, so rounds cost more
// than additions there (BENCHMARKS.md, "Lavapipe's solver"); on a
// hardware GPU the two are alike.
const SUM_LANES: u32 = 16u;

fn workgroup_sums(lane: Lane, value: vec4<f32>) -> vec4<f32> {
    let lid = lane.index;
    scratch[lid] = value;
    workgroupBarrier();
    if lid < SUM_LANES {
        var s = scratch[lid];
        for (var k = lid + SUM_LANES; k < WORKGROUP; k += SUM_LANES) {
            s += scratch[k];
        }
        scratch[lid] = s;
    }
    workgroupBarrier();
    if lid == 0u {
        var s = scratch[0];
        for (var k = 1u; k < SUM_LANES; k++) {
            s += scratch[k];
        }
        scratch[0] = s;
    }
    // Its barriers order this call's reads of `scratch` before the next
    // call's writes.
    return workgroupUniformLoad(&scratch[0]);
}
