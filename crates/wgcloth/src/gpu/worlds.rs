//! The kernels of a batch of worlds (issue 67): each scene stage's WGSL
//! rewritten so that the workgroups of row `workgroup_id.y` step world
//! `y` alone. Every per-world buffer holds the worlds' regions one after
//! another; the rewrite offsets each of its indices by the world's region,
//! and reads the world's own [`WorldParams`] where `params` has them. A
//! world's kernels then do exactly what they do alone, on its own data,
//! so world k of a batch ends bit for bit where its scene alone ends.
//!
//! The rewrite works on naga's WGSL output of the validated module, where
//! every name is unique across the module: an identifier that names a
//! global there names the global, never a local that shadows it.

use std::collections::BTreeMap;

use crate::gpu::layout::WorldParams;
use crate::gpu::shaders::{self, Variant};

/// Worlds whose [`WorldParams`] one uniform binding holds: as many as fill
/// WebGPU's default 64 KiB.
pub const WORLDS_PER_BINDING: u32 = 512;

/// Uniform bindings of [`WorldParams`]: with `params` and
/// `world_strides`, four of a stage's 12 by WebGPU's default.
pub const WORLD_PARAMS_BINDINGS: u32 = 2;

/// Worlds one batch holds.
pub const MAX_WORLDS: u32 = WORLDS_PER_BINDING * WORLD_PARAMS_BINDINGS;

/// The storage globals every world shares: the cloth's rest grid and
/// topology, the body's mesh and BVH (in its own frame), the multigrid
/// hierarchy's shape, and the network batch, whose entries name their
/// world (wgsl/contact.wgsl) so the network runs once over every world's
/// contacts.
pub const SHARED: [&str; 11] = [
    "topology",
    "rest_positions",
    "body_vertices",
    "body_normals",
    "body_face_normals",
    "bvh_nodes",
    "bound_hop",
    "hop_list",
    "net_batch",
    "net_inputs",
    "net_outputs",
];

/// Every per-world storage global of the stages, by name: its slot in
/// `world_strides`, the elements of its type one world's region holds.
pub const PER_WORLD: [&str; 31] = [
    "x",
    "v",
    "b",
    "r",
    "zq",
    "p",
    "p_next",
    "inv_diag",
    "vectors",
    "matrix",
    "operators",
    "partials",
    "contacts",
    "responses",
    "triangle_contacts",
    "rigid",
    "bounds",
    "lines",
    "x_start",
    "separations",
    "pairs",
    "dispatches",
    "cloth_lists",
    "cloth_pairs",
    "cloth_loads",
    "frame",
    "state",
    "scalars",
    "scalars_in",
    "scalars_next",
    "scalars_spare",
];

/// The binding in group 0 of each per-world global's region size.
pub const WORLD_STRIDES_BINDING: u32 = 1;
/// The first binding in group 0 of the worlds' own parameters; binding
/// `WORLD_PARAMS_BINDING + k` holds worlds from `k × WORLDS_PER_BINDING`.
pub const WORLD_PARAMS_BINDING: u32 = 2;

/// `vec4<u32>`s of `world_strides`.
pub const STRIDE_VECTORS: usize = PER_WORLD.len().div_ceil(4);

/// The slot of per-world global `name` in `world_strides`.
pub fn slot(name: &str) -> Option<usize> {
    PER_WORLD.iter().position(|n| *n == name)
}

/// The bytes of one element of each per-world global, as the scene
/// stages declare it (one struct of a struct global): a world's region of
/// a buffer is a whole number of each name's elements it is bound under.
pub fn element_bytes(variant: Variant) -> Result<BTreeMap<String, u32>, String> {
    let mut bytes = BTreeMap::new();
    for &(stage, _) in shaders::STAGES {
        if shaders::STANDALONE.contains(&stage) {
            continue;
        }
        let src = shaders::source(stage, variant);
        let module = naga::front::wgsl::parse_str(&src).map_err(|e| e.emit_to_string(&src))?;
        let mut layouter = naga::proc::Layouter::default();
        layouter
            .update(module.to_ctx())
            .map_err(|e| format!("{stage}: {e}"))?;
        for (_, var) in module.global_variables.iter() {
            let Some(name) = var.name.as_deref().filter(|n| slot(n).is_some()) else {
                continue;
            };
            let element = match module.types[var.ty].inner {
                naga::TypeInner::Array { stride, .. } => stride,
                _ => layouter[var.ty].to_stride(),
            };
            if let Some(other) = bytes.insert(name.to_string(), element)
                && other != element
            {
                return Err(format!(
                    "`{name}` is declared with elements of {other} and {element} bytes"
                ));
            }
        }
    }
    Ok(bytes)
}

