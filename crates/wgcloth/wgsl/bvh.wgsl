// The rigid body's BVH (src/bvh.rs, built once on the host) and one walk
// over it, shared by the stages that query the body. Prepended after
// common.wgsl to the stages that list it (gpu::shaders::INCLUDES).

@group(1) @binding(30) var<storage, read> bvh_nodes: array<BvhNode>;

// A depth-first walk: a box query (p ± reach) or a ray query (p + s x̂,
// s ≥ 0, its boxes' faces and edges included: Bvh::query_x_ray).
struct BvhWalk {
    stack: array<u32, 64>,
    top: u32,
    p: vec3<f32>,
    reach: f32,
    ray: bool,
}

fn box_walk(p: vec3<f32>, reach: f32) -> BvhWalk {
    var w: BvhWalk;
    w.top = 1u;
    w.stack[0] = 0u;
    w.p = p;
    w.reach = reach;
    w.ray = false;
    return w;
}

fn ray_walk(p: vec3<f32>) -> BvhWalk {
    var w = box_walk(p, 0.0);
    w.ray = true;
    return w;
}

fn walk_overlaps(w: ptr<function, BvhWalk>, node: BvhNode) -> bool {
    if !(*w).ray {
        return box_near(node.lo, node.hi, (*w).p, (*w).reach);
    }
    let p = (*w).p;
    return node.hi.x >= p.x && all(node.lo.yz <= p.yz) && all(p.yz <= node.hi.yz);
}

// The next leaf the query reaches, or NO_TRIANGLE when the walk is over.
// Its primitives are bvh_primitive(first .. first + count).
fn next_leaf(w: ptr<function, BvhWalk>) -> u32 {
    while (*w).top > 0u {
        (*w).top--;
        let k = (*w).stack[(*w).top];
        let node = bvh_nodes[k];
        if !walk_overlaps(w, node) {
            continue;
        }
        if node.count > 0u {
            return k;
        }
        (*w).stack[(*w).top] = node.first;
        (*w).stack[(*w).top + 1u] = node.first + 1u;
        (*w).top += 2u;
    }
    return NO_TRIANGLE;
}
