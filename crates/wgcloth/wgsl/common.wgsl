// Shared by every stage: the run parameters, symmetric 3×3 blocks, and the
// workgroup reduction. Prepended to each stage file when it is compiled.

// Constant over a run. Mirrors `gpu::layout::Params`.
struct Params {
    n_vertices: u32, n_springs: u32, n_triangles: u32, n_rigid_vertices: u32,
    n_rigid_triangles: u32, model: u32, has_rigid: u32, cg_max_iters: u32,
    dt: f32, vertex_mass: f32, stiffness: f32, cg_tol: f32,
    damping_mass: f32, damping_stiffness: f32, thickness: f32, max_depth: f32,
    gravity: vec3<f32>, naive_stiffness: f32,
    force_scale: f32, kn: f32, kd: f32, kt: f32,
    mu: f32, motion_kind: u32, motion_period: f32, motion_phase: f32,
    rigid_position: vec3<f32>, motion_amplitude: f32,
    rigid_rotation: vec4<f32>,
    motion_vector: vec3<f32>, cells_x: u32,
    cells_y: u32, tiles_x: u32, tiles_y: u32, supertiles_x: u32,
    supertiles_y: u32, net_width: u32, net_rows: u32, net_outputs: u32,
    max_speed: f32, springs_at: u32, adjacency_at: u32, pinned_at: u32,
    vertex_triangles_at: u32, spring_triangles_at: u32, body_triangles_at: u32, bvh_order_at: u32,
    // Where parts 1 and 2 of an array bound in parts start (gpu::shaders).
    topology_splits: vec2<u32>, matrix_splits: vec2<u32>, operators_splits: vec2<u32>,
    self_contact: u32, self_gamma: f32, self_floor: f32, self_capacity: u32,
    cloth_thickness: f32, cloth_capacity: u32, rest_spacing: vec2<f32>, cloth_per_vertex: u32, cloth_limit: f32,
    // Substeps of dt per step of solver.dt (Scene::substeps).
    substeps: u32,
}

// The run's constants: group 0, alone, so a pass binds it once and each
// kernel's buffers (group 1) change under it without rebinding it (lavapipe
// recompiles a kernel whenever its uniforms are rebound).
@group(0) @binding(0) var<uniform> params: Params;

// The world this invocation steps: 0 for one scene; in a batch of worlds
// (gpu::worlds) its workgroup's row, set where each entry point starts.
var<private> world: u32;

// Time and run statistics, on the GPU so a step needs no host writes.
// Mirrors `gpu::layout::StepState`.
struct StepState {
    clock: u32,
    steps: u32,
    cg_iterations_total: u32,
    cg_breakdowns: u32,
    cg_residual_max: f32,
    contacts_total: u32,
    contacts_last: atomic<u32>,
    // Bit pattern of a non-negative f32: integer order is float order.
    max_penetration_bits: atomic<u32>,
    last_iterations: u32,
    last_residual: f32,
    // NOT_FINITE | TOO_FAST of wgsl/integrate.wgsl, sticky.
    health: atomic<u32>,
    // Self-contact (separate.wgsl): the most near pairs a detection found,
    // the steps that reached the last resort, the vertex steps it held,
    // the steps whose pairs overflowed the list, the vertex steps the
    // failsafe changed, those impulses changed, impact zones moved and the
    // body stopped, and the detections run.
    self_pairs_max: u32,
    self_fallbacks: u32,
    self_held_total: atomic<u32>,
    self_overflows: u32,
    self_changed_total: atomic<u32>,
    self_pushed_total: atomic<u32>,
    self_zoned_total: atomic<u32>,
    self_stopped_total: atomic<u32>,
    self_detections_total: u32,
    // Stage "self_contact": the most cloth–cloth contacts a step applied,
    // and those left out, summed.
    cloth_contacts_max: u32,
    cloth_contacts_dropped: u32,
    // Which of cg_breakdowns, self_fallbacks and self_overflows this step
    // has counted already (STEP_*): a step counts once, however many of its
    // substeps. Cleared by the step's first solve (pcg.wgsl `finish`).
    step_flags: u32,
}

const STEP_BREAKDOWN: u32 = 1u;
const STEP_FALLBACK: u32 = 2u;
const STEP_OVERFLOW: u32 = 4u;

// `flag` where `happened` is the step's first of it (`flags` being
// StepState.step_flags), else 0.
fn first_in_step(flags: u32, happened: bool, flag: u32) -> u32 {
    return select(0u, flag, happened && (flags & flag) == 0u);
}

// A cloth–cloth contact and what it adds to the system (stage
// "self_contact"; mirrors `gpu::layout::ClothPair`): the force on vertex k
// is β_k f, v_rel = Σ β_k v_k and the gap from the surface to the
// penetrating point Σ β_k x_k; the pair adds β_k β_l B at (k, l) and β_k
// rhs to b.
struct ClothPair {
    // The vertices, EDGE_PAIR on the first of an edge–edge pair (the key
    // pairs are ordered by).
    key: vec4<u32>,
    beta: vec4<f32>,
    rhs: vec3<f32>,
    applied: u32,
    block: PackedSym3,
    // Eq. 8's normal force F_c at the step's start.
    pushes: f32,
    pad: u32,
}

