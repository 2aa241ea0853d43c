// What stage "separate" does to the near pairs that would close below the
// floor: impulses, then impact zones (CPU twin: src/cpu/impact.rs, which
// says why). Part of wgsl/separate.wgsl, whose bindings it reads: the
// steps, flags, counts, labels and fixed-point sums in `separations`.

fn vertex_word(section: u32, i: u32) -> u32 {
    return section * params.n_vertices + i;
}

fn step_word(i: u32, k: u32) -> u32 {
    return SEP_STEP * params.n_vertices + 3u * i + k;
}

fn swept_word(i: u32, k: u32) -> u32 {
    return SEP_SWEPT * params.n_vertices + 3u * i + k;
}

fn sum_word(i: u32, k: u32) -> u32 {
    return SEP_SUM * params.n_vertices + 6u * i + 2u * k;
}

// Vertex i's step, as the failsafe has it.
fn step_of(i: u32) -> vec3<f32> {
    return vec3<f32>(
        bitcast<f32>(atomicLoad(&separations[step_word(i, 0u)])),
        bitcast<f32>(atomicLoad(&separations[step_word(i, 1u)])),
        bitcast<f32>(atomicLoad(&separations[step_word(i, 2u)])),
    );
}

// Vertex i's step when the current detection ran.
fn swept_step(i: u32) -> vec3<f32> {
    return vec3<f32>(
        bitcast<f32>(atomicLoad(&separations[swept_word(i, 0u)])),
        bitcast<f32>(atomicLoad(&separations[swept_word(i, 1u)])),
        bitcast<f32>(atomicLoad(&separations[swept_word(i, 2u)])),
    );
}

fn set_step(i: u32, d: vec3<f32>) {
    atomicStore(&separations[step_word(i, 0u)], bitcast<u32>(d.x));
    atomicStore(&separations[step_word(i, 1u)], bitcast<u32>(d.y));
    atomicStore(&separations[step_word(i, 2u)], bitcast<u32>(d.z));
}

fn flags(i: u32) -> u32 {
    return atomicLoad(&separations[vertex_word(SEP_FLAGS, i)]);
}

// Whether the failsafe may not move vertex i: pinned, or pushed out of the
// body this step (measure.wgsl marks it in its velocity's w) with no
// contact at the step's start to bound it (a vertex with one is kept out
// by `clip`).
fn is_fixed(i: u32) -> bool {
    return is_pinned(i) || (v[i].w != 0.0 && contacts[i].valid == 0u);
}

// The body wins (Impact::clip): step d of vertex i, in contact with the
// body at the step's start (its vertex–face slot), moved out along the
// surface's normal where it would end nearer the moving surface than the
// floor; the vertex is then stopped (FLAG_BODY): no push moves it nearer,
// and its zone moves with the body.
fn clip(i: u32, d: vec3<f32>) -> vec3<f32> {
    let c = contacts[i];
    if c.valid == 0u || is_pinned(i) {
        return d;
    }
    let surface_step = -c.offset * params.dt;
    let along = dot(c.normal, d - surface_step);
    let least = params.self_floor - c.distance;
    if along < least {
        atomicOr(&separations[vertex_word(SEP_FLAGS, i)], FLAG_BODY);
        return d + c.normal * (least - along);
    }
    return d;
}

// x m in fixed point (cpu::impact::to_fixed), as (low word, high word) of
// a two's complement 64-bit integer.
fn to_fixed(x: f32) -> vec2<u32> {
    // Not finite: 0 (a NaN fails every comparison).
    if !(abs(x) <= 0x1.fffffep+127f) {
        return vec2<u32>(0u);
    }
    let w = min(abs(x), FIXED_LARGEST) * FIXED_UNITS;
    let high = trunc(w / FIXED_UNITS);
    let low = w - high * FIXED_UNITS;
    var q = vec2<u32>(u32(low), u32(high));
    if x < 0.0 {
        q = negate(q);
    }
    return q;
}

// A fixed-point integer back in metres (cpu::impact::from_fixed).
fn from_fixed(q: vec2<u32>) -> f32 {
    let negative = bitcast<i32>(q.y) < 0;
    var m = q;
    if negative {
        m = negate(q);
    }
    let x = (f32(m.y) * FIXED_UNITS + f32(m.x)) / FIXED_UNITS;
    return select(x, -x, negative);
}

// −q, wrapping as the CPU's i64 negation does.
fn negate(q: vec2<u32>) -> vec2<u32> {
    return vec2<u32>(~q.x + 1u, ~q.y + select(0u, 1u, q.x == 0u));
}

// Adds q to the 64-bit integer at word `at` (low) and at + 1 (high): the
// low word's carry goes into the high one, so the sum, like the CPU's, does
// not depend on the order of the additions.
fn add_fixed(at: u32, q: vec2<u32>) {
    let old = atomicAdd(&separations[at], q.x);
    let carry = select(0u, 1u, old + q.x < old);
    atomicAdd(&separations[at + 1u], q.y + carry);
}

fn add_fixed3(i: u32, q: array<vec2<u32>, 3>) {
    for (var k = 0u; k < 3u; k++) {
        add_fixed(sum_word(i, k), q[k]);
    }
}

fn read_fixed(at: u32) -> vec2<u32> {
    return vec2<u32>(atomicLoad(&separations[at]), atomicLoad(&separations[at + 1u]));
}

// Vertex i's sum back in metres.
fn sum_of(i: u32) -> vec3<f32> {
    return vec3<f32>(
        from_fixed(read_fixed(sum_word(i, 0u))),
        from_fixed(read_fixed(sum_word(i, 1u))),
        from_fixed(read_fixed(sum_word(i, 2u))),
    );
}

