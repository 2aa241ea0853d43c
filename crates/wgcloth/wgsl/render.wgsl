// Render pipeline (thesis Figures 1–2): the cloth, smoothly shaded with
// vertex normals, and the rigid body, flat, both with two-sided Phong, an optional cloth wireframe, and each contact's
// force as a green segment. Vertices are pulled from the simulator's own
// storage buffers by index, so nothing is copied to draw a frame. Not a
// compute stage: src/render owns its pipelines. The colours and Phong's
// terms (CLOTH_COLOR, AMBIENT, …) come from src/render/shade.rs, which
// holds this file's `grid_normal` and `phong` twins for the CPU.

struct Camera {
    view_proj: mat4x4<f32>,
    eye: vec4<f32>,
    // Direction towards the light.
    light: vec4<f32>,
    // The cloth grid's vertices per row and per column (x, y).
    grid: vec4<u32>,
}

@group(0) @binding(0) var<uniform> camera: Camera;
// Cloth positions (xyz, w unused) and triangles (three indices each).
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> triangles: array<u32>;
// The placed rigid body.
@group(0) @binding(3) var<storage, read> body_vertices: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> body_triangles: array<u32>;
// Segment endpoints in pairs; w = 0 marks an unused pair (wgsl/lines.wgsl).
@group(0) @binding(5) var<storage, read> lines: array<vec4<f32>>;

struct Surface {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    // The vertex normal, zero where the surface is drawn flat.
    @location(1) normal: vec3<f32>,
}

fn surface_at(p: vec3<f32>) -> Surface {
    return Surface(camera.view_proj * vec4<f32>(p, 1.0), p, vec3<f32>(0.0));
}

// Cloth vertex (row r, column c) = r * nx + c.
fn grid_position(c: u32, r: u32) -> vec3<f32> {
    return positions[r * camera.grid.x + c].xyz;
}

// A cloth vertex's normal from its grid neighbours: the cross product of
// the central differences along the row and the column (one-sided at the
// border), which weighs the four cells around the vertex alike.
fn grid_normal(v: u32) -> vec3<f32> {
    let nx = camera.grid.x;
    let ny = camera.grid.y;
    let c = v % nx;
    let r = v / nx;
    let along_row = grid_position(min(c + 1u, nx - 1u), r) - grid_position(max(c, 1u) - 1u, r);
    let along_column = grid_position(c, min(r + 1u, ny - 1u)) - grid_position(c, max(r, 1u) - 1u);
    return cross(along_row, along_column);
}

@vertex
fn vs_cloth(@builtin(vertex_index) i: u32) -> Surface {
    let v = triangles[i];
    var s = surface_at(positions[v].xyz);
    s.normal = grid_normal(v);
    return s;
}

@vertex
fn vs_body(@builtin(vertex_index) i: u32) -> Surface {
    return surface_at(body_vertices[body_triangles[i]].xyz);
}

// Edge k of triangle t as two vertices: corners (0,1), (1,2), (2,0).
@vertex
fn vs_wire(@builtin(vertex_index) i: u32) -> Surface {
    let t = i / 6u;
    let corner = array<u32, 6>(0u, 1u, 1u, 2u, 2u, 0u)[i % 6u];
    return surface_at(positions[triangles[3u * t + corner]].xyz);
}

@vertex
fn vs_line(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let pair = i / 2u;
    if lines[2u * pair].w == 0.0 {
        // Outside the clip volume: the segment is dropped.
        return vec4<f32>(0.0, 0.0, 2.0, 1.0);
    }
    return camera.view_proj * vec4<f32>(lines[i].xyz, 1.0);
}

// Phong on the side facing the viewer, so both sides of the cloth are
// lit. The face normal comes from the screen-space derivatives of the
// position; the interpolated vertex normal, where there is one, shades,
// turned to the face normal's side (a fold's vertex normals may point
// away from a face the viewer sees).
fn phong(s: Surface, base: vec3<f32>) -> vec4<f32> {
    let world = s.world;
    var face = normalize(cross(dpdx(world), dpdy(world)));
    let to_eye = normalize(camera.eye.xyz - world);
    if dot(face, to_eye) < 0.0 {
        face = -face;
    }
    var n = face;
    let vertex = s.normal;
    if dot(vertex, vertex) > 0.0 {
        n = normalize(vertex);
        if dot(n, face) < 0.0 {
            n = -n;
        }
    }
    let l = normalize(camera.light.xyz);
    let diffuse = max(dot(n, l), 0.0);
    let specular = pow(max(dot(reflect(-l, n), to_eye), 0.0), SHININESS);
    return vec4<f32>(base * (AMBIENT + DIFFUSE * diffuse) + vec3<f32>(SPECULAR * specular), 1.0);
}

@fragment
fn fs_cloth(s: Surface) -> @location(0) vec4<f32> {
    return phong(s, CLOTH_COLOR);
}

@fragment
fn fs_body(s: Surface) -> @location(0) vec4<f32> {
    return phong(s, BODY_COLOR);
}

@fragment
fn fs_wire() -> @location(0) vec4<f32> {
    return vec4<f32>(WIRE_COLOR, 1.0);
}

@fragment
fn fs_force() -> @location(0) vec4<f32> {
    return vec4<f32>(FORCE_COLOR, 1.0);
}
