//! The configs of `scenes/`, as `wgcloth run --config scenes/NAME.toml`
//! reads them.
#![allow(dead_code)]

use std::path::Path;

use wgcloth::Config;

/// `scenes/NAME.toml`.
pub fn scene_config(name: &str) -> Config {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../../scenes/{name}.toml"));
    let text = std::fs::read_to_string(&path).unwrap();
    let config: Config = toml::from_str(&text).unwrap();
    config.validate().unwrap();
    config
}

/// `scenes/pleat.toml` with its box square to the cloth, so that it pushes
/// exactly edge-on: the cloth stays in its plane and piles up within it,
/// coplanar layers pressed by the box (from 64² on), the failsafe's
/// hardest case: its zones, its last resort and the box's stops all act.
pub fn edge_on_pleat() -> Config {
    let mut config = scene_config("pleat");
    config.rigid.rotation = Default::default();
    config
}
