// Workgroup sums through subgroup operations, for a device with them
// (wgpu::Features::SUBGROUP); sums.wgsl is the fallback, with the same
// `Lane` and `workgroup_sums`.

struct Lane {
    @builtin(local_invocation_index) index: u32,
    @builtin(subgroup_invocation_id) in_subgroup: u32,
    @builtin(subgroup_size) subgroup_size: u32,
    @builtin(subgroup_id) subgroup: u32,
    @builtin(num_subgroups) subgroups: u32,
}

// One partial per subgroup (a subgroup has at least one invocation).
var<workgroup> scratch: array<vec4<f32>, WORKGROUP>;
var<workgroup> scratch_total: vec4<f32>;

// Sum of `value` over the workgroup, as a uniform value the workgroup may
// branch on. Every invocation must call it. Up to four sums in one cost
// what one does. Each subgroup sums its values in registers, then the
// first subgroup sums the subgroups' partials: three barriers, counting
// the uniform load's two, where workgroup memory alone takes five. The
// order is fixed by the subgroup size, so a pipeline repeats its sums bit
// for bit (some drivers choose the size per pipeline).
fn workgroup_sums(lane: Lane, value: vec4<f32>) -> vec4<f32> {
    let partial = subgroupAdd(value);
    if lane.in_subgroup == 0u {
        scratch[lane.subgroup] = partial;
    }
    workgroupBarrier();
    if lane.subgroup == 0u {
        var s = vec4<f32>(0.0);
        for (var k = lane.in_subgroup; k < lane.subgroups; k += lane.subgroup_size) {
            s += scratch[k];
        }
        s = subgroupAdd(s);
        if lane.in_subgroup == 0u {
            scratch_total = s;
        }
    }
    // Its barriers order this call's reads of `scratch` before the next
    // call's writes.
    return workgroupUniformLoad(&scratch_total);
}
