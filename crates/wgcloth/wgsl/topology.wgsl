// The static connectivity of the cloth and the body in one u32 buffer, so
// no stage needs more than WebGPU's 8 storage buffers. Sections (their
// starts in `params`, laid out by gpu::layout::Sections):
//   cloth triangles (3 per triangle; first, so the buffer is the index
//   buffer an app draws with), springs (2 vertices and the rest length's
//   bits each), adjacency (offsets per
//   vertex, then (spring, other vertex) pairs), pinned flags, vertex
//   triangles (offsets, then 3 t + corner), spring triangles (3 t + edge,
//   twice per spring), body triangles, the body BVH's primitive order.
// Read through `topology_at` (gpu::shaders writes it), so that a cloth whose
// topology outgrows one binding can have it bound in parts.

@group(1) @binding(40) var<storage, read> topology: array<u32>;

fn cloth_index(k: u32) -> u32 {
    return topology_at(k);
}

fn spring_ends(s: u32) -> vec2<u32> {
    let at = params.springs_at + 3u * s;
    return vec2<u32>(topology_at(at), topology_at(at + 1u));
}

fn rest_length(s: u32) -> f32 {
    return bitcast<f32>(topology_at(params.springs_at + 3u * s + 2u));
}

// Vertex i's springs are adjacency entries adjacency_begin(i) .. adjacency_begin(i + 1).
fn adjacency_begin(i: u32) -> u32 {
    return topology_at(params.adjacency_at + i);
}

fn adjacent_spring(k: u32) -> u32 {
    return topology_at(params.adjacency_at + params.n_vertices + 1u + 2u * k);
}

fn adjacent_vertex(k: u32) -> u32 {
    return topology_at(params.adjacency_at + params.n_vertices + 2u + 2u * k);
}

fn is_pinned(i: u32) -> bool {
    return topology_at(params.pinned_at + i) != 0u;
}

fn vertex_triangles_begin(i: u32) -> u32 {
    return topology_at(params.vertex_triangles_at + i);
}

// Triangle index × 3 + the vertex's corner in it.
fn vertex_triangle(q: u32) -> u32 {
    return topology_at(params.vertex_triangles_at + params.n_vertices + 1u + q);
}

// Triangle index × 3 + edge for the ≤ 2 triangles along spring s,
// NO_TRIANGLE where there is none.
fn spring_triangles(s: u32) -> vec2<u32> {
    let at = params.spring_triangles_at + 2u * s;
    return vec2<u32>(topology_at(at), topology_at(at + 1u));
}

fn body_index(k: u32) -> u32 {
    return topology_at(params.body_triangles_at + k);
}

fn bvh_primitive(k: u32) -> u32 {
    return topology_at(params.bvh_order_at + k);
}
