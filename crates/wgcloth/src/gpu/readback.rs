//! Reading GPU buffers back without waiting: a ring of staging buffers,
//! each copied into by the app's own encoder and mapped with `map_async`,
//! whose callbacks run whenever the app polls the device (on the web, when
//! the event loop runs). The simulation never needs it; it is for apps and
//! tools that want the state on the host now and then.

use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

use bytemuck::Pod;

const FREE: u8 = 0;
const COPYING: u8 = 1;
const MAPPING: u8 = 2;
const READY: u8 = 3;

struct Slot {
    buffer: wgpu::Buffer,
    state: Arc<AtomicU8>,
    /// Which copy this is, to hand back the newest first.
    sequence: u64,
}

/// A ring of staging buffers for one source buffer of `size` bytes.
pub struct Readback {
    slots: Vec<Slot>,
    size: u64,
    copies: u64,
}

impl Readback {
    /// `depth` staging buffers (2–3 keep a copy in flight every frame).
    pub fn new(device: &wgpu::Device, size: u64, depth: usize) -> Readback {
        let slots = (0..depth.max(1))
            .map(|_| Slot {
                buffer: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("readback ring"),
                    size,
                    usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }),
                state: Arc::new(AtomicU8::new(FREE)),
                sequence: 0,
            })
            .collect();
        Readback {
            slots,
            size,
            copies: 0,
        }
    }

    /// Records a copy of `source` into a free staging buffer; false (and
    /// nothing recorded) while every buffer is still in flight or unread.
    pub fn encode_copy(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        source: &wgpu::Buffer,
    ) -> bool {
        let Some(slot) = self
            .slots
            .iter_mut()
            .find(|s| s.state.load(Ordering::Acquire) == FREE)
        else {
            return false;
        };
        encoder.copy_buffer_to_buffer(source, 0, &slot.buffer, 0, self.size);
        slot.state.store(COPYING, Ordering::Release);
        self.copies += 1;
        slot.sequence = self.copies;
        true
    }

    /// Starts mapping the copies recorded since the last call: call it
    /// right after submitting the encoder they were recorded into.
    pub fn submitted(&mut self) {
        for slot in &self.slots {
            if slot.state.load(Ordering::Acquire) != COPYING {
                continue;
            }
            slot.state.store(MAPPING, Ordering::Release);
            let state = slot.state.clone();
            slot.buffer
                .map_async(wgpu::MapMode::Read, .., move |result| {
                    state.store(if result.is_ok() { READY } else { FREE }, Ordering::Release);
                });
        }
    }

    /// The newest finished copy as whole elements of `T`, if one is ready;
    /// never waits. Older finished copies are dropped.
    pub fn try_take<T: Pod>(&mut self) -> Option<Vec<T>> {
        let newest = self
            .slots
            .iter()
            .filter(|s| s.state.load(Ordering::Acquire) == READY)
            .map(|s| s.sequence)
            .max()?;
        let mut taken = None;
        for slot in &self.slots {
            // A copy that finished since `newest` was found stays for the
            // next call.
            if slot.state.load(Ordering::Acquire) != READY || slot.sequence > newest {
                continue;
            }
            if slot.sequence == newest
                && let Ok(view) = slot.buffer.get_mapped_range(..)
            {
                let whole = view.len() / size_of::<T>() * size_of::<T>();
                taken = Some(bytemuck::pod_collect_to_vec(&view[..whole]));
            }
            slot.buffer.unmap();
            slot.state.store(FREE, Ordering::Release);
        }
        taken
    }
}
