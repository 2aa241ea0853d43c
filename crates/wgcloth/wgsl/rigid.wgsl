// Stage "rigid": places the kinematic body at the end of the step from the
// GPU clock and its prescribed motion. CPU twin: src/cpu/rigid.rs.

@group(1) @binding(1) var<storage, read> body_vertices: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> body_normals: array<vec4<f32>>;
// The placed body: its vertices, then their normals.
@group(1) @binding(3) var<storage, read_write> rigid: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read_write> frame: RigidFrame;
@group(1) @binding(5) var<storage, read_write> state: StepState;

const TAU: f32 = 6.283185307179586;

// Places the rigid body at the end of the step.
@compute @workgroup_size(WORKGROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    // The end of the step, from the step count: an f32 sum of h drifts.
    let t = f32(state.clock + 1u) * params.dt;
    var offset = vec3<f32>(0.0);
    var velocity = vec3<f32>(0.0);
    if params.motion_kind == MOTION_LINEAR {
        offset = params.motion_vector * t;
        velocity = params.motion_vector;
    } else if params.motion_kind == MOTION_SINUSOID {
        let w = TAU / params.motion_period;
        // Whole periods out first, as scene::rigid::angle.
        let phase = TAU * fract(t / params.motion_period) + params.motion_phase;
        offset = params.motion_vector * params.motion_amplitude * sin(phase);
        velocity = params.motion_vector * params.motion_amplitude * w * cos(phase);
    }
    let q = params.rigid_rotation;
    let translation = params.rigid_position + offset;
    let k = id.x;
    if k == 0u {
        frame = RigidFrame(q, translation, 0.0, velocity, 0.0);
        // This step's contact count starts here; collide adds to it.
        atomicStore(&state.contacts_last, 0u);
    }
    if k >= params.n_rigid_vertices {
        return;
    }
    rigid[k] = vec4<f32>(rotate(q, body_vertices[k].xyz) + translation, 1.0);
    rigid[params.n_rigid_vertices + k] = vec4<f32>(rotate(q, body_normals[k].xyz), 0.0);
}
