// Includes: topology, response.
// Stage "contact": each contact's force and Jacobian blocks from the
// selected model. CPU twin: src/cpu/contact.rs (same equations, same
// branch structure). The network models gather the step's contacts into a
// batch (`gather`), run the network over it (stages "batch" and "mlp") and
// read its outputs back into responses (`respond_batch`).

@group(1) @binding(1) var<storage, read> v: array<vec4<f32>>;
// Contact slots and their responses: one per cloth vertex (vertex–face),
// then one per rigid vertex (face–vertex).
@group(1) @binding(2) var<storage, read> contacts: array<Contact>;
@group(1) @binding(3) var<storage, read_write> responses: array<Response>;
// The naive network's geometry: cloth positions and the placed rigid body
// (vertices, then normals); the triangles are in `topology`.
@group(1) @binding(4) var<storage, read> x: array<vec4<f32>>;
@group(1) @binding(5) var<storage, read> rigid: array<vec4<f32>>;
// The batch: its size, then each entry's contact slot; the network inputs
// [entry × width] and outputs [entry × R × net_outputs]: row 0 the output,
// row 1 + t its derivative along input wrt_start + t. A friction network
// has frame_rows() entries per contact: at +slide, −slide (and 0).
@group(1) @binding(6) var<storage, read_write> net_batch: array<atomic<u32>>;
@group(1) @binding(7) var<storage, read_write> net_inputs: array<f32>;
@group(1) @binding(8) var<storage, read> net_outputs: array<f32>;

// A batch entry names contact slot s of world w as w × world_slots() + s,
// so one network batch serves every world of a batch (gpu::worlds).
fn world_slots() -> u32 {
    return params.n_vertices + params.n_rigid_vertices;
}

// Naive penalty (thesis eq. 6): f = −c_n d̃ n = −c_n c.
fn naive(c: vec3<f32>) -> ForceJacobian {
    let k = params.naive_stiffness;
    return ForceJacobian(-k * c, -k * IDENTITY, ZERO3);
}

fn evaluate(c: vec3<f32>, v_rel: vec3<f32>) -> ForceJacobian {
    if params.model == MODEL_NAIVE {
        return naive(c);
    }
    let g = friction(c, v_rel, Coefficients(params.kn, params.kd, params.kt, params.mu));
    let s = params.force_scale;
    return ForceJacobian(s * g.force, s * g.d_c, s * g.d_v);
}

fn relative_velocity(c: Contact) -> vec3<f32> {
    return c.offset + c.beta.x * v[c.vertices.x].xyz + c.beta.y * v[c.vertices.y].xyz
        + c.beta.z * v[c.vertices.z].xyz;
}

fn respond(c: Contact) -> Response {
    let v_rel = relative_velocity(c);
    return response(evaluate(c.normal * c.depth, v_rel), c.normal, v_rel, 0.0);
}

// The analytic models: every contact slot, both directions, in one pass.
@compute @workgroup_size(WORKGROUP)
fn respond_slots(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = id.x;
    if s < params.n_vertices + params.n_rigid_vertices && contacts[s].valid != 0u {
        responses[s] = respond(contacts[s]);
    }
}

// --- The network models (thesis 2.4, 2.7). ---

// The naive network's local frame (mirrors cpu::contact::local_frame): the
// contact's triangle wound along its normal, a at the origin, b on +x, the
// triangle in the xy-plane; the point moved by ε against the normal.
struct LocalFrame {
    rotation: mat3x3<f32>,
    b: vec3<f32>,
    c: vec3<f32>,
    p: vec3<f32>,
    valid: bool,
}

fn local_frame(s: u32, k: Contact) -> LocalFrame {
    var tri: array<vec3<f32>, 3>;
    var point: vec3<f32>;
    if s < params.n_vertices {
        for (var i = 0u; i < 3u; i++) {
            tri[i] = rigid[body_index(3u * k.triangle + i)].xyz;
        }
        point = x[s].xyz;
    } else {
        for (var i = 0u; i < 3u; i++) {
            tri[i] = x[cloth_index(3u * k.triangle + i)].xyz;
        }
        point = rigid[s - params.n_vertices].xyz;
    }
    var a = tri[0];
    var b = tri[1];
    var c = tri[2];
    if dot(cross(b - a, c - a), k.normal) < 0.0 {
        b = tri[2];
        c = tri[1];
    }
    point -= (k.distance - k.depth) * k.normal;
    let ab = b - a;
    let normal = cross(ab, c - a);
    var f: LocalFrame;
    f.valid = dot(ab, ab) > 0.0 && dot(normal, normal) > 0.0;
    if !f.valid {
        return f;
    }
    let e1 = normalize(ab);
    let e3 = normalize(normal);
    f.rotation = transpose(mat3x3<f32>(e1, cross(e3, e1), e3));
    f.b = f.rotation * ab;
    f.c = f.rotation * (c - a);
    f.p = f.rotation * (point - a);
    return f;
}


