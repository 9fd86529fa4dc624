//! Tests of the geometry module: intersection against analytic answers, watertightness, the BVH
//! against brute force, area sampling, the uv footprint and OBJ loading. (Teapot tests live in
//! `teapot.rs`.)

use super::bvh::{intersect_brute_force, WatertightRay};
use super::*;
use crate::math::Ray;
use crate::testing::{chi2_discrete, MeanEstimate};
use arrayvec::ArrayVec;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// A closed UV-sphere mesh with shared vertices (poles, `n_lat - 1` rings of `n_lon`), wound
/// outward.
pub(crate) fn uv_sphere_mesh(n_lat: u32, n_lon: u32, radius: f32) -> TriangleMesh {
    let mut positions = vec![Vec3::new(0.0, 0.0, radius)];
    for i in 1..n_lat {
        let theta = PI * i as f32 / n_lat as f32;
        for j in 0..n_lon {
            let phi = 2.0 * PI * j as f32 / n_lon as f32;
            positions.push(
                radius
                    * Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.sin() * phi.sin(),
                        theta.cos(),
                    ),
            );
        }
    }
    positions.push(Vec3::new(0.0, 0.0, -radius));
    let south = positions.len() as u32 - 1;
    let ring = |i: u32, j: u32| 1 + (i - 1) * n_lon + j % n_lon;
    let mut indices = Vec::new();
    for j in 0..n_lon {
        indices.push([0, ring(1, j), ring(1, j + 1)]);
        indices.push([south, ring(n_lat - 1, j + 1), ring(n_lat - 1, j)]);
    }
    for i in 1..n_lat - 1 {
        for j in 0..n_lon {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i + 1, j),
                ring(i + 1, j + 1),
                ring(i, j + 1),
            );
            indices.push([a, b, c]);
            indices.push([a, c, d]);
        }
    }
    TriangleMesh::new(positions, indices, None, None, None).unwrap()
}

fn shape(geometry: ShapeGeometry) -> Shape {
    Shape {
        geometry,
        material: 0,
        area_light: None,
    }
}

fn random_unit(rng: &mut Pcg64) -> Vec3 {
    crate::sampling::square_to_uniform_sphere(Vec2::new(rng.random(), rng.random()))
}

#[test]
fn ray_triangle_matches_analytic_answer() {
    let (p0, p1, p2) = (
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    );
    let ray = Ray::new(Vec3::new(0.2, 0.3, 5.0), -Vec3::Z);
    let (t, b1, b2) = WatertightRay::new(&ray)
        .intersect(p0, p1, p2, f32::INFINITY)
        .unwrap();
    assert!(
        (t - 5.0).abs() < 1e-6 && (b1 - 0.2).abs() < 1e-6 && (b2 - 0.3).abs() < 1e-6,
        "{t} {b1} {b2}"
    );
    // Oblique ray, non-unit direction: hit at (0.25, 0.25, 0) from (1.25, -0.75, 2): d = (-1, 1, -2) t=1.
    let ray = Ray::new(Vec3::new(1.25, -0.75, 2.0), Vec3::new(-1.0, 1.0, -2.0));
    let (t, b1, b2) = WatertightRay::new(&ray)
        .intersect(p0, p1, p2, f32::INFINITY)
        .unwrap();
    assert!((t - 1.0).abs() < 1e-6 && (b1 - 0.25).abs() < 1e-6 && (b2 - 0.25).abs() < 1e-6);
    // Back side hits too (two-sided); outside, behind and beyond t_max miss.
    assert!(
        WatertightRay::new(&Ray::new(Vec3::new(0.2, 0.3, -5.0), Vec3::Z))
            .intersect(p0, p1, p2, f32::INFINITY)
            .is_some()
    );
    assert!(
        WatertightRay::new(&Ray::new(Vec3::new(0.6, 0.6, 5.0), -Vec3::Z))
            .intersect(p0, p1, p2, f32::INFINITY)
            .is_none()
    );
    assert!(
        WatertightRay::new(&Ray::new(Vec3::new(0.2, 0.3, 5.0), Vec3::Z))
            .intersect(p0, p1, p2, f32::INFINITY)
            .is_none()
    );
    assert!(
        WatertightRay::new(&Ray::new(Vec3::new(0.2, 0.3, 5.0), -Vec3::Z))
            .intersect(p0, p1, p2, 4.99)
            .is_none()
    );
    // Parallel to the plane.
    assert!(
        WatertightRay::new(&Ray::new(Vec3::new(-1.0, 0.3, 0.0), Vec3::X))
            .intersect(p0, p1, p2, f32::INFINITY)
            .is_none()
    );
}

