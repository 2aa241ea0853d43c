// Stage "mlp": one dense layer of a collision network (thesis 2.4, 2.7) over
// a batch of contacts, carrying its forward-mode input Jacobian. CPU twin:
// src/nn/mlp.rs (`Mlp::forward_jacobian`).
//
// Each contact owns R = 1 + T consecutive rows: its activations, then their
// derivatives along each of the T inputs wrt_start .. wrt_start + T. A layer
// is then one matrix product over all rows, Z = A Wᵀ (+ b on value rows),
// tiled through workgroup memory. The activation is applied as the next
// layer loads Z: σ(z) on a value row and σ'(z_value) z on a tangent row,
// which is the chain rule T ← diag(σ'(z)) W T. The first layer loads the
// inputs and unit seeds instead. Layer sizes come from the weights file;
// large batches run in chunks so the activations fit the binding limits.
//
// `per_contact` is the same network with one contact per invocation, no
// workgroup memory or barriers, for CPU adapters (lavapipe), which run it
// faster than the tiled kernel.

// MLP_THREADS, threads per tile edge, comes with the prelude:
// gpu::kernels picks 16 or 8 from the adapter's limits.
// Each thread computes a 4×4 block of the output tile.
const MLP_TILE: u32 = MLP_THREADS * 4u;
// Inputs per step through the tiles.
const MLP_K: u32 = 16u;

// Mirrors `gpu::mlp::LayerParams`.
struct LayerParams {
    inputs: u32, outputs: u32, weight_offset: u32, bias_offset: u32,
    rows_per_contact: u32, wrt_start: u32, first: u32, chunk_start: u32,
    chunk_contacts: u32, out_row_offset: u32, negative_slope: f32, n_layers: u32,
    units_half: u32, pad0: u32, pad1: u32, pad2: u32,
}

@group(0) @binding(0) var<uniform> layer_params: LayerParams;
// Every layer's weights (row-major [outputs × inputs]) and biases.
@group(0) @binding(1) var<storage, read> weights: array<f32>;
// The batch inputs [contacts × inputs] (first layer) or the previous
// layer's Z [chunk rows × inputs].
@group(0) @binding(2) var<storage, read> z_in: array<f32>;
// This layer's Z [chunk rows × outputs], or the batch outputs
// [contacts × R × 3] for the last layer.
@group(0) @binding(3) var<storage, read_write> z_out: array<f32>;
// The number of contacts in the batch.
@group(0) @binding(4) var<storage, read> count: array<u32>;
// Per layer: inputs, outputs, and in vec4s its weight and bias offsets
// (`per_contact`).
@group(0) @binding(5) var<storage, read> layer_table: array<vec4<u32>>;
// The same weights packed by quads of outputs (`per_contact`): one load
// per four weights.
@group(0) @binding(6) var<storage, read> weight_quads: array<vec4<f32>>;
// `per_contact`'s activations: unit slot s of the chunk's contact i at
// i * 2 units_half + s, each contact's together (lavapipe, which runs it,
// gathers them faster than slot by slot). A layer reads slots from
// `src` and writes the other half.
@group(0) @binding(7) var<storage, read_write> units: array<vec4<f32>>;

// Element m of a tile row is component m % 4 of vec4 m / 4: each thread
// reads its 4 rows and its 4 outputs with one load each.
var<workgroup> a_tile: array<array<vec4<f32>, MLP_THREADS>, MLP_K>;
var<workgroup> w_tile: array<array<vec4<f32>, MLP_THREADS>, MLP_K>;

fn chunk_rows() -> u32 {
    let n = count[0];
    if n <= layer_params.chunk_start {
        return 0u;
    }
    return min(n - layer_params.chunk_start, layer_params.chunk_contacts) * layer_params.rows_per_contact;
}

// Row r of A at input k, activated (or seeded, for the first layer).
fn load_a(r: u32, k: u32, rows: u32) -> f32 {
    if r >= rows || k >= layer_params.inputs {
        return 0.0;
    }
    let t = r % layer_params.rows_per_contact;
    if layer_params.first != 0u {
        if t == 0u {
            let contact = layer_params.chunk_start + r / layer_params.rows_per_contact;
            return z_in[contact * layer_params.inputs + k];
        }
        return select(0.0, 1.0, k == layer_params.wrt_start + t - 1u);
    }
    let z = z_in[r * layer_params.inputs + k];
    let z_value = z_in[(r - t) * layer_params.inputs + k];
    return z * select(1.0, layer_params.negative_slope, z_value < 0.0);
}

