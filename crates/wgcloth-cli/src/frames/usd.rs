//! `wgcloth run --out DIR --export usd`: the whole run as one USD file,
//! `animation.usda`, written by the openusd crate: the cloth and the body
//! as two `UsdGeomMesh` prims, `/World/cloth` and `/World/body`, whose
//! `points` (and `extent`) are sampled at each recorded step. Time codes
//! are steps and `timeCodesPerSecond` is 1 / h, so a time code's seconds
//! are the simulation's; y is up and a unit is a metre.

use std::path::Path;

use glam::Vec3;
use openusd::gf::Vec3f;
use openusd::sdf::{self, ChildrenKey, FieldKey, SpecType, Specifier, Value, Variability};
use openusd::usda::TextWriter;

use wgcloth::error::{Error, Result};
use wgcloth::scene::Scene;

/// The run's USD file in the frame directory.
pub const USD_NAME: &str = "animation.usda";

/// A mesh's samples: (time code, points) and (time code, extent).
#[derive(Default)]
struct Samples {
    points: Vec<(f64, Value)>,
    extent: Vec<(f64, Value)>,
}

impl Samples {
    fn push(&mut self, step: f64, points: &[Vec3]) {
        let (lo, hi) = points.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let vec3f = |p: Vec3| Vec3f::from(p.to_array());
        let points = points.iter().copied().map(vec3f).collect();
        self.points.push((step, Value::Vec3fVec(points)));
        self.extent
            .push((step, Value::Vec3fVec(vec![vec3f(lo), vec3f(hi)])));
    }
}

/// The frames of a run, gathered until [`UsdRecording::write`].
#[derive(Default)]
pub struct UsdRecording {
    cloth: Samples,
    body: Samples,
    steps: Vec<f64>,
}

impl UsdRecording {
    /// The frame of step `step`: the cloth at `x`, the body placed at the
    /// step's time.
    pub fn push(&mut self, scene: &Scene, step: u64, x: &[Vec3]) {
        let code = step as f64;
        self.cloth.push(code, x);
        if let Some(body) = &scene.rigid {
            let time = step as f32 * scene.config.solver.dt;
            self.body.push(code, &body.placed_vertices(time));
        }
        self.steps.push(code);
    }

    /// Writes the frames of `scene`'s run to `path` as USD text.
    pub fn write(self, path: &Path, scene: &Scene) -> Result<()> {
        let mut data = sdf::Data::new();
        let root = data.create_spec(sdf::Path::abs_root(), SpecType::PseudoRoot);
        root.add(ChildrenKey::PrimChildren, tokens(&["World"]));
        root.add(FieldKey::DefaultPrim, Value::Token("World".into()));
        root.add("upAxis", Value::Token("Y".into()));
        root.add("metersPerUnit", Value::Double(1.0));
        let (first, last) = (self.steps.first(), self.steps.last());
        root.add(
            FieldKey::StartTimeCode,
            Value::Double(*first.unwrap_or(&0.0)),
        );
        root.add(FieldKey::EndTimeCode, Value::Double(*last.unwrap_or(&0.0)));
        let per_second = (1.0 / scene.config.solver.dt) as f64;
        root.add(FieldKey::TimeCodesPerSecond, Value::Double(per_second));
        // Played back at the simulation's own rate, not a viewer's 24 fps.
        root.add("framesPerSecond", Value::Double(per_second));
        let world = prim(&mut data, "/World", "Xform");
        let meshes: &[&str] = match scene.rigid {
            Some(_) => &["cloth", "body"],
            None => &["cloth"],
        };
        world.add(ChildrenKey::PrimChildren, tokens(meshes));
        mesh(
            &mut data,
            "/World/cloth",
            &scene.cloth.triangles,
            self.cloth,
        );
        if let Some(body) = &scene.rigid {
            mesh(&mut data, "/World/body", &body.mesh.triangles, self.body);
        }
        let text = TextWriter::write_to_string(&data)
            .map_err(|e| Error::file(path, format!("cannot write USD: {e}")))?;
        std::fs::write(path, text).map_err(|e| Error::io(path, e))
    }
}

fn tokens(names: &[&str]) -> Value {
    Value::TokenVec(names.iter().map(|&n| n.into()).collect())
}

fn spec_path(path: &str) -> sdf::Path {
    sdf::Path::new(path).expect("a valid USD path")
}

fn prim<'d>(data: &'d mut sdf::Data, path: &str, kind: &str) -> &'d mut sdf::SpecData {
    let prim = data.create_spec(spec_path(path), SpecType::Prim);
    prim.add(FieldKey::Specifier, Value::Specifier(Specifier::Def));
    prim.add(FieldKey::TypeName, Value::Token(kind.into()));
    prim
}

/// An attribute at `path` of type `kind` with one field (its default or
/// its time samples), `uniform` where it cannot vary in time.
fn attribute(
    data: &mut sdf::Data,
    path: String,
    kind: &str,
    (key, value): (FieldKey, Value),
    uniform: bool,
) {
    let spec = data.create_spec(spec_path(&path), SpecType::Attribute);
    spec.add(FieldKey::TypeName, Value::Token(kind.into()));
    if uniform {
        spec.add(
            FieldKey::Variability,
            Value::Variability(Variability::Uniform),
        );
    }
    spec.add(key, value);
}

/// A `Mesh` of `triangles` at `path`, its points and extent sampled, seen
/// from both sides (cloth has no inside).
fn mesh(data: &mut sdf::Data, path: &str, triangles: &[[u32; 3]], samples: Samples) {
    let properties = [
        "faceVertexCounts",
        "faceVertexIndices",
        "points",
        "extent",
        "doubleSided",
    ];
    prim(data, path, "Mesh").add(ChildrenKey::PropertyChildren, tokens(&properties));
    let at = |name: &str| format!("{path}.{name}");
    let counts = Value::IntVec(vec![3; triangles.len()]);
    let indices = Value::IntVec(triangles.iter().flatten().map(|&i| i as i32).collect());
    attribute(
        data,
        at("faceVertexCounts"),
        "int[]",
        (FieldKey::Default, counts),
        false,
    );
    attribute(
        data,
        at("faceVertexIndices"),
        "int[]",
        (FieldKey::Default, indices),
        false,
    );
    let sampled = |s| (FieldKey::TimeSamples, Value::TimeSamples(s));
    attribute(
        data,
        at("points"),
        "point3f[]",
        sampled(samples.points),
        false,
    );
    attribute(
        data,
        at("extent"),
        "float3[]",
        sampled(samples.extent),
        false,
    );
    let double_sided = (FieldKey::Default, Value::Bool(true));
    attribute(data, at("doubleSided"), "bool", double_sided, true);
}