/// Rays shot at a closed UV sphere of radius `1.3 scale` centred at `centre`:
/// `(aimed, aimed_misses, random, random_misses)`. Aimed rays go at a vertex (one in four) or a
/// point of an edge, from inside (near the centre) or from outside (about `far` away), and are
/// tested with `intersect`; random ones go from inside in uniform directions and are tested
/// with `intersect` and `occluded`. The only way out of a closed surface is through it, so
/// every miss is a leak.
fn leaks(
    triangles: TriangleTest,
    (centre, scale, far): (Vec3, f32, f32),
    aimed: usize,
    random: usize,
) -> (usize, usize, usize, usize) {
    let place = Transform::scale(Vec3::splat(scale))
        .unwrap()
        .then(&Transform::translate(centre).unwrap());
    let mesh = uv_sphere_mesh(24, 37, 1.3).transformed(&place).unwrap();
    let geometry =
        Geometry::with_triangles(vec![shape(ShapeGeometry::Mesh(mesh.clone()))], triangles);
    let mut rng = Pcg64::seed_from_u64(7);
    let mut aimed_misses = 0;
    for k in 0..aimed {
        let tri = mesh.indices()[rng.random_range(0..mesh.triangle_count())];
        let (a, b) = (
            mesh.positions()[tri[0] as usize],
            mesh.positions()[tri[1] as usize],
        );
        let target = if k % 4 == 0 {
            a
        } else {
            a.lerp(b, rng.random::<f32>())
        };
        let origin = if k % 2 == 0 {
            centre + 0.3 * scale * random_unit(&mut rng)
        } else {
            target + far * ((target - centre).normalize() + 0.8 * random_unit(&mut rng))
        };
        let ray = Ray::new(origin, (target - origin).normalize());
        aimed_misses += geometry.intersect(&ray).is_none() as usize;
    }
    let mut random_misses = 0;
    for _ in 0..random {
        let origin = centre + 0.3 * scale * random_unit(&mut rng);
        let ray = Ray::new(origin, random_unit(&mut rng));
        random_misses += (geometry.intersect(&ray).is_none() || !geometry.occluded(&ray)) as usize;
    }
    (aimed, aimed_misses, random, random_misses)
}

#[test]
fn closed_mesh_is_watertight_at_shared_edges_and_vertices() {
    // The watertight test (the fast test, guarded) on the sphere as it is, seen from far away,
    // small and far from the world's origin (large `o - v0` against small edges: its rounding
    // bound at its widest), and tiny.
    for placement in [
        (Vec3::ZERO, 1.0, 4.0),
        (Vec3::ZERO, 1.0, 500.0),
        (Vec3::new(1000.0, -2000.0, 500.0), 0.05, 50.0),
        (Vec3::new(3.0, 1.0, -2.0), 0.01, 5.0),
    ] {
        let (aimed, aimed_misses, random, random_misses) =
            leaks(TriangleTest::Watertight, placement, 40_000, 20_000);
        assert_eq!(
            (aimed_misses, random_misses),
            (0, 0),
            "{placement:?}: {aimed_misses} of {aimed} rays aimed at edges and {random_misses} of {random} random rays slipped through"
        );
    }
}

#[test]
fn closed_mesh_leaks_only_where_aimed_at_its_edges() {
    // What the fast test gives up (`TriangleTest::Fast`): of rays aimed exactly at a shared
    // edge or vertex, some pass between the triangles (3.4 % measured; at most 5 % allowed), but
    // rays in random directions, which meet an edge only by chance, do not leak.
    let (aimed, aimed_misses, random, random_misses) =
        leaks(TriangleTest::Fast, (Vec3::ZERO, 1.0, 4.0), 40_000, 200_000);
    let share = aimed_misses as f64 / aimed as f64;
    eprintln!("fast test: {aimed_misses} of {aimed} aimed rays leak, {random_misses} of {random} random ones");
    assert!(
        share < 0.05,
        "{aimed_misses} of {aimed} rays aimed at edges slipped through"
    );
    assert_eq!(
        random_misses, 0,
        "{random_misses} of {random} random rays slipped through"
    );
}

