// Stage "lines": each contact's force as a segment from the penetrating
// point, for the renderer (wgsl/render.wgsl, thesis Figures 1–2). CPU
// twin: src/render/lines.rs. Pair 2s, 2s + 1 belongs to contact slot s
// (vertex–face slots first); an empty slot gets w = 0.

@group(1) @binding(1) var<storage, read> x: array<vec4<f32>>;
// The placed body: its vertices, then their normals.
@group(1) @binding(2) var<storage, read> rigid: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read> contacts: array<Contact>;
@group(1) @binding(4) var<storage, read> responses: array<Response>;
// Metres of segment per unit of force.
@group(1) @binding(5) var<uniform> line_scale: vec4<f32>;
@group(1) @binding(6) var<storage, read_write> lines: array<vec4<f32>>;

// Each contact's force as a segment for the renderer.
@compute @workgroup_size(WORKGROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = id.x;
    if s >= params.n_vertices + params.n_rigid_vertices {
        return;
    }
    var point: vec3<f32>;
    let valid = contacts[s].valid != 0u;
    let force = responses[s].force;
    if s < params.n_vertices {
        point = x[s].xyz;
    } else {
        point = rigid[s - params.n_vertices].xyz;
    }
    let w = select(0.0, 1.0, valid);
    lines[2u * s] = vec4<f32>(point, w);
    lines[2u * s + 1u] = vec4<f32>(point + line_scale.x * force, w);
}
