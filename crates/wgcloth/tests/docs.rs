//! Text kept outside the code says what the code does: the README's
//! "Embed it" code is the crate docs' example, `examples/embed.rs`, word for
//! word, so what a reader copies is what CI runs; its "How a step works"
//! lists the stages of `Stage::ALL` in their order; the fuzzer's config
//! dictionary names every table, key, model and solver choice the config
//! reads.

use wgcloth::Config;
use wgcloth::config::{ModelKind, Preconditioner, SceneKind, Smoother};
use wgcloth::stage::Stage;

#[test]
fn the_readme_embeds_the_example_ci_runs() {
    let readme = include_str!("../../../README.md");
    let example = include_str!("../examples/embed.rs");
    let section = readme
        .split("## Embed it")
        .nth(1)
        .expect("the README has an \"Embed it\" section");
    let code = section
        .split("```rust\n")
        .nth(1)
        .and_then(|rest| rest.split("```").next())
        .expect("the section has a rust code block");
    assert_eq!(
        code, example,
        "README's Embed it code differs from examples/embed.rs"
    );
}

#[test]
fn the_readme_describes_every_stage_in_the_order_a_step_runs_them() {
    let readme = include_str!("../../../README.md");
    let section = (readme.split("## How a step works").nth(1))
        .and_then(|rest| rest.split("\n## ").next())
        .expect("the README has a \"How a step works\" section");
    // Its numbered items, "1. `rigid` — ...", by their stage names.
    let listed: Vec<&str> = (section.lines())
        .filter_map(|l| l.split_once(". `")?.1.split_once('`'))
        .filter(|(_, rest)| rest.starts_with(" —"))
        .map(|(name, _)| name)
        .collect();
    let stages: Vec<&str> = Stage::ALL.iter().map(|s| s.name()).collect();
    assert_eq!(
        listed, stages,
        "README's How a step works against Stage::ALL"
    );
}

/// The `[table]` headers and `key = ` entries of a TOML table, nested ones
/// under their dotted path.
fn tokens(table: &toml::Table, path: &str, out: &mut Vec<String>) {
    for (key, value) in table {
        match value {
            toml::Value::Table(inner) => {
                let path = format!("{path}{key}");
                out.push(format!("[{path}]"));
                tokens(inner, &format!("{path}."), out);
            }
            _ => out.push(format!("{key} = ")),
        }
    }
}

#[test]
fn the_fuzz_dictionary_names_every_table_key_model_and_solver_of_the_config() {
    let dict = include_str!("../../../fuzz/dicts/config.dict");
    let entries: Vec<&str> = (dict.lines())
        .filter_map(|l| l.strip_prefix('"')?.strip_suffix('"'))
        .collect();
    let config: toml::Table =
        toml::from_str(&toml::to_string(&Config::default()).unwrap()).unwrap();
    let mut wanted = Vec::new();
    tokens(&config, "", &mut wanted);
    let names = (ModelKind::ALL.iter().map(|m| m.name()))
        .chain(SceneKind::ALL.iter().map(|s| s.name()))
        .chain(Preconditioner::ALL.iter().map(|p| p.name()))
        .chain(Smoother::ALL.iter().map(|s| s.name()));
    wanted.extend(names.map(|n| format!("\\\"{n}\\\"")));
    let missing: Vec<&String> = (wanted.iter())
        .filter(|w| !entries.contains(&w.as_str()))
        .collect();
    assert!(
        missing.is_empty(),
        "fuzz/dicts/config.dict lacks {missing:?}"
    );
}