fn test_scene() -> Vec<Shape> {
    let t = Transform::rotate(Vec3::new(1.0, 2.0, 0.5), 40.0)
        .unwrap()
        .then(&Transform::translate(Vec3::new(0.5, 0.0, 0.2)).unwrap());
    vec![
        shape(ShapeGeometry::Mesh(
            uv_sphere_mesh(12, 20, 1.0).transformed(&t).unwrap(),
        )),
        shape(ShapeGeometry::sphere(Vec3::new(-1.5, 0.5, 0.0), 0.7).unwrap()),
        shape(ShapeGeometry::Mesh(
            TriangleMesh::rectangle()
                .transformed(
                    &Transform::scale(Vec3::splat(3.0))
                        .unwrap()
                        .then(&Transform::translate(Vec3::new(0.0, 0.0, -1.0)).unwrap()),
                )
                .unwrap(),
        )),
        shape(ShapeGeometry::Mesh(
            TriangleMesh::cuboid()
                .transformed(
                    &Transform::scale(Vec3::new(0.5, 0.2, 0.4))
                        .unwrap()
                        .then(&Transform::translate(Vec3::new(1.0, 1.5, 0.0)).unwrap()),
                )
                .unwrap(),
        )),
    ]
}

/// Compares `intersect` and `occluded` of the binary BVH (whose leaves take Woop, Benthin and
/// Wald's test, as brute force does) with brute force over `rays`: the same hits bit for bit.
fn check_against_brute_force(shapes: &[Shape], rays: &[Ray]) -> usize {
    let geometry = Geometry::with_bvh(shapes.to_vec(), BvhKind::Bvh2, TriangleTest::Watertight);
    let mut hits = 0;
    for ray in rays {
        let bvh = geometry.intersect(ray);
        let brute = intersect_brute_force(shapes, ray);
        match (bvh, brute) {
            (None, None) => {}
            (Some(h), Some((t, s, p))) => {
                hits += 1;
                assert_eq!(h.t, t, "ray {ray:?}");
                assert_eq!((h.shape, h.prim), (s, p), "ray {ray:?}");
                assert!(h.t > 0.0 && h.t < ray.t_max);
                assert!((h.p - ray.at(h.t)).length() < 1e-4 * (1.0 + h.t * ray.d.length()));
                for v in [h.p, h.ng, h.ns, h.dpdu, h.dpdv] {
                    assert!(v.is_finite());
                }
                assert!(h.uv.is_finite());
                assert!(
                    (h.ng.length() - 1.0).abs() < 1e-4
                        && (h.ns.length() - 1.0).abs() < 1e-4
                        && h.ng.dot(h.ns) >= 0.0
                );
            }
            (a, b) => panic!("bvh {a:?} vs brute force {b:?} for {ray:?}"),
        }
        assert_eq!(geometry.occluded(ray), brute.is_some(), "ray {ray:?}");
    }
    hits
}

fn random_rays(rng: &mut Pcg64, n: usize, centre: Vec3, radius: f32) -> Vec<Ray> {
    (0..n)
        .map(|k| {
            let o = centre + radius * random_unit(rng) * rng.random::<f32>().sqrt();
            let mut d = random_unit(rng);
            if k % 7 == 0 {
                // Axis-aligned directions with signed zeros (obvhs picks slabs by the sign bit).
                d = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z][k % 6];
            }
            let mut ray = Ray::new(o, d);
            if k % 3 == 0 {
                ray.t_max = radius * rng.random::<f32>();
            }
            ray
        })
        .collect()
}

/// Compares `intersect` and `occluded` of the 8-wide BVH with the triangle test `triangles`
/// with brute force (Woop, Benthin and Wald's test) over `rays`: the same primitive with `t`
/// within rounding, but for at most one ray in 2,000 (a ray through an edge may find either
/// triangle, or with the fast test slip through); returns the number of rays that hit.
fn check_bvh8_against_brute_force(
    shapes: &[Shape],
    rays: &[Ray],
    triangles: TriangleTest,
) -> usize {
    let geometry = Geometry::with_triangles(shapes.to_vec(), triangles);
    let (mut hits, mut differ) = (0, 0);
    for ray in rays {
        let fast = geometry.intersect(ray);
        let brute = intersect_brute_force(shapes, ray);
        match (fast, brute) {
            (Some(h), Some((t, s, p))) if (h.shape, h.prim) == (s, p) => {
                hits += 1;
                assert!(
                    (h.t - t).abs() <= 1e-5 * (1.0 + t),
                    "{ray:?}: t {} against {t}",
                    h.t
                );
                assert!(h.t > 0.0 && h.t < ray.t_max);
            }
            (None, None) => {}
            _ => differ += 1,
        }
        differ += (geometry.occluded(ray) != brute.is_some()) as usize;
    }
    assert!(
        differ * 2000 <= rays.len(),
        "{differ} of {} rays differ",
        rays.len()
    );
    hits
}

