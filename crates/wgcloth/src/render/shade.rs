//! How a frame is shaded: the colours and the terms of the two-sided Phong
//! of wgsl/render.wgsl, written once here and handed to the shader as
//! constants ([`prelude`]), and the CPU twins of its `grid_normal` and
//! `phong`, which a software rasteriser (the CLI's, where no adapter can
//! draw) shades with.

use glam::Vec3;

/// The cloth's colour (linear RGB).
pub const CLOTH: Vec3 = Vec3::new(0.85, 0.35, 0.25);
/// The rigid body's colour.
pub const BODY: Vec3 = Vec3::new(0.35, 0.45, 0.85);
/// The wireframe's colour.
pub const WIRE: Vec3 = Vec3::new(0.1, 0.1, 0.1);
/// A contact force's colour.
pub const FORCE: Vec3 = Vec3::new(0.0, 1.0, 0.0);
/// The background's colour.
pub const BACKGROUND: Vec3 = Vec3::ONE;
/// Phong: the share of the base colour lit everywhere,
pub const AMBIENT: f32 = 0.3;
/// the share lit by the light along the normal,
pub const DIFFUSE: f32 = 0.65;
/// the white highlight's strength,
pub const SPECULAR: f32 = 0.15;
/// and its exponent.
pub const SHININESS: f32 = 32.0;

/// The constants above in WGSL, in front of wgsl/render.wgsl.
pub fn prelude() -> String {
    let colour = |c: Vec3| format!("vec3<f32>({:?}, {:?}, {:?})", c.x, c.y, c.z);
    format!(
        "const CLOTH_COLOR = {};\nconst BODY_COLOR = {};\nconst WIRE_COLOR = {};\n\
         const FORCE_COLOR = {};\nconst AMBIENT = {AMBIENT:?};\nconst DIFFUSE = {DIFFUSE:?};\n\
         const SPECULAR = {SPECULAR:?};\nconst SHININESS = {SHININESS:?};\n",
        colour(CLOTH),
        colour(BODY),
        colour(WIRE),
        colour(FORCE),
    )
}

/// Cloth vertex `v`'s normal from its grid neighbours, `nx` × `ny`
/// vertices of `x` (twin of `grid_normal`): the cross product of the
/// central differences along its row and its column, one-sided at the
/// border.
pub fn grid_normal(x: &[Vec3], [nx, ny]: [u32; 2], v: u32) -> Vec3 {
    let (c, r) = (v % nx, v / nx);
    let at = |c: u32, r: u32| x[(r * nx + c) as usize];
    let along_row = at((c + 1).min(nx - 1), r) - at(c.max(1) - 1, r);
    let along_column = at(c, (r + 1).min(ny - 1)) - at(c, r.max(1) - 1);
    along_row.cross(along_column)
}

/// The colour of a surface point at `world` (twin of `phong`): lit on the
/// side facing `eye`, its triangle's normal `face` turned that way; a
/// nonzero `vertex` normal shades, turned to the face's side.
pub fn phong(
    world: Vec3,
    vertex: Vec3,
    face: Vec3,
    (eye, light): (Vec3, Vec3),
    base: Vec3,
) -> Vec3 {
    let to_eye = (eye - world).normalize();
    let face = match face.dot(to_eye) < 0.0 {
        true => -face,
        false => face,
    };
    let n = match vertex.length_squared() > 0.0 {
        true if vertex.dot(face) < 0.0 => -vertex.normalize(),
        true => vertex.normalize(),
        false => face,
    };
    let l = light.normalize();
    let diffuse = n.dot(l).max(0.0);
    let specular = (-l).reflect(n).dot(to_eye).max(0.0).powf(SHININESS);
    base * (AMBIENT + DIFFUSE * diffuse) + Vec3::splat(SPECULAR * specular)
}

/// A linear colour as an sRGB target (`Rgba8UnormSrgb`) stores it, opaque.
pub fn srgb(c: Vec3) -> [u8; 4] {
    let encode = |u: f32| {
        let u = u.clamp(0.0, 1.0);
        let s = match u <= 0.003_130_8 {
            true => 12.92 * u,
            false => 1.055 * u.powf(1.0 / 2.4) - 0.055,
        };
        (255.0 * s).round() as u8
    };
    [encode(c.x), encode(c.y), encode(c.z), 255]
}
