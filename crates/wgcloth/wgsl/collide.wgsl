// Stage "collide": contact detection in both directions (thesis 2.2–2.3).
// CPU twin: src/cpu/collide.rs, which finds exactly the same contacts.
//
// (a) vertex–face: each cloth vertex, moved into body space, walks the
//     rigid body's BVH (built once on the host).
// (b) face–vertex: each rigid vertex walks a two-level hierarchy over the
//     cloth grid: tiles of TILE×TILE cells and super-tiles of TILE×TILE
//     tiles, refitted every step by `tiles` and `supertiles` (two
//     dispatches whatever the size, where a BVH refit needs one per level).
//     Each contact is also linked into its cloth triangle's list, which the
//     assembly gathers from.

@group(1) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> body_vertices: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read> body_face_normals: array<vec4<f32>>;
// The placed body: its vertices, then their normals.
@group(1) @binding(4) var<storage, read> rigid: array<vec4<f32>>;
@group(1) @binding(5) var<storage, read> frame: RigidFrame;
@group(1) @binding(7) var<storage, read_write> contacts: array<Contact>;
// Per cloth triangle the head of its face–vertex contact list, then per
// rigid vertex the next entry of the list it is in (entries: rigid vertex
// + 1; 0 ends a list).
@group(1) @binding(8) var<storage, read_write> triangle_contacts: array<atomic<u32>>;
@group(1) @binding(9) var<storage, read_write> state: StepState;

fn reach() -> f32 {
    return max(params.thickness, params.max_depth);
}

fn no_contact() -> Contact {
    return Contact(vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0.0, vec3<f32>(0.0), 0u, vec3<u32>(0u), NO_TRIANGLE);
}

// Bounds of the cloth vertices of tile (tx, ty): cells [8tx, 8tx + 8).
@compute @workgroup_size(WORKGROUP)
fn tiles(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= params.tiles_x * params.tiles_y {
        return;
    }
    let tx = k % params.tiles_x;
    let ty = k / params.tiles_x;
    let nx = params.cells_x + 1u;
    var lo = vec3<f32>(3.4e38);
    var hi = vec3<f32>(-3.4e38);
    for (var r = ty * TILE; r <= min(ty * TILE + TILE, params.cells_y); r++) {
        for (var c = tx * TILE; c <= min(tx * TILE + TILE, params.cells_x); c++) {
            let p = x[r * nx + c].xyz;
            lo = min(lo, p);
            hi = max(hi, p);
        }
    }
    bounds[k] = Bounds(vec4<f32>(lo, 0.0), vec4<f32>(hi, 0.0));
}

@compute @workgroup_size(WORKGROUP)
fn supertiles(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= params.supertiles_x * params.supertiles_y {
        return;
    }
    let sx = k % params.supertiles_x;
    let sy = k / params.supertiles_x;
    bounds[params.tiles_x * params.tiles_y + k] = block_bounds(0u, params.tiles_x, params.tiles_y, sx, sy);
}

// (a) The rigid triangle closest to each cloth vertex.
@compute @workgroup_size(WORKGROUP)
fn vertex_face(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    let p = inverse_rotate(frame.rotation, x[i].xyz - frame.translation);
    var best_t = NO_TRIANGLE;
    var best = vec4<f32>(0.0);
    var walk = box_walk(p, reach());
    for (var leaf = next_leaf(&walk); leaf != NO_TRIANGLE; leaf = next_leaf(&walk)) {
        let node = bvh_nodes[leaf];
        for (var k = node.first; k < node.first + node.count; k++) {
            let t = bvh_primitive(k);
            let n = body_face_normals[t].xyz;
            let hit = point_triangle(p, body_vertices[body_index(3u * t)].xyz,
                                     body_vertices[body_index(3u * t + 1u)].xyz,
                                     body_vertices[body_index(3u * t + 2u)].xyz,
                                     n, params.thickness, params.max_depth);
            if found(hit) && better(hit.x, t, best.x, best_t) {
                best_t = t;
                best = hit;
            }
        }
    }
    var c = no_contact();
    if best_t != NO_TRIANGLE {
        c = Contact(rotate(frame.rotation, body_face_normals[best_t].xyz), best.x - params.thickness,
                    vec3<f32>(1.0, 0.0, 0.0), best.x, -frame.velocity, 1u, vec3<u32>(i), best_t);
        atomicAdd(&state.contacts_last, 1u);
    }
    contacts[i] = c;
}

