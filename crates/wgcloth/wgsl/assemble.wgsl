// Includes: topology, springs.
// Stage "assemble": the linearised backward Euler system (thesis eqs. 1–3
// with the velocity Jacobian D), gathered per vertex and per spring, each
// spring's force and block computed here (wgsl/springs.wgsl, eqs. 4–5):
//   A_ii = (1 + hα) m I + (h² + hβ) Σ K_s + Σ β_k² C,   C = −(h D_c + h² K_c)
//   A_ij = −(h² + hβ) K_s + Σ β_k β_l C                 (per spring)
//   b_i  = m v_i + h (m g + Σ ±f_s) + Σ β_k h (f − D_c (v_rel − u))
// CPU twin: src/cpu/assemble.rs (which scatters the contacts instead).

@group(1) @binding(1) var<storage, read> v: array<vec4<f32>>;
// Contact slots and their responses: one per cloth vertex (vertex–face),
// then one per rigid vertex (face–vertex).
@group(1) @binding(3) var<storage, read> contacts: array<Contact>;
@group(1) @binding(4) var<storage, read> responses: array<Response>;
// Per cloth triangle the head of its face–vertex contact list, then per
// rigid vertex the next entry (wgsl/collide.wgsl).
@group(1) @binding(5) var<storage, read> triangle_contacts: array<u32>;
// A: its diagonal blocks (one per vertex), then one block per spring.
@group(1) @binding(6) var<storage, read_write> matrix: array<PackedSym3>;
// A solver vector (`b_set`: gpu::shaders::SOLVER_VECTORS).
@group(1) @binding(7) var<storage, read_write> b: array<VectorEntry>;

fn stiffness_scale() -> f32 {
    return params.dt * params.dt + params.dt * params.damping_stiffness;
}

// The face–vertex contacts on triangle t in rigid-vertex order, as entries
// (rigid vertex + 1; 0 ends the list), as collide.wgsl's `order` linked
// them: the sums so taken do not depend on the order the detection's
// threads found them in.
fn first_triangle_contact(t: u32) -> u32 {
    return triangle_contacts[params.n_triangles + t];
}

fn next_triangle_contact(e: u32) -> u32 {
    return triangle_contacts[2u * params.n_triangles + params.n_rigid_vertices + e - 1u];
}

// Σ β_k v_k (a vertex–face contact has β = (1, 0, 0)).
fn cloth_velocity(c: Contact) -> vec3<f32> {
    return c.beta.x * v[c.vertices.x].xyz + c.beta.y * v[c.vertices.y].xyz
        + c.beta.z * v[c.vertices.z].xyz;
}

// A's diagonal block and b, per vertex.
@compute @workgroup_size(WORKGROUP)
fn vertex(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    let h = params.dt;
    let m = params.vertex_mass;
    var k_sum = sym_zero();
    var f = m * params.gravity;
    for (var k = adjacency_begin(i); k < adjacency_begin(i + 1u); k++) {
        let s = adjacent_spring(k);
        let term = spring_term(s);
        k_sum = sym_add(k_sum, term.block);
        // The term's force acts on the spring's first vertex.
        let sign = select(-1.0, 1.0, spring_ends(s).x == i);
        f += sign * term.force;
    }
    var diag = sym_add(sym_diagonal((1.0 + h * params.damping_mass) * m), sym_scale(k_sum, stiffness_scale()));
    var rhs = m * v[i].xyz + h * f;
    // No branch on params.has_rigid: without a body every slot stays
    // invalid and every triangle count zero, and lavapipe recompiles a
    // kernel with a uniform-only branch at each dispatch.
    let c = contacts[i];
    if c.valid != 0u {
        let r = responses[i];
        diag = sym_add(diag, contact_block(r, c.normal));
        rhs += h * (r.force - sym_mul(sym_unpack(r.damping), v[i].xyz));
    }
    for (var q = vertex_triangles_begin(i); q < vertex_triangles_begin(i + 1u); q++) {
        let t = vertex_triangle(q) / 3u;
        let corner = vertex_triangle(q) % 3u;
        for (var e = first_triangle_contact(t); e != 0u; e = next_triangle_contact(e)) {
            let c = contacts[params.n_vertices + e - 1u];
            let r = responses[params.n_vertices + e - 1u];
            let beta = c.beta[corner];
            diag = sym_add(diag, sym_scale(contact_block(r, c.normal), beta * beta));
            rhs += beta * h * (r.force - sym_mul(sym_unpack(r.damping), cloth_velocity(c)));
        }
    }
    matrix_set(i, sym_pack(diag));
    b_set(i, rhs);
}

// A's off-diagonal block, per spring.
@compute @workgroup_size(WORKGROUP)
fn spring(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = id.x;
    if s >= params.n_springs {
        return;
    }
    var off = sym_scale(spring_term(s).block, -stiffness_scale());
    // No branch on params.has_rigid: without a body every slot stays
    // invalid and every triangle count zero, and lavapipe recompiles a
    // kernel with a uniform-only branch at each dispatch.
    let along = spring_triangles(s);
    for (var side = 0u; side < 2u; side++) {
        if along[side] == NO_TRIANGLE {
            continue;
        }
        let t = along[side] / 3u;
        let edge = along[side] % 3u;
        for (var e = first_triangle_contact(t); e != 0u; e = next_triangle_contact(e)) {
            let c = contacts[params.n_vertices + e - 1u];
            let weight = c.beta[edge] * c.beta[(edge + 1u) % 3u];
            off = sym_add(off, sym_scale(contact_block(responses[params.n_vertices + e - 1u], c.normal), weight));
        }
    }
    matrix_set(params.n_vertices + s, sym_pack(off));
}
