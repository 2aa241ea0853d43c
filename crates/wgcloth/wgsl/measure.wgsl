// Stage "measure": how deep the cloth got inside the rigid body after the
// step (a ray-parity inside test, then the distance to the nearest face
// plane containing the projection; no depth limit), folded into the run's
// maximum, and the step's contact count into the total.
// CPU twin: src/cpu/measure.rs.

@group(1) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> body_vertices: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read> body_face_normals: array<vec4<f32>>;
@group(1) @binding(4) var<storage, read> frame: RigidFrame;
@group(1) @binding(5) var<storage, read_write> state: StepState;

fn corner(t: u32, k: u32) -> vec3<f32> {
    return body_vertices[body_index(3u * t + k)].xyz;
}

// Whether the ray o + s d (s > 0) crosses triangle t (Möller–Trumbore).
fn ray_crosses(o: vec3<f32>, d: vec3<f32>, t: u32) -> bool {
    let a = corner(t, 0u);
    let e1 = corner(t, 1u) - a;
    let e2 = corner(t, 2u) - a;
    let pv = cross(d, e2);
    let det = dot(e1, pv);
    if abs(det) < 1e-12 {
        return false;
    }
    let s = (o - a) / det;
    let u = dot(s, pv);
    let qv = cross(s, e1);
    let v = dot(d, qv);
    return u >= 0.0 && v >= 0.0 && u + v <= 1.0 && dot(e2, qv) > 0.0;
}

// Odd crossings along a direction no generated mesh is aligned with.
fn inside(p: vec3<f32>) -> bool {
    let d = normalize(vec3<f32>(1.0, 0.7548777, 0.5698403));
    var crossings = 0u;
    var walk = ray_walk(p, d);
    for (var leaf = next_leaf(&walk); leaf != NO_TRIANGLE; leaf = next_leaf(&walk)) {
        let node = bvh_nodes[leaf];
        for (var k = node.first; k < node.first + node.count; k++) {
            crossings += u32(ray_crosses(p, d, bvh_primitive(k)));
        }
    }
    return crossings % 2u == 1u;
}

fn depth_inside(p: vec3<f32>) -> f32 {
    let root = bvh_nodes[0];
    let reach = length(root.hi - root.lo);
    var depth = 3.4e38;
    var walk = box_walk(p, reach);
    for (var leaf = next_leaf(&walk); leaf != NO_TRIANGLE; leaf = next_leaf(&walk)) {
        let node = bvh_nodes[leaf];
        for (var k = node.first; k < node.first + node.count; k++) {
            let t = bvh_primitive(k);
            let hit = point_triangle(p, corner(t, 0u), corner(t, 1u), corner(t, 2u), body_face_normals[t].xyz, 0.0, reach);
            if found(hit) {
                depth = min(depth, -hit.x);
            }
        }
    }
    if depth < 3.4e38 {
        return depth;
    }
    // A concave corner no face projection covers: the nearest vertex bounds it.
    for (var k = 0u; k < params.n_rigid_vertices; k++) {
        depth = min(depth, length(body_vertices[k].xyz - p));
    }
    return depth;
}

@compute @workgroup_size(WORKGROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i == 0u {
        state.contacts_total += atomicLoad(&state.contacts_last);
    }
    if i >= params.n_vertices {
        return;
    }
    let p = inverse_rotate(frame.rotation, x[i].xyz - frame.translation);
    let root = bvh_nodes[0];
    if !box_near(root.lo, root.hi, p, 0.0) || !inside(p) {
        return;
    }
    atomicMax(&state.max_penetration_bits, bitcast<u32>(depth_inside(p)));
}
