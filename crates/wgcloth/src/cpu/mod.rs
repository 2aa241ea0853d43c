//! The CPU reference path: each module is one stage of the step, the plain
//! statement of its equation and the twin of the WGSL file of the same name.
//! [`CpuSim`] holds the per-scene state and runs the stages in order.

pub mod assemble;
pub mod body_grid;
pub mod collide;
pub mod contact;
pub mod impact;
pub mod integrate;
pub mod load;
pub mod measure;
pub mod multigrid;
pub mod pcg;
pub mod precondition;
pub mod rigid;
pub mod self_contact;
pub mod separate;
pub mod springs;
pub mod worlds;

#[cfg(not(target_arch = "wasm32"))]
use std::time::Instant;
#[cfg(target_arch = "wasm32")]
use web_time::Instant;

use glam::Vec3;

use crate::bvh::{Bvh, triangle_boxes};
use crate::scene::Scene;
use crate::stage::Stage;
use assemble::StepParams;
use body_grid::BodyGrid;
use collide::{Contact, Tolerances};
use contact::{Model, Response};
use pcg::{BlockMatrix, PcgOutcome, PcgScratch};
use rigid::RigidFrame;

/// What one step did, over its substeps ([`Scene::substeps`]).
#[derive(Clone, Debug, Default)]
pub struct StepStats {
    /// How the step's PCG solves ended: their iterations summed, the worst
    /// residual, any breakdown.
    pub pcg: PcgOutcome,
    /// Contacts found and responded to (both directions), summed.
    pub contacts: usize,
    /// Deepest cloth vertex inside the rigid surface after a solve, m,
    /// before the push-out moved it back onto the surface.
    pub max_penetration: f32,
    /// What self-contact changed (`self_contact` on): the most near pairs
    /// of a detection, the vertices pushed, zoned and held summed, settled
    /// if no substep reached the last resort.
    pub separation: separate::Separation,
    /// Cloth–cloth contacts responded to (`self_contact` with a
    /// thickness), the most of a substep.
    pub self_contacts: usize,
    /// Cloth–cloth contacts dropped at vertices in more than
    /// `self_contact::PAIRS_PER_VERTEX`, summed.
    pub self_contacts_dropped: usize,
    /// Seconds spent in each of [`Stage::ALL`], summed.
    pub stage_seconds: [f64; Stage::ALL.len()],
}

impl StepStats {
    /// Folds in a later substep's (see the fields).
    fn add(&mut self, sub: &StepStats) {
        let (pcg, next) = (&mut self.pcg, &sub.pcg);
        pcg.iterations += next.iterations;
        pcg.relative_residual = pcg.relative_residual.max(next.relative_residual);
        pcg.breakdown |= next.breakdown;
        self.contacts += sub.contacts;
        self.max_penetration = self.max_penetration.max(sub.max_penetration);
        let (sep, next) = (&mut self.separation, &sub.separation);
        sep.pairs = sep.pairs.max(next.pairs);
        sep.changed += next.changed;
        sep.pushed += next.pushed;
        sep.zoned += next.zoned;
        sep.stopped += next.stopped;
        sep.held += next.held;
        sep.detections += next.detections;
        sep.settled &= next.settled;
        self.self_contacts = self.self_contacts.max(sub.self_contacts);
        self.self_contacts_dropped += sub.self_contacts_dropped;
        for (total, s) in self.stage_seconds.iter_mut().zip(&sub.stage_seconds) {
            *total += s;
        }
    }
}

/// Cloth state: positions, velocities, time.
#[derive(Clone, Debug)]
pub struct State {
    /// Vertex positions, m.
    pub x: Vec<Vec3>,
    /// Vertex velocities, m/s.
    pub v: Vec<Vec3>,
    /// Simulated time, s.
    pub time: f64,
    /// Steps taken so far.
    pub step: u64,
    /// Per vertex, the normal force (N) its cloth–cloth contacts carried
    /// in the last step's solve (stage "load"), which bounds the next
    /// step's friction; 0 where it had none, and none at all if empty.
    pub loads: Vec<f32>,
}

impl State {
    /// The cloth at rest, before the first step.
    pub fn initial(scene: &Scene) -> State {
        State {
            x: scene.cloth.rest_positions.clone(),
            v: vec![Vec3::ZERO; scene.cloth.vertex_count()],
            time: 0.0,
            step: 0,
            loads: vec![0.0; scene.cloth.vertex_count()],
        }
    }