#[test]
fn bvh_closest_hit_equals_brute_force_and_occlusion_agrees() {
    let shapes = test_scene();
    let mut rng = Pcg64::seed_from_u64(11);
    let rays = random_rays(&mut rng, 10_000, Vec3::ZERO, 4.0);
    let hits = check_against_brute_force(&shapes, &rays);
    assert!(
        hits > 2500,
        "only {hits} hits: the test scene is not exercised"
    );
    for triangles in [TriangleTest::Fast, TriangleTest::Watertight] {
        assert!(check_bvh8_against_brute_force(&shapes, &rays, triangles) > 2500);
    }
}

#[test]
fn bvh_closest_hit_equals_brute_force_on_the_teapot() {
    let shapes = vec![shape(ShapeGeometry::Mesh(TriangleMesh::teapot(6)))];
    let mut rng = Pcg64::seed_from_u64(12);
    let mut rays = random_rays(&mut rng, 3_000, Vec3::new(0.0, 0.0, 1.5), 4.0);
    // Camera-like rays from outside.
    for i in 0..40 {
        for j in 0..30 {
            let target = Vec3::new(-3.5 + 7.0 * i as f32 / 39.0, 0.0, 3.3 * j as f32 / 29.0);
            let o = Vec3::new(1.0, -8.0, 2.5);
            rays.push(Ray::new(o, (target - o).normalize()));
        }
    }
    let hits = check_against_brute_force(&shapes, &rays);
    assert!(hits > 1000, "only {hits} hits");
    for triangles in [TriangleTest::Fast, TriangleTest::Watertight] {
        assert!(check_bvh8_against_brute_force(&shapes, &rays, triangles) > 1000);
    }
}

#[test]
fn packets_of_rays_find_what_single_rays_find() {
    // Packets as a pinhole camera makes them: up to PACKET rays from one origin through
    // jittered points of one "pixel" around a random target, some with a short `t_max`. Every
    // ray's hit must be bit for bit the single-ray query's, with either triangle test (which
    // `check_bvh8_against_brute_force` compares with brute force). Packets whose directions
    // straddle an axis, or whose origins differ, fall back to single rays.
    let teapot = vec![shape(ShapeGeometry::Mesh(TriangleMesh::teapot(6)))];
    let scenes = [
        ("test scene", test_scene(), Vec3::ZERO),
        ("teapot", teapot, Vec3::new(0.0, 0.0, 1.5)),
    ];
    for ((name, shapes, centre), triangles) in scenes
        .iter()
        .flat_map(|s| [(s, TriangleTest::Watertight), (s, TriangleTest::Fast)])
    {
        let (name, centre) = (format!("{name}, {triangles:?}"), *centre);
        let geometry = Geometry::with_triangles(shapes.clone(), triangles);
        let mut rng = Pcg64::seed_from_u64(13);
        let (mut hits, mut packets, mut fallbacks) = (0, 0, 0);
        for k in 0..3000 {
            let o = centre + 6.0 * random_unit(&mut rng);
            let target = centre + 1.5 * random_unit(&mut rng) * rng.random::<f32>();
            let pixel = 10f32.powf(rng.random_range(-4.0..-1.0));
            let n = 1 + k % PACKET;
            let straddle = k % 10 == 0;
            let moved = k % 10 == 5;
            let rays: Vec<Ray> = (0..n)
                .map(|j| {
                    let mut d = (target - o).normalize() + pixel * random_unit(&mut rng);
                    if straddle {
                        // One ray on each side of the x = 0 plane (a direction's sign).
                        d.x = if j % 2 == 0 { 1e-3 } else { -1e-3 };
                    }
                    let origin = if moved && j == n - 1 {
                        o + Vec3::X * 1e-3
                    } else {
                        o
                    };
                    let mut ray = Ray::new(origin, d.normalize());
                    if k % 3 == 0 {
                        ray.t_max = 8.0 * rng.random::<f32>();
                    }
                    ray
                })
                .collect();
            let mut out = ArrayVec::new();
            let packet = geometry.intersect_coherent_counted(&rays, &mut out);
            assert_eq!(out.len(), n);
            if packet {
                packets += 1;
                assert!(
                    n > 1 && !(straddle || moved),
                    "{name}: packet {k} can't be one"
                );
            } else if n > 1 && !(straddle || moved) {
                fallbacks += 1;
            }
            for (ray, got) in rays.iter().zip(&out) {
                let single = geometry.intersect(ray);
                assert_eq!(
                    format!("{got:?}"),
                    format!("{single:?}"),
                    "{name}: packet {k} ray {ray:?}"
                );
                hits += got.is_some() as usize;
            }
        }
        assert!(hits > 3000, "{name}: only {hits} hits");
        assert!(
            packets > 2000,
            "{name}: only {packets} packets, {fallbacks} fell back"
        );
    }
}

