// Stage "springs": force and stiffness block of every spring (thesis 2.2,
// eqs. 4–5). CPU twin: src/cpu/springs.rs.

@group(1) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> rest_lengths: array<f32>;
@group(1) @binding(3) var<storage, read_write> spring_terms: array<SpringTerm>;

// f_i = E (l − L) d on the first vertex; K_s = E [(L/l) d dᵀ + max(0, 1 − L/l) I].
@compute @workgroup_size(WORKGROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = id.x;
    if s >= params.n_springs {
        return;
    }
    let ij = spring_ends(s);
    let dx = x[ij.y].xyz - x[ij.x].xyz;
    let l = length(dx);
    if l <= 1.17549435e-38 {
        spring_terms[s] = SpringTerm(sym_pack(sym_zero()), vec2<f32>(0.0), 0.0, 0.0);
        return;
    }
    let d = dx / l;
    let rest = rest_lengths[s];
    let ratio = rest / l;
    let e = params.stiffness;
    let force = e * (l - rest) * d;
    let block = sym_add(sym_scale(sym_outer(d), e * ratio), sym_diagonal(e * max(1.0 - ratio, 0.0)));
    spring_terms[s] = SpringTerm(sym_pack(block), force.xy, force.z, 0.0);
}
