//! The WGSL stages (`wgsl/`, one file per stage, each prefixed with
//! `common.wgsl`), validated with naga, and the bind group layout of each
//! reflected from its global variables, so binding numbers live only in
//! the WGSL and Rust binds buffers by variable name.

use std::collections::BTreeMap;

use wgpu::naga;

/// The stage files, by name.
pub const STAGES: [(&str, &str); 11] = [
    ("rigid", include_str!("../../wgsl/rigid.wgsl")),
    ("collide", include_str!("../../wgsl/collide.wgsl")),
    ("contact", include_str!("../../wgsl/contact.wgsl")),
    ("springs", include_str!("../../wgsl/springs.wgsl")),
    ("assemble", include_str!("../../wgsl/assemble.wgsl")),
    ("pcg", include_str!("../../wgsl/pcg.wgsl")),
    ("integrate", include_str!("../../wgsl/integrate.wgsl")),
    ("measure", include_str!("../../wgsl/measure.wgsl")),
    ("batch", include_str!("../../wgsl/batch.wgsl")),
    ("mlp", include_str!("../../wgsl/mlp.wgsl")),
    ("lines", include_str!("../../wgsl/lines.wgsl")),
];

/// The network layer's threads per tile edge as written in wgsl/mlp.wgsl;
/// [`source_for`] replaces it.
const MLP_THREADS_DECLARED: &str = "const MLP_THREADS: u32 = 16u;";

/// A stage's source for a device: the network layer's tile edge set to
/// `mlp_threads`.
pub fn source_for(stage: &str, mlp_threads: u32) -> String {
    let src = source(stage);
    assert!(
        stage != "mlp" || src.contains(MLP_THREADS_DECLARED),
        "wgsl/mlp.wgsl must declare `{MLP_THREADS_DECLARED}`"
    );
    src.replace(
        MLP_THREADS_DECLARED,
        &format!("const MLP_THREADS: u32 = {mlp_threads}u;"),
    )
}

pub const COMMON: &str = include_str!("../../wgsl/common.wgsl");

/// Shared code with bindings of its own (so not in `COMMON`), and the
/// stages it is prepended to.
pub const INCLUDES: [(&str, &str, &[&str]); 1] = [(
    "bvh",
    include_str!("../../wgsl/bvh.wgsl"),
    &["collide", "measure"],
)];

/// Stages that do not depend on the scene and get no common code.
pub const STANDALONE: [&str; 2] = ["batch", "mlp"];

/// Common code, the stage's includes, then the stage's own code.
pub fn source(stage: &str) -> String {
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
    match STANDALONE.contains(&stage) {
        true => body.to_string(),
        false => format!("{COMMON}\n{includes}{body}"),
    }
}

/// A binding of group 0 as the WGSL declares it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Binding {
    pub binding: u32,
    pub ty: wgpu::BufferBindingType,
}

/// A parsed and validated stage: its bindings by variable name and its
/// entry points.
#[derive(Clone, Debug)]
pub struct Reflected {
    pub bindings: BTreeMap<String, Binding>,
    pub entry_points: Vec<String>,
}

/// Parses and validates a stage with naga, returning a readable error.
pub fn reflect(stage: &str) -> Result<Reflected, String> {
    let src = source(stage);
    let module = naga::front::wgsl::parse_str(&src).map_err(|e| e.emit_to_string(&src))?;
    naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::empty(),
    )
    .validate(&module)
    .map_err(|e| e.emit_to_string(&src))?;
    let mut bindings = BTreeMap::new();
    for (_, var) in module.global_variables.iter() {
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
        if rb.group != 0 {
            return Err(format!("{stage}: `{name}` is not in group 0"));
        }
        bindings.insert(
            name.clone(),
            Binding {
                binding: rb.binding,
                ty,
            },
        );
    }
    let entry_points = module.entry_points.iter().map(|e| e.name.clone()).collect();
    Ok(Reflected {
        bindings,
        entry_points,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_stage_validates_with_naga() {
        for (stage, _) in STAGES {
            let r = reflect(stage).unwrap_or_else(|e| panic!("{stage}.wgsl:\n{e}"));
            assert!(!r.entry_points.is_empty(), "{stage} has no entry point");
            // The network stages have their own uniforms.
            let uniform = match stage {
                "mlp" => "layer_params",
                "batch" => "batch",
                _ => "params",
            };
            assert!(
                r.bindings.contains_key(uniform),
                "{stage} does not read {uniform}"
            );
        }
    }
}
