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
const FAILED: u8 = 4;

/// One staging buffer and where its mapping stands: copied into by the
/// app's encoder, mapped with `map_async` once that is submitted, read and
/// unmapped. [`Readback`] keeps a ring of them and hands back the newest;
/// an app that must read every copy in order (a run loop reading each
/// step's statistics) keeps its own.
pub struct Staging {
    buffer: wgpu::Buffer,
    state: Arc<AtomicU8>,
}

/// How a [`Staging`] buffer's mapping ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mapped {
    /// Not yet: the copy or the mapping is still in flight.
    Pending,
    /// Mapped: [`Staging::take`] reads it.
    Ready,
    /// The mapping failed (a lost device).
    Failed,
}

impl Staging {
    /// A staging buffer of `size` bytes, free.
    pub fn new(device: &wgpu::Device, label: &str, size: u64) -> Staging {
        Staging {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            state: Arc::new(AtomicU8::new(FREE)),
        }
    }

    /// The buffer to copy into.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Whether it holds nothing in flight or unread (a failed mapping
    /// leaves it free again).
    pub fn is_free(&self) -> bool {
        matches!(self.state.load(Ordering::Acquire), FREE | FAILED)
    }

    /// Marks a copy into it as recorded.
    pub fn copying(&self) {
        self.state.store(COPYING, Ordering::Release);
    }

    /// Starts mapping it: call once the copy into it is submitted.
    pub fn map(&self) {
        self.state.store(MAPPING, Ordering::Release);
        let state = self.state.clone();
        self.buffer
            .map_async(wgpu::MapMode::Read, .., move |result| {
                state.store(
                    if result.is_ok() { READY } else { FAILED },
                    Ordering::Release,
                );
            });
    }

    /// How its mapping stands; never waits (the app's device polls run
    /// the callbacks).
    pub fn mapped(&self) -> Mapped {
        match self.state.load(Ordering::Acquire) {
            READY => Mapped::Ready,
            FAILED => Mapped::Failed,
            _ => Mapped::Pending,
        }
    }

    /// Whether a copy is recorded into it and not yet being mapped.
    fn is_copying(&self) -> bool {
        self.state.load(Ordering::Acquire) == COPYING
    }

    /// Its bytes from `offset` as whole elements of `T` if it is mapped
    /// (`None` if not), and it is free again.
    pub fn take<T: Pod>(&self, offset: usize) -> Option<Vec<T>> {
        if self.mapped() != Mapped::Ready {
            return None;
        }
        let taken = self.buffer.get_mapped_range(..).ok().map(|view| {
            let bytes = &view[offset.min(view.len())..];
            let whole = bytes.len() / size_of::<T>() * size_of::<T>();
            bytemuck::pod_collect_to_vec(&bytes[..whole])
        });
        self.release();
        taken
    }

    /// Unmaps it, unread.
    fn release(&self) {
        self.buffer.unmap();
        self.state.store(FREE, Ordering::Release);
    }
}

struct Slot {
    staging: Staging,
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
                staging: Staging::new(device, "readback ring", size),
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
        let Some(slot) = self.slots.iter_mut().find(|s| s.staging.is_free()) else {
            return false;
        };
        encoder.copy_buffer_to_buffer(source, 0, slot.staging.buffer(), 0, self.size);
        slot.staging.copying();
        self.copies += 1;
        slot.sequence = self.copies;
        true
    }

    /// Starts mapping the copies recorded since the last call: call it
    /// right after submitting the encoder they were recorded into.
    pub fn submitted(&mut self) {
        for slot in self.slots.iter().filter(|s| s.staging.is_copying()) {
            slot.staging.map();
        }
    }

    /// The newest finished copy as whole elements of `T`, if one is ready;
    /// never waits. Older finished copies are dropped.
    pub fn try_take<T: Pod>(&mut self) -> Option<Vec<T>> {
        let ready = |s: &&Slot| s.staging.mapped() == Mapped::Ready;
        let newest = self.slots.iter().filter(ready).map(|s| s.sequence).max()?;
        let mut taken = None;
        // A copy that finished since `newest` was found stays for the
        // next call.
        for slot in self
            .slots
            .iter()
            .filter(ready)
            .filter(|s| s.sequence <= newest)
        {
            if slot.sequence == newest {
                taken = slot.staging.take(0);
            } else {
                slot.staging.release();
            }
        }
        taken
    }
}