#[test]
fn hits_very_close_to_the_origin_are_found() {
    // A small triangle 3e-5 ahead must be hit (and occlude) by every hierarchy: a node test that
    // clamps a box's entry distance (as obvhs' compressed wide BVH does, at 1e-4) would skip it.
    // A cluster of 64 tiny triangles (so the BVH's nested boxes are tiny too, not just rounded up to
    // a coarse parent grid) at z in [3e-5, 6e-5], the nearest (z = 3e-5) centred on the z axis.
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for k in 0..64 {
        let c = Vec3::new(
            if k == 0 {
                0.0
            } else {
                2e-5 * ((k % 8) as f32 - 3.5)
            },
            if k == 0 {
                0.0
            } else {
                2e-5 * ((k / 8) as f32 - 3.5)
            },
            3e-5 + if k == 0 { 0.0 } else { 3e-5 * k as f32 / 64.0 },
        );
        let base = positions.len() as u32;
        positions.extend([
            c + Vec3::new(-1e-5, -1e-5, 0.0),
            c + Vec3::new(1e-5, -1e-5, 0.0),
            c + Vec3::new(0.0, 1e-5, 0.0),
        ]);
        indices.push([base, base + 1, base + 2]);
    }
    let tri = TriangleMesh::new(positions, indices, None, None, None).unwrap();
    let far = TriangleMesh::rectangle()
        .transformed(&Transform::translate(Vec3::new(0.0, 0.0, 5.0)).unwrap())
        .unwrap();
    for (kind, triangles) in [
        (BvhKind::Bvh8, TriangleTest::Watertight),
        (BvhKind::Bvh8, TriangleTest::Fast),
        (BvhKind::Bvh2, TriangleTest::Watertight),
    ] {
        let g = Geometry::with_bvh(
            vec![
                shape(ShapeGeometry::Mesh(tri.clone())),
                shape(ShapeGeometry::Mesh(far.clone())),
            ],
            kind,
            triangles,
        );
        let ray = Ray::new(Vec3::ZERO, Vec3::Z);
        let h = g.intersect(&ray).unwrap();
        assert_eq!(h.shape, 0, "{kind:?} {triangles:?}");
        assert!((h.t - 3e-5).abs() < 1e-9);
        let mut short = ray;
        short.t_max = 1e-4;
        assert!(g.occluded(&short), "{kind:?} {triangles:?}");
    }
}

#[test]
fn empty_geometry_hits_nothing() {
    let g = Geometry::new(vec![]);
    let ray = Ray::new(Vec3::ZERO, Vec3::Z);
    assert!(g.intersect(&ray).is_none() && !g.occluded(&ray));
}

#[test]
fn sphere_hit_record_is_exact() {
    let g = Geometry::new(vec![shape(
        ShapeGeometry::sphere(Vec3::new(0.0, 0.0, 1.0), 2.0).unwrap(),
    )]);
    let h = g
        .intersect(&Ray::new(Vec3::new(0.0, -10.0, 1.0), Vec3::Y))
        .unwrap();
    assert!((h.t - 8.0).abs() < 1e-5 && (h.ng - -Vec3::Y).length() < 1e-6 && h.ns == h.ng);
    // uv: phi = 3 pi / 2 -> u = 0.75; theta = pi / 2 -> v = 0.5.
    assert!((h.uv - Vec2::new(0.75, 0.5)).length() < 1e-5, "{:?}", h.uv);
    // From inside: the far side, normal still outward.
    let h = g
        .intersect(&Ray::new(Vec3::new(0.0, 0.0, 1.0), Vec3::X))
        .unwrap();
    assert!((h.t - 2.0).abs() < 1e-5 && (h.ng - Vec3::X).length() < 1e-6);
}

