// Stage "lines": each contact's force as a segment from the penetrating
// point, for the renderer (wgsl/render.wgsl, thesis Figures 1–2). CPU
// twin: src/render/lines.rs. Pair 2s, 2s + 1 belongs to contact slot s
// (vertex–face slots first); an empty slot gets w = 0.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> rigid_vertices: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> vf_contacts: array<Contact>;
@group(0) @binding(4) var<storage, read> fv_contacts: array<Contact>;
@group(0) @binding(5) var<storage, read> vf_responses: array<Response>;
@group(0) @binding(6) var<storage, read> fv_responses: array<Response>;
// Metres of segment per unit of force.
@group(0) @binding(7) var<uniform> line_scale: vec4<f32>;
@group(0) @binding(8) var<storage, read_write> lines: array<vec4<f32>>;

@compute @workgroup_size(WORKGROUP)
fn force_lines(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = id.x;
    if s >= params.n_vertices + params.n_rigid_vertices {
        return;
    }
    var valid = false;
    var point: vec3<f32>;
    var force: vec3<f32>;
    if s < params.n_vertices {
        valid = vf_contacts[s].valid != 0u;
        point = x[s].xyz;
        force = vf_responses[s].force;
    } else {
        let k = s - params.n_vertices;
        valid = fv_contacts[k].valid != 0u;
        point = rigid_vertices[k].xyz;
        force = fv_responses[k].force;
    }
    let w = select(0.0, 1.0, valid);
    lines[2u * s] = vec4<f32>(point, w);
    lines[2u * s + 1u] = vec4<f32>(point + line_scale.x * force, w);
}