/// A per-world global as naga writes it: its name in the output, whether
/// it is an array (else a struct, one per world), and its slot.
struct Global {
    name: String,
    array: bool,
    slot: usize,
}

/// Stage `stage`'s WGSL for a batch of worlds: [`shaders::source`]
/// validated, written back by naga, and rewritten as the module says.
pub fn source(stage: &str, variant: Variant) -> Result<String, String> {
    let src = shaders::source(stage, variant);
    let mut module = naga::front::wgsl::parse_str(&src).map_err(|e| e.emit_to_string(&src))?;
    with_workgroup_id(&mut module);
    let info = shaders::validate(&module, variant, &src)?;
    let written =
        naga::back::wgsl::write_string(&module, &info, naga::back::wgsl::WriterFlags::empty())
            .map_err(|e| format!("{stage}: writing WGSL: {e}"))?;
    let mut globals = Vec::new();
    for (_, var) in module.global_variables.iter() {
        let (Some(name), Some(binding)) = (&var.name, &var.binding) else {
            continue;
        };
        if binding.group != 1 || !matches!(var.space, naga::AddressSpace::Storage { .. }) {
            continue;
        }
        if SHARED.contains(&name.as_str()) {
            continue;
        }
        let slot = slot(name).ok_or_else(|| {
            format!("{stage}: `{name}` is neither per world (gpu::worlds::PER_WORLD) nor shared")
        })?;
        let array = matches!(module.types[var.ty].inner, naga::TypeInner::Array { .. });
        globals.push(Global {
            name: written_name(&written, binding.binding)?,
            array,
            slot,
        });
    }
    let body = rewrite(&written, &globals)?;
    let body = with_world_set(&body, &module)?;
    Ok(format!("{}{body}", declarations()))
}

/// Adds a `workgroup_id` argument to each entry point without one.
fn with_workgroup_id(module: &mut naga::Module) {
    let ty = module.types.insert(
        naga::Type {
            name: None,
            inner: naga::TypeInner::Vector {
                size: naga::VectorSize::Tri,
                scalar: naga::Scalar::U32,
            },
        },
        naga::Span::UNDEFINED,
    );
    let group = Some(naga::Binding::BuiltIn(naga::BuiltIn::WorkGroupId));
    for entry in &mut module.entry_points {
        let arguments = &mut entry.function.arguments;
        if !arguments.iter().any(|a| a.binding == group) {
            arguments.push(naga::FunctionArgument {
                name: Some("world_group".into()),
                ty,
                binding: group.clone(),
            });
        }
    }
}

/// The name naga wrote for the group-1 global at `binding`.
fn written_name(written: &str, binding: u32) -> Result<String, String> {
    let mark = format!("@group(1) @binding({binding})");
    let at = written
        .find(&mark)
        .ok_or_else(|| format!("no global at group 1 binding {binding} in naga's WGSL"))?;
    let declared = &written[at + mark.len()..];
    let name = declared
        .split_once('>')
        .map(|(_, rest)| rest.trim_start())
        .and_then(|rest| rest.split_once(':'))
        .map(|(name, _)| name.trim().to_string())
        .ok_or_else(|| format!("global at binding {binding}: no name"))?;
    Ok(name)
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Rewrites every use of a per-world global to world `world`'s element,
/// and every read of a world's own parameter to `world_params[world]`.
fn rewrite(text: &str, globals: &[Global]) -> Result<String, String> {
    let chars: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len() + text.len() / 4);
    let mut at = 0;
    rewrite_span(&chars, &mut at, chars.len(), globals, &mut out)?;
    Ok(out)
}

