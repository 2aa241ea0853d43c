//! The WGSL stages (`wgsl/`, one file per stage, each prefixed with
//! `common.wgsl`), validated with naga, and the bind group layout of each
//! reflected from its global variables, so binding numbers live only in
//! the WGSL and Rust binds buffers by variable name.

use std::collections::BTreeMap;

use crate::gpu::constants;
use crate::gpu::layout::VectorLayout;

/// The stage files, by name: every file of `wgsl/` with a `@compute`
/// entry point, found by `build.rs`.
pub const STAGES: &[(&str, &str)] = include!(concat!(env!("OUT_DIR"), "/stages.rs"));

/// `wgsl/common.wgsl`: the code every scene stage starts with (`Params`,
/// the shared structs and helpers).
pub const COMMON: &str = include_str!("../../wgsl/common.wgsl");

/// Shared code with bindings of its own (so not in `COMMON`), in the order
/// a stage that names some of them (its `// Includes:` line,
/// [`includes_of`]) gets them.
pub const INCLUDES: &[(&str, &str)] = &[
    ("topology", include_str!("../../wgsl/topology.wgsl")),
    ("bvh", include_str!("../../wgsl/bvh.wgsl")),
    ("tiles", include_str!("../../wgsl/tiles.wgsl")),
    ("walk", include_str!("../../wgsl/walk.wgsl")),
    ("response", include_str!("../../wgsl/response.wgsl")),
    ("springs", include_str!("../../wgsl/springs.wgsl")),
    ("impact", include_str!("../../wgsl/impact.wgsl")),
    ("sums", include_str!("../../wgsl/sums.wgsl")),
    ("partials", include_str!("../../wgsl/partials.wgsl")),
];

/// `wgsl/sums_subgroup.wgsl`: the workgroup sums through subgroup
/// operations, in the place of the `sums` include where
/// [`Variant::subgroups`].
pub const SUBGROUP_SUMS: &str = include_str!("../../wgsl/sums_subgroup.wgsl");

/// What one device's kernels are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Variant {
    /// Threads per edge of the network layer's tile
    /// ([`mlp_threads`](crate::gpu::kernels::mlp_threads)).
    pub mlp_threads: u32,
    /// Whether the largest arrays are bound in parts ([`SPLIT_ARRAYS`]).
    pub split: bool,
    /// Whether workgroup sums use subgroup operations: the device has
    /// `wgpu::Features::SUBGROUP` and is not a browser's, whose WGSL asks
    /// for an `enable subgroups;` that naga refuses.
    pub subgroups: bool,
    /// How the solver's vectors lie in memory ([`SOLVER_VECTORS`]).
    pub vectors: VectorLayout,
}

impl Variant {
    /// The kernels' variant for `device`: whether they bind in parts, and
    /// the vectors' layout, are the caller's choice.
    pub fn for_device(device: &wgpu::Device, split: bool, vectors: VectorLayout) -> Variant {
        Variant {
            mlp_threads: crate::gpu::kernels::mlp_threads(&device.limits()),
            split,
            subgroups: cfg!(not(target_arch = "wasm32"))
                && device.features().contains(wgpu::Features::SUBGROUP),
            vectors,
        }
    }
}

/// Stages that do not depend on the scene and get no common code.
pub const STANDALONE: [&str; 2] = ["batch", "mlp"];

/// The arrays that can outgrow one binding (at 1024² the topology is
/// 289 MB, the matrix 176 MB and the multigrid operators 143 MB; a binding
/// holds 128 MiB on lavapipe and by WebGPU's default). The kernels read and
/// write them only through `NAME_at(k)` and `NAME_set(k, value)`, which
/// [`source`] writes: a plain index, or, where the kernels are compiled to
/// split them, a choice among up to [`PARTS`] bindings (`NAME`, `NAME_1`,
/// `NAME_2`: windows of the same buffer) at the element indices
/// `params.NAME_splits`.
pub const SPLIT_ARRAYS: [&str; 3] = ["topology", "matrix", "operators"];
/// The most bindings a split array takes.
pub const PARTS: usize = 3;
/// Binding number of part k of a split array: its own number plus k times this.
pub const PART_BINDING_STRIDE: u32 = 100;

/// The solver's vectors, laid out as [`Variant::vectors`] says: declared
/// `array<VectorEntry>` (`f32` packed, three a vertex, or `vec4<f32>`),
/// read and written only through `NAME_at(i)` and `NAME_set(i, value)` of
/// `vec3<f32>` at vertex (or coarse node) i, which [`source`] writes.
pub const SOLVER_VECTORS: [&str; 7] = ["b", "r", "zq", "p", "p_next", "inv_diag", "vectors"];

/// The WGSL element type of the solver's vectors.
fn vector_entry(vectors: VectorLayout) -> &'static str {
    match vectors {
        VectorLayout::Packed => "f32",
        VectorLayout::Vec4 => "vec4<f32>",
    }
}

