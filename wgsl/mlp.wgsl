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

// Threads per tile edge; gpu::kernels picks 16 or 8 from the adapter's limits.
const MLP_THREADS: u32 = 16u;
// Each thread computes a 4×4 block of the output tile.
const MLP_PER_THREAD: u32 = 4u;
const MLP_TILE: u32 = MLP_THREADS * MLP_PER_THREAD;
// Inputs per step through the tiles.
const MLP_K: u32 = 16u;

// Mirrors `gpu::mlp::LayerParams`.
struct LayerParams {
    inputs: u32, outputs: u32, weight_offset: u32, bias_offset: u32,
    rows_per_contact: u32, wrt_start: u32, first: u32, chunk_start: u32,
    chunk_contacts: u32, out_row_offset: u32, negative_slope: f32, pad0: u32,
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

var<workgroup> a_tile: array<array<f32, MLP_TILE>, MLP_K>;
var<workgroup> w_tile: array<array<f32, MLP_TILE>, MLP_K>;

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

@compute @workgroup_size(MLP_THREADS, MLP_THREADS)
fn layer(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let rows = chunk_rows();
    let row0 = group.x * MLP_TILE;
    let out0 = group.y * MLP_TILE;
    var acc: array<array<f32, MLP_PER_THREAD>, MLP_PER_THREAD>;
    for (var k0 = 0u; k0 < layer_params.inputs; k0 += MLP_K) {
        // k fastest, so neighbouring threads read neighbouring floats.
        for (var e = li; e < MLP_K * MLP_TILE; e += MLP_THREADS * MLP_THREADS) {
            let kk = e % MLP_K;
            let m = e / MLP_K;
            a_tile[kk][m] = load_a(row0 + m, k0 + kk, rows);
            w_tile[kk][m] = load_w(out0 + m, k0 + kk);
        }
        workgroupBarrier();
        for (var kk = 0u; kk < MLP_K; kk++) {
            var a: array<f32, MLP_PER_THREAD>;
            var w: array<f32, MLP_PER_THREAD>;
            for (var i = 0u; i < MLP_PER_THREAD; i++) {
                a[i] = a_tile[kk][lid.y + i * MLP_THREADS];
                w[i] = w_tile[kk][lid.x + i * MLP_THREADS];
            }
            for (var i = 0u; i < MLP_PER_THREAD; i++) {
                for (var j = 0u; j < MLP_PER_THREAD; j++) {
                    acc[i][j] = fma(a[i], w[j], acc[i][j]);
                }
            }
        }
        workgroupBarrier();
    }
    for (var i = 0u; i < MLP_PER_THREAD; i++) {
        let r = row0 + lid.y + i * MLP_THREADS;
        if r >= rows {
            continue;
        }
        let value_row = r % layer_params.rows_per_contact == 0u;
        for (var j = 0u; j < MLP_PER_THREAD; j++) {
            let o = out0 + lid.x + j * MLP_THREADS;
            if o < layer_params.outputs {
                let bias = select(0.0, weights[layer_params.bias_offset + o], value_row);
                z_out[(layer_params.out_row_offset + r) * layer_params.outputs + o] = acc[i][j] + bias;
            }
        }
    }
}
