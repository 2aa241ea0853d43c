//! Registers the compute kernels from the WGSL itself, as
//! `vello_shaders/build.rs` does: every file of `wgsl/` with a `@compute`
//! entry point is a stage (`gpu::shaders::STAGES`), and each entry point a
//! variant of `gpu::kernels::Entry`, documented by the comment above it. A
//! kernel is declared once, where it is written.

use std::fmt::Write;
use std::path::Path;

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("wgsl");
    println!("cargo:rerun-if-changed={}", dir.display());
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("wgsl/ is readable")
        .map(|f| f.expect("wgsl/ is readable").path())
        .filter(|p| p.extension().is_some_and(|e| e == "wgsl"))
        .collect();
    files.sort();

    let mut stages = String::from("&[\n");
    let mut entries = String::from("entry_points! {\n");
    for path in &files {
        let text = std::fs::read_to_string(path).expect("a WGSL file is UTF-8");
        let kernels = entry_points(&text);
        if kernels.is_empty() {
            continue;
        }
        let stage = path.file_stem().unwrap().to_str().unwrap();
        writeln!(
            stages,
            "    ({stage:?}, include_str!({:?})),",
            path.display()
        )
        .unwrap();
        for (name, doc) in kernels {
            let variant = match name.as_str() {
                "main" => camel(stage),
                _ => camel(stage) + &camel(&name),
            };
            let doc = match doc.is_empty() {
                true => format!("`{stage}::{name}`."),
                false => format!("{doc} (`{stage}::{name}`)"),
            };
            writeln!(
                entries,
                "    #[doc = {doc:?}]\n    {variant} => ({stage:?}, {name:?}),"
            )
            .unwrap();
        }
    }
    stages.push_str("]\n");
    entries.push_str("}\n");
    let out = std::env::var("OUT_DIR").expect("cargo sets OUT_DIR");
    let out = Path::new(&out);
    std::fs::write(out.join("stages.rs"), stages).unwrap();
    std::fs::write(out.join("entries.rs"), entries).unwrap();
}

/// Each `@compute` function's name and the `//` comment lines right above
/// its attributes, joined.
fn entry_points(text: &str) -> Vec<(String, String)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut found = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        if !line.trim_start().starts_with("@compute") {
            continue;
        }
        let name = lines[i..]
            .iter()
            .find_map(|l| l.trim_start().strip_prefix("fn "))
            .and_then(|rest| rest.split('(').next())
            .expect("a @compute attribute is followed by its fn")
            .trim()
            .to_string();
        let mut doc: Vec<&str> = lines[..i]
            .iter()
            .rev()
            .map_while(|l| l.trim_start().strip_prefix("//"))
            .map(str::trim)
            .collect();
        doc.reverse();
        found.push((name, doc.join(" ")));
    }
    found
}

/// `snake_case` as `CamelCase`.
fn camel(snake: &str) -> String {
    snake
        .split('_')
        .map(|w| {
            let mut c = w.chars();
            c.next()
                .map(|f| f.to_ascii_uppercase().to_string() + c.as_str())
                .unwrap_or_default()
        })
        .collect()
}