    /// Positions `x` and velocities `v` after `step` steps of `dt`,
    /// carrying no contact load.
    pub fn at(x: Vec<Vec3>, v: Vec<Vec3>, step: u64, dt: f32) -> State {
        State {
            loads: vec![0.0; x.len()],
            x,
            v,
            time: step as f64 * dt as f64,
            step,
        }
    }

    /// Moves every vertex `by` metres, each in a fixed, irregular direction
    /// of its own: the start of a sensitivity run, which shows how far
    /// rounding-level differences grow (`wgcloth validate`).
    pub fn nudge(&mut self, by: f32) {
        for (i, x) in self.x.iter_mut().enumerate() {
            let phase = i as f32 * 2.399_963;
            *x += by * Vec3::new(phase.cos(), phase.sin(), (0.5 * phase).cos()).normalize();
        }
    }
}

/// The offset of a sensitivity run's start ([`State::nudge`]), m: a few
/// f32 ulps at 1 m.
pub const PERTURBATION: f32 = 1e-7;

/// The CPU simulator: one scene, its cloth state, the collision model, and
/// what each stage leaves for the next. [`step`](CpuSim::step) runs the
/// stages of [`Stage::ALL`] in order.
pub struct CpuSim {
    /// The scene simulated: cloth, rigid body, configuration, network.
    pub scene: Scene,
    /// The cloth's positions, velocities and time.
    pub state: State,
    /// The collision model, built from the scene's configuration.
    pub model: Model,
    params: StepParams,
    tolerances: Tolerances,
    cloth_bvh: Bvh,
    /// The vertex–face broad phase; `None` without a rigid body.
    body_grid: Option<BodyGrid>,
    frame: RigidFrame,
    contacts: Vec<Contact>,
    responses: Vec<Response>,
    spring_forces: Vec<Vec3>,
    matrix: BlockMatrix,
    rhs: Vec<Vec3>,
    scratch: PcgScratch,
    /// The cloth's edges, for self-contact.
    edges: Vec<[u32; 2]>,
    /// Positions at the start of the step (self-contact only).
    x_start: Vec<Vec3>,
    /// The vertices the body pushed out this step, which stage `separate`
    /// does not move.
    backed: Vec<bool>,
    /// The cloth in its flat rest grid (self-contact forces only).
    rest_grid: Vec<Vec3>,
    /// The last step's cloth–cloth contacts and what each added.
    self_pairs: Vec<self_contact::Pair>,
    self_terms: Vec<self_contact::PairTerm>,
}

impl CpuSim {
    /// A simulator for `scene`, its cloth at rest at time 0.
    pub fn new(scene: Scene) -> CpuSim {
        let cfg = &scene.config;
        let cloth = &scene.cloth;
        let n = cloth.vertex_count();
        let state = State::initial(&scene);
        let params = StepParams {
            dt: scene.substep_dt(),
            gravity: Vec3::from_array(cfg.solver.gravity),
            damping_mass: cfg.cloth.damping_mass,
            damping_stiffness: cfg.cloth.damping_stiffness,
        };
        let tolerances = Tolerances {
            thickness: cfg.contact.thickness,
            max_depth: cfg.contact.max_depth,
        };
        CpuSim {
            model: Model::new(cfg.model, &cfg.contact, scene.network.as_ref()),
            tolerances,
            cloth_bvh: Bvh::build(&triangle_boxes(&cloth.rest_positions, &cloth.triangles)),
            body_grid: (scene.rigid.as_ref()).map(|body| BodyGrid::new(body, tolerances.reach())),
            frame: RigidFrame::default(),
            contacts: Vec::new(),
            responses: Vec::new(),
            spring_forces: vec![Vec3::ZERO; cloth.springs.len()],
            matrix: BlockMatrix::new(n, cloth.springs.len()),
            rhs: vec![Vec3::ZERO; n],
            scratch: PcgScratch::default(),
            edges: if cfg.self_contact.enabled {
                separate::triangle_edges(&cloth.triangles)
            } else {
                Vec::new()
            },
            x_start: Vec::new(),
            backed: vec![false; n],
            rest_grid: if cfg.self_contact.enabled && cfg.self_contact.thickness > 0.0 {
                self_contact::rest_grid(cloth)
            } else {
                Vec::new()
            },
            self_pairs: Vec::new(),
            self_terms: Vec::new(),
            params,
            state,
            scene,
        }
    }

    /// The contacts the last step responded to.
    pub fn contacts(&self) -> &[Contact] {
        &self.contacts
    }

    /// The responses of the last step's contacts, in the same order.
    pub fn responses(&self) -> &[Response] {
        &self.responses
    }

