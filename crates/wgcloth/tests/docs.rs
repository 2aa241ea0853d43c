//! The README's "Embed it" code is the crate docs' example,
//! `examples/embed.rs`, word for word, so what a reader copies is what CI
//! runs.

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