fn clear_sum(i: u32) {
    for (var k = 0u; k < 6u; k++) {
        atomicStore(&separations[SEP_SUM * params.n_vertices + 6u * i + k], 0u);
    }
}

// A failing pair's push (cpu::impact::Push): its free first-side vertices
// each move by `first` times `change`, its free second-side ones by
// −`second` times it, the others (not in `free`) not at all.
struct Push {
    change: vec3<f32>,
    first: u32,
    second: u32,
    free: array<u32, 4>,
    valid: bool,
}

// Whether vertex i may move along `direction` (Impact::free): not fixed,
// and not stopped against the body where that brings it nearer.
fn free_along(i: u32, direction: vec3<f32>) -> bool {
    let stopped = (flags(i) & FLAG_BODY) != 0u;
    let c = contacts[i];
    let into = c.valid != 0u && dot(c.normal, direction) < 0.0;
    return !is_fixed(i) && !(stopped && into);
}

// The push that makes a failing pair pass (Impact::push); not valid where
// it passes or no push can.
fn push_of(p: vec4<u32>, edge: bool, g: Gap) -> Push {
    let none = Push(vec3<f32>(0.0), 0u, 0u, array<u32, 4>(0u, 0u, 0u, 0u), false);
    if touching(g) {
        return none;
    }
    let d = array<vec3<f32>, 4>(step_of(p.x), step_of(p.y), step_of(p.z), step_of(p.w));
    let ids = array<u32, 4>(p.x, p.y, p.z, p.w);
    let split = select(1u, 2u, edge);
    let slabs = array<Slab, 2>(g.nearest, g.plane);
    var best = none;
    var best_t = 0.0;
    var best_n = vec3<f32>(0.0);
    for (var s = 0u; s < 2u; s++) {
        if !usable(slabs[s], s) {
            continue;
        }
        let n = slabs[s].normal;
        var free: array<u32, 4>;
        var free_p = 0u;
        var free_q = 0u;
        for (var k = 0u; k < 4u; k++) {
            let direction = select(-n, n, k < split);
            free[k] = select(0u, 1u, free_along(ids[k], direction));
            if k < split {
                free_p += free[k];
            } else {
                free_q += free[k];
            }
        }
        var first = free_q;
        var second = free_p;
        if free_p == 0u && free_q == 0u {
            first = 0u;
            second = 0u;
        } else if free_p == 0u {
            first = 0u;
            second = 1u;
        } else if free_q == 0u {
            first = 1u;
            second = 0u;
        }
        let allowed = allowance(slabs[s].width);
        let aim = allowed - allowed / 64.0;
        var most = 0.0;
        var t = 0.0;
        var pushable = true;
        for (var a = 0u; a < split; a++) {
            for (var b = split; b < 4u; b++) {
                let approach = dot(n, d[b] - d[a]);
                most = max(most, approach);
                if approach > aim {
                    let rate = f32(free[a] * first + free[b] * second);
                    pushable = pushable && rate > 0.0;
                    t = max(t, (approach - aim) / rate);
                }
            }
        }
        if most <= allowed {
            return none;
        }
        if pushable && (!best.valid || t < best_t) {
            best = Push(vec3<f32>(0.0), first, second, free, true);
            best_t = t;
            best_n = n;
        }
    }
    if !best.valid {
        return none;
    }
    var mean_p = vec3<f32>(0.0);
    var mean_q = vec3<f32>(0.0);
    for (var k = 0u; k < 4u; k++) {
        if k < split {
            mean_p += d[k];
        } else {
            mean_q += d[k];
        }
    }
    let relative = mean_p / f32(split) - mean_q / f32(4u - split);
    let tangential = relative - best_n * dot(best_n, relative);
    let slide = length(tangential);
    var moving_p = 0u;
    var moving_q = 0u;
    for (var k = 0u; k < 4u; k++) {
        if k < split {
            moving_p += best.free[k];
        } else {
            moving_q += best.free[k];
        }
    }
    let rate = f32(moving_p * best.first) / f32(split)
        + f32(moving_q * best.second) / f32(4u - split);
    var friction = vec3<f32>(0.0);
    if slide > 0.0 {
        friction = tangential * (min(slide / rate, params.mu * best_t) / slide);
    }
    best.change = best_n * best_t - friction;
    return best;
}

// A failing pair's push, divided among the most failing pairs at any of
// its vertices, added to their sums (Impact::shares).
fn add_shares(p: vec4<u32>, edge: bool, push: Push) {
    let ids = array<u32, 4>(p.x, p.y, p.z, p.w);
    var most = 0u;
    for (var k = 0u; k < 4u; k++) {
        most = max(most, atomicLoad(&separations[vertex_word(SEP_COUNT, ids[k])]));
    }
    let c = push.change / f32(most);
    let base = array<vec2<u32>, 3>(to_fixed(c.x), to_fixed(c.y), to_fixed(c.z));
    let split = select(1u, 2u, edge);
    for (var k = 0u; k < 4u; k++) {
        if push.free[k] == 0u {
            continue;
        }
        // factor · b as 64-bit integers: the low word's product, and its
        // carry into the high word's.
        let factor = select(push.second, push.first, k < split);
        var q: array<vec2<u32>, 3>;
        for (var j = 0u; j < 3u; j++) {
            q[j] = times(base[j], factor);
            if k >= split {
                q[j] = negate(q[j]);
            }
        }
        add_fixed3(ids[k], q);
    }
}

// The 64-bit integer q times a small factor (at most 3), wrapping as the
// CPU's i64 product does.
fn times(q: vec2<u32>, factor: u32) -> vec2<u32> {
    var out = vec2<u32>(0u);
    for (var k = 0u; k < factor; k++) {
        let low = out.x + q.x;
        out = vec2<u32>(low, out.y + q.y + select(0u, 1u, low < out.x));
    }
    return out;
}
