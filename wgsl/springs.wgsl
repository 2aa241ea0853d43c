// Stage "springs": force and stiffness block of every spring (thesis 2.2,
// eqs. 4–5). CPU twin: src/cpu/springs.rs.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> springs: array<vec2<u32>>;
@group(0) @binding(3) var<storage, read> rest_lengths: array<f32>;
@group(0) @binding(4) var<storage, read_write> spring_force: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> spring_block: array<Sym3>;

// f_i = E (l − L) d on the first vertex; K_s = E [(L/l) d dᵀ + max(0, 1 − L/l) I].
@compute @workgroup_size(WORKGROUP)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = id.x;
    if s >= params.n_springs {
        return;
    }
    let ij = springs[s];
    let dx = x[ij.y].xyz - x[ij.x].xyz;
    let l = length(dx);
    if l <= 1.17549435e-38 {
        spring_force[s] = vec4<f32>(0.0);
        spring_block[s] = sym_zero();
        return;
    }
    let d = dx / l;
    let rest = rest_lengths[s];
    let ratio = rest / l;
    let e = params.stiffness;
    spring_force[s] = vec4<f32>(e * (l - rest) * d, 0.0);
    spring_block[s] = sym_add(sym_scale(sym_outer(d), e * ratio), sym_diagonal(e * max(1.0 - ratio, 0.0)));
}