// Unit normal of cloth triangle t, turned to face away from the rigid
// vertex's outward normal (the cloth is two-sided).
fn cloth_normal(t: u32, rigid_normal: vec3<f32>) -> vec3<f32> {
    let a = x[cloth_index(3u * t)].xyz;
    let n = cross(x[cloth_index(3u * t + 1u)].xyz - a, x[cloth_index(3u * t + 2u)].xyz - a);
    let len = length(n);
    if len == 0.0 {
        return vec3<f32>(0.0);
    }
    return select(n / len, -n / len, dot(n, rigid_normal) > 0.0);
}

// (b) The cloth triangle closest to each rigid vertex.
@compute @workgroup_size(WORKGROUP)
fn face_vertex(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= params.n_rigid_vertices {
        return;
    }
    let p = rigid[k].xyz;
    let np = rigid[params.n_rigid_vertices + k].xyz;
    let r = reach();
    var best_t = NO_TRIANGLE;
    var best = vec4<f32>(0.0);
    var best_n = vec3<f32>(0.0);
    for (var s = 0u; s < params.supertiles_x * params.supertiles_y; s++) {
        let sb = bounds[params.tiles_x * params.tiles_y + s];
        if !box_near(sb.lo.xyz, sb.hi.xyz, p, r) {
            continue;
        }
        let sx = s % params.supertiles_x;
        let sy = s / params.supertiles_x;
        for (var ty = sy * TILE; ty < min(sy * TILE + TILE, params.tiles_y); ty++) {
            for (var tx = sx * TILE; tx < min(sx * TILE + TILE, params.tiles_x); tx++) {
                let tb = bounds[ty * params.tiles_x + tx];
                if !box_near(tb.lo.xyz, tb.hi.xyz, p, r) {
                    continue;
                }
                for (var cy = ty * TILE; cy < min(ty * TILE + TILE, params.cells_y); cy++) {
                    for (var cx = tx * TILE; cx < min(tx * TILE + TILE, params.cells_x); cx++) {
                        for (var half = 0u; half < 2u; half++) {
                            let t = 2u * (cy * params.cells_x + cx) + half;
                            let n = cloth_normal(t, np);
                            if all(n == vec3<f32>(0.0)) {
                                continue;
                            }
                            let hit = point_triangle(p, x[cloth_index(3u * t)].xyz, x[cloth_index(3u * t + 1u)].xyz,
                                                     x[cloth_index(3u * t + 2u)].xyz, n, params.thickness,
                                                     params.max_depth);
                            if found(hit) && better(hit.x, t, best.x, best_t) {
                                best_t = t;
                                best = hit;
                                best_n = n;
                            }
                        }
                    }
                }
            }
        }
    }
    var c = no_contact();
    if best_t != NO_TRIANGLE {
        let verts = vec3<u32>(cloth_index(3u * best_t), cloth_index(3u * best_t + 1u), cloth_index(3u * best_t + 2u));
        c = Contact(best_n, best.x - params.thickness, -best.yzw, best.x, frame.velocity, 1u, verts, best_t);
        // Linked in at the head of the triangle's list (entries are k + 1;
        // 0 ends a list): one node per rigid vertex, so nothing can overflow.
        let next = atomicExchange(&triangle_contacts[best_t], k + 1u);
        atomicStore(&triangle_contacts[params.n_triangles + k], next);
        atomicAdd(&state.contacts_last, 1u);
    }
    contacts[params.n_vertices + k] = c;
}
