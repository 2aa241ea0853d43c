//! Stage "lines" on the CPU (twin of wgsl/lines.wgsl): each contact's
//! force as a segment from the penetrating point, two vec4s per contact
//! slot (vertex–face slots, one per cloth vertex, then face–vertex ones,
//! one per body vertex); w = 0 marks a slot without a contact.

use crate::cpu::CpuSim;

/// The force segments of the contacts of `sim`'s last step, `metres_per_force`
/// m per unit of force, in the slot layout above.
pub fn force_lines(sim: &CpuSim, metres_per_force: f32) -> Vec<[f32; 4]> {
    let n = sim.state.x.len();
    let body = sim.rigid_frame().map_or(&[][..], |f| &f.vertices[..]);
    let mut lines = vec![[0.0; 4]; 2 * (n + body.len())];
    for (c, r) in sim.contacts().iter().zip(sim.responses()) {
        let (slot, point) = match c.cloth_triangle {
            None => (c.vertices[0] as usize, sim.state.x[c.vertices[0] as usize]),
            Some(_) => (n + c.rigid_feature as usize, body[c.rigid_feature as usize]),
        };
        lines[2 * slot] = point.extend(1.0).to_array();
        lines[2 * slot + 1] = (point + metres_per_force * r.force).extend(1.0).to_array();
    }
    lines
}
