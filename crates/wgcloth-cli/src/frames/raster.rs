//! Frames drawn on the CPU where no adapter can draw (no Vulkan driver):
//! wgsl/render.wgsl's picture rasterised by euc, with the same camera,
//! colours and two-sided Phong (`wgcloth::render::shade`), the cloth
//! smooth-shaded by the same grid vertex normals and the body flat, the
//! wireframe depth-tested in front of the surfaces and the forces drawn
//! over everything.

use euc::Pipeline;
use euc::buffer::Buffer2d;
use euc::rasterizer::{BackfaceCullingDisabled, Lines, Triangles};
use glam::{Mat4, Vec3};
use wgcloth::render::shade::{self, BACKGROUND, BODY, CLOTH, FORCE, WIRE};
use wgcloth::render::{Camera, Frame, Style};

/// What a frame shows, as the GPU renderer's buffers hold it.
pub struct Geometry<'a> {
    /// Cloth positions, `grid[0]` × `grid[1]` vertices, row after row.
    pub cloth: &'a [Vec3],
    pub grid: [u32; 2],
    pub triangles: &'a [[u32; 3]],
    /// The body's vertices placed in the world, and its triangles.
    pub body: &'a [Vec3],
    pub body_triangles: &'a [[u32; 3]],
    /// Force segments, two per contact slot (w = 0: no contact).
    pub lines: &'a [[f32; 4]],
}

/// Clip depth a line is pulled towards the eye by (in multiples of w), so
/// that the wireframe wins over the surface it lies on, as the GPU's
/// depth bias on surfaces does.
const LINE_BIAS: f32 = 1e-5;

type Triple = (f32, f32, f32);

fn triple(v: Vec3) -> Triple {
    (v.x, v.y, v.z)
}

fn vec((x, y, z): Triple) -> Vec3 {
    Vec3::new(x, y, z)
}

/// A triangle corner: its world position, its vertex normal (zero: flat)
/// and its triangle's normal.
type Corner = (Vec3, Vec3, Vec3);

/// Lit surfaces of one colour.
struct Surfaces {
    view_proj: Mat4,
    light: (Vec3, Vec3),
    base: Vec3,
}

impl Pipeline for Surfaces {
    type Vertex = Corner;
    type VsOut = (Triple, Triple, Triple);
    type Pixel = [u8; 4];

    fn vert(&self, &(p, normal, face): &Corner) -> ([f32; 4], Self::VsOut) {
        let clip = self.view_proj * p.extend(1.0);
        (clip.to_array(), (triple(p), triple(normal), triple(face)))
    }

    fn frag(&self, &(p, normal, face): &Self::VsOut) -> [u8; 4] {
        let c = shade::phong(vec(p), vec(normal), vec(face), self.light, self.base);
        shade::srgb(c)
    }
}

/// Segments of one colour; depth-tested where drawn with a depth buffer.
struct Segments {
    view_proj: Mat4,
    colour: [u8; 4],
}

impl Pipeline for Segments {
    type Vertex = Vec3;
    type VsOut = ();
    type Pixel = [u8; 4];

    fn vert(&self, p: &Vec3) -> ([f32; 4], ()) {
        let mut clip = self.view_proj * p.extend(1.0);
        clip.z -= LINE_BIAS * clip.w;
        (clip.to_array(), ())
    }

    fn frag(&self, _: &()) -> [u8; 4] {
        self.colour
    }
}

/// Each triangle's corners: the cloth's with their grid vertex normals,
/// or flat (`grid` None, the body's).
fn corners(x: &[Vec3], triangles: &[[u32; 3]], grid: Option<[u32; 2]>) -> Vec<Corner> {
    let normals: Vec<Vec3> = match grid {
        Some(grid) => (0..x.len() as u32)
            .map(|v| shade::grid_normal(x, grid, v))
            .collect(),
        None => vec![Vec3::ZERO; x.len()],
    };
    triangles
        .iter()
        .flat_map(|t| {
            let [a, b, c] = t.map(|i| x[i as usize]);
            let face = (b - a).cross(c - a).normalize_or_zero();
            t.map(|i| (x[i as usize], normals[i as usize], face))
        })
        .collect()
}

/// A frame of `width` × `height` pixels of `geometry` seen by `camera`.
pub fn render(
    geometry: &Geometry,
    camera: &Camera,
    style: Style,
    [width, height]: [u32; 2],
) -> Frame {
    let size = [width as usize, height as usize];
    let view_proj = camera.view_proj(width as f32 / height as f32);
    let mut colour = Buffer2d::new(size, shade::srgb(BACKGROUND));
    let mut depth = Buffer2d::new(size, 1.0f32);
    let light = (camera.eye, camera.light);
    let g = geometry;
    for (base, corners) in [
        (CLOTH, corners(g.cloth, g.triangles, Some(g.grid))),
        (BODY, corners(g.body, g.body_triangles, None)),
    ] {
        let surfaces = Surfaces {
            view_proj,
            light,
            base,
        };
        surfaces.draw::<Triangles<_, BackfaceCullingDisabled>, _>(
            &corners,
            &mut colour,
            Some(&mut depth),
        );
    }
    let segments = |colour| Segments {
        view_proj,
        colour: shade::srgb(colour),
    };
    if style.wireframe {
        let edges: Vec<Vec3> = (g.triangles.iter())
            .flat_map(|t| [t[0], t[1], t[1], t[2], t[2], t[0]])
            .map(|i| g.cloth[i as usize])
            .collect();
        segments(WIRE).draw::<Lines<_>, _>(&edges, &mut colour, Some(&mut depth));
    }
    if style.forces {
        let ends: Vec<Vec3> = (g.lines.chunks_exact(2))
            .filter(|pair| pair[0][3] != 0.0)
            .flat_map(|pair| pair.iter().map(|p| Vec3::new(p[0], p[1], p[2])))
            .collect();
        segments(FORCE).draw::<Lines<Buffer2d<f32>>, _>(&ends, &mut colour, None);
    }
    Frame {
        width,
        height,
        rgba: colour.as_ref().iter().flatten().copied().collect(),
    }
}