// A contact in its own frame (mirrors cpu::contact::ContactFrame); depth 0
// has no frame.
struct ContactFrame {
    c_hat: vec3<f32>,
    t_hat: vec3<f32>,
    t_dot: vec3<f32>,
    depth: f32,
    approach: f32,
    slide: f32,
}

fn contact_frame(c: vec3<f32>, v: vec3<f32>) -> ContactFrame {
    var f: ContactFrame;
    f.depth = length(c);
    if f.depth == 0.0 {
        return f;
    }
    f.c_hat = c / f.depth;
    f.approach = dot(v, f.c_hat);
    f.t_dot = v - f.approach * f.c_hat;
    f.slide = length(f.t_dot);
    if f.slide > SLIDE_AT_REST {
        f.t_hat = f.t_dot / f.slide;
    }
    return f;
}

// Gradients wrt c and v of a function of (depth, approach, slide) with
// partial derivatives d.
fn frame_grad_c(f: ContactFrame, d: vec3<f32>) -> vec3<f32> {
    return d.x * f.c_hat + (d.y / f.depth) * f.t_dot - (d.z * f.approach / f.depth) * f.t_hat;
}

fn frame_grad_v(f: ContactFrame, d: vec3<f32>) -> vec3<f32> {
    return d.y * f.c_hat + d.z * f.t_hat;
}

// Empties the network batch.
@compute @workgroup_size(1)
fn reset_batch() {
    atomicStore(&net_batch[0], 0u);
}

// Appends every valid contact to the batch with its network inputs.
@compute @workgroup_size(WORKGROUP)
fn gather(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = id.x;
    if s >= params.n_vertices + params.n_rigid_vertices {
        return;
    }
    let k = contacts[s];
    if k.valid == 0u {
        return;
    }
    if framed() {
        // Rows at +slide, −slide and (contact-frame network) slide 0
        // (ContactFrame::inputs).
        let entry = atomicAdd(&net_batch[0], frame_rows());
        let f = contact_frame(k.normal * k.depth, relative_velocity(k));
        let slides = array<f32, CONTACT_FRAME_ROWS>(f.slide, -f.slide, 0.0);
        let c = f.depth * f.c_hat;
        for (var r = 0u; r < frame_rows(); r++) {
            atomicStore(&net_batch[1u + entry + r], world * world_slots() + s);
            let base = (entry + r) * params.net_width;
            if params.model == MODEL_FRICTION_CONTACT_NET {
                let row = array<f32, 7>(f.depth, f.approach, slides[r], params.kn, params.kd, params.kt, params.mu);
                for (var i = 0u; i < 7u; i++) {
                    net_inputs[base + i] = row[i];
                }
            } else {
                let v = f.approach * f.c_hat + slides[r] * f.t_hat;
                let row = array<f32, 10>(c.x, c.y, c.z, v.x, v.y, v.z,
                                         params.kn, params.kd, params.kt, params.mu);
                for (var i = 0u; i < 10u; i++) {
                    net_inputs[base + i] = row[i];
                }
            }
        }
        return;
    }
    let entry = atomicAdd(&net_batch[0], 1u);
    atomicStore(&net_batch[1u + entry], world * world_slots() + s);
    let base = entry * params.net_width;
    let f = local_frame(s, k);
    let row = array<f32, 7>(f.b.x, f.c.x, f.c.y, 0.0, f.p.x, f.p.y, f.p.z);
    for (var i = 0u; i < 7u; i++) {
        net_inputs[base + i] = row[i];
    }
}

// Whether the model's network is a friction network, evaluated in the
// contact frame at `frame_rows()` rows a contact.
fn framed() -> bool {
    return params.model == MODEL_FRICTION_CONTACT_NET || params.model == MODEL_FRICTION_NET;
}

// NetKind::evaluations of a friction network.
fn frame_rows() -> u32 {
    return select(WORLD_FRAME_ROWS, CONTACT_FRAME_ROWS, params.model == MODEL_FRICTION_CONTACT_NET);
}

