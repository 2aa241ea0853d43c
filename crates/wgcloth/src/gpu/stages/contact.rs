//! Stage "contact" (wgsl/contact.wgsl; CPU twin cpu/contact.rs): each
//! contact's force and Jacobian blocks from the model (thesis eqs. 6,
//! 8–9); a network model gathers the contacts into a batch, runs the
//! network over it (gpu::mlp) and reads its outputs into the responses.

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::layout::Params;
use crate::gpu::mlp::{GpuMlp, NetworkKernel};

pub(crate) struct Contact {
    vertex_face: Bound,
    face_vertex: Bound,
    reset_batch: Bound,
    gather: Bound,
    respond_batch: Bound,
    /// The network of a network model.
    network: Option<GpuMlp>,
}

impl Contact {
    pub(crate) fn new(
        kernels: &Kernels,
        device: &wgpu::Device,
        b: &Buffers,
        network: Option<GpuMlp>,
    ) -> Contact {
        let buffers = [
            ("params", &b.params),
            ("v", &b.v),
            ("contacts", &b.contacts),
            ("responses", &b.responses),
            ("x", &b.x),
            ("topology", &b.topology),
            ("rigid", &b.rigid),
            ("net_batch", &b.net_batch),
            ("net_inputs", &b.net_inputs),
            ("net_outputs", &b.net_outputs),
        ];
        let bind = |entry| kernels.kernel(entry).bind(device, &buffers);
        Contact {
            vertex_face: bind(Entry::ContactVertexFace),
            face_vertex: bind(Entry::ContactFaceVertex),
            reset_batch: bind(Entry::ContactResetBatch),
            gather: bind(Entry::ContactGather),
            respond_batch: bind(Entry::ContactRespondBatch),
            network,
        }
    }

    /// The kernel running a network model's network.
    pub(crate) fn network_kernel(&self) -> Option<NetworkKernel> {
        self.network.as_ref().map(GpuMlp::kernel)
    }

    pub(crate) fn encode(&self, pass: &mut wgpu::ComputePass, p: &Params) -> u32 {
        let (n, r) = (p.n_vertices, p.n_rigid_vertices);
        let Some(net) = &self.network else {
            self.vertex_face.dispatch(pass, n, WORKGROUP);
            self.face_vertex.dispatch(pass, r, WORKGROUP);
            return 2;
        };
        self.reset_batch.dispatch(pass, 1, 1);
        self.gather.dispatch(pass, n + r, WORKGROUP);
        let network = net.record(pass);
        // One thread per batch entry, sized on the GPU: no readback.
        let (args, offset) = net.per_contact_dispatch();
        self.respond_batch.set(pass);
        pass.dispatch_workgroups_indirect(args, offset);
        3 + network
    }
}
