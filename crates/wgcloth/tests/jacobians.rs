//! Every analytic Jacobian against central finite differences.

mod common;

use common::{Rng, assert_close, fd_jacobian};
use glam::{Mat3, Quat, Vec3};
use wgcloth::cpu::collide::{self, Contact, Geometry, Tolerances};
use wgcloth::cpu::contact::{
    Coefficients, ContactFrame, ForceJacobian, Model, friction, local_frame, naive, naive_net,
};
use wgcloth::cpu::rigid::{RigidFrame, transform};
use wgcloth::cpu::springs::spring;
use wgcloth::math::outer;
use wgcloth::nn::weights::NetKind;
use wgcloth::nn::{Layer, Mlp};
use wgcloth::scene::{Cloth, Motion, RigidBody, TriMesh};

#[test]
fn spring_block_matches_finite_differences_when_stretched() {
    let mut rng = Rng(7);
    for _ in 0..50 {
        let xi = rng.vec3(-1.0, 1.0);
        let dir = rng.vec3(-1.0, 1.0).normalize();
        let rest = rng.range(0.05, 0.2);
        let xj = xi + dir * rest * rng.range(1.05, 1.5);
        let block = spring(xi, xj, rest, 500.0).1.to_mat3();
        // K_s = ∂f_i/∂x_j and ∂f_i/∂x_i = −K_s (thesis eq. 5).
        let d_xj = fd_jacobian(xj, 1e-4, |y| spring(xi, y, rest, 500.0).0);
        let d_xi = fd_jacobian(xi, 1e-4, |y| spring(y, xj, rest, 500.0).0);
        assert_close(block, d_xj, 2e-3, 1e-2, "∂f_i/∂x_j stretched");
        assert_close(-block, d_xi, 2e-3, 1e-2, "∂f_i/∂x_i stretched");
    }
}

#[test]
fn spring_block_under_compression_drops_only_the_negative_isotropic_term() {
    let mut rng = Rng(11);
    for _ in 0..50 {
        let xi = rng.vec3(-1.0, 1.0);
        let dir = rng.vec3(-1.0, 1.0).normalize();
        let rest = rng.range(0.05, 0.2);
        let l = rest * rng.range(0.5, 0.95);
        let xj = xi + dir * l;
        let block = spring(xi, xj, rest, 500.0).1.to_mat3();
        let fd = fd_jacobian(xj, 1e-3, |y| spring(xi, y, rest, 500.0).0);
        // The exact derivative has E (1 − L/l) I < 0 on top of the clamped block.
        let dropped = 500.0 * (1.0 - rest / l) * Mat3::IDENTITY;
        assert_close(block + dropped, fd, 5e-3, 5e-2, "∂f_i/∂x_j compressed");
        // What is kept is symmetric positive semidefinite (K_s = E (L/l) d dᵀ).
        let (values, _) = wgcloth::math::symmetric_eigen(block);
        assert!(values.min_element() > -1e-3, "{values:?}");
    }
}

fn coefficients() -> Coefficients {
    Coefficients {
        kn: 1000.0,
        kd: 10.0,
        kt: 100.0,
        mu: 0.5,
    }
}

/// Checks ∂g/∂c and ∂g/∂v of a model at (c, v) against finite differences.
fn check_model(eval: impl Fn(Vec3, Vec3) -> ForceJacobian, c: Vec3, v: Vec3, what: &str) {
    let fj = eval(c, v);
    let d_c = fd_jacobian(c, 1e-5, |y| eval(y, v).force);
    let d_v = fd_jacobian(v, 1e-4, |y| eval(c, y).force);
    assert_close(fj.d_c, d_c, 5e-3, 1e-1, &format!("{what}: ∂f/∂c"));
    assert_close(fj.d_v, d_v, 5e-3, 1e-2, &format!("{what}: ∂f/∂v"));
}

/// A unit normal, a unit tangent, and c = n d̃.
fn frame(rng: &mut Rng, depth: f32) -> (Vec3, Vec3, Vec3) {
    let n = rng.vec3(-1.0, 1.0).normalize();
    let t = n.any_orthonormal_vector();
    let t = Quat::from_axis_angle(n, rng.range(0.0, std::f32::consts::TAU)) * t;
    (n, t, n * depth)
}