fn pair_vertex(key: vec4<u32>, k: u32) -> u32 {
    return key[k] & ~select(0u, EDGE_PAIR, k == 0u);
}

// Where the contact lists (`cloth_lists`, gpu::constants::cloth_header)
// hold vertex i's contacts found, its contacts listed, and its list's
// entry k (4 · contact + the vertex's slot in it).
fn found_at(i: u32) -> u32 {
    return CLOTH_HEADER + i;
}

fn listed_at(i: u32) -> u32 {
    return CLOTH_HEADER + params.n_vertices + i;
}

fn entry_at(i: u32, k: u32) -> u32 {
    return CLOTH_HEADER + 2u * params.n_vertices + params.cloth_per_vertex * i + k;
}

// A symmetric 3×3 block as the kernels compute with it: a = (xx, yy, zz,
// xy), b = (xz, yz, 0, 0).
struct Sym3 {
    a: vec4<f32>,
    b: vec4<f32>,
}

// A symmetric 3×3 block as buffers hold it: (xx, yy), (zz, xy), (xz, yz).
// Every block of the system matrix is symmetric, so 6 floats (24 bytes)
// instead of 9 keep the SpMV's and the V-cycle's memory traffic down.
struct PackedSym3 {
    xx_yy: vec2<f32>,
    zz_xy: vec2<f32>,
    xz_yz: vec2<f32>,
}

// Threads of a multigrid patch sweep of an nx × ny level: four per patch of
// one colour, ⌈nx / 4⌉ × ⌈ny / 4⌉ patches (multigrid::patch_threads).
fn patch_threads(nx: u32, ny: u32) -> u32 {
    return PATCH * ((nx + 3u) / 4u) * ((ny + 3u) / 4u);
}

fn sym_pack(m: Sym3) -> PackedSym3 {
    return PackedSym3(m.a.xy, m.a.zw, m.b.xy);
}

fn sym_unpack(m: PackedSym3) -> Sym3 {
    return Sym3(vec4<f32>(m.xx_yy, m.zz_xy), vec4<f32>(m.xz_yz, 0.0, 0.0));
}

fn sym_zero() -> Sym3 {
    return Sym3(vec4<f32>(0.0), vec4<f32>(0.0));
}

fn sym_diagonal(s: f32) -> Sym3 {
    return Sym3(vec4<f32>(s, s, s, 0.0), vec4<f32>(0.0));
}

fn sym_outer(d: vec3<f32>) -> Sym3 {
    return Sym3(vec4<f32>(d.x * d.x, d.y * d.y, d.z * d.z, d.x * d.y),
                vec4<f32>(d.x * d.z, d.y * d.z, 0.0, 0.0));
}

fn sym_add(m: Sym3, n: Sym3) -> Sym3 {
    return Sym3(m.a + n.a, m.b + n.b);
}

fn sym_scale(m: Sym3, s: f32) -> Sym3 {
    return Sym3(m.a * s, m.b * s);
}

fn sym_mul(m: Sym3, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(
        m.a.x * v.x + m.a.w * v.y + m.b.x * v.z,
        m.a.w * v.x + m.a.y * v.y + m.b.y * v.z,
        m.b.x * v.x + m.b.y * v.y + m.a.z * v.z,
    );
}

fn sym_diag(m: Sym3) -> vec3<f32> {
    return m.a.xyz;
}

// Contacts live in fixed slots: one per cloth vertex (vertex–face) and one
// per rigid vertex (face–vertex). Mirrors `cpu::collide::Contact`: the
// force on cloth vertex k is β_k f and v_rel = Σ β_k v_k + offset.
struct Contact {
    normal: vec3<f32>,
    depth: f32,
    beta: vec3<f32>,
    distance: f32,
    offset: vec3<f32>,
    valid: u32,
    vertices: vec3<u32>,
    // The cloth triangle (face–vertex) or the rigid triangle (vertex–face).
    triangle: u32,
}

// What a contact adds to the system (mirrors `cpu::contact::Response`):
// force on the penetrating point, K_c = normal_stiffness n nᵀ, and D_c.
struct Response {
    force: vec3<f32>,
    normal_stiffness: f32,
    damping: PackedSym3,
    pad: vec2<f32>,
}


// −(h D_c + h² K_c): the contact's block of A before the β weights.
fn contact_block(r: Response, n: vec3<f32>) -> Sym3 {
    let h = params.dt;
    return sym_scale(sym_add(sym_scale(sym_unpack(r.damping), h), sym_scale(sym_outer(n), h * h * r.normal_stiffness)), -1.0);
}

// The rigid body at the end of the step (written by stage "rigid").
struct RigidFrame {
    rotation: vec4<f32>,
    translation: vec3<f32>,
    pad0: f32,
    velocity: vec3<f32>,
    pad1: f32,
}

