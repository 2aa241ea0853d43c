//! The README's table of `wgcloth run` flags says what the binary takes:
//! every flag it names is one `wgcloth run --help` lists, and each list of
//! values it gives (`--model naive|friction|…`) is the one the flag
//! accepts, so the table cannot drift from the command.

use std::collections::BTreeSet;
use std::process::Command;

/// The flags table: the rows of the first table after "Useful flags".
fn flag_rows() -> Vec<&'static str> {
    let readme = include_str!("../../../README.md");
    let after = readme
        .split("Useful flags")
        .nth(1)
        .expect("the README has its \"Useful flags\" table");
    (after.lines())
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .skip(2)
        .collect()
}

/// `wgcloth run --help`.
fn help() -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_wgcloth"))
        .args(["run", "--help"])
        .output()
        .expect("wgcloth runs");
    assert!(out.status.success());
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// The values `--flag` accepts, from the error a bad one gets.
fn accepted(flag: &str) -> BTreeSet<String> {
    let out = Command::new(env!("CARGO_BIN_EXE_wgcloth"))
        .args(["run", flag, "not-a-value"])
        .output()
        .expect("wgcloth runs");
    let stderr = String::from_utf8_lossy(&out.stderr).to_string();
    // clap's own list, or the one a parser of the library's names gives.
    let list = ["possible values: ", "expected one of "]
        .iter()
        .find_map(|lead| stderr.split(lead).nth(1))
        .unwrap_or_else(|| panic!("{flag}: no list of values in {stderr}"));
    let list = list
        .lines()
        .next()
        .unwrap_or_default()
        .trim_end_matches(']');
    list.split(", ").map(str::to_string).collect()
}

#[test]
fn the_readme_flag_table_names_the_flags_and_values_run_takes() {
    let help = help();
    let rows = flag_rows();
    assert!(rows.len() > 10, "{rows:?}");
    let mut lists = 0;
    for row in rows {
        let first = row.split(" | ").next().unwrap_or_default();
        // Each `--flag` or `--flag a\|b` in the first cell, backquoted.
        for cell in first.split('`').skip(1).step_by(2) {
            let mut words = cell.split(' ');
            let flag = words.next().unwrap_or_default();
            assert!(flag.starts_with("--"), "{cell} in {row}");
            assert!(
                help.contains(&format!("{flag} ")) || help.contains(&format!("{flag}\n")),
                "README names {flag}, which `wgcloth run --help` does not list"
            );
            if let Some(values) = words.next().filter(|v| v.contains("\\|")) {
                let listed: BTreeSet<String> = values.split("\\|").map(str::to_string).collect();
                assert_eq!(listed, accepted(flag), "README's values of {flag}");
                lists += 1;
            }
        }
    }
    // --scene, --model, --backend, --vectors, --preconditioner, --smoother.
    assert!(lists >= 6, "only {lists} value lists found");
}
