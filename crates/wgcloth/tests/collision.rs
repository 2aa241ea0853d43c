//! The broad phases (the body's grid, the cloth's BVH) find exactly the
//! contacts an all-pairs search finds.

mod common;

use common::Rng;
use glam::{Quat, Vec3};
use wgcloth::bvh::{Bvh, triangle_boxes};
use wgcloth::cpu::body_grid::BodyGrid;
use wgcloth::cpu::collide::{self, Best, Tolerances, cloth_normal};
use wgcloth::cpu::measure;
use wgcloth::cpu::rigid::{RigidFrame, transform};
use wgcloth::scene::{Cloth, Motion, RigidBody, TriMesh};

fn brute_rigid(body: &RigidBody, frame: &RigidFrame, x: Vec3, tol: Tolerances) -> Option<Best> {
    let p = frame.to_body(x);
    let mut best = None;
    for (t, tri) in body.mesh.triangles.iter().enumerate() {
        let tri = tri.map(|i| body.mesh.vertices[i as usize]);
        Best::consider(&mut best, t as u32, p, tri, body.face_normals[t], tol);
    }
    best
}

fn brute_cloth(cloth: &Cloth, x: &[Vec3], p: Vec3, np: Vec3, tol: Tolerances) -> Option<Best> {
    let mut best = None;
    for (t, tri) in cloth.triangles.iter().enumerate() {
        let n = cloth_normal(cloth, x, t as u32, np);
        Best::consider(&mut best, t as u32, p, tri.map(|i| x[i as usize]), n, tol);
    }
    best
}

#[test]
fn bvh_contacts_equal_all_pairs_contacts() {
    let mut rng = Rng(99);
    let tol = Tolerances {
        thickness: 0.025,
        max_depth: 0.05,
    };
    let (mut total_vf, mut total_fv) = (0, 0);
    for trial in 0..12 {
        let mesh = match trial % 3 {
            0 => TriMesh::icosphere(rng.range(0.1, 0.3), 2),
            1 => TriMesh::cuboid(rng.vec3(0.05, 0.25), 4),
            _ => TriMesh::plane([0.8, 0.8], 6),
        };
        let rotation = Quat::from_axis_angle(rng.vec3(-1.0, 1.0).normalize(), rng.range(0.0, 6.0));
        let body = RigidBody::new(mesh, rotation, rng.vec3(-0.05, 0.05), Motion::Static);
        let mut frame = RigidFrame::default();
        transform(&body, 0.0, &mut frame);
        // A crumpled 16×16 cloth through the body: a grid with random jitter.
        let cloth = Cloth::grid(16, 16, 1.0, 1.0, &[], |u, v| {
            Vec3::new(u - 0.5, 0.5 - v, 0.0) * 0.7
        });
        let x: Vec<Vec3> = cloth
            .rest_positions
            .iter()
            .map(|p| *p + rng.vec3(-0.06, 0.06))
            .collect();
        let mut bvh = Bvh::build(&triangle_boxes(&cloth.rest_positions, &cloth.triangles));
        collide::refit_cloth(&cloth, &mut bvh, &x); // refit, as in a step

        let grid = BodyGrid::new(&body, tol.reach());
        let vf = collide::vertex_face(&grid, &frame, &x, tol);
        let expect_vf: Vec<(u32, u32, f32)> = x
            .iter()
            .enumerate()
            .filter_map(|(i, &xi)| {
                brute_rigid(&body, &frame, xi, tol).map(|b| (i as u32, b.triangle, b.distance))
            })
            .collect();
        let got_vf: Vec<(u32, u32, f32)> = vf
            .iter()
            .map(|c| (c.vertices[0], c.rigid_feature, c.distance))
            .collect();
        assert_eq!(got_vf, expect_vf, "vertex–face, trial {trial}");

        let fv = collide::face_vertex(&cloth, &bvh, &x, &frame, tol);
        let expect_fv: Vec<(u32, u32, f32)> = frame
            .vertices
            .iter()
            .zip(&frame.vertex_normals)
            .enumerate()
            .filter_map(|(k, (&p, &np))| {
                brute_cloth(&cloth, &x, p, np, tol).map(|b| (k as u32, b.triangle, b.distance))
            })
            .collect();
        let got_fv: Vec<(u32, u32, f32)> = fv
            .iter()
            .map(|c| (c.rigid_feature, c.cloth_triangle.unwrap(), c.distance))
            .collect();
        assert_eq!(got_fv, expect_fv, "face–vertex, trial {trial}");
        total_vf += vf.len();
        total_fv += fv.len();
    }
    // The configurations must actually collide for the comparison to mean anything.
    assert!(
        total_vf > 50 && total_fv > 50,
        "{total_vf} vertex–face, {total_fv} face–vertex"
    );
}

