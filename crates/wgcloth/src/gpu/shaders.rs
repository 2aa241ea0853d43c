//! The WGSL stages (`wgsl/`, one file per stage, each prefixed with
//! `common.wgsl`), validated with naga, and the bind group layout of each
//! reflected from its global variables, so binding numbers live only in
//! the WGSL and Rust binds buffers by variable name.

use std::collections::BTreeMap;

use crate::gpu::constants;

/// The stage files, by name.
pub const STAGES: [(&str, &str); 11] = [
    ("rigid", include_str!("../../wgsl/rigid.wgsl")),
    ("collide", include_str!("../../wgsl/collide.wgsl")),
    ("contact", include_str!("../../wgsl/contact.wgsl")),
    ("assemble", include_str!("../../wgsl/assemble.wgsl")),
    ("pcg", include_str!("../../wgsl/pcg.wgsl")),
    ("multigrid", include_str!("../../wgsl/multigrid.wgsl")),
    ("integrate", include_str!("../../wgsl/integrate.wgsl")),
    ("measure", include_str!("../../wgsl/measure.wgsl")),
    ("batch", include_str!("../../wgsl/batch.wgsl")),
    ("mlp", include_str!("../../wgsl/mlp.wgsl")),
    ("lines", include_str!("../../wgsl/lines.wgsl")),
];

/// `wgsl/common.wgsl`: the code every scene stage starts with (`Params`,
/// the shared structs and helpers).
pub const COMMON: &str = include_str!("../../wgsl/common.wgsl");

/// Shared code with bindings of its own (so not in `COMMON`), and the
/// stages it is prepended to.
pub const INCLUDES: [(&str, &str, &[&str]); 4] = [
    (
        "topology",
        include_str!("../../wgsl/topology.wgsl"),
        &[
            "collide",
            "contact",
            "assemble",
            "pcg",
            "multigrid",
            "integrate",
            "measure",
        ],
    ),
    (
        "bvh",
        include_str!("../../wgsl/bvh.wgsl"),
        &["collide", "measure"],
    ),
    (
        "springs",
        include_str!("../../wgsl/springs.wgsl"),
        &["assemble"],
    ),
    (
        "partials",
        include_str!("../../wgsl/partials.wgsl"),
        &["pcg", "multigrid"],
    ),
];

/// Stages that do not depend on the scene and get no common code.
pub const STANDALONE: [&str; 2] = ["batch", "mlp"];

/// The shared constants ([`constants::prelude`], the network tile set to
/// `mlp_threads` per edge), common code, the stage's includes, then the
/// stage's own code.
pub fn source(stage: &str, mlp_threads: u32) -> String {
    let body = STAGES
        .iter()
        .find(|(name, _)| *name == stage)
        .unwrap_or_else(|| panic!("no WGSL stage `{stage}`"))
        .1;
    let includes: String = INCLUDES
        .iter()
        .filter(|(_, _, users)| users.contains(&stage))
        .map(|(_, text, _)| format!("{text}\n"))
        .collect();
    let prelude = constants::prelude(mlp_threads);
    match STANDALONE.contains(&stage) {
        true => format!("{prelude}\n{body}"),
        false => format!("{prelude}\n{COMMON}\n{includes}{body}"),
    }
}

/// A binding as the WGSL declares it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Binding {
    /// Its bind group.
    pub group: u32,
    /// Its binding number in the group.
    pub binding: u32,
    /// Uniform or storage, and whether read-only.
    pub ty: wgpu::BufferBindingType,
}

/// The scene stages' group 0: `params` alone ([`PARAMS_BINDING`]); their
/// other bindings are group 1. The standalone stages bind all in group 0.
pub const PARAMS_GROUP: u32 = 0;
/// The binding of `params` in group [`PARAMS_GROUP`].
pub const PARAMS_BINDING: u32 = 0;