/// [`rewrite`] of `chars[*at..end]`.
fn rewrite_span(
    chars: &[char],
    at: &mut usize,
    end: usize,
    globals: &[Global],
    out: &mut String,
) -> Result<(), String> {
    let next_char = |from: usize| {
        chars[from..end]
            .iter()
            .copied()
            .find(|c| !c.is_whitespace())
    };
    while *at < end {
        let c = chars[*at];
        let starts_ident =
            (c.is_ascii_alphabetic() || c == '_') && (*at == 0 || !is_ident(chars[*at - 1]));
        if !starts_ident {
            out.push(c);
            *at += 1;
            continue;
        }
        let start = *at;
        while *at < end && is_ident(chars[*at]) {
            *at += 1;
        }
        let ident: String = chars[start..*at].iter().collect();
        let member = chars[..start].iter().rev().find(|c| !c.is_whitespace()) == Some(&'.');
        if member {
            out.push_str(&ident);
            continue;
        }
        if ident == "params" && next_char(*at) == Some('.') {
            let dot = *at
                + chars[*at..end]
                    .iter()
                    .position(|&c| c == '.')
                    .expect("found");
            let mut field_end = dot + 1;
            while field_end < end && is_ident(chars[field_end]) {
                field_end += 1;
            }
            let field: String = chars[dot + 1..field_end].iter().collect();
            if WorldParams::FIELDS.iter().any(|(name, _)| *name == field) {
                out.push_str(&format!("world_{field}()"));
                *at = field_end;
                continue;
            }
        }
        let Some(global) = globals.iter().find(|g| g.name == ident) else {
            out.push_str(&ident);
            continue;
        };
        // The declaration: a struct per world becomes an array of them.
        if next_char(*at) == Some(':') {
            out.push_str(&ident);
            if !global.array {
                let semicolon = *at + chars[*at..end].iter().position(|&c| c == ';').ok_or("")?;
                let ty: String = chars[*at..semicolon].iter().collect();
                let ty = ty.trim_start().trim_start_matches(':').trim();
                out.push_str(&format!(": array<{ty}>"));
                *at = semicolon;
            }
            continue;
        }
        let slot = global.slot;
        if !global.array {
            out.push_str(&format!("{ident}[world_at({slot}u, 0u)]"));
            continue;
        }
        if next_char(*at) != Some('[') {
            return Err(format!("`{ident}` is used other than indexed"));
        }
        let open = *at
            + chars[*at..end]
                .iter()
                .position(|&c| c == '[')
                .expect("found");
        let mut depth = 0;
        let mut close = open;
        for (k, &c) in chars[open..end].iter().enumerate() {
            depth += match c {
                '[' => 1,
                ']' => -1,
                _ => 0,
            };
            if depth == 0 {
                close = open + k;
                break;
            }
        }
        if close == open {
            return Err(format!("`{ident}[` is not closed"));
        }
        out.push_str(&format!("{ident}[world_at({slot}u, "));
        *at = open + 1;
        rewrite_span(chars, at, close, globals, out)?;
        out.push_str(")]");
        *at = close + 1;
    }
    Ok(())
}

