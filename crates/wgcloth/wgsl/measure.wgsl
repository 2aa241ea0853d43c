// Includes: topology, bvh.
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

// Edge u → v of a triangle projected along the ray, the ray at the
// origin: its edge function u × v, whether the origin lies to its left (an
// exact zero decided as if the ray were moved by (ε, ε²), so that the two
// triangles sharing the edge take opposite sides), and false for an edge
// along the ray. Evaluated from the lower endpoint, so that both triangles
// round alike (cpu::measure::projected_edge).
struct ProjectedEdge {
    e: f32,
    left: bool,
    proper: bool,
}

fn projected_edge(u: vec2<f32>, v: vec2<f32>) -> ProjectedEdge {
    let swapped = v.x < u.x || (v.x == u.x && v.y < u.y);
    let lo = select(u, v, swapped);
    let hi = select(v, u, swapped);
    let e = lo.x * hi.y - lo.y * hi.x;
    let w = hi - lo;
    let tie = select(w.x > 0.0, w.y < 0.0, w.y != 0.0);
    let left = select(tie, e > 0.0, e != 0.0);
    return ProjectedEdge(select(e, -e, swapped), left != swapped, any(w != vec2<f32>(0.0)));
}

// Whether the ray from p along +x (cpu::measure::INSIDE_RAY) crosses
// triangle t: the origin on the same side of its three projected edges,
// and the crossing, whose barycentric weights are the edge functions,
// ahead of p.
fn ray_crosses(p: vec3<f32>, t: u32) -> bool {
    let a = corner(t, 0u) - p;
    let b = corner(t, 1u) - p;
    let c = corner(t, 2u) - p;
    let ea = projected_edge(b.yz, c.yz);
    let eb = projected_edge(c.yz, a.yz);
    let ec = projected_edge(a.yz, b.yz);
    let left = ea.left;
    let ahead = ea.e * a.x + eb.e * b.x + ec.e * c.x;
    // All left, the edge functions sum to a positive area; all right, negative.
    return ea.proper && eb.proper && ec.proper && eb.left == left && ec.left == left
        && ahead != 0.0 && (ahead > 0.0) == left;
}

// Odd crossings: inside.
fn inside(p: vec3<f32>) -> bool {
    var crossings = 0u;
    var walk = ray_walk(p);
    for (var leaf = next_leaf(&walk); leaf != NO_TRIANGLE; leaf = next_leaf(&walk)) {
        let node = bvh_nodes[leaf];
        for (var k = node.first; k < node.first + node.count; k++) {
            crossings += u32(ray_crosses(p, bvh_primitive(k)));
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
    // With self-contact, w marks the vertex for stage "separate", which
    // does not move it (the body wins) and clears the mark.
    let pushed = select(0.0, 1.0, params.self_contact != 0u);
    v[i] = vec4<f32>(vi + max(dot(frame.velocity, n) - dot(vi, n), 0.0) * n, pushed);
}
