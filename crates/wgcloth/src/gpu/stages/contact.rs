//! Stage "contact" (wgsl/contact.wgsl; CPU twin cpu/contact.rs): each
//! contact's force and Jacobian blocks from the model (thesis eqs. 6,
//! 8–9); a network model gathers the contacts into a batch, runs the
//! network over it (gpu::mlp) and reads its outputs into the responses.

use crate::gpu::buffers::Buffers;
use crate::gpu::constants::WORKGROUP;
use crate::gpu::kernels::{Bound, Entry, Kernels};
use crate::gpu::mlp::{GpuMlp, NetworkKernel};
use crate::gpu::pass::Pass;
use crate::gpu::stages::{Record, Recording};

pub(crate) struct Contact {
    respond_slots: Bound,
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
            ("v", &b.v),
            ("contacts", &b.contacts),
            ("responses", &b.responses),
            ("x", &b.x),
            ("rigid", &b.rigid),
            ("net_batch", &b.net_batch),
            ("net_inputs", &b.net_inputs),
            ("net_outputs", &b.net_outputs),
        ];
        let bind = |entry| {
            kernels
                .kernel(entry)
                .bind_parts(device, &buffers, &[&b.topology])
        };
        Contact {
            respond_slots: bind(Entry::ContactRespondSlots),
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

    /// Dispatches the network's batch records (0 without one).
    pub(crate) fn network_dispatches(&self) -> u32 {
        self.network.as_ref().map_or(0, GpuMlp::dispatches)
    }
}

impl Record for Contact {
    /// The network's own kernels replace the pass's group 0; it is set
    /// back after them.
    fn encode(&self, pass: &mut Pass, r: &Recording) {
        let (p, group0) = (r.params, r.group0);
        let (n, r) = (p.n_vertices, p.n_rigid_vertices);
        let Some(net) = &self.network else {
            self.respond_slots.dispatch(pass, n + r, WORKGROUP);
            return;
        };
        // One batch for every world's contacts (`gpu::worlds`).
        self.reset_batch.dispatch_once(pass, 1, 1);
        self.gather.dispatch(pass, n + r, WORKGROUP);
        net.record(pass);
        pass.set_bind_group(0, group0);
        // One thread per batch entry, sized on the GPU: no readback.
        let (args, offset) = net.per_contact_dispatch();
        self.respond_batch.dispatch_indirect(pass, args, offset);
    }
}