fn load_w(o: u32, k: u32) -> f32 {
    if o >= layer_params.outputs || k >= layer_params.inputs {
        return 0.0;
    }
    return weights[layer_params.weight_offset + o * layer_params.inputs + k];
}

// Thread (x, y) computes rows row0 + 4y .. 4y + 3 and outputs
// out0 + 4x .. 4x + 3 of the workgroup's tile.
@compute @workgroup_size(MLP_THREADS, MLP_THREADS)
fn layer(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let rows = chunk_rows();
    let row0 = group.x * MLP_TILE;
    let out0 = group.y * MLP_TILE;
    // acc_i holds row 4y + i, outputs 4x .. 4x + 3.
    var acc0 = vec4<f32>(0.0);
    var acc1 = vec4<f32>(0.0);
    var acc2 = vec4<f32>(0.0);
    var acc3 = vec4<f32>(0.0);
    for (var k0 = 0u; k0 < layer_params.inputs; k0 += MLP_K) {
        // k fastest, so neighbouring threads read neighbouring floats.
        for (var e = li; e < MLP_K * MLP_TILE; e += MLP_THREADS * MLP_THREADS) {
            let kk = e % MLP_K;
            let m = e / MLP_K;
            a_tile[kk][m / 4u][m % 4u] = load_a(row0 + m, k0 + kk, rows);
            w_tile[kk][m / 4u][m % 4u] = load_w(out0 + m, k0 + kk);
        }
        workgroupBarrier();
        for (var kk = 0u; kk < MLP_K; kk++) {
            let a = a_tile[kk][lid.y];
            let w = w_tile[kk][lid.x];
            acc0 = fma(vec4<f32>(a.x), w, acc0);
            acc1 = fma(vec4<f32>(a.y), w, acc1);
            acc2 = fma(vec4<f32>(a.z), w, acc2);
            acc3 = fma(vec4<f32>(a.w), w, acc3);
        }
        workgroupBarrier();
    }
    let acc = array<vec4<f32>, 4>(acc0, acc1, acc2, acc3);
    for (var i = 0u; i < 4u; i++) {
        let r = row0 + 4u * lid.y + i;
        if r >= rows {
            continue;
        }
        let value_row = r % layer_params.rows_per_contact == 0u;
        for (var j = 0u; j < 4u; j++) {
            let o = out0 + 4u * lid.x + j;
            if o < layer_params.outputs {
                let bias = select(0.0, weights[layer_params.bias_offset + o], value_row);
                z_out[(layer_params.out_row_offset + r) * layer_params.outputs + o] = acc[i][j] + bias;
            }
        }
    }
}

// One contact per invocation, its Jacobian in forward mode with the
// tangents riding along the value: unit k of a layer is a vec4 (its value,
// then its derivatives along inputs wrt_start .. wrt_start + 2), or two
// vec4s for up to seven rows (`per_contact_wide`). A layer is then one pass
// over its weights, each weight scaling a whole vec4, and the activation
// scales a unit's vec4 by σ'(value) as a whole, the chain rule
// T ← diag(σ'(z)) W T. Four outputs at a time: a quad of weights (the
// layer's weights packed by output quad, then input, `mlp::pack_quads`)
// meets each input unit once, so one load of the activations serves four
// outputs. Reads the batch inputs (z_in) and writes the batch outputs
// (z_out) in the tiled kernel's layout. Lavapipe, which runs it, stops an
// invocation after 65,535 loop iterations (`gpu::mlp` checks).

// The whole network, one contact per invocation, up to three Jacobian
// columns.
@compute @workgroup_size(BATCH_GROUP)
fn per_contact(@builtin(global_invocation_id) id: vec3<u32>) {
    evaluate(id.x, false);
}

// The whole network, one contact per invocation, up to seven Jacobian
// columns.
@compute @workgroup_size(BATCH_GROUP)
fn per_contact_wide(@builtin(global_invocation_id) id: vec3<u32>) {
    evaluate(id.x, true);
}

// Where `put` sends a quad of outputs: contact c's batch outputs (the last
// layer) or the next layer's units from slot `dst`.
struct Out {
    c: u32, i: u32, o: u32, last: bool, dst: u32, per_unit: u32, n_out: u32,
}

