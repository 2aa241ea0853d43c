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
// workgroup memory or barriers, and its Jacobian in reverse mode, for CPU
// adapters (lavapipe), which run it about 3× faster than the tiled kernel
// on small networks.

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
// Per layer: inputs, outputs, weight offset, bias offset (`per_contact`).
@group(0) @binding(5) var<storage, read> layer_table: array<vec4<u32>>;
// The same weights as whole vec4s (`per_contact`, whose rows are padded
// to them): one load per four weights.
@group(0) @binding(6) var<storage, read> weight_quads: array<vec4<f32>>;

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

// MLP_MAX_WIDTH and MLP_MAX_LAYERS (the prelude): the widest layer and
// most layers `per_contact` holds (gpu::mlp checks).

// One contact per invocation, in reverse mode: the value row through every
// layer, keeping each hidden unit's sign as a bit, then for each output o
// the row ∂y_o/∂a carried back through the layers with those signs,
// Δ ← (Δ diag(σ'(z))) W, as `Mlp::forward_jacobian` does. That is 1 + 3
// passes over the weights where forward mode takes 1 + T. Reads the batch
// inputs (z_in) and writes the batch outputs (z_out) in the tiled kernel's
// layout. Weight rows are padded to whole vec4s here, so the inner loops
// take four inputs at a time (lavapipe also stops any invocation after
// 65,535 loop iterations).
@compute @workgroup_size(BATCH_GROUP)
fn per_contact(@builtin(global_invocation_id) id: vec3<u32>) {
    let c = id.x;
    if c >= count[0] {
        return;
    }
    let rows = layer_params.rows_per_contact;
    let n_layers = layer_params.n_layers;
    let n_in = layer_table[0].x;
    let n_out = layer_table[n_layers - 1u].y;
    // Activation k is component k % 4 of a[k / 4].
    var a: array<vec4<f32>, MLP_MAX_WIDTH / 4u>;
    var z: array<f32, MLP_MAX_WIDTH>;
    var negative: array<u32, MLP_MAX_WIDTH * MLP_MAX_LAYERS / 32u>;
    for (var k = 0u; k < n_in; k++) {
        a[k / 4u][k % 4u] = z_in[c * n_in + k];
    }
    for (var l = 0u; l < n_layers; l++) {
        let info = layer_table[l];
        let quads = (info.x + 3u) / 4u;
        for (var o = 0u; o < info.y; o++) {
            var sum = weights[info.w + o];
            let row = info.z / 4u + quads * o;
            for (var q = 0u; q < quads; q++) {
                sum += dot(weight_quads[row + q], a[q]);
            }
            z[o] = sum;
        }
        if l + 1u == n_layers {
            break;
        }
        for (var o = 0u; o < info.y; o++) {
            let bit = l * MLP_MAX_WIDTH + o;
            let negative_here = z[o] < 0.0;
            if negative_here {
                negative[bit / 32u] |= 1u << (bit % 32u);
            } else {
                negative[bit / 32u] &= ~(1u << (bit % 32u));
            }
            a[o / 4u][o % 4u] = select(z[o], z[o] * layer_params.negative_slope, negative_here);
        }
    }
    for (var o = 0u; o < n_out; o++) {
        z_out[c * rows * n_out + o] = z[o];
    }
    // Reverse passes: Δ lives in z (one unit per element), the next Δ
    // accumulates in a (four inputs per vec4).
    for (var r = 0u; r < n_out; r++) {
        for (var o = 0u; o < n_out; o++) {
            z[o] = select(0.0, 1.0, o == r);
        }
        for (var l = n_layers; l > 0u; l--) {
            let info = layer_table[l - 1u];
            let quads = (info.x + 3u) / 4u;
            for (var q = 0u; q < quads; q++) {
                a[q] = vec4<f32>(0.0);
            }
            for (var o = 0u; o < info.y; o++) {
                let bit = (l - 1u) * MLP_MAX_WIDTH + o;
                let hidden = l < n_layers;
                let negative_here = hidden && (negative[bit / 32u] & (1u << (bit % 32u))) != 0u;
                let d = select(z[o], z[o] * layer_params.negative_slope, negative_here);
                let row = info.z / 4u + quads * o;
                for (var q = 0u; q < quads; q++) {
                    a[q] = fma(vec4<f32>(d), weight_quads[row + q], a[q]);
                }
            }
            for (var k = 0u; k < info.x; k++) {
                z[k] = a[k / 4u][k % 4u];
            }
        }
        for (var t = 1u; t < rows; t++) {
            z_out[(c * rows + t) * n_out + r] = z[layer_params.wrt_start + t - 1u];
        }
    }
}