// Row `row` of a batch entry's outputs (three of them).
fn output_row(entry: u32, row: u32) -> vec3<f32> {
    let o = params.net_outputs * (entry * params.net_rows + row);
    return vec3<f32>(net_outputs[o], net_outputs[o + 1u], net_outputs[o + 2u]);
}

// Row `row` of a contact-frame entry's outputs (g_n, g_t).
fn output_pair(entry: u32, row: u32) -> vec2<f32> {
    let o = params.net_outputs * (entry * params.net_rows + row);
    return vec2<f32>(net_outputs[o], net_outputs[o + 1u]);
}

// A friction network's row in the contact frame: (g_n, g_t) and their
// derivatives along (depth, approach, slide).
struct FrameRow {
    y: vec2<f32>,
    d: array<vec2<f32>, 3>,
}

// Batch entry `entry` read in frame f (ContactFrame::network_force): the
// contact-frame network's outputs as they are; the world-frame network's g
// along n and t̂, its Jacobian along ĉ (depth and approach) and t̂ (slide),
// at rest the slide's along the tangent plane's mean
// (ContactFrame::read_world_rows).
fn frame_row(entry: u32, f: ContactFrame) -> FrameRow {
    var row: FrameRow;
    if params.model == MODEL_FRICTION_CONTACT_NET {
        row.y = output_pair(entry, 0u);
        for (var t = 0u; t < 3u; t++) {
            row.d[t] = output_pair(entry, 1u + t);
        }
        return row;
    }
    let g = output_row(entry, 0u);
    let j_c = output_jacobian(entry, 1u);
    let j_v = output_jacobian(entry, 4u);
    row.y = vec2<f32>(-dot(f.c_hat, g), dot(f.t_hat, g));
    let along = array<vec3<f32>, 3>(j_c * f.c_hat, j_v * f.c_hat, j_v * f.t_hat);
    for (var t = 0u; t < 3u; t++) {
        row.d[t] = vec2<f32>(-dot(f.c_hat, along[t]), dot(f.t_hat, along[t]));
    }
    if f.slide <= SLIDE_AT_REST {
        row.d[2].y = 0.5 * (j_v[0].x + j_v[1].y + j_v[2].z - dot(f.c_hat, j_v * f.c_hat));
    }
    return row;
}

// ln(1 + e^y) (cpu::contact::softplus).
fn softplus(y: f32) -> f32 {
    return max(y, 0.0) + log(1.0 + exp(-abs(y)));
}

// A value and its gradient in (depth, approach, slide).
struct Graded {
    y: f32,
    d: vec3<f32>,
}

// The contact-frame network's outputs in the form of eqs. 8–9's cone
// (cpu::contact::cone): g_n = L softplus(y_n) with L = k_n r + k_d max(a, 0),
// g_t = −min(k_t e^w s, μ g_n). Returns (g_n, g_t).
fn cone(normal: Graded, rate: Graded, f: ContactFrame) -> array<Graded, 2> {
    let load = params.kn * f.depth + params.kd * max(f.approach, 0.0);
    let d_load = vec3<f32>(params.kn, select(0.0, params.kd, f.approach > 0.0), 0.0);
    let share = softplus(normal.y);
    let g_n = Graded(load * share, share * d_load + (load / (1.0 + exp(-normal.y))) * normal.d);
    var w = rate;
    if w.y > STICK_LOG_MAX {
        w = Graded(STICK_LOG_MAX, vec3<f32>(0.0));
    }
    let stick = params.kt * exp(w.y);
    let cap = params.mu * g_n.y;
    var g_t = Graded(-cap, -params.mu * g_n.d);
    if stick * f.slide <= cap {
        g_t = Graded(-stick * f.slide, -stick * (vec3<f32>(0.0, 0.0, 1.0) + f.slide * w.d));
    }
    return array<Graded, 2>(g_n, g_t);
}