#[test]
fn naive_force_jacobian_matches_finite_differences() {
    let mut rng = Rng(3);
    for _ in 0..20 {
        let depth = -rng.range(0.001, 0.05);
        let (n, _, c) = frame(&mut rng, depth);
        check_model(|c, _| naive(c, 300.0), c, rng.vec3(-1.0, 1.0), "naive");
        // f = −c_n d̃ n pushes out along n (thesis eq. 6).
        assert!(naive(c, 300.0).force.dot(n) > 0.0);
    }
}

#[test]
fn friction_jacobians_match_finite_differences_in_every_regime() {
    let k = coefficients();
    let mut rng = Rng(5);
    for _ in 0..30 {
        let depth = -rng.range(0.01, 0.05);
        let (n, t, c) = frame(&mut rng, depth);
        let f_c = |v: Vec3| k.kn * -depth + k.kd * -v.dot(n);

        // Stick: small tangential speed, friction = −k_t ṫ.
        let v = -0.05 * n + 0.01 * t;
        assert!(k.kt * 0.01 < 0.5 * k.mu * f_c(v));
        let g = friction(c, v, &k).force;
        assert!((g - (f_c(v) * n - k.kt * 0.01 * t)).length() < 1e-3 * g.length());
        check_model(|c, v| friction(c, v, &k), c, v, "friction stick");

        // Slip: Coulomb friction −μ F_c t̂.
        let v = -0.05 * n + 1.0 * t;
        assert!(k.kt * 1.0 > 2.0 * k.mu * f_c(v));
        let g = friction(c, v, &k).force;
        assert!((g - f_c(v) * (n - k.mu * t)).length() < 1e-3 * g.length());
        check_model(|c, v| friction(c, v, &k), c, v, "friction slip");

        // Separated: leaving fast enough that eq. 8 would pull; no force at all.
        let v = 5.0 * n + 0.3 * t;
        assert!(f_c(v) < 0.0);
        let fj = friction(c, v, &k);
        assert_eq!(fj.force, Vec3::ZERO);
        check_model(|c, v| friction(c, v, &k), c, v, "friction separated");
    }
}

/// A friction network is read in the contact frame (`ContactFrame`): a
/// world-frame network that computed eqs. 8–9 exactly would give eqs. 8–9,
/// force and Jacobians, in stick and in slip.
#[test]
fn a_world_frame_network_read_in_the_contact_frame_keeps_the_exact_law() {
    let k = coefficients();
    let mut rng = Rng(9);
    for _ in 0..30 {
        let depth = -rng.range(0.01, 0.05);
        let (n, t, c) = frame(&mut rng, depth);
        for v in [-0.05 * n + 0.01 * t, -0.05 * n + 1.0 * t, 0.1 * n + 0.3 * t] {
            let frame = ContactFrame::new(c, v).expect("in contact");
            let rows = frame.inputs(NetKind::Friction, &k);
            let (mut y, mut j) = (Vec::new(), Vec::new());
            for x in rows.chunks_exact(10) {
                let exact = friction(Vec3::from_slice(x), Vec3::from_slice(&x[3..]), &k);
                y.extend(exact.force.to_array());
                // Row-major [3 outputs × (c, v)].
                for o in 0..3 {
                    j.extend((0..3).map(|t| exact.d_c.col(t)[o]));
                    j.extend((0..3).map(|t| exact.d_v.col(t)[o]));
                }
            }
            let got = frame.network_force(NetKind::Friction, &y, &j, &k);
            let want = friction(c, v, &k);
            assert!((got.force - want.force).length() <= 1e-4 * want.force.length());
            assert_close(got.d_c, want.d_c, 1e-2, 1e-3, "∂g/∂c read in the frame");
            assert_close(got.d_v, want.d_v, 1e-2, 1e-3, "∂g/∂v read in the frame");
        }
    }
}

