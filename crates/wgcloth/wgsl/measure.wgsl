// Stage "measure": how deep the cloth got inside the rigid body after the
// solve (a ray-parity inside test, then the distance to the nearest point
// of the surface; no depth limit), folded into the run's maximum, the
// push-out of every vertex found inside, and the step's contact count
// folded into the total.
// CPU twin: src/cpu/measure.rs.

@group(1) @binding(1) var<storage, read_write> x: array<vec4<f32>>;
@group(1) @binding(6) var<storage, read_write> v: array<vec4<f32>>;
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

// Where body-space point p (inside) leaves the body: the nearest point of
// its surface, of equally near ones the lower triangle's (cpu::measure::way_out).
struct WayOut {
    depth: f32,
    surface: vec3<f32>,
    triangle: u32,
}

fn way_out(p: vec3<f32>) -> WayOut {
    let root = bvh_nodes[0];
    var best = WayOut(3.4e38, p, NO_TRIANGLE);
    var walk = box_walk(p, length(root.hi - root.lo));
    for (var leaf = next_leaf(&walk); leaf != NO_TRIANGLE; leaf = next_leaf(&walk)) {
        let node = bvh_nodes[leaf];
        for (var k = node.first; k < node.first + node.count; k++) {
            let t = bvh_primitive(k);
            let q = closest_on_triangle(p, corner(t, 0u), corner(t, 1u), corner(t, 2u));
            let d2 = dot(q - p, q - p);
            if d2 < best.depth || (d2 == best.depth && t < best.triangle) {
                best = WayOut(d2, q, t);
            }
        }
    }
    best.depth = sqrt(best.depth);
    return best;
}

// The push-out (cpu::measure::push_out): a free vertex the step left inside
// moves to the nearest surface point and ε beyond it along the normal, and
// loses the velocity with which it moves into the body relative to it.
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
    let out = way_out(p);
    atomicMax(&state.max_penetration_bits, bitcast<u32>(out.depth));
    if is_pinned(i) || out.triangle == NO_TRIANGLE {
        return;
    }
    let n = rotate(frame.rotation, body_face_normals[out.triangle].xyz);
    x[i] = vec4<f32>(rotate(frame.rotation, out.surface) + frame.translation + params.thickness * n, 1.0);
    let vi = v[i].xyz;
    v[i] = vec4<f32>(vi + max(dot(frame.velocity, n) - dot(vi, n), 0.0) * n, 0.0);
}
