// Stage "batch": sizes the indirect dispatches of a network batch from the
// number of contacts gathered on the GPU, so no count is read back. Entry
// c × per_chunk + d is dispatch d of chunk c (tiled: layer d, workgroups
// along the rows, the host filling in the output-tile counts;
// `per_contact`: one, a thread per contact); the entry after them covers
// one thread per contact in groups of `threads_per_contact_group` (the
// caller's pass).

// Mirrors `gpu::mlp::BatchParams`.
struct BatchParams {
    n_chunks: u32, per_chunk: u32, chunk_contacts: u32, rows_per_contact: u32,
    rows_per_group: u32, threads_per_contact_group: u32, pad0: u32, pad1: u32,
}

@group(0) @binding(0) var<uniform> batch: BatchParams;
@group(0) @binding(1) var<storage, read> count: array<u32>;
// Indirect dispatch arguments, 3 × u32 per entry.
@group(0) @binding(2) var<storage, read_write> dispatch: array<u32>;

// Sizes a network batch's indirect dispatches.
@compute @workgroup_size(BATCH_GROUP)
fn plan(@builtin(global_invocation_id) id: vec3<u32>) {
    let e = id.x;
    let chunk_entries = batch.n_chunks * batch.per_chunk;
    let n = count[0];
    if e < chunk_entries {
        let start = (e / batch.per_chunk) * batch.chunk_contacts;
        var contacts = 0u;
        if n > start {
            contacts = min(n - start, batch.chunk_contacts);
        }
        let rows = contacts * batch.rows_per_contact;
        dispatch[3u * e] = (rows + batch.rows_per_group - 1u) / batch.rows_per_group;
    } else if e == chunk_entries {
        dispatch[3u * e] = (n + batch.threads_per_contact_group - 1u) / batch.threads_per_contact_group;
    }
}
