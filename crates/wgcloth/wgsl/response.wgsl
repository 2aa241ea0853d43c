// The friction model of thesis eqs. 8–9 with its Jacobians, and the chain
// rule into the implicit system made safe for PCG: shared by stage
// "contact" (the cloth against the body) and stage "self_contact" (the
// cloth against itself). CPU twin: cpu::contact::{friction, response}.
// Prepended to those stages (gpu::shaders::INCLUDES).

// A force with its Jacobians ∂f/∂c and ∂f/∂v_rel.
struct ForceJacobian {
    force: vec3<f32>,
    d_c: mat3x3<f32>,
    d_v: mat3x3<f32>,
}

const IDENTITY: mat3x3<f32> = mat3x3<f32>(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
const ZERO3: mat3x3<f32> = mat3x3<f32>(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);

// a bᵀ
fn outer(a: vec3<f32>, b: vec3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(a * b.x, a * b.y, a * b.z);
}

// k_n, k_d, k_t, μ (cpu::contact::Coefficients).
struct Coefficients {
    kn: f32,
    kd: f32,
    kt: f32,
    mu: f32,
}

// Eq. 8's normal force F_c, 0 on the surface (cpu::contact::normal_force).
fn normal_force(c: vec3<f32>, v: vec3<f32>, k: Coefficients) -> f32 {
    let r = length(c);
    if r == 0.0 {
        return 0.0;
    }
    return max(k.kn * r + k.kd * dot(v, c / r), 0.0);
}

// Friction model (thesis eqs. 8–9), unscaled g; see cpu::contact::friction.
fn friction(c: vec3<f32>, v: vec3<f32>, k: Coefficients) -> ForceJacobian {
    let f_c = normal_force(c, v, k);
    if f_c == 0.0 {
        return ForceJacobian(vec3<f32>(0.0), ZERO3, ZERO3);
    }
    let r = length(c);
    let c_hat = c / r;
    let n = -c_hat;
    let p = IDENTITY - outer(c_hat, c_hat);
    let approach = dot(v, c_hat);
    let dfc_dc = k.kn * c_hat + k.kd * (p * v) / r;
    let dfc_dv = k.kd * c_hat;
    var force = f_c * n;
    var d_c = -1.0 * outer(c_hat, dfc_dc) - (f_c / r) * p;
    var d_v = -1.0 * outer(c_hat, dfc_dv);
    let t_dot = p * v;
    let dt_dc = (-1.0 / r) * (approach * p + outer(c_hat, p * v));
    let speed = length(t_dot);
    if k.kt * speed <= k.mu * f_c {
        force -= k.kt * t_dot;
        d_c -= k.kt * dt_dc;
        d_v -= k.kt * p;
    } else {
        let t_hat = t_dot / speed;
        let turn = (IDENTITY - outer(t_hat, t_hat)) * (1.0 / speed);
        force -= k.mu * f_c * t_hat;
        d_c -= k.mu * (outer(t_hat, dfc_dc) + f_c * turn * dt_dc);
        d_v -= k.mu * (outer(t_hat, dfc_dv) + f_c * turn * p);
    }
    return ForceJacobian(force, d_c, d_v);
}

fn symmetric_part(m: mat3x3<f32>) -> mat3x3<f32> {
    return 0.5 * (m + transpose(m));
}

// Whether symmetric m is NSD: every principal minor of −m is nonnegative
// (mirrors math::is_nsd).
fn is_nsd(m: mat3x3<f32>) -> bool {
    let n = -1.0 * m;
    return n[0][0] >= 0.0 && n[1][1] >= 0.0 && n[2][2] >= 0.0
        && n[0][0] * n[1][1] >= n[1][0] * n[1][0]
        && n[0][0] * n[2][2] >= n[2][0] * n[2][0]
        && n[1][1] * n[2][2] >= n[2][1] * n[2][1]
        && determinant(n) >= 0.0;
}

// Nearest symmetric NSD matrix (mirrors math::project_nsd): a block that is
// NSD already, nearly every one, is its own projection; any other has its
// positive eigenvalues clamped to zero.
fn project_nsd(m: mat3x3<f32>) -> Sym3 {
    let s = symmetric_part(m);
    var out = s;
    if !is_nsd(s) {
        out = clamp_eigenvalues(s);
    }
    return Sym3(vec4<f32>(out[0][0], out[1][1], out[2][2], 0.5 * (out[0][1] + out[1][0])),
                vec4<f32>(0.5 * (out[0][2] + out[2][0]), 0.5 * (out[1][2] + out[2][1]), 0.0, 0.0));
}

// Symmetric s with its positive eigenvalues clamped to zero: cyclic Jacobi
// eigen-decomposition (math::symmetric_eigen).
fn clamp_eigenvalues(s: mat3x3<f32>) -> mat3x3<f32> {
    var a = s;
    var q = IDENTITY;
    for (var sweep = 0u; sweep < 8u; sweep++) {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        let diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
        if off <= 1e-14 * diag || off == 0.0 {
            break;
        }
        for (var pair = 0u; pair < 3u; pair++) {
            let pi = select(select(1u, 0u, pair < 2u), 0u, pair == 0u);
            let qi = select(2u, 1u, pair == 0u);
            let apq = a[pi][qi];
            if apq == 0.0 {
                continue;
            }
            let theta = (a[qi][qi] - a[pi][pi]) / (2.0 * apq);
            let t = sign(theta) / (abs(theta) + sqrt(theta * theta + 1.0));
            let tt = select(t, 1.0, theta == 0.0);
            let cs = 1.0 / sqrt(tt * tt + 1.0);
            let sn = tt * cs;
            // A ← Jᵀ A J; Q ← Q J.
            for (var k = 0u; k < 3u; k++) {
                let akp = a[k][pi];
                let akq = a[k][qi];
                a[k][pi] = cs * akp - sn * akq;
                a[k][qi] = sn * akp + cs * akq;
            }
            for (var k = 0u; k < 3u; k++) {
                let apk = a[pi][k];
                let aqk = a[qi][k];
                a[pi][k] = cs * apk - sn * aqk;
                a[qi][k] = sn * apk + cs * aqk;
            }
            for (var k = 0u; k < 3u; k++) {
                let vp = q[pi][k];
                let vq = q[qi][k];
                q[pi][k] = cs * vp - sn * vq;
                q[qi][k] = sn * vp + cs * vq;
            }
        }
    }
    // Column j of q is eigenvector j.
    var out = ZERO3;
    for (var j = 0u; j < 3u; j++) {
        out += min(a[j][j], 0.0) * outer(q[j], q[j]);
    }
    return out;
}

// The chain rule into the system with the three safety moves of
// cpu::contact::response: n–t cross terms dropped, the floor on sliding
// friction's damping (the secant less `inertia`, the mass the contact
// moves over h), and the NSD projection.
fn response(fj: ForceJacobian, n: vec3<f32>, v_rel: vec3<f32>, inertia: f32) -> Response {
    let nn = outer(n, n);
    let tangent_plane = IDENTITY - nn;
    let normal_stiffness = min(dot(n, fj.d_c * n), 0.0);
    var damping = dot(n, fj.d_v * n) * nn + tangent_plane * symmetric_part(fj.d_v) * tangent_plane;
    let t_dot = tangent_plane * v_rel;
    let speed = length(t_dot);
    if speed > 0.0 {
        let t_hat = t_dot / speed;
        let floor = -dot(fj.force, t_hat) / speed - inertia;
        let deficit = floor + dot(t_hat, damping * t_hat);
        if deficit > 0.0 {
            damping -= deficit * outer(t_hat, t_hat);
        }
    }
    return Response(fj.force, normal_stiffness, sym_pack(project_nsd(damping)), vec2<f32>(0.0));
}