/// `NAME_at` and `NAME_set` of a solver vector (see [`SOLVER_VECTORS`]).
fn vector_accessors(name: &str, ty: &str, write: bool, vectors: VectorLayout) -> String {
    assert_eq!(ty, "VectorEntry", "vector `{name}` is declared array<{ty}>");
    let (read, set) = match vectors {
        VectorLayout::Packed => (
            format!("let k = 3u * i; return vec3<f32>({name}[k], {name}[k + 1u], {name}[k + 2u]);"),
            format!(
                "let k = 3u * i; {name}[k] = value.x; {name}[k + 1u] = value.y; \
                 {name}[k + 2u] = value.z;"
            ),
        ),
        VectorLayout::Vec4 => (
            format!("return {name}[i].xyz;"),
            format!("{name}[i] = vec4<f32>(value, 0.0);"),
        ),
    };
    let mut out = format!("fn {name}_at(i: u32) -> vec3<f32> {{ {read} }}\n");
    if write {
        out += &format!("fn {name}_set(i: u32, value: vec3<f32>) {{ {set} }}\n");
    }
    out
}

/// The accessors of every split array ([`SPLIT_ARRAYS`]) and solver
/// vector ([`SOLVER_VECTORS`]) `text` declares.
fn accessors(text: &str, variant: Variant) -> String {
    let mut out = String::new();
    for line in text.lines() {
        let Some((head, declared)) = line.split_once(" var<storage, ") else {
            continue;
        };
        let Some((mode, rest)) = declared.split_once("> ") else {
            continue;
        };
        let Some((name, ty)) = rest.split_once(": array<") else {
            continue;
        };
        let ty = ty.trim_end_matches(">;");
        let write = mode == "read_write";
        if SOLVER_VECTORS.contains(&name) {
            out += &vector_accessors(name, ty, write, variant.vectors);
            continue;
        }
        if !SPLIT_ARRAYS.contains(&name) {
            continue;
        }
        if !variant.split {
            out += &format!("fn {name}_at(k: u32) -> {ty} {{ return {name}[k]; }}\n");
            if write {
                out += &format!("fn {name}_set(k: u32, value: {ty}) {{ {name}[k] = value; }}\n");
            }
            continue;
        }
        let binding: u32 = head
            .split("@binding(")
            .nth(1)
            .and_then(|b| b.split(')').next())
            .and_then(|b| b.parse().ok())
            .unwrap_or_else(|| panic!("`{name}` has no binding number"));
        let group = head.split(" @binding").next().unwrap_or(head);
        for k in 1..PARTS as u32 {
            let number = binding + k * PART_BINDING_STRIDE;
            out += &format!(
                "{group} @binding({number}) var<storage, {mode}> {name}_{k}: array<{ty}>;\n"
            );
        }
        // Parts 1 and 2 start at the element indices params.NAME_splits.
        let pick = |read: bool| {
            let act = |part: &str, index: &str| match read {
                true => format!("return {part}[{index}];"),
                false => format!("{part}[{index}] = value; return;"),
            };
            format!(
                "let s = params.{name}_splits; if k < s.x {{ {} }} if k < s.y {{ {} }} {}",
                act(name, "k"),
                act(&format!("{name}_1"), "k - s.x"),
                act(&format!("{name}_2"), "k - s.y"),
            )
        };
        out += &format!("fn {name}_at(k: u32) -> {ty} {{ {} }}\n", pick(true));
        if write {
            out += &format!("fn {name}_set(k: u32, value: {ty}) {{ {} }}\n", pick(false));
        }
    }
    out
}

/// The includes a stage's code names on its `// Includes: a, b.` line
/// (none without one).
pub fn includes_of(code: &str) -> Vec<&str> {
    code.lines()
        .find_map(|l| l.strip_prefix("// Includes: "))
        .map(|names| names.trim_end_matches('.').split(", ").collect())
        .unwrap_or_default()
}

/// The shared constants ([`constants::prelude`], the network tile set to
/// `mlp_threads` per edge), common code, the stage's includes, the stage's
/// own code, then the accessors of its solver vectors ([`SOLVER_VECTORS`],
/// as [`Variant::vectors`] lays them out) and split arrays
/// ([`SPLIT_ARRAYS`], bound in parts where `split`).
pub fn source(stage: &str, variant: Variant) -> String {
    let body = STAGES
        .iter()
        .find(|(name, _)| *name == stage)
        .unwrap_or_else(|| panic!("no WGSL stage `{stage}`"))
        .1;
    let named = includes_of(body);
    let includes: String = INCLUDES
        .iter()
        .filter(|(name, _)| named.contains(name))
        .map(|(name, text)| match *name == "sums" && variant.subgroups {
            true => format!("{SUBGROUP_SUMS}\n"),
            false => format!("{text}\n"),
        })
        .collect();
    let prelude = constants::prelude(variant.mlp_threads);
    match STANDALONE.contains(&stage) {
        true => format!("{prelude}\n{body}"),
        false => {
            let code = format!("{includes}{body}");
            let accessors = accessors(&code, variant);
            let entry = vector_entry(variant.vectors);
            format!("{prelude}\nalias VectorEntry = {entry};\n{COMMON}\n{code}\n{accessors}")
        }
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

/// Validates `module`, parsed from `src`, with the capabilities `variant`
/// uses; a readable error where it is not valid.
pub fn validate(
    module: &naga::Module,
    variant: Variant,
    src: &str,
) -> Result<naga::valid::ModuleInfo, String> {
    let capabilities = match variant.subgroups {
        true => naga::valid::Capabilities::SUBGROUP,
        false => naga::valid::Capabilities::empty(),
    };
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), capabilities)
        .validate(module)
        .map_err(|e| e.emit_to_string(src))
}

