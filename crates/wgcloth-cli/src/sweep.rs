//! Each world's configuration in a batch run (`run --worlds N --sweep
//! FILE`): the run's configuration with a world's values set over it
//! (`Config::with_overrides`). A sweep is a TOML file of `[[world]]`
//! tables laid out as a configuration file is, or a CSV file whose header
//! names dotted keys (`contact.mu`) and whose rows are worlds, each cell a
//! TOML value (a bare word is a string).

use std::path::Path;

use wgcloth::Config;
use wgcloth::error::{Error, Result};

/// The worlds of a sweep file: each world's values, and `base` with them
/// set over it.
pub fn read(path: &Path, base: &Config) -> Result<Vec<(toml::Table, Config)>> {
    let overrides = match path.extension().and_then(|e| e.to_str()) {
        Some("toml") => toml_worlds(path)?,
        Some("csv") => csv_worlds(path)?,
        _ => {
            return Err(Error::file(
                path,
                "is neither a .toml nor a .csv sweep file",
            ));
        }
    };
    if overrides.is_empty() {
        return Err(Error::file(path, "names no world"));
    }
    (overrides.into_iter().enumerate())
        .map(|(k, o)| match base.with_overrides(&o) {
            Ok(config) => Ok((o, config)),
            Err(e) => Err(Error::file(path, format!("world {}: {e}", k + 1))),
        })
        .collect()
}

/// A world's values as dotted `key = value` pairs, for its summary line.
pub fn describe(values: &toml::Table) -> String {
    fn flat(prefix: &str, table: &toml::Table, out: &mut Vec<String>) {
        for (key, value) in table {
            let key = match prefix.is_empty() {
                true => key.clone(),
                false => format!("{prefix}.{key}"),
            };
            match value {
                toml::Value::Table(t) => flat(&key, t, out),
                v => out.push(format!("{key} = {v}")),
            }
        }
    }
    let mut out = Vec::new();
    flat("", values, &mut out);
    out.join(", ")
}

/// The `[[world]]` tables of a TOML sweep.
fn toml_worlds(path: &Path) -> Result<Vec<toml::Table>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let mut doc: toml::Table =
        toml::from_str(&text).map_err(|e| Error::file(path, e.message().trim().to_string()))?;
    let worlds = doc.remove("world");
    if let Some(other) = doc.keys().next() {
        return Err(Error::file(
            path,
            format!("`{other}`: a sweep holds only [[world]] tables"),
        ));
    }
    match worlds {
        None => Ok(Vec::new()),
        Some(toml::Value::Array(worlds)) => (worlds.into_iter())
            .map(|w| match w {
                toml::Value::Table(t) => Ok(t),
                _ => Err(Error::file(path, "`world` holds tables ([[world]])")),
            })
            .collect(),
        Some(_) => Err(Error::file(path, "`world` holds tables ([[world]])")),
    }
}

/// The rows of a CSV sweep, each a table of its header's dotted keys.
fn csv_worlds(path: &Path) -> Result<Vec<toml::Table>> {
    let bad = |e: csv::Error| Error::file(path, e.to_string());
    let mut reader = csv::Reader::from_path(path).map_err(bad)?;
    let keys: Vec<Vec<String>> = (reader.headers().map_err(bad)?.iter())
        .map(|k| k.trim().split('.').map(str::to_string).collect())
        .collect();
    if let Some(k) = keys.iter().find(|k| k.iter().any(String::is_empty)) {
        return Err(Error::file(
            path,
            format!("header `{}` is not a dotted key", k.join(".")),
        ));
    }
    let mut worlds = Vec::new();
    for record in reader.records() {
        let record = record.map_err(bad)?;
        let mut world = toml::Table::new();
        for (key, cell) in keys.iter().zip(record.iter()) {
            set(&mut world, key, value_of(cell.trim()));
        }
        worlds.push(world);
    }
    Ok(worlds)
}

/// A cell as TOML reads it (`0.3`, `true`, `[0, 1, 0]`, `"a b"`), else as
/// a string (`sinusoid`).
fn value_of(cell: &str) -> toml::Value {
    toml::from_str::<toml::Table>(&format!("v = {cell}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(cell.to_string()))
}

/// Sets the dotted `key` in `table`, making the tables on its way.
pub fn set(table: &mut toml::Table, key: &[String], value: toml::Value) {
    match key {
        [] => {}
        [last] => {
            table.insert(last.clone(), value);
        }
        [first, rest @ ..] => {
            let inner = table
                .entry(first.clone())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            if let toml::Value::Table(t) = inner {
                set(t, rest, value);
            }
        }
    }
}
