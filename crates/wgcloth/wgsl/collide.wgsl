// Includes: topology, bvh, tiles.
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

// Refits the super-tile bounds from the tiles.
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

// (b) The cloth triangle closest to each rigid vertex, in one of two
// ways with the same result (`Collide::new` picks by the cloth's size):
// `face_vertex_serial`, one invocation per rigid vertex walking every cell
// of every near tile, or `face_vertex`, one workgroup per rigid vertex
// with a lane per tile of a super-tile and then per cell of a tile. On a
// fine grid a vertex has thousands of triangles within reach, which the
// second spreads over TILE² lanes; on a coarse one its barriers cost more
// than they spread. Both keep the best by `better`, a total order (larger
// d, then the lower triangle), so the contact is the one the CPU finds.

// A rigid vertex's best hit so far.
struct Hit {
    t: u32,
    at: vec4<f32>,
    normal: vec3<f32>,
}

fn no_hit() -> Hit {
    return Hit(NO_TRIANGLE, vec4<f32>(0.0), vec3<f32>(0.0));
}

// `best`, or the hit on either triangle of cell (cx, cy) of rigid vertex
// p (outward normal np) where it is better.
fn cell_hit(best: Hit, cx: u32, cy: u32, p: vec3<f32>, np: vec3<f32>) -> Hit {
    var out = best;
    for (var half = 0u; half < 2u; half++) {
        let t = 2u * (cy * params.cells_x + cx) + half;
        let n = cloth_normal(t, np);
        if all(n == vec3<f32>(0.0)) {
            continue;
        }
        let hit = point_triangle(p, x[cloth_index(3u * t)].xyz, x[cloth_index(3u * t + 1u)].xyz,
                                 x[cloth_index(3u * t + 2u)].xyz, n, params.thickness, params.max_depth);
        if found(hit) && better(hit.x, t, out.at.x, out.t) {
            out = Hit(t, hit, n);
        }
    }
    return out;
}

// Where `triangle_contacts` keeps, per rigid vertex k, the next entry of
// its triangle's list as the search linked it, then the next in
// rigid-vertex order (`order`); before them, per cloth triangle, the head
// of each.
fn linked_at(k: u32) -> u32 {
    return 2u * params.n_triangles + k;
}

fn ordered_at(k: u32) -> u32 {
    return 2u * params.n_triangles + params.n_rigid_vertices + k;
}

// Each face–vertex contact's place in its triangle's list in rigid-vertex
// order (entries k + 1): the next entry above its own, and whether it is
// the least, which heads the list. Sums over a list so taken do not depend
// on the order the search's threads linked it in; each contact walks its
// list once, where finding each next entry by walking the whole list
// again cost the square of its length at every vertex of the triangle
// (170 contacts a triangle on an 8 × 8 cloth against a sphere of 10,242
// vertices), and lavapipe then summed only some of them.
@compute @workgroup_size(WORKGROUP)
fn order(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= params.n_rigid_vertices || contacts[params.n_vertices + k].valid == 0u {
        return;
    }
    let t = contacts[params.n_vertices + k].triangle;
    let own = k + 1u;
    var next = 0u;
    var least = true;
    var e = atomicLoad(&triangle_contacts[t]);
    // A list holds at most the body's vertices; the bound only guards it.
    for (var hops = 0u; e != 0u && hops < params.n_rigid_vertices; hops++) {
        least = least && e >= own;
        if e > own && (next == 0u || e < next) {
            next = e;
        }
        e = atomicLoad(&triangle_contacts[linked_at(e - 1u)]);
    }
    atomicStore(&triangle_contacts[ordered_at(k)], next);
    if least {
        atomicStore(&triangle_contacts[params.n_triangles + t], own);
    }
}

