//! The library's top-level modules form a one-way stack: each names (by a
//! `crate::` path in its code) only modules below it in [`STACK`], so a
//! reader can draw the library from its imports and no change can close a
//! cycle unseen (issue 66). A new module takes its place in the list.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Bottom to top. Below config are the pieces it and everything else
/// read: errors, small maths, the CPU's split into threads, the grid
/// walks and the networks' weights files; then the scene; then the
/// physics (the CPU twins) and the GPU host side over it; then what
/// compares and draws the two paths.
const STACK: [&str; 16] = [
    "error",
    "math",
    "parallel",
    "grid",
    "nn",
    "config",
    "bvh",
    "scene",
    "stage",
    "multigrid",
    "health",
    "intersections",
    "cpu",
    "gpu",
    "sensitivity",
    "render",
];

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `text` with its comments blanked out (line breaks kept, so line
/// numbers hold); string literals are left as they are.
fn code_of(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while !rest.is_empty() {
        if rest.starts_with("//") {
            let end = rest.find('\n').unwrap_or(rest.len());
            rest = &rest[end..];
        } else if rest.starts_with("/*") {
            let end = rest.find("*/").map_or(rest.len(), |e| e + 2);
            out.extend(rest[..end].chars().filter(|&c| c == '\n'));
            rest = &rest[end..];
        } else {
            let c = rest.chars().next().unwrap();
            out.push(c);
            rest = &rest[c.len_utf8()..];
        }
    }
    out
}

/// The identifier at the start of `s`.
fn ident(s: &str) -> &str {
    let end = s
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(s.len());
    &s[..end]
}

/// The top-level modules `code` names, each with the line of its first
/// mention: `crate::m…` paths, and the first segment of each item of a
/// `use crate::{…}` group.
fn named(code: &str) -> BTreeMap<String, usize> {
    let mut found = BTreeMap::new();
    let line_of = |at: usize| code[..at].matches('\n').count() + 1;
    for (at, _) in code.match_indices("crate::") {
        let after = &code[at + "crate::".len()..];
        if let Some(group) = after.strip_prefix('{') {
            // The group's items at depth 0, up to its closing brace.
            let (mut depth, mut start) = (0usize, true);
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => start = true,
                    c if start && !c.is_whitespace() => {
                        start = false;
                        let name = ident(&group[i..]);
                        found.entry(name.to_string()).or_insert(line_of(at));
                    }
                    _ => {}
                }
            }
        } else {
            let name = ident(after);
            found.entry(name.to_string()).or_insert(line_of(at));
        }
    }
    found
}

/// The items lib.rs re-exports (`pub use m::Item;` or `pub use m::{A,
/// B};`), each with its module: `crate::Item` names that module.
fn reexports(lib: &str) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for line in code_of(lib).lines() {
        let Some(path) = line.trim().strip_prefix("pub use ") else {
            continue;
        };
        let module = ident(path);
        let items = path[module.len()..].trim_start_matches("::");
        let items = items
            .trim_end_matches(';')
            .trim_matches(|c| c == '{' || c == '}');
        for item in items.split(',') {
            out.insert(item.trim().to_string(), module.to_string());
        }
    }
    out
}

#[test]
fn each_module_names_only_modules_below_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    files.sort();
    let reexported = reexports(&std::fs::read_to_string(src.join("lib.rs")).unwrap());
    let place = |m: &str| {
        let m = reexported.get(m).map_or(m, String::as_str);
        STACK.iter().position(|&s| s == m)
    };
    let mut wrong = Vec::new();
    for file in &files {
        let rel = file.strip_prefix(&src).unwrap();
        // The root declares every module.
        if rel == Path::new("lib.rs") {
            continue;
        }
        let first = rel.components().next().unwrap().as_os_str();
        let module = first.to_str().unwrap().trim_end_matches(".rs");
        let Some(level) = place(module) else {
            wrong.push(format!(
                "module `{module}` ({}) has no place in STACK",
                rel.display()
            ));
            continue;
        };
        let code = code_of(&std::fs::read_to_string(file).unwrap());
        for (other, line) in named(&code) {
            match place(&other) {
                Some(l) if l > level => wrong.push(format!(
                    "{}:{line}: `{module}` names `{other}`, which is above it",
                    rel.display()
                )),
                _ => {}
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// The parse the test rests on: a path, a one-line and a nested
/// multi-line group, and names in comments left out.
#[test]
fn the_parse_finds_paths_and_groups_but_not_comments() {
    let code = code_of(
        "use crate::cpu::GRAIN;\n\
         use crate::{config::Config, gpu::{a, b},\n    scene::Scene};\n\
         // crate::render\n\
         /* crate::bvh */ let x = crate::nn::weights::f();\n",
    );
    let names: Vec<(String, usize)> = named(&code).into_iter().collect();
    let expect = [
        ("config", 2),
        ("cpu", 1),
        ("gpu", 2),
        ("nn", 5),
        ("scene", 2),
    ];
    assert_eq!(
        names,
        expect.map(|(n, l)| (n.to_string(), l)).to_vec(),
        "{code}"
    );
    let lib = "pub use config::Config;\npub use error::{Error, Result};\n";
    let modules: Vec<(String, String)> = reexports(lib).into_iter().collect();
    let expect = [
        ("Config", "config"),
        ("Error", "error"),
        ("Result", "error"),
    ];
    let expect = expect.map(|(i, m)| (i.to_string(), m.to_string()));
    assert_eq!(modules, expect.to_vec());
}
