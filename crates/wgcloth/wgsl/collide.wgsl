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

// (b) The cloth triangle closest to each rigid vertex: one workgroup per
// rigid vertex (strided when there are more than workgroups), one lane per
// tile of a super-tile and then per cell of a tile, so a vertex's thousands
// of triangle tests at a fine grid spread over TILE² lanes instead of
// running in one. Each lane keeps its best, and lane 0 picks the best of
// those by `better`, a total order (larger d, then the lower triangle), so
// the contact is the one a single search finds, as on the CPU.
// The near tiles of the super-tile being searched, in any order (the
// winner does not depend on it), and their count, one counter per parity
// of the search's round so that one is reset while the other is read.
var<workgroup> near_tiles: array<u32, FACE_VERTEX_LANES>;
var<workgroup> near_count: array<atomic<u32>, 2>;
var<workgroup> lane_d: array<f32, FACE_VERTEX_LANES>;
var<workgroup> lane_t: array<u32, FACE_VERTEX_LANES>;
// Written by lane 0 after the next vertex's first barrier, by which every
// lane has read this one's.
var<workgroup> lane_winner: u32;

@compute @workgroup_size(FACE_VERTEX_LANES)
fn face_vertex(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    let r = reach();
    // This lane's tile of a super-tile, and its cell of a tile.
    let lx = lid % TILE;
    let ly = lid / TILE;
    var round = 0u;
    for (var k = wg.x; k < params.n_rigid_vertices; k += groups.x) {
        let p = rigid[k].xyz;
        let np = rigid[params.n_rigid_vertices + k].xyz;
        var best_t = NO_TRIANGLE;
        var best = vec4<f32>(0.0);
        var best_n = vec3<f32>(0.0);
        for (var s = 0u; s < params.supertiles_x * params.supertiles_y; s++) {
            let sb = bounds[params.tiles_x * params.tiles_y + s];
            let near = box_near(sb.lo.xyz, sb.hi.xyz, p, r);
            let sx = s % params.supertiles_x;
            let sy = s / params.supertiles_x;
            let tx = sx * TILE + lx;
            let ty = sy * TILE + ly;
            let parity = round % 2u;
            round++;
            if near && tx < params.tiles_x && ty < params.tiles_y {
                let tb = bounds[ty * params.tiles_x + tx];
                if box_near(tb.lo.xyz, tb.hi.xyz, p, r) {
                    near_tiles[atomicAdd(&near_count[parity], 1u)] = lid;
                }
            }
            workgroupBarrier();
            if lid == 0u {
                // Last read in the previous round, which a barrier ended.
                atomicStore(&near_count[1u - parity], 0u);
            }
            for (var i = 0u; i < atomicLoad(&near_count[parity]); i++) {
                let j = near_tiles[i];
                let cx = (sx * TILE + j % TILE) * TILE + lx;
                let cy = (sy * TILE + j / TILE) * TILE + ly;
                if cx >= params.cells_x || cy >= params.cells_y {
                    continue;
                }
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
            // The next round writes the list again.
            workgroupBarrier();
        }
        lane_d[lid] = best.x;
        lane_t[lid] = best_t;
        workgroupBarrier();
        if lid == 0u {
            var d = lane_d[0];
            var t = lane_t[0];
            for (var l = 1u; l < FACE_VERTEX_LANES; l++) {
                if lane_t[l] != NO_TRIANGLE && better(lane_d[l], lane_t[l], d, t) {
                    d = lane_d[l];
                    t = lane_t[l];
                }
            }
            lane_winner = t;
        }
        let winner = workgroupUniformLoad(&lane_winner);
        // The lane that found the winner writes it (triangles are unique).
        if winner != NO_TRIANGLE && best_t == winner {
            let verts = vec3<u32>(cloth_index(3u * best_t), cloth_index(3u * best_t + 1u), cloth_index(3u * best_t + 2u));
            contacts[params.n_vertices + k] = Contact(best_n, best.x - params.thickness, -best.yzw, best.x,
                                                      frame.velocity, 1u, verts, best_t);
            // Linked in at the head of the triangle's list (entries are k + 1;
            // 0 ends a list): one node per rigid vertex, so nothing can overflow.
            let next = atomicExchange(&triangle_contacts[best_t], k + 1u);
            atomicStore(&triangle_contacts[params.n_triangles + k], next);
            atomicAdd(&state.contacts_last, 1u);
        }
        if winner == NO_TRIANGLE && lid == 0u {
            contacts[params.n_vertices + k] = no_contact();
        }
    }
}