    /// The last step's cloth–cloth contacts and what each added to the
    /// system, in the same order.
    pub fn self_contacts(&self) -> (&[self_contact::Pair], &[self_contact::PairTerm]) {
        (&self.self_pairs, &self.self_terms)
    }

    /// The system the last step solved.
    pub fn system(&self) -> (&BlockMatrix, &[Vec3]) {
        (&self.matrix, &self.rhs)
    }

    /// The rigid body as placed by the last step.
    pub fn rigid_frame(&self) -> Option<&RigidFrame> {
        self.scene.rigid.as_ref().map(|_| &self.frame)
    }

    /// One step of `solver.dt`: [`Scene::substeps`] backward Euler steps
    /// of [`Scene::substep_dt`], each every stage in order. Each first
    /// moves the rigid body to its end, so contacts are found against
    /// where it will be. The stats sum the substeps' counts and take their
    /// worst.
    pub fn step(&mut self) -> StepStats {
        let mut stats: Option<StepStats> = None;
        // One hand-over to the pool for the whole step (see `run_stage`).
        rayon::scope(|_| {
            for _ in 0..self.scene.substeps {
                let mut sub = StepStats::default();
                for stage in Stage::ALL {
                    let start = Instant::now();
                    self.run_stage_on_pool(stage, &mut sub);
                    sub.stage_seconds[stage.index()] = start.elapsed().as_secs_f64();
                }
                sub.contacts = self.contacts.len();
                self.state.time += self.params.dt as f64;
                match &mut stats {
                    Some(stats) => stats.add(&sub),
                    None => stats = Some(sub),
                }
            }
        });
        self.state.step += 1;
        stats.expect("a scene takes at least one substep")
    }

    /// Runs one stage of the current step on what the earlier stages left
    /// (the per-stage benches time them one by one); `step` runs them all.
    pub fn run_stage(&mut self, stage: Stage, stats: &mut StepStats) {
        // On a pool thread a pass shorter than its grain runs in place;
        // from another thread each one would be handed over and waited for.
        rayon::scope(|_| self.run_stage_on_pool(stage, stats));
    }

