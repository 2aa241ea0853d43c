//! Stage "assemble": the linearised backward Euler system (thesis eqs. 1–3
//! with the velocity Jacobian D):
//!   (M − hD − h²K) v' = M v + h f − h D v.
//! Springs carry Rayleigh damping D = −αM + βK, whose force D v cancels
//! from the right-hand side; contacts add their own K_c and D_c.
//! Mirrors wgsl/assemble.wgsl: per-vertex gathers over the adjacency, then
//! the contacts. The system's matrix, [`BlockMatrix`], is defined here:
//! the solve and its preconditioners read it.

use glam::Vec3;
use rayon::prelude::*;

use crate::cpu::collide::Contact;
use crate::cpu::contact::Response;
use crate::cpu::self_contact::Couplings;
use crate::math::Sym3;
use crate::parallel::GRAIN;
use crate::scene::Cloth;
use crate::scene::cloth::Adjacency;

/// A = M − hD − h²K in the cloth's sparsity: one diagonal block per vertex
/// and one symmetric off-diagonal block per spring, A_ij = A_ji = `off[s]`
/// (the face contacts' couplings lie on a spring's pair), and the
/// cloth–cloth contacts' couplings, which do not.
#[derive(Clone, Debug, Default)]
pub struct BlockMatrix {
    /// A_ii, one block per vertex.
    pub diag: Vec<Sym3>,
    /// A_ij = A_ji, one block per spring (i, j), in spring order.
    pub off: Vec<Sym3>,
    /// The cloth–cloth contacts' off-diagonal blocks (none without
    /// self-contact forces); the preconditioners see only their diagonal.
    pub couplings: Couplings,
}

impl BlockMatrix {
    /// The zero matrix of a cloth with `vertices` vertices and `springs`
    /// springs.
    pub fn new(vertices: usize, springs: usize) -> BlockMatrix {
        BlockMatrix {
            diag: vec![Sym3::ZERO; vertices],
            off: vec![Sym3::ZERO; springs],
            couplings: Couplings::default(),
        }
    }

    /// Row i of A x, gathered over the vertex's springs.
    fn row(&self, adj: &Adjacency, x: &[Vec3], i: usize) -> Vec3 {
        let mut acc = self.diag[i] * x[i];
        for k in adj.range(i) {
            acc += self.off[adj.spring[k] as usize] * x[adj.other[k] as usize];
        }
        acc + self.couplings.row(i, x)
    }

    /// y = A x.
    pub fn multiply(&self, adj: &Adjacency, x: &[Vec3], y: &mut [Vec3]) {
        y.par_iter_mut()
            .with_min_len(GRAIN)
            .enumerate()
            .for_each(|(i, yi)| *yi = self.row(adj, x, i));
    }

    /// y = S A x with pinned rows zeroed, returning xᵀy (one pass).
    pub fn multiply_filtered_dot(
        &self,
        adj: &Adjacency,
        pinned: &[bool],
        x: &[Vec3],
        y: &mut [Vec3],
    ) -> f64 {
        y.par_iter_mut()
            .with_min_len(GRAIN)
            .enumerate()
            .map(|(i, yi)| {
                *yi = if pinned[i] {
                    Vec3::ZERO
                } else {
                    self.row(adj, x, i)
                };
                yi.dot(x[i]) as f64
            })
            .sum()
    }
}

/// Scalars of one step.
#[derive(Clone, Copy, Debug)]
pub struct StepParams {
    /// Time step h, s.
    pub dt: f32,
    /// Gravitational acceleration, m/s².
    pub gravity: Vec3,
    /// Rayleigh α (1/s) of D = −αM + βK.
    pub damping_mass: f32,
    /// Rayleigh β (s) of D = −αM + βK.
    pub damping_stiffness: f32,
}

/// Springs and gravity: A's diagonal and spring blocks, and b, from the
/// springs' forces and their blocks K_s, which `a.off` holds on entry
/// (`springs::evaluate`): one array of blocks, not two.
pub fn springs_and_inertia(
    cloth: &Cloth,
    p: &StepParams,
    v: &[Vec3],
    spring_forces: &[Vec3],
    a: &mut BlockMatrix,
    b: &mut [Vec3],
) {
    let h = p.dt;
    let m = cloth.vertex_mass;
    // A_ij = −(h² + hβ) K_s; A_ii = (1 + hα) m I + (h² + hβ) Σ K_s.
    let k_scale = h * h + h * p.damping_stiffness;
    let mass_diag = Sym3::from_diagonal(Vec3::splat((1.0 + h * p.damping_mass) * m));
    let adj = &cloth.adjacency;
    let (diag, spring_blocks) = (&mut a.diag, &a.off);
    diag.par_iter_mut()
        .with_min_len(GRAIN)
        .zip(b.par_iter_mut())
        .enumerate()
        .for_each(|(i, (d, bi))| {
            let mut k_sum = Sym3::ZERO;
            let mut f = m * p.gravity;
            for k in adj.range(i) {
                let s = adj.spring[k] as usize;
                k_sum += spring_blocks[s];
                // spring_forces[s] acts on the spring's first vertex.
                let sign = if cloth.springs[s][0] as usize == i {
                    1.0
                } else {
                    -1.0
                };
                f += sign * spring_forces[s];
            }
            *d = mass_diag + k_scale * k_sum;
            *bi = m * v[i] + h * f;
        });
    a.off
        .par_iter_mut()
        .with_min_len(GRAIN)
        .for_each(|o| *o = -k_scale * *o);
}

/// Adds every contact: b_k += h β_k (f − D_c (v_rel − u)) and
/// A_kl += −β_k β_l (h D_c + h² K_c), the off-diagonal pairs landing on
/// the spring along each edge of the cloth triangle.
pub fn contacts(
    cloth: &Cloth,
    dt: f32,
    v: &[Vec3],
    contacts: &[Contact],
    responses: &[Response],
    a: &mut BlockMatrix,
    b: &mut [Vec3],
) {
    let h = dt;
    for (c, r) in contacts.iter().zip(responses) {
        let block = Sym3::from_mat3(-(h * r.damping + h * h * r.stiffness));
        let cloth_velocity = c.relative_velocity(v) - c.velocity_offset;
        let rhs = h * (r.force - r.damping * cloth_velocity);
        let count = c.vertex_count();
        for k in 0..count {
            let i = c.vertices[k] as usize;
            b[i] += c.beta[k] * rhs;
            a.diag[i] += c.beta[k] * c.beta[k] * block;
        }
        if let Some(t) = c.cloth_triangle {
            let edge_springs = cloth.triangle_springs[t as usize];
            for (e, &s) in edge_springs.iter().enumerate() {
                let (k, l) = (e, (e + 1) % 3);
                a.off[s as usize] += c.beta[k] * c.beta[l] * block;
            }
        }
    }
}