#[test]
fn smooth_normals_are_interpolated_onto_the_geometric_side() {
    // One triangle with vertex normals tilted; one of them points below the plane.
    let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
    let normals = vec![
        Vec3::new(0.3, 0.0, 1.0),
        Vec3::new(0.0, 0.3, 1.0),
        Vec3::new(0.0, 0.0, 1.0),
    ];
    let m = TriangleMesh::new(
        positions.clone(),
        vec![[0, 1, 2]],
        Some(normals),
        None,
        None,
    )
    .unwrap();
    let (_, ng, ns, uv, dpdu, dpdv) = m.surface(0, 0.25, 0.25);
    let expect = (0.5 * Vec3::new(0.3, 0.0, 1.0).normalize()
        + 0.25 * Vec3::new(0.0, 0.3, 1.0).normalize()
        + 0.25 * Vec3::Z)
        .normalize();
    assert!((ns - expect).length() < 1e-5 && (ng - Vec3::Z).length() < 1e-6);
    assert_eq!(uv, Vec2::new(0.25, 0.25));
    assert!(dpdu.cross(dpdv).dot(ng) > 0.0 && dpdu.dot(ng).abs() < 1e-6);
    let flipped = vec![-Vec3::Z; 3];
    let m = TriangleMesh::new(positions, vec![[0, 1, 2]], Some(flipped), None, None).unwrap();
    let (_, ng, ns, ..) = m.surface(0, 0.2, 0.2);
    assert!(ns.dot(ng) > 0.999);
}

#[test]
fn mesh_area_sampling_is_uniform_per_face() {
    // A box with unequal faces: the face hit by each sample must follow area / total (chi-square).
    let mesh = TriangleMesh::cuboid()
        .transformed(&Transform::scale(Vec3::new(0.5, 1.0, 2.0)).unwrap())
        .unwrap();
    let s = shape(ShapeGeometry::Mesh(mesh.clone()));
    let area = s.area();
    assert!((area - 2.0 * (1.0 * 2.0 + 1.0 * 4.0 + 2.0 * 4.0)).abs() < 1e-4);
    let mut rng = Pcg64::seed_from_u64(3);
    let n = 60_000;
    // Faces by outward normal, each split into 4 quadrants (checks uniformity inside a face).
    let mut counts = vec![0u64; 24];
    for _ in 0..n {
        let (p, nrm, pdf) = s.sample_area(Vec2::new(rng.random(), rng.random()));
        assert!((pdf - 1.0 / area).abs() < 1e-7);
        let axis = nrm.abs().max_position();
        assert!(
            (p[axis].abs() - [0.5, 1.0, 2.0][axis]).abs() < 1e-5,
            "off the surface: {p:?}"
        );
        let face = 2 * axis + (nrm[axis] < 0.0) as usize;
        let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
        counts[4 * face + 2 * (p[a] > 0.0) as usize + (p[b] > 0.0) as usize] += 1;
    }
    let dims = [0.5f64, 1.0, 2.0];
    let expected: Vec<f64> = (0..24)
        .map(|c| {
            let axis = c / 8;
            let face_area = 4.0 * dims[(axis + 1) % 3] * dims[(axis + 2) % 3];
            n as f64 * face_area / 4.0 / area as f64
        })
        .collect();
    let r = chi2_discrete(&counts, &expected);
    assert!(r.p_value > 1e-3, "{r:?} {counts:?}");
}

#[test]
fn sphere_area_sampling_mean() {
    let s = shape(ShapeGeometry::sphere(Vec3::new(1.0, 2.0, 3.0), 0.5).unwrap());
    let mut rng = Pcg64::seed_from_u64(5);
    let (mut mx, mut mz2) = (MeanEstimate::default(), MeanEstimate::default());
    for _ in 0..20_000 {
        let (p, n, pdf) = s.sample_area(Vec2::new(rng.random(), rng.random()));
        assert!((pdf * 4.0 * PI * 0.25 - 1.0).abs() < 1e-5);
        assert!(((p - Vec3::new(1.0, 2.0, 3.0)) - 0.5 * n).length() < 1e-5);
        mx.push(p.x as f64);
        mz2.push(((p.z - 3.0) * (p.z - 3.0)) as f64);
    }
    assert!(mx.agrees_with(1.0, 4.0, 1e-6), "{mx:?}");
    assert!(mz2.agrees_with(0.25 / 3.0, 4.0, 1e-6), "{mz2:?}");
}