/// An entry point and the bindings it uses (through any function it
/// calls), by variable name: its pipeline's layout holds these alone, so
/// a stage's file may declare more than a WebGPU stage can bind as long
/// as no one entry point uses more.
#[derive(Clone, Debug)]
pub struct EntryPoint {
    /// The entry point's WGSL function name.
    pub name: String,
    /// The bindings it uses, by variable name.
    pub bindings: BTreeMap<String, Binding>,
}

/// Parses and validates a stage with naga, returning a readable error, and
/// lists its entry points with the bindings each uses.
pub fn reflect(stage: &str, mlp_threads: u32) -> Result<Vec<EntryPoint>, String> {
    let src = source(stage, mlp_threads);
    let module = naga::front::wgsl::parse_str(&src).map_err(|e| e.emit_to_string(&src))?;
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .map_err(|e| e.emit_to_string(&src))?;
    let mut declared = Vec::new();
    for (handle, var) in module.global_variables.iter() {
        let (Some(name), Some(rb)) = (&var.name, &var.binding) else {
            continue;
        };
        let ty = match var.space {
            naga::AddressSpace::Uniform => wgpu::BufferBindingType::Uniform,
            naga::AddressSpace::Storage { access } => wgpu::BufferBindingType::Storage {
                read_only: !access.contains(naga::StorageAccess::STORE),
            },
            other => {
                return Err(format!(
                    "{stage}: `{name}` is in unsupported space {other:?}"
                ));
            }
        };
        let own_group = match STANDALONE.contains(&stage) {
            true => 0,
            false if name == "params" => PARAMS_GROUP,
            false => 1,
        };
        if rb.group != own_group {
            return Err(format!("{stage}: `{name}` belongs in group {own_group}"));
        }
        let binding = Binding {
            group: rb.group,
            binding: rb.binding,
            ty,
        };
        declared.push((handle, name.clone(), binding));
    }
    Ok(module
        .entry_points
        .iter()
        .enumerate()
        .map(|(i, entry)| {
            let uses = info.get_entry_point(i);
            EntryPoint {
                name: entry.name.clone(),
                bindings: declared
                    .iter()
                    .filter(|(handle, _, _)| !uses[*handle].is_empty())
                    .map(|(_, name, binding)| (name.clone(), binding.clone()))
                    .collect(),
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every file of `wgsl/`, by name, as written.
    fn files() -> Vec<(&'static str, &'static str)> {
        let includes = INCLUDES.iter().map(|(name, text, _)| (*name, *text));
        STAGES
            .into_iter()
            .chain(includes)
            .chain([("common", COMMON)])
            .collect()
    }

    #[test]
    fn every_entry_point_validates_and_fits_webgpu_default_limits() {
        let limits = wgpu::Limits::default();
        for (stage, _) in STAGES {
            let entries = reflect(stage, 16).unwrap_or_else(|e| panic!("{stage}.wgsl:\n{e}"));
            assert!(!entries.is_empty(), "{stage} has no entry point");
            for entry in entries {
                let storage = entry
                    .bindings
                    .values()
                    .filter(|b| matches!(b.ty, wgpu::BufferBindingType::Storage { .. }))
                    .count() as u32;
                let uniform = entry.bindings.len() as u32 - storage;
                assert!(
                    storage <= limits.max_storage_buffers_per_shader_stage
                        && uniform <= limits.max_uniform_buffers_per_shader_stage,
                    "{stage}::{}: {storage} storage and {uniform} uniform buffers",
                    entry.name
                );
            }
        }
    }

    #[test]
    fn shared_constants_come_from_the_prelude_alone() {
        let names = constants::SHARED.iter().map(|(name, _)| *name);
        for name in names.chain(constants::SHARED_F32.iter().map(|(name, _)| *name)) {
            let declaration = format!("const {name}:");
            let mut used = false;
            for (file, text) in files() {
                assert!(
                    !text.contains(&declaration),
                    "wgsl/{file}.wgsl declares {name}, which gpu::constants owns"
                );
                used |= text.contains(name);
            }
            assert!(used, "no WGSL file uses the shared constant {name}");
        }
    }
}