fn unit_index(slot: u32, i: u32) -> u32 {
    return i * 2u * layer_params.units_half + slot;
}

// Contact i of the chunk. `wide` is a constant at each call, so each
// entry point compiles to one branch-free loop.
fn evaluate(i: u32, wide: bool) {
    let c = layer_params.chunk_start + i;
    if i >= layer_params.chunk_contacts || c >= count[0] {
        return;
    }
    let n_layers = layer_params.n_layers;
    let n_in = layer_table[0].x;
    let n_out = layer_table[n_layers - 1u].y;
    let per_unit = select(1u, 2u, wide);
    for (var k = 0u; k < n_in; k++) {
        // Tangent row t seeds input wrt_start + t - 1 (wrapping below).
        let t = k - layer_params.wrt_start + 1u;
        let seed = vec4<f32>(vec4<u32>(0u, 1u, 2u, 3u) == vec4<u32>(t));
        units[unit_index(k * per_unit, i)] = vec4<f32>(z_in[c * n_in + k], seed.yzw);
        if wide {
            units[unit_index(k * 2u + 1u, i)] = vec4<f32>(vec4<u32>(4u, 5u, 6u, 7u) == vec4<u32>(t));
        }
    }
    var src = 0u;
    for (var l = 0u; l < n_layers; l++) {
        let info = layer_table[l];
        let dst = layer_params.units_half - src;
        let last = l + 1u == n_layers;
        for (var o = 0u; o < info.y; o += 4u) {
            // Four outputs' sums in named variables, not an array: an
            // array indexed at run time lives in memory on lavapipe.
            let bias = weight_quads[info.w + o / 4u];
            var acc0 = vec4<f32>(bias.x, 0.0, 0.0, 0.0);
            var acc1 = vec4<f32>(bias.y, 0.0, 0.0, 0.0);
            var acc2 = vec4<f32>(bias.z, 0.0, 0.0, 0.0);
            var acc3 = vec4<f32>(bias.w, 0.0, 0.0, 0.0);
            var more0 = vec4<f32>(0.0);
            var more1 = vec4<f32>(0.0);
            var more2 = vec4<f32>(0.0);
            var more3 = vec4<f32>(0.0);
            let row = info.z + (o / 4u) * info.x;
            for (var k = 0u; k < info.x; k++) {
                let w = weight_quads[row + k];
                let a = units[unit_index(src + k * per_unit, i)];
                acc0 = fma(vec4<f32>(w.x), a, acc0);
                acc1 = fma(vec4<f32>(w.y), a, acc1);
                acc2 = fma(vec4<f32>(w.z), a, acc2);
                acc3 = fma(vec4<f32>(w.w), a, acc3);
                if wide {
                    let b = units[unit_index(src + k * 2u + 1u, i)];
                    more0 = fma(vec4<f32>(w.x), b, more0);
                    more1 = fma(vec4<f32>(w.y), b, more1);
                    more2 = fma(vec4<f32>(w.z), b, more2);
                    more3 = fma(vec4<f32>(w.w), b, more3);
                }
            }
            let out = Out(c, i, o, last, dst, per_unit, n_out);
            put(out, 0u, acc0, more0);
            put(out, 1u, acc1, more1);
            put(out, 2u, acc2, more2);
            put(out, 3u, acc3, more3);
        }
        src = dst;
    }
}

// Output o + j of a layer: the batch outputs' rows (value, then tangents)
// for the last layer, else the unit activated: leaky ReLU on the value,
// its slope on the tangents.
fn put(u: Out, j: u32, acc: vec4<f32>, more: vec4<f32>) {
    let o = u.o + j;
    if u.last {
        if o < u.n_out {
            let rows = layer_params.rows_per_contact;
            for (var t = 0u; t < rows; t++) {
                let v = select(more[t % 4u], acc[t % 4u], t < 4u);
                z_out[(u.c * rows + t) * u.n_out + o] = v;
            }
        }
        return;
    }
    let slope = select(1.0, layer_params.negative_slope, acc.x < 0.0);
    units[unit_index(u.dst + o * u.per_unit, u.i)] = acc * slope;
    if u.per_unit == 2u {
        units[unit_index(u.dst + o * 2u + 1u, u.i)] = more * slope;
    }
}
