// Springs (thesis 2.2, eqs. 4–5): each spring's force and stiffness block
// at the current positions, computed where stage "assemble" gathers them,
// so no buffer holds them. CPU twin: src/cpu/springs.rs.

@group(1) @binding(42) var<storage, read> x: array<vec4<f32>>;

struct SpringTerm {
    // On the spring's first vertex; the second gets the opposite.
    force: vec3<f32>,
    // K_s = ∂f_i/∂x_j.
    block: Sym3,
}

// f_i = E (l − L) d on the first vertex; K_s = E [(L/l) d dᵀ + max(0, 1 − L/l) I].
fn spring_term(s: u32) -> SpringTerm {
    let ij = spring_ends(s);
    let dx = x[ij.y].xyz - x[ij.x].xyz;
    let l = length(dx);
    if l <= 1.17549435e-38 {
        return SpringTerm(vec3<f32>(0.0), sym_zero());
    }
    let d = dx / l;
    let rest = rest_length(s);
    let ratio = rest / l;
    let e = params.stiffness;
    return SpringTerm(
        e * (l - rest) * d,
        sym_add(sym_scale(sym_outer(d), e * ratio), sym_diagonal(e * max(1.0 - ratio, 0.0))),
    );
}