// A node of the rigid body's BVH (see src/bvh.rs): a leaf holds `count`
// primitives from `first` in the order array; an internal node has
// count = 0 and children `first`, `first + 1`.
struct BvhNode {
    lo: vec3<f32>,
    first: u32,
    hi: vec3<f32>,
    count: u32,
}

struct Bounds {
    lo: vec4<f32>,
    hi: vec4<f32>,
}

// q v q⁻¹ for a unit quaternion (x, y, z, w).
fn rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

fn inverse_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    return rotate(vec4<f32>(-q.xyz, q.w), v);
}

fn box_near(lo: vec3<f32>, hi: vec3<f32>, p: vec3<f32>, r: f32) -> bool {
    return all(p + r >= lo) && all(p - r <= hi);
}

// The proximity test of thesis 2.3 (mirrors cpu::collide::point_triangle):
// returns (d, w0, w1, w2) when p projects inside triangle (a, b, c) and
// −max_depth < d < thickness; w0 = 2 (impossible weight) otherwise.
fn point_triangle(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>, n: vec3<f32>,
                  thickness: f32, max_depth: f32) -> vec4<f32> {
    let none = vec4<f32>(0.0, 2.0, 0.0, 0.0);
    let d = dot(p - a, n);
    if !(d > -max_depth && d < thickness) {
        return none;
    }
    let e0 = b - a;
    let e1 = c - a;
    let ep = p - a;
    let d00 = dot(e0, e0);
    let d01 = dot(e0, e1);
    let d11 = dot(e1, e1);
    let d20 = dot(ep, e0);
    let d21 = dot(ep, e1);
    let denom = d00 * d11 - d01 * d01;
    if denom <= 1.1920929e-7 * d00 * d11 {
        return none;
    }
    let v = (d11 * d20 - d01 * d21) / denom;
    let w = (d00 * d21 - d01 * d20) / denom;
    let u = 1.0 - v - w;
    if min(u, min(v, w)) < 0.0 || max(u, max(v, w)) > 1.0 {
        return none;
    }
    return vec4<f32>(d, u, v, w);
}

// The point of triangle (a, b, c) nearest to p, by the Voronoi region p
// lies in (mirrors math::closest_on_triangle; Ericson 5.1.5).
fn closest_on_triangle(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec3<f32> {
    let ab = b - a;
    let ac = c - a;
    let d1 = dot(ab, p - a);
    let d2 = dot(ac, p - a);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let d3 = dot(ab, p - b);
    let d4 = dot(ac, p - b);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let d5 = dot(ab, p - c);
    let d6 = dot(ac, p - c);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let inv = 1.0 / (va + vb + vc);
    return a + ab * (vb * inv) + ac * (vc * inv);
}

// The closest points of segments (p1, q1) and (p2, q2), one on each; a
// degenerate segment is its point (mirrors math::closest_between_segments;
// Ericson 5.1.9). Returns them as columns 0 and 1.
fn closest_between_segments(p1: vec3<f32>, q1: vec3<f32>, p2: vec3<f32>, q2: vec3<f32>) -> mat2x3<f32> {
    let st = segment_parameters(p1, q1, p2, q2);
    return mat2x3<f32>(p1 + (q1 - p1) * st.x, p2 + (q2 - p2) * st.y);
}

// The parameters (s, t) of those closest points (mirrors
// math::segment_parameters).
fn segment_parameters(p1: vec3<f32>, q1: vec3<f32>, p2: vec3<f32>, q2: vec3<f32>) -> vec2<f32> {
    let d1 = q1 - p1;
    let d2 = q2 - p2;
    let r = p1 - p2;
    let a = dot(d1, d1);
    let e = dot(d2, d2);
    let f = dot(d2, r);
    // f32::EPSILON and f32::MIN_POSITIVE.
    let tiny = 1.1920929e-7 * max(a + e, 0x1p-126f);
    var s = 0.0;
    var t = 0.0;
    if a <= tiny && e <= tiny {
    } else if a <= tiny {
        t = clamp(f / e, 0.0, 1.0);
    } else {
        let c = dot(d1, r);
        if e <= tiny {
            s = clamp(-c / a, 0.0, 1.0);
        } else {
            let b = dot(d1, d2);
            let denom = a * e - b * b;
            if denom > tiny * max(a, e) {
                s = clamp((b * f - c * e) / denom, 0.0, 1.0);
            }
            t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = clamp(-c / a, 0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = clamp((b - c) / a, 0.0, 1.0);
            }
        }
    }
    return vec2<f32>(s, t);
}

fn found(hit: vec4<f32>) -> bool {
    return hit.y <= 1.0;
}

// Larger d wins, then the lower triangle index (as on the CPU).
fn better(d: f32, t: u32, best_d: f32, best_t: u32) -> bool {
    return best_t == NO_TRIANGLE || d > best_d || (d == best_d && t < best_t);
}
