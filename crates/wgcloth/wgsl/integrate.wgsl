// Includes: topology.
// Stage "integrate": x' = x + h v'; pinned vertices return to their
// prescribed positions with zero velocity; with self-contact, x is kept
// as where the step started (separate.wgsl holds the step back from it);
// the clock advances a substep; a vertex left not finite or faster than `max_speed` raises its flag in
// `state.health` (src/health.rs diagnoses it).
// CPU twin: src/cpu/integrate.rs.

// By the exponent bits, which no fast-math assumption can fold away.
fn finite3(a: vec3<f32>) -> bool {
    let e = bitcast<vec3<u32>>(a) & vec3<u32>(0x7f800000u);
    return all(e != vec3<u32>(0x7f800000u));
}

@group(1) @binding(1) var<storage, read_write> x: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read_write> v: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read> rest_positions: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read_write> state: StepState;
// Where the step started (self-contact only).
@group(1) @binding(5) var<storage, read_write> x_start: array<vec4<f32>>;

// x' = x + h v', the clock and the health flags.
@compute @workgroup_size(WORKGROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i == 0u {
        // Nothing else in this pass reads the clock, which counts
        // substeps; a step ends with its last.
        state.clock += 1u;
        if state.clock % params.substeps == 0u {
            state.steps += 1u;
        }
    }
    if i >= params.n_vertices {
        return;
    }
    if params.self_contact != 0u {
        x_start[i] = x[i];
    }
    if is_pinned(i) {
        x[i] = vec4<f32>(rest_positions[i].xyz, 1.0);
        v[i] = vec4<f32>(0.0);
    } else {
        x[i] = vec4<f32>(x[i].xyz + params.dt * v[i].xyz, 1.0);
    }
    let xi = x[i].xyz;
    let vi = v[i].xyz;
    var flags = 0u;
    if !finite3(xi) || !finite3(vi) {
        flags = NOT_FINITE;
    } else if dot(vi, vi) > params.max_speed * params.max_speed {
        flags = TOO_FAST;
    }
    if flags != 0u {
        atomicOr(&state.health, flags);
    }
}
