// Stage "batch": sizes the indirect dispatches of a network batch from the
// number of contacts gathered on the GPU, so no count is read back. Entry
// c × n_layers + l is layer l of chunk c (workgroups along the rows; the
// host fills the output-tile counts); the two entries after them cover one
// thread per contact in groups of `threads_per_network_group` (the
// network's per-contact kernel) and `threads_per_contact_group` (the
// caller's pass).

// Mirrors `gpu::mlp::BatchParams`.
struct BatchParams {
    n_chunks: u32, n_layers: u32, chunk_contacts: u32, rows_per_contact: u32,
    rows_per_group: u32, threads_per_network_group: u32, threads_per_contact_group: u32,
    pad0: u32,
}

@group(0) @binding(0) var<uniform> batch: BatchParams;
@group(0) @binding(1) var<storage, read> count: array<u32>;
// Indirect dispatch arguments, 3 × u32 per entry.
@group(0) @binding(2) var<storage, read_write> dispatch: array<u32>;

@compute @workgroup_size(BATCH_GROUP)
fn plan(@builtin(global_invocation_id) id: vec3<u32>) {
    let e = id.x;
    let layer_entries = batch.n_chunks * batch.n_layers;
    let n = count[0];
    if e < layer_entries {
        let start = (e / batch.n_layers) * batch.chunk_contacts;
        var contacts = 0u;
        if n > start {
            contacts = min(n - start, batch.chunk_contacts);
        }
        let rows = contacts * batch.rows_per_contact;
        dispatch[3u * e] = (rows + batch.rows_per_group - 1u) / batch.rows_per_group;
    } else if e == layer_entries {
        dispatch[3u * e] = (n + batch.threads_per_network_group - 1u) / batch.threads_per_network_group;
    } else if e == layer_entries + 1u {
        dispatch[3u * e] = (n + batch.threads_per_contact_group - 1u) / batch.threads_per_contact_group;
    }
}
