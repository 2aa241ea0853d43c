// Stage "load": the normal force each vertex's cloth–cloth contacts
// carried in the step's solve, which bounds the next step's friction
// (self_contact.wgsl `sort`). A contact's force over the step is its
// linearisation at the solved velocities v': h f' = rhs − B Σ β_k v'_k;
// vertex i carries |β_i| n·f' of it, n the normal at the step's start
// (x has not moved yet). CPU twin: src/cpu/load.rs.

@group(1) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> v: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read> cloth_lists: array<u32>;
@group(1) @binding(4) var<storage, read> cloth_pairs: array<ClothPair>;
// Per vertex, the load carried (x) and the bound's scale (y, self_contact).
@group(1) @binding(5) var<storage, read_write> cloth_loads: array<vec2<f32>>;

// Vertex i's load, over its contacts in key order, at least 0.
@compute @workgroup_size(WORKGROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    var load = 0.0;
    for (var a = 0u; a < cloth_lists[listed_at(i)]; a++) {
        let e = cloth_lists[entry_at(i, a)];
        let pair = cloth_pairs[e / 4u];
        var gap = vec3<f32>(0.0);
        var v_rel = vec3<f32>(0.0);
        for (var k = 0u; k < 4u; k++) {
            gap += pair.beta[k] * x[pair_vertex(pair.key, k)].xyz;
            v_rel += pair.beta[k] * v[pair_vertex(pair.key, k)].xyz;
        }
        let distance = length(gap);
        let n = select(vec3<f32>(0.0), gap / distance, distance > 0.0);
        let pushed = dot(n, pair.rhs - sym_mul(sym_unpack(pair.block), v_rel)) / params.dt;
        load += abs(pair.beta[e % 4u]) * pushed;
    }
    cloth_loads[i].x = max(load, 0.0);
}