/// A sphere of radius 0.2 at the origin and a 9×9 cloth patch at height z0,
/// moving rigidly at `u`; returns the contacts of both directions.
fn sphere_and_patch(
    z0: f32,
    u: Vec3,
) -> (Cloth, RigidBody, RigidFrame, Vec<Contact>, Vec<Contact>) {
    let body = RigidBody::new(
        TriMesh::icosphere(0.2, 3),
        Quat::IDENTITY,
        Vec3::ZERO,
        Motion::Linear { velocity: u },
    );
    let mut frame = RigidFrame::default();
    transform(&body, 0.0, &mut frame);
    let cloth = Cloth::grid(9, 9, 0.1, 100.0, &[], |a, b| {
        Vec3::new((a - 0.5) * 0.2, (0.5 - b) * 0.2, z0)
    });
    let bvh = wgcloth::bvh::Bvh::build(&wgcloth::bvh::triangle_boxes(
        &cloth.rest_positions,
        &cloth.triangles,
    ));
    let tol = Tolerances {
        thickness: 0.025,
        max_depth: 0.025,
    };
    let grid = wgcloth::cpu::body_grid::BodyGrid::new(&body, tol.reach());
    let vf = collide::vertex_face(&grid, &frame, &cloth.rest_positions, tol);
    let fv = collide::face_vertex(&cloth, &bvh, &cloth.rest_positions, &frame, tol);
    (cloth, body, frame, vf, fv)
}

/// The analytic models never ask for the triangle and point.
fn no_geometry() -> Geometry {
    unreachable!("an analytic model asked for the contact geometry")
}

/// The chain rule of the assembly, checked on real contacts: with the
/// surface frame (n, barycentric weights) frozen over the step, the force on
/// cloth vertex k, β_k f(c(x), v_rel(v)), has ∂/∂x_l = β_k β_l (∂f/∂c) n nᵀ
/// and ∂/∂v_l = β_k β_l ∂f/∂v_rel.
fn check_chain_rule(contact: &Contact, x0: &[Vec3], model: &Model, v: &[Vec3]) {
    let count = contact.vertex_count();
    let n = contact.normal;
    // d(x) = (Σ β_l x_l)·n + const, reproducing the detected distance at x0.
    let lin = |x: &[Vec3]| {
        (0..count).fold(Vec3::ZERO, |a, l| {
            a + contact.beta[l] * x[contact.vertices[l] as usize]
        })
    };
    let offset = contact.depth - lin(x0).dot(n);
    let force_on = |k: usize, x: &[Vec3], v: &[Vec3]| {
        let depth = lin(x).dot(n) + offset;
        contact.beta[k]
            * model
                .evaluate(n * depth, contact.relative_velocity(v), no_geometry)
                .force
    };
    let fj = model.evaluate(
        contact.collision_vector(),
        contact.relative_velocity(v),
        no_geometry,
    );
    for k in 0..count {
        for l in 0..count {
            let vl = contact.vertices[l] as usize;
            let moved = |field: &[Vec3], y: Vec3| {
                let mut f = field.to_vec();
                f[vl] = y;
                f
            };
            let kx = fd_jacobian(x0[vl], 1e-5, |y| force_on(k, &moved(x0, y), v));
            let kv = fd_jacobian(v[vl], 1e-4, |y| force_on(k, x0, &moved(v, y)));
            let bb = contact.beta[k] * contact.beta[l];
            assert_close(
                bb * fj.d_c * outer(n, n),
                kx,
                5e-3,
                1e-1,
                &format!("K block ({k},{l})"),
            );
            assert_close(bb * fj.d_v, kv, 5e-3, 1e-2, &format!("D block ({k},{l})"));
        }
    }
}