#[test]
fn uv_footprint_on_a_plane_matches_the_pinhole_value() {
    // The rectangle scaled by 5: uv = (x + 5) / 10, so du = dx / 10. A pinhole at height h looking
    // down with directions (x, y, -1): a pixel step delta in x moves the hit by h delta.
    let g = Geometry::new(vec![shape(ShapeGeometry::Mesh(
        TriangleMesh::rectangle()
            .transformed(&Transform::scale(Vec3::splat(5.0)).unwrap())
            .unwrap(),
    ))]);
    let (h, delta) = (3.0f32, 0.01f32);
    let o = Vec3::new(0.0, 0.0, h);
    for (x, y) in [(0.1f32, 0.2f32), (-0.5, 0.3), (0.8, -0.9)] {
        let d = Vec3::new(x, y, -1.0);
        let hit = g.intersect(&Ray::new(o, d)).unwrap();
        let rd = RayDifferential {
            rx_o: o,
            rx_d: d + Vec3::new(delta, 0.0, 0.0),
            ry_o: o,
            ry_d: d + Vec3::new(0.0, delta, 0.0),
        };
        let (dx, dy) = uv_footprint(&hit, &rd);
        let expect = h * delta / 10.0;
        assert!((dx - Vec2::new(expect, 0.0)).length() < 1e-6, "{dx:?}");
        assert!((dy - Vec2::new(0.0, expect)).length() < 1e-6, "{dy:?}");
    }
    // Offset rays parallel to the plane: degenerate, zero.
    let hit = g.intersect(&Ray::new(o, -Vec3::Z)).unwrap();
    let rd = RayDifferential {
        rx_o: o,
        rx_d: Vec3::X,
        ry_o: o,
        ry_d: Vec3::Y,
    };
    assert_eq!(uv_footprint(&hit, &rd), (Vec2::ZERO, Vec2::ZERO));
}

#[test]
fn sphere_transform_rejects_non_uniform_scale() {
    let s = ShapeGeometry::sphere(Vec3::ZERO, 1.0).unwrap();
    let moved = s
        .transformed(
            &Transform::scale(Vec3::splat(2.0))
                .unwrap()
                .then(&Transform::translate(Vec3::X).unwrap()),
        )
        .unwrap();
    assert!(
        matches!(moved, ShapeGeometry::Sphere { centre, radius } if (centre - Vec3::X).length() < 1e-6 && (radius - 2.0).abs() < 1e-6)
    );
    assert!(s
        .transformed(&Transform::scale(Vec3::new(1.0, 2.0, 1.0)).unwrap())
        .is_err());
    assert!(ShapeGeometry::sphere(Vec3::ZERO, -1.0).is_err());
}