    fn run_stage_on_pool(&mut self, stage: Stage, stats: &mut StepStats) {
        let cloth = &self.scene.cloth;
        let h = self.params.dt;
        let State { x, v, loads, .. } = &mut self.state;
        let body = &self.scene.rigid;
        match stage {
            Stage::Rigid => {
                if let Some(body) = body {
                    let t_end = (self.state.time + h as f64) as f32;
                    rigid::transform(body, t_end, &mut self.frame);
                }
            }
            Stage::Collide => {
                self.contacts.clear();
                if let Some(grid) = &self.body_grid {
                    collide::refit_cloth(cloth, &mut self.cloth_bvh, x);
                    self.contacts = collide::vertex_face(grid, &self.frame, x, self.tolerances);
                    self.contacts.extend(collide::face_vertex(
                        cloth,
                        &self.cloth_bvh,
                        x,
                        &self.frame,
                        self.tolerances,
                    ));
                }
            }
            Stage::Contact => {
                let frame = &self.frame;
                let geometry = |c: &Contact| {
                    let body = body.as_ref().expect("contacts need a rigid body");
                    c.geometry(cloth, body, frame, x)
                };
                contact::respond(
                    &self.model,
                    &self.contacts,
                    v,
                    geometry,
                    &mut self.responses,
                );
            }
            Stage::Assemble => {
                // Each K_s goes where A's block for its spring will be.
                springs::evaluate(cloth, x, &mut self.spring_forces, &mut self.matrix.off);
                assemble::springs_and_inertia(
                    cloth,
                    &self.params,
                    v,
                    &self.spring_forces,
                    &mut self.matrix,
                    &mut self.rhs,
                );
                assemble::contacts(
                    cloth,
                    h,
                    v,
                    &self.contacts,
                    &self.responses,
                    &mut self.matrix,
                    &mut self.rhs,
                );
            }
            Stage::SelfContact => {
                let keep = &self.scene.config.self_contact;
                self.self_pairs.clear();
                self.self_terms.clear();
                if keep.enabled && keep.thickness > 0.0 {
                    if body.is_none() {
                        // Collide refits it when there is a body.
                        collide::refit_cloth(cloth, &mut self.cloth_bvh, x);
                    }
                    let sheet = self_contact::Sheet::new(
                        &cloth.triangles,
                        &self.edges,
                        &self.rest_grid,
                        keep.thickness,
                    );
                    let found = sheet.find(x, &self.cloth_bvh, self_contact::PAIRS_PER_VERTEX);
                    let band = self_contact::Band {
                        coefficients: self.scene.config.contact.coefficients(),
                        thickness: keep.thickness,
                        h,
                        limit: keep.mass_ratio * cloth.vertex_mass,
                        vertex_mass: cloth.vertex_mass,
                    };
                    // A state set without its loads carries none.
                    loads.resize(x.len(), 0.0);
                    self.self_terms =
                        self_contact::respond(&found.pairs, &found.counts, loads, x, v, &band);
                    self.self_pairs = found.pairs;
                    self_contact::add_to_system(
                        &self.self_pairs,
                        &self.self_terms,
                        &mut self.matrix.diag,
                        &mut self.rhs,
                    );
                    stats.self_contacts = self.self_pairs.len();
                    stats.self_contacts_dropped = found.dropped;
                }
                self.matrix.couplings =
                    self_contact::Couplings::new(x.len(), &self.self_pairs, &self.self_terms);
            }
            Stage::Pcg => {
                // v holds the initial guess (last velocity; pinned entries are 0).
                let cfg = &self.scene.config.solver;
                let settings = pcg::SolveSettings {
                    max_iters: cfg.cg_iters,
                    tol: cfg.cg_tol,
                    preconditioner: cfg.preconditioner,
                    smoother: cfg.smoother,
                };
                stats.pcg = pcg::solve(
                    &self.matrix,
                    cloth,
                    &self.rhs,
                    v,
                    settings,
                    &mut self.scratch,
                );
            }
            Stage::Load => {
                loads.resize(x.len(), 0.0);
                load::carry(&self.self_pairs, &self.self_terms, (x, v), h, loads);
            }
            Stage::Integrate => {
                if self.scene.config.self_contact.enabled {
                    self.x_start.clone_from(x);
                }
                integrate::integrate(cloth, h, x, v)
            }
            Stage::Measure => {
                if let Some(body) = body {
                    self.backed.fill(false);
                    stats.max_penetration = measure::push_out(
                        body,
                        &self.frame,
                        self.tolerances.thickness,
                        &cloth.pinned,
                        (x, v),
                        &mut self.backed,
                    );
                }
            }
            Stage::Separate => {
                let keep = &self.scene.config.self_contact;
                if keep.enabled {
                    let body = impact::body_gaps(&self.contacts, &cloth.pinned, h);
                    // A vertex pushed out with no contact at the start has
                    // no plane to be kept out of the body by: it stays.
                    let fixed: Vec<bool> = (0..body.len())
                        .map(|i| cloth.pinned[i] || (self.backed[i] && body[i].is_none()))
                        .collect();
                    let within = separate::Within {
                        triangles: &cloth.triangles,
                        edges: &self.edges,
                        keep,
                        mu: self.scene.config.contact.mu,
                        fixed: &fixed,
                        body: &body,
                        h,
                    };
                    // Collide refits the BVH to where the next step starts.
                    stats.separation = within.keep_apart(&self.x_start, x, v, &mut self.cloth_bvh);
                }
            }
        }
    }

    /// Kinetic, gravitational and elastic energy (J), in f64.
    pub fn energy(&self) -> Energy {
        energy(&self.scene, &self.state.x, &self.state.v)
    }

    /// True when every position and velocity is finite.
    pub fn is_finite(&self) -> bool {
        self.state
            .x
            .iter()
            .chain(&self.state.v)
            .all(|p| p.is_finite())
    }
}

/// Kinetic, gravitational and elastic energy (J) of a cloth state, in f64.
pub fn energy(scene: &Scene, x: &[Vec3], v: &[Vec3]) -> Energy {
    let cloth = &scene.cloth;
    let m = cloth.vertex_mass as f64;
    let g = Vec3::from_array(scene.config.solver.gravity).as_dvec3();
    Energy {
        kinetic: v
            .iter()
            .map(|v| 0.5 * m * v.as_dvec3().length_squared())
            .sum(),
        gravity: x.iter().map(|x| -m * g.dot(x.as_dvec3())).sum(),
        elastic: springs::potential_energy(cloth, x),
    }
}

/// The energy of a cloth state, J, in f64.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Energy {
    /// Σ ½ m |v|².
    pub kinetic: f64,
    /// Gravitational potential Σ −m g·x (zero at the origin).
    pub gravity: f64,
    /// Elastic potential of the springs, Σ ½ E (l − L)².
    pub elastic: f64,
}

impl Energy {
    /// Kinetic + gravitational + elastic, J.
    pub fn total(&self) -> f64 {
        self.kinetic + self.gravity + self.elastic
    }
}