#[test]
fn contact_chain_rule_matches_finite_differences_in_both_directions() {
    let friction_model = Model::Friction {
        scale: 0.5,
        coefficients: coefficients(),
    };
    let naive_model = Model::Naive { stiffness: 800.0 };
    let (cloth, _, _, vf, fv) = sphere_and_patch(0.19, Vec3::ZERO);
    assert!(
        !vf.is_empty() && !fv.is_empty(),
        "both directions must find contacts"
    );
    for c in vf.iter().take(6).chain(fv.iter().take(6)) {
        let t = c.normal.any_orthonormal_vector();
        for (tangential_speed, regime) in [(1.0, "slip"), (1e-4, "stick")] {
            // Cloth moving so that v_rel approaches at 5 cm/s and slides along t.
            let target = -0.05 * c.normal + tangential_speed * t;
            let beta_sum: f32 = c.beta[..c.vertex_count()].iter().sum();
            let v = vec![(target - c.velocity_offset) / beta_sum; cloth.vertex_count()];
            assert!((c.relative_velocity(&v) - target).length() < 1e-5);
            for model in [&friction_model, &naive_model] {
                check_chain_rule(c, &cloth.rest_positions, model, &v);
            }
            let g = friction_model
                .evaluate(c.collision_vector(), target, no_geometry)
                .force;
            let normal = g.dot(c.normal);
            let tangential = (g - normal * c.normal).length();
            assert!(normal > 0.0, "contact force pushes out");
            let coulomb = 0.5 * normal; // μ F_c, scaled like g
            match regime {
                "slip" => assert!(
                    (tangential - coulomb).abs() < 1e-3 * coulomb,
                    "{regime}: {tangential} vs {coulomb}"
                ),
                _ => assert!(
                    tangential < 0.5 * coulomb,
                    "{regime}: {tangential} vs {coulomb}"
                ),
            }
        }
    }
}

/// A naive network that is exact by construction: f = (0, 0, −pz) in the
/// local frame, pz passed through two LeakyReLU units, since
/// σ(x) − σ(−x) = 1.01 x at slope 0.01.
fn exact_naive_net() -> Mlp {
    let pz = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
    let minus_pz = pz.map(|w: f32| -w);
    Mlp {
        layers: vec![
            Layer {
                inputs: 7,
                outputs: 2,
                weight: [pz, minus_pz].concat(),
                bias: vec![0.0; 2],
            },
            Layer {
                inputs: 2,
                outputs: 3,
                weight: vec![0.0, 0.0, 0.0, 0.0, -1.0 / 1.01, 1.0 / 1.01],
                bias: vec![0.0; 3],
            },
        ],
        negative_slope: 0.01,
    }
}

/// The local frame, the triangle's winding and the thickness shift, checked
/// on real contacts in both directions: an exact naive network gives the
/// naive model's force and contact stiffness.
#[test]
fn naive_net_with_an_exact_network_is_the_naive_model_in_both_directions() {
    let (cloth, body, frame, vf, fv) = sphere_and_patch(0.19, Vec3::ZERO);
    let net = exact_naive_net();
    let x = &cloth.rest_positions;
    for c in vf.iter().take(8).chain(fv.iter().take(8)) {
        let g = c.geometry(&cloth, &body, &frame, x);
        let lf = local_frame(&g).expect("a real triangle");
        assert_eq!(lf.inputs[3], 0.0, "cz");
        assert!((lf.inputs[6] - c.depth).abs() < 1e-5, "pz is d̃");
        let got = naive_net(&net, &g);
        let want = naive(c.collision_vector(), 1.0);
        assert!(
            (got.force - want.force).length() < 1e-5,
            "{got:?} vs {want:?}"
        );
        let nn = outer(c.normal, c.normal);
        assert_close(got.d_c * nn, want.d_c * nn, 1e-4, 1e-4, "(∂f/∂c) n nᵀ");
        assert_eq!(got.d_v, Mat3::ZERO);
    }
}

/// naive_net's Jacobian against finite differences of the point, for a
/// generic (inexact) network.
#[test]
fn naive_net_jacobian_matches_finite_differences() {
    let mut rng = Rng(11);
    let mut net = exact_naive_net();
    for w in net.layers[0].weight.iter_mut() {
        *w += rng.range(-0.5, 0.5);
    }
    for w in net.layers[1].weight.iter_mut() {
        *w += rng.range(-0.5, 0.5);
    }
    for _ in 0..10 {
        let triangle = [
            rng.vec3(-0.05, 0.05),
            rng.vec3(-0.05, 0.05),
            rng.vec3(-0.05, 0.05),
        ];
        let point = rng.vec3(-0.05, 0.05);
        let f = |p: Vec3| naive_net(&net, &Geometry { triangle, point: p }).force;
        let fj = naive_net(&net, &Geometry { triangle, point });
        assert_close(fj.d_c, fd_jacobian(point, 1e-4, f), 1e-2, 1e-3, "∂f/∂p");
    }
}