#[test]
fn penetration_depth_is_exact_for_a_box_and_close_for_a_sphere() {
    let mut rng = Rng(5);
    let half = Vec3::new(0.2, 0.1, 0.3);
    let rotation = Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
    let offset = Vec3::new(0.5, -0.2, 0.1);
    let boxed = RigidBody::new(TriMesh::cuboid(half, 3), rotation, offset, Motion::Static);
    let mut frame = RigidFrame::default();
    transform(&boxed, 0.0, &mut frame);
    for _ in 0..500 {
        let local = rng.vec3(-0.5, 0.5);
        let expected = (half - local.abs()).min_element().max(0.0);
        let got = measure::penetration_depth(&boxed, &frame, rotation * local + offset);
        assert!(
            (got - expected).abs() < 1e-5,
            "box point {local}: {got} vs {expected}"
        );
    }
    // No depth limit: the centre of a 0.3 m sphere is ~0.3 m deep, far beyond
    // the contact band.
    let sphere = RigidBody::new(
        TriMesh::icosphere(0.3, 3),
        Quat::IDENTITY,
        Vec3::ZERO,
        Motion::Static,
    );
    transform(&sphere, 0.0, &mut frame);
    for _ in 0..500 {
        let p = rng.vec3(-0.4, 0.4);
        let expected = (0.3 - p.length()).max(0.0);
        let got = measure::penetration_depth(&sphere, &frame, p);
        // Facets lie inside the true sphere by up to r (1 − cos θ) ≈ 3 mm.
        assert!(
            (got - expected).abs() < 4e-3,
            "sphere point {p}: {got} vs {expected}"
        );
    }
}

/// The inside test casts a ray, and a ray that passes exactly through a
/// mesh vertex or along an edge shared by two triangles must count that
/// crossing once: every such ray of a sphere and of a box (whose faces'
/// grid lines and diagonals the ray meets exactly), from points before,
/// inside and past the body ([`common::on_rays_through_vertices_and_edges`]).
#[test]
fn a_ray_through_a_mesh_vertex_or_edge_counts_one_crossing() {
    let bodies = [
        TriMesh::icosphere(0.2, 3),
        TriMesh::cuboid(Vec3::new(0.2, 0.1, 0.3), 4),
    ]
    .map(|mesh| RigidBody::new(mesh, Quat::IDENTITY, Vec3::ZERO, Motion::Static));
    let (mut checked, mut wrong) = (0, Vec::new());
    for body in &bodies {
        for p in common::on_rays_through_vertices_and_edges(body) {
            let Some(expected) = common::inside_convex(body, p, 1e-4) else {
                continue;
            };
            checked += 1;
            if measure::inside_body(body, p) != expected {
                wrong.push((p, expected));
            }
        }
    }
    assert!(checked > 10_000, "{checked} points checked");
    assert!(
        wrong.is_empty(),
        "{} of {checked} points misjudged, e.g. {:?}",
        wrong.len(),
        &wrong[..wrong.len().min(4)]
    );
}