/// Each entry point's body starts by setting `world` (common.wgsl) from
/// its workgroup's row (the `workgroup_id` argument [`with_workgroup_id`] made sure of),
/// and keeps its own name (naga escapes one that is also a builtin's).
fn with_world_set(text: &str, module: &naga::Module) -> Result<String, String> {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    for entry in &module.entry_points {
        let at = rest
            .find("@compute")
            .ok_or("fewer entry points than the module's")?;
        let fn_at = at
            + rest[at..]
                .find("fn ")
                .ok_or("an entry point without `fn`")?;
        let open = fn_at
            + rest[fn_at..]
                .find('(')
                .ok_or("an entry point without arguments")?;
        let brace = open
            + rest[open..]
                .find('{')
                .ok_or("an entry point without a body")?;
        let group = rest[open..brace]
            .split_once("@builtin(workgroup_id)")
            .and_then(|(_, args)| args.split_once(':'))
            .map(|(name, _)| name.trim().to_string())
            .ok_or_else(|| format!("entry point `{}` has no workgroup_id", entry.name))?;
        out.push_str(&rest[..fn_at]);
        out.push_str(&format!("fn {}", entry.name));
        out.push_str(&rest[open..=brace]);
        out.push_str(&format!("\n    world = {group}.y;"));
        rest = &rest[brace + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

/// What the rewritten code uses: the world's parameters (`world_F()` for
/// each field F, from the binding that holds the world) and the size of
/// each per-world global's region.
fn declarations() -> String {
    let fields: String = WorldParams::FIELDS
        .iter()
        .map(|(name, ty)| format!("    {name}: {ty},\n"))
        .collect();
    let mut out = format!(
        "struct WorldParams {{\n{fields}}}\n\
         @group(0) @binding({WORLD_STRIDES_BINDING}) var<uniform> world_strides: array<vec4<u32>, {STRIDE_VECTORS}>;\n\
         fn world_at(slot: u32, i: u32) -> u32 {{\n    \
             return world * world_strides[slot / 4u][slot % 4u] + i;\n}}\n"
    );
    for k in 0..WORLD_PARAMS_BINDINGS {
        let binding = WORLD_PARAMS_BINDING + k;
        out += &format!(
            "@group(0) @binding({binding}) var<uniform> world_params_{k}: \
             array<WorldParams, {WORLDS_PER_BINDING}>;\n"
        );
    }
    for (name, ty) in WorldParams::FIELDS {
        let mut body = String::new();
        for k in 0..WORLD_PARAMS_BINDINGS {
            let read = format!(
                "world_params_{k}[world - {}u].{name}",
                k * WORLDS_PER_BINDING
            );
            body += &match k + 1 == WORLD_PARAMS_BINDINGS {
                true => format!("    return {read};\n"),
                false => format!(
                    "    if world < {}u {{ return {read}; }}\n",
                    (k + 1) * WORLDS_PER_BINDING
                ),
            };
        }
        out += &format!("fn world_{name}() -> {ty} {{\n{body}}}\n");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::layout::VectorLayout;

    fn variant(subgroups: bool) -> Variant {
        Variant {
            mlp_threads: 16,
            split: false,
            subgroups,
            vectors: VectorLayout::Packed,
        }
    }

    #[test]
    fn every_scene_stage_rewrites_for_worlds_and_validates() {
        for subgroups in [false, true] {
            for &(stage, _) in shaders::STAGES {
                if shaders::STANDALONE.contains(&stage) {
                    continue;
                }
                let text =
                    source(stage, variant(subgroups)).unwrap_or_else(|e| panic!("{stage}: {e}"));
                let module = naga::front::wgsl::parse_str(&text)
                    .unwrap_or_else(|e| panic!("{stage}:\n{}", e.emit_to_string(&text)));
                shaders::validate(&module, variant(subgroups), &text)
                    .unwrap_or_else(|e| panic!("{stage}:\n{e}"));
            }
        }
    }

    #[test]
    fn world_params_match_their_wgsl_layout() {
        let text = format!(
            "{}var<private> world: u32;\n@compute @workgroup_size(1) fn main() {{ world = 0u; }}",
            declarations()
        );
        let module = naga::front::wgsl::parse_str(&text).expect("parses");
        let (_, ty) = (module.types.iter())
            .find(|(_, t)| t.name.as_deref() == Some("WorldParams"))
            .expect("declared");
        assert_eq!(
            ty.inner.size(module.to_ctx()) as usize,
            size_of::<WorldParams>()
        );
        assert_eq!(size_of::<WorldParams>() as u32 * WORLDS_PER_BINDING, 65536);
    }

    #[test]
    fn indices_of_a_per_world_array_take_the_worlds_region() {
        let globals = [Global {
            name: "x".into(),
            array: true,
            slot: 0,
        }];
        let out = rewrite(
            "let y = x[i + x[j]]; let z = v.x[1]; let w = params.kn;",
            &globals,
        )
        .expect("rewrites");
        assert_eq!(
            out,
            "let y = x[world_at(0u, i + x[world_at(0u, j)])]; let z = v.x[1]; \
             let w = world_kn();"
        );
    }
}