// g and its Jacobians from a friction network's entries `entry` (+slide),
// `entry + 1` (−slide) and, for the contact-frame network, `entry + 2`
// (slide 0): mirrors ContactFrame::force.
fn contact_net_force(entry: u32, c: vec3<f32>, v: vec3<f32>) -> ForceJacobian {
    let f = contact_frame(c, v);
    if f.depth == 0.0 {
        return ForceJacobian(vec3<f32>(0.0), ZERO3, ZERO3);
    }
    let plus = frame_row(entry, f);
    let minus = frame_row(entry + 1u, f);
    // Even and odd parts in the slide; the mirror's slide derivative flips.
    var even: array<Graded, 2>;
    var odd = Graded(0.5 * (plus.y.y - minus.y.y), vec3<f32>(0.0));
    for (var o = 0u; o < 2u; o++) {
        even[o].y = 0.5 * (plus.y[o] + minus.y[o]);
    }
    for (var t = 0u; t < 3u; t++) {
        let b = select(1.0, -1.0, t == 2u) * minus.d[t];
        odd.d[t] = 0.5 * (plus.d[t].y - b.y);
        even[0].d[t] = 0.5 * (plus.d[t].x + b.x);
        even[1].d[t] = 0.5 * (plus.d[t].y + b.y);
    }
    var g_n: f32;
    var d_gn: vec3<f32>;
    var g_t: f32;
    var d_gt: vec3<f32>;
    if frame_rows() == CONTACT_FRAME_ROWS {
        let still = frame_row(entry + 2u, f);
        let held = cone(Graded(still.y.x, vec3<f32>(still.d[0].x, still.d[1].x, 0.0)), even[1], f);
        g_n = held[0].y;
        d_gn = held[0].d;
        g_t = held[1].y;
        d_gt = held[1].d;
    } else {
        // Inside the friction cone (cpu::contact::coulomb): g_n ≥ 0, |g_t| ≤ μ g_n.
        g_n = even[0].y;
        d_gn = even[0].d;
        g_t = odd.y;
        d_gt = odd.d;
        if g_n <= 0.0 {
            g_n = 0.0;
            g_t = 0.0;
            d_gn = vec3<f32>(0.0);
            d_gt = vec3<f32>(0.0);
        }
        let cap = params.mu * g_n;
        if abs(g_t) > cap {
            let side = sign(g_t);
            g_t = side * cap;
            d_gt = side * params.mu * d_gn;
        }
    }
    let p = IDENTITY - outer(f.c_hat, f.c_hat);
    let n = -f.c_hat;
    var ratio = d_gt.z;
    if f.slide > SLIDE_AT_REST {
        ratio = g_t / f.slide;
    }
    let turn = ratio * (IDENTITY - outer(f.t_hat, f.t_hat));
    let dt_dc = (-1.0 / f.depth) * (f.approach * p + outer(f.c_hat, f.t_dot));
    let sc = params.force_scale;
    return ForceJacobian(
        sc * (g_n * n + g_t * f.t_hat),
        sc * (outer(n, frame_grad_c(f, d_gn)) - (g_n / f.depth) * p
              + outer(f.t_hat, frame_grad_c(f, d_gt)) + turn * dt_dc),
        sc * (outer(n, frame_grad_v(f, d_gn)) + outer(f.t_hat, frame_grad_v(f, d_gt)) + turn * p),
    );
}

// The Jacobian whose column j is output row first + j.
fn output_jacobian(entry: u32, first: u32) -> mat3x3<f32> {
    return mat3x3<f32>(output_row(entry, first), output_row(entry, first + 1u),
                       output_row(entry, first + 2u));
}

// The network's force and Jacobians for batch entry `entry` (mirrors
// cpu::contact::friction_net and naive_net, scaled to force units).
fn network_force(entry: u32, s: u32, k: Contact, v_rel: vec3<f32>) -> ForceJacobian {
    if framed() {
        return contact_net_force(entry, k.normal * k.depth, v_rel);
    }
    let g = output_row(entry, 0u);
    let f = local_frame(s, k);
    if !f.valid {
        return ForceJacobian(vec3<f32>(0.0), ZERO3, ZERO3);
    }
    let back = transpose(f.rotation);
    let st = params.naive_stiffness;
    return ForceJacobian(st * (back * g), st * (back * output_jacobian(entry, 1u) * f.rotation), ZERO3);
}

// Responses from the network's outputs.
@compute @workgroup_size(WORKGROUP)
fn respond_batch(@builtin(global_invocation_id) id: vec3<u32>) {
    let entry = id.x;
    // A contact-frame contact's later entries are read with its first.
    let second = framed() && entry % frame_rows() != 0u;
    if entry >= atomicLoad(&net_batch[0]) || second {
        return;
    }
    // One thread per entry of every world's: the entry names its world.
    let named = atomicLoad(&net_batch[1u + entry]);
    world = named / world_slots();
    let s = named % world_slots();
    let k = contacts[s];
    let v_rel = relative_velocity(k);
    let r = response(network_force(entry, s, k, v_rel), k.normal, v_rel, 0.0);
    responses[s] = r;
}