// Rigid vertex k's contact slot, and its link into the triangle's list.
fn store_face_vertex(k: u32, best: Hit) {
    var c = no_contact();
    if best.t != NO_TRIANGLE {
        let verts = vec3<u32>(cloth_index(3u * best.t), cloth_index(3u * best.t + 1u), cloth_index(3u * best.t + 2u));
        c = Contact(best.normal, best.at.x - params.thickness, -best.at.yzw, best.at.x, frame.velocity, 1u, verts,
                    best.t);
        // Linked in at the head of the triangle's list (entries are k + 1;
        // 0 ends a list): one node per rigid vertex, so nothing can overflow.
        let next = atomicExchange(&triangle_contacts[best.t], k + 1u);
        atomicStore(&triangle_contacts[linked_at(k)], next);
        atomicAdd(&state.contacts_last, 1u);
    }
    contacts[params.n_vertices + k] = c;
}

fn super_tile_near(s: u32, p: vec3<f32>) -> bool {
    let sb = bounds[params.tiles_x * params.tiles_y + s];
    return box_near(sb.lo.xyz, sb.hi.xyz, p, reach());
}

// Whether tile (tx, ty) exists and is within reach of p.
fn tile_near(tx: u32, ty: u32, p: vec3<f32>) -> bool {
    if tx >= params.tiles_x || ty >= params.tiles_y {
        return false;
    }
    let tb = bounds[ty * params.tiles_x + tx];
    return box_near(tb.lo.xyz, tb.hi.xyz, p, reach());
}

// The cloth triangle closest to each rigid vertex, one invocation per
// rigid vertex, on a coarse cloth (gpu::stages::collide).
@compute @workgroup_size(WORKGROUP)
fn face_vertex_serial(@builtin(global_invocation_id) id: vec3<u32>) {
    let k = id.x;
    if k >= params.n_rigid_vertices {
        return;
    }
    let p = rigid[k].xyz;
    let np = rigid[params.n_rigid_vertices + k].xyz;
    var best = no_hit();
    for (var s = 0u; s < params.supertiles_x * params.supertiles_y; s++) {
        if !super_tile_near(s, p) {
            continue;
        }
        for (var j = 0u; j < FACE_VERTEX_LANES; j++) {
            let tx = (s % params.supertiles_x) * TILE + j % TILE;
            let ty = (s / params.supertiles_x) * TILE + j / TILE;
            if !tile_near(tx, ty, p) {
                continue;
            }
            for (var cy = ty * TILE; cy < min(ty * TILE + TILE, params.cells_y); cy++) {
                for (var cx = tx * TILE; cx < min(tx * TILE + TILE, params.cells_x); cx++) {
                    best = cell_hit(best, cx, cy, p, np);
                }
            }
        }
    }
    store_face_vertex(k, best);
}

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

// The cloth triangle closest to each rigid vertex.
@compute @workgroup_size(FACE_VERTEX_LANES)
fn face_vertex(@builtin(workgroup_id) wg: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>,
               @builtin(local_invocation_index) lid: u32) {
    // This lane's tile of a super-tile, and its cell of a tile.
    let lx = lid % TILE;
    let ly = lid / TILE;
    // Super-tiles searched so far (not `round`, a WGSL built-in).
    var searched = 0u;
    // Rigid vertex k, strided when there are more than workgroups.
    for (var k = wg.x; k < params.n_rigid_vertices; k += groups.x) {
        let p = rigid[k].xyz;
        let np = rigid[params.n_rigid_vertices + k].xyz;
        var best = no_hit();
        for (var s = 0u; s < params.supertiles_x * params.supertiles_y; s++) {
            let near = super_tile_near(s, p);
            let sx = s % params.supertiles_x;
            let sy = s / params.supertiles_x;
            let parity = searched % 2u;
            searched++;
            if near && tile_near(sx * TILE + lx, sy * TILE + ly, p) {
                near_tiles[atomicAdd(&near_count[parity], 1u)] = lid;
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
                if cx < params.cells_x && cy < params.cells_y {
                    best = cell_hit(best, cx, cy, p, np);
                }
            }
            // The next round writes the list again.
            workgroupBarrier();
        }
        lane_d[lid] = best.at.x;
        lane_t[lid] = best.t;
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
        // The lane that found the winner stores it (triangles are unique);
        // lane 0 stores that there is none.
        if (winner != NO_TRIANGLE && best.t == winner) || (winner == NO_TRIANGLE && lid == 0u) {
            store_face_vertex(k, best);
        }
    }
}