#[test]
fn obj_files_load_and_bad_ones_are_named() {
    let dir = std::env::temp_dir().join(format!("striae-obj-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A unit quad as one polygon (triangulated on load), with uvs and normals.
    let quad = dir.join("quad.obj");
    std::fs::write(&quad, "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n").unwrap();
    let m = TriangleMesh::from_obj(&quad).unwrap();
    assert_eq!(m.triangle_count(), 2);
    assert!((m.area() - 2.0).abs() < 1e-6);
    assert!(m.uvs().is_some() && m.normals().is_some());
    let g = Geometry::new(vec![shape(ShapeGeometry::Mesh(m))]);
    let h = g
        .intersect(&Ray::new(Vec3::new(1.5, 0.5, 1.0), -Vec3::Z))
        .unwrap();
    assert!((h.uv - Vec2::new(0.75, 0.5)).length() < 1e-6 && (h.ng - Vec3::Z).length() < 1e-6);
    // `v` is flipped on load (OBJ's texture origin is the image's bottom-left, striae's its
    // top-left), so v grows toward -y here.
    assert!(
        (h.dpdu - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-5 && (h.dpdv + Vec3::Y).length() < 1e-5
    );
    let h = g
        .intersect(&Ray::new(Vec3::new(0.5, 0.8, 1.0), -Vec3::Z))
        .unwrap();
    assert!((h.uv - Vec2::new(0.25, 0.2)).length() < 1e-6, "{:?}", h.uv);

    let missing = dir.join("missing.obj");
    let err = TriangleMesh::from_obj(&missing).unwrap_err().to_string();
    assert!(err.contains("missing.obj"), "{err}");
    let empty = dir.join("points.obj");
    std::fs::write(&empty, "v 0 0 0\nv 1 0 0\n").unwrap();
    let err = TriangleMesh::from_obj(&empty).unwrap_err().to_string();
    assert!(
        err.contains("points.obj") && err.contains("no triangles"),
        "{err}"
    );
    let corrupt = dir.join("corrupt.obj");
    std::fs::write(&corrupt, "v 0 0 0\nv 1 0 zz\nv 0 1 0\nf 1 2 3\n").unwrap();
    let err = TriangleMesh::from_obj(&corrupt).unwrap_err().to_string();
    assert!(err.contains("corrupt.obj"), "{err}");
    let bad_index = dir.join("bad_index.obj");
    std::fs::write(&bad_index, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n").unwrap();
    let err = TriangleMesh::from_obj(&bad_index).unwrap_err().to_string();
    assert!(err.contains("bad_index.obj"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn obj_export_round_trips_the_teapot() {
    let dir = std::env::temp_dir().join(format!("striae-obj-export-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("teapot.obj");
    let teapot = TriangleMesh::teapot(3);
    teapot.write_obj(&path).unwrap();
    let back = TriangleMesh::from_obj(&path).unwrap();
    assert_eq!(back.triangle_count(), teapot.triangle_count());
    for i in 0..teapot.triangle_count() {
        assert_eq!(back.triangle(i), teapot.triangle(i), "triangle {i}");
    }
    assert!(back.uvs().is_some() && back.normals().is_some());
    // Same hits through both (uv and shading normal included).
    let (a, b) = (
        Geometry::new(vec![shape(ShapeGeometry::Mesh(teapot))]),
        Geometry::new(vec![shape(ShapeGeometry::Mesh(back))]),
    );
    for k in 0..50 {
        let ray = Ray::new(Vec3::new(-3.0 + 0.12 * k as f32, -6.0, 1.4), Vec3::Y);
        match (a.intersect(&ray), b.intersect(&ray)) {
            (None, None) => {}
            (Some(x), Some(y)) => {
                assert_eq!(x.t, y.t);
                assert!((x.uv - y.uv).length() < 1e-6 && (x.ns - y.ns).length() < 1e-5);
            }
            other => panic!("{other:?}"),
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn geometry_is_shareable_across_threads() {
    fn assert_send_sync<T: Send + Sync>() {}
    assert_send_sync::<Geometry>();
    assert_send_sync::<Shape>();
    assert_send_sync::<Transform>();
}

#[test]
fn rays_at_the_teapot_body_seams_never_slip_through() {
    // (With the watertight test.) Patches 1-12 (rim and body) meet along shared boundary curves; the mesh has separate
    // vertices per patch but bit-identical positions there. Rays from outside aimed at points on
    // those seams (including the tessellation's vertices) must hit.
    let n = 8;
    let mesh = TriangleMesh::teapot(n);
    let g = Geometry::with_triangles(
        vec![shape(ShapeGeometry::Mesh(mesh.clone()))],
        TriangleTest::Watertight,
    );
    let per_patch = ((n + 1) * (n + 1)) as usize;
    let pos = mesh.positions();
    let mut rng = Pcg64::seed_from_u64(21);
    let (mut misses, mut rays) = (0, 0);
    for patch in 4..12 {
        let base = patch * per_patch;
        // Seam at s = 0 (column i = 0) and at t = 0 (row j = 0).
        for seam in 0..2 {
            for k in 0..n as usize {
                let (a, b) = if seam == 0 {
                    (
                        pos[base + k * (n as usize + 1)],
                        pos[base + (k + 1) * (n as usize + 1)],
                    )
                } else {
                    (pos[base + k], pos[base + k + 1])
                };
                for _ in 0..20 {
                    let on_seam = if rng.random::<f32>() < 0.25 {
                        a
                    } else {
                        a.lerp(b, rng.random::<f32>())
                    };
                    // Jittered by a few ulps' worth around the seam, so a gap would be hit.
                    let target = on_seam + 2e-6 * random_unit(&mut rng);
                    let outward = Vec3::new(target.x, target.y, 0.0).normalize();
                    let origin = target + 3.0 * (outward + 0.5 * random_unit(&mut rng));
                    let ray = Ray::new(origin, (target - origin).normalize());
                    rays += 1;
                    // A ray through a gap would hit the far wall: the first hit must be no farther
                    // than the seam (it may be nearer: the handle, spout or rim can be in front).
                    let dist = (target - origin).length();
                    let at_seam = g.intersect(&ray).is_some_and(|h| h.t < dist + 1e-3);
                    let mut short = ray;
                    short.t_max = dist + 1e-3;
                    if !at_seam || !g.occluded(&short) {
                        misses += 1;
                    }
                }
            }
        }
    }
    assert_eq!(
        misses, 0,
        "{misses} of {rays} rays slipped through the seams"
    );
}