/// Parses and validates a stage with naga, returning a readable error, and
/// lists its entry points with the bindings each uses.
pub fn reflect(stage: &str, variant: Variant) -> Result<Vec<EntryPoint>, String> {
    let src = source(stage, variant);
    let module = naga::front::wgsl::parse_str(&src).map_err(|e| e.emit_to_string(&src))?;
    let info = validate(&module, variant, &src)?;
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
        let includes = INCLUDES.iter().copied();
        STAGES
            .iter()
            .copied()
            .chain(includes)
            .chain([("common", COMMON), ("sums_subgroup", SUBGROUP_SUMS)])
            .collect()
    }

    /// Every variant of the kernels: with either vector layout, with and
    /// without subgroup sums, as
    /// compiled for a device with WebGPU's default limits, and as compiled
    /// to split the largest arrays ([`SPLIT_ARRAYS`]) where the device
    /// allows [`SPLIT_STORAGE_BUFFERS`](crate::gpu::kernels::SPLIT_STORAGE_BUFFERS).
    fn variants() -> impl Iterator<Item = Variant> {
        VectorLayout::ALL.into_iter().flat_map(|vectors| {
            [false, true].into_iter().flat_map(move |split| {
                [false, true].map(|subgroups| Variant {
                    mlp_threads: 16,
                    split,
                    subgroups,
                    vectors,
                })
            })
        })
    }

    #[test]
    fn every_entry_point_validates_and_fits_webgpu_default_limits() {
        for variant in variants() {
            let limit = match variant.split {
                false => wgpu::Limits::default().max_storage_buffers_per_shader_stage,
                true => crate::gpu::kernels::SPLIT_STORAGE_BUFFERS,
            };
            check_bindings(variant, limit);
        }
    }

    #[test]
    fn only_the_subgroup_variant_uses_subgroup_operations() {
        for variant in variants() {
            for stage in ["pcg", "multigrid"] {
                let source = source(stage, variant);
                assert_eq!(source.contains("subgroupAdd"), variant.subgroups);
                assert!(source.contains("fn workgroup_sum(lane: Lane"));
            }
        }
    }

    #[test]
    fn split_arrays_are_reached_only_through_their_accessors() {
        for (file, text) in files() {
            for name in SPLIT_ARRAYS {
                assert!(
                    !text.contains(&format!("{name}[")),
                    "wgsl/{file}.wgsl indexes `{name}` directly: use {name}_at / {name}_set"
                );
            }
        }
        for variant in variants() {
            let source = source("multigrid", variant);
            assert_eq!(source.contains("operators_2"), variant.split);
            assert!(source.contains("fn operators_set("));
            assert!(source.contains("fn matrix_at(") && !source.contains("fn matrix_set("));
        }
    }

    fn check_bindings(variant: Variant, limit: u32) {
        let limits = wgpu::Limits::default();
        for &(stage, _) in STAGES {
            let entries = reflect(stage, variant)
                .unwrap_or_else(|e| panic!("{stage}.wgsl ({variant:?}):\n{e}"));
            assert!(!entries.is_empty(), "{stage} has no entry point");
            for entry in entries {
                let storage = entry
                    .bindings
                    .values()
                    .filter(|b| matches!(b.ty, wgpu::BufferBindingType::Storage { .. }))
                    .count() as u32;
                let uniform = entry.bindings.len() as u32 - storage;
                assert!(
                    storage <= limit && uniform <= limits.max_uniform_buffers_per_shader_stage,
                    "{stage}::{}: {storage} storage and {uniform} uniform buffers",
                    entry.name
                );
            }
        }
    }

    /// Every name on a stage's `// Includes:` line is an include, and every
    /// include is named by some stage.
    #[test]
    fn each_include_is_named_by_a_stage_and_each_name_is_an_include() {
        let named: Vec<&str> = STAGES
            .iter()
            .flat_map(|(_, text)| includes_of(text))
            .collect();
        for name in &named {
            assert!(
                INCLUDES.iter().any(|(n, _)| n == name),
                "`{name}` is no include"
            );
        }
        for (name, _) in INCLUDES {
            assert!(named.contains(name), "no stage includes `{name}`");
        }
        assert_eq!(includes_of("// Includes: a, b.\nfn f() {}"), ["a", "b"]);
        assert!(includes_of("fn f() {}").is_empty());
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
