// Stage "separate": each cloth vertex's least separation from the cloth
// primitives it could reach, for the bound on its step that keeps the cloth
// from passing through itself (issue 23; integrate.wgsl applies it).
// CPU twin: src/cpu/separate.rs, which finds the same least separations.
//
// Vertex–triangle and edge–edge pairs sharing no vertex, within the step's
// reach (self_reach: the radius, or farther when the longest solved step
// needs it). The broad phase is collide's tile hierarchy over the
// cloth grid (refitted this step): a query box walks the super-tiles and
// tiles it overlaps, then the cells whose box (of their four corners) it
// overlaps, and tests the cell's two triangles. A pair lowers the
// separation of its four vertices by an atomic minimum over the bits of a
// non-negative f32, which order as the floats do: the result does not
// depend on the order pairs are met in.

@group(1) @binding(1) var<storage, read> x: array<vec4<f32>>;
@group(1) @binding(2) var<storage, read> v: array<vec4<f32>>;
// The tiles' bounds, then the super-tiles' (collide.wgsl refits them).
@group(1) @binding(6) var<storage, read> bounds: array<Bounds>;
// Per vertex, its least separation's bits; then the step's longest
// stride |h v'|'s (zeroed before the pass).
@group(1) @binding(10) var<storage, read_write> separations: array<atomic<u32>>;

fn overlaps(lo: vec3<f32>, hi: vec3<f32>, b_lo: vec3<f32>, b_hi: vec3<f32>) -> bool {
    return all(lo <= b_hi) && all(b_lo <= hi);
}

fn note(q: Query, vertices: vec4<u32>, s: f32) {
    if s < q.reach {
        let bits = bitcast<u32>(s);
        atomicMin(&separations[vertices.x], bits);
        atomicMin(&separations[vertices.y], bits);
        atomicMin(&separations[vertices.z], bits);
        atomicMin(&separations[vertices.w], bits);
    }
}

// A query: vertex `a` (edge false) or the edge (a, b), a < b, the box
// around it grown by the step's reach, and the reach.
struct Query {
    lo: vec3<f32>,
    a: u32,
    hi: vec3<f32>,
    b: u32,
    edge: bool,
    reach: f32,
}

fn reach() -> f32 {
    return self_reach(bitcast<f32>(atomicLoad(&separations[params.n_vertices])));
}

// The query against cloth triangle t: the vertex against the triangle, or
// the edge against each of its edges above it (each pair from its lower
// edge, as on the CPU; met twice, from both triangles along the other
// edge, the minimum minds not).
fn against(q: Query, t: u32) {
    let tri = vec3<u32>(cloth_index(3u * t), cloth_index(3u * t + 1u), cloth_index(3u * t + 2u));
    if !q.edge {
        if any(tri == vec3<u32>(q.a)) {
            return;
        }
        let p = x[q.a].xyz;
        let c = closest_on_triangle(p, x[tri.x].xyz, x[tri.y].xyz, x[tri.z].xyz);
        note(q, vec4<u32>(q.a, tri), length(p - c));
        return;
    }
    for (var k = 0u; k < 3u; k++) {
        let u = tri[k];
        let w = tri[(k + 1u) % 3u];
        let f = vec2<u32>(min(u, w), max(u, w));
        let above = f.x > q.a || (f.x == q.a && f.y > q.b);
        let apart = f.x != q.a && f.x != q.b && f.y != q.a && f.y != q.b;
        if above && apart {
            let m = closest_between_segments(x[q.a].xyz, x[q.b].xyz, x[f.x].xyz, x[f.y].xyz);
            note(q, vec4<u32>(q.a, q.b, f), length(m[0] - m[1]));
        }
    }
}

// Every cloth triangle in a cell whose box the query's overlaps.
fn walk(q: Query) {
    let nx = params.cells_x + 1u;
    let tiles = params.tiles_x * params.tiles_y;
    for (var s = 0u; s < params.supertiles_x * params.supertiles_y; s++) {
        let sb = bounds[tiles + s];
        if !overlaps(q.lo, q.hi, sb.lo.xyz, sb.hi.xyz) {
            continue;
        }
        let sx = s % params.supertiles_x;
        let sy = s / params.supertiles_x;
        for (var ty = sy * TILE; ty < min(sy * TILE + TILE, params.tiles_y); ty++) {
            for (var tx = sx * TILE; tx < min(sx * TILE + TILE, params.tiles_x); tx++) {
                let tb = bounds[ty * params.tiles_x + tx];
                if !overlaps(q.lo, q.hi, tb.lo.xyz, tb.hi.xyz) {
                    continue;
                }
                for (var cy = ty * TILE; cy < min(ty * TILE + TILE, params.cells_y); cy++) {
                    for (var cx = tx * TILE; cx < min(tx * TILE + TILE, params.cells_x); cx++) {
                        let k = cy * nx + cx;
                        let p00 = x[k].xyz;
                        let p10 = x[k + 1u].xyz;
                        let p01 = x[k + nx].xyz;
                        let p11 = x[k + nx + 1u].xyz;
                        let lo = min(min(p00, p10), min(p01, p11));
                        let hi = max(max(p00, p10), max(p01, p11));
                        if overlaps(q.lo, q.hi, lo, hi) {
                            let t = 2u * (cy * params.cells_x + cx);
                            against(q, t);
                            against(q, t + 1u);
                        }
                    }
                }
            }
        }
    }
}

// Every vertex starts with nothing near (+∞), and the step's longest
// stride is taken.
@compute @workgroup_size(WORKGROUP)
fn prepare(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i < params.n_vertices {
        atomicStore(&separations[i], 0x7f800000u);
        atomicMax(&separations[params.n_vertices], bitcast<u32>(length(params.dt * v[i].xyz)));
    }
}

// Each vertex against the triangles within the radius.
@compute @workgroup_size(WORKGROUP)
fn vertices(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if i >= params.n_vertices {
        return;
    }
    let p = x[i].xyz;
    let r = reach();
    walk(Query(p - r, i, p + r, i, false, r));
}

// Each triangle edge (a spring along a triangle) against the edges within
// the radius.
@compute @workgroup_size(WORKGROUP)
fn edges(@builtin(global_invocation_id) id: vec3<u32>) {
    let s = id.x;
    if s >= params.n_springs || spring_triangles(s).x == NO_TRIANGLE {
        return;
    }
    let ends = spring_ends(s);
    let a = min(ends.x, ends.y);
    let b = max(ends.x, ends.y);
    let r = reach();
    let lo = min(x[a].xyz, x[b].xyz) - r;
    let hi = max(x[a].xyz, x[b].xyz) + r;
    walk(Query(lo, a, hi, b, true, r));
}
