//! The Utah teapot: Newell's 32 bicubic Bezier patches (1975; the 4 bottom patches are Frank
//! Crow's), embedded from `data/newell_teapot.txt` and tessellated into a [`TriangleMesh`] with
//! per-vertex normals, uvs and tangents taken from the patch parameters (the scratch layers are
//! mapped with them, METHOD.md section 5).
//!
//! **Orientation.** With `s` running along a patch's control-point columns and `t` along its
//! rows, `dP/ds x dP/dt` points out of the body (Newell's "du x dv points inward" holds for his
//! `u` along `t`); every triangle is wound so the geometric normal is `dP/ds x dP/dt`, outward. Degenerate patch corners (lid knob top, bottom centre, where a row of
//! control points collapses to one point) have no normal of their own: it is the limit taken
//! from a parameter nudged toward the patch centre.
//!
//! **UV mapping** (continuous around every surface of revolution and across patch rows):
//! the patches form groups of `ncols x nrows` patches, `u = 1 - (column + s) / ncols` goes around
//! the group (counter-clockwise seen from above on the body) and `v = 1 - (row + t) / nrows` runs
//! from the group's last patch row to its first (on the body: from the base, 0, to the rim, 1):
//!
//! | patches (1-based) | group          | ncols x nrows |
//! |-------------------|----------------|---------------|
//! | 1-12              | rim and body   | 4 x 3         |
//! | 13-16             | handle         | 2 x 2         |
//! | 17-20             | spout          | 2 x 2         |
//! | 21-28             | lid            | 4 x 2         |
//! | 29-32             | bottom         | 4 x 1         |
//!
//! so the body's `u` wraps once around the axis (seam at `u = 0 = 1`) and `v` rises from the
//! base (0) to the rim (1), stretched unevenly because the three patch rows differ in height.
//! Groups overlap in uv space. The stored tangents follow the chain rule:
//! `dP/du = -ncols dP/ds`, `dP/dv = -nrows dP/dt`, so `dP/du x dP/dv` is outward too.
//!
//! **Not watertight** (a property of the data, left as is): there is a gap between the lid
//! (rim radius 1.3) and the body's opening (radius 1.4), the spout tip is open, and the handle and
//! spout ends are buried in the body. Shared patch edges are, however, evaluated bit-identically
//! from the same control points, so rays do not slip between neighbouring patches.

use super::TriangleMesh;
use crate::math::Vec2;
use glam::DVec3;

const DATA: &str = include_str!("../../../assets/newell_teapot.txt");

/// A bicubic Bezier patch: `points[row][column]`; `s` runs along columns, `t` along rows.
pub type Patch = [[DVec3; 4]; 4];

/// Newell's 32 patches, parsed from the embedded data (z up, height 0 to 3.15).
pub fn patches() -> Vec<Patch> {
    let mut lines = DATA
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'));
    let count = |line: Option<&str>, key: &str| -> usize {
        let line = line.unwrap_or_default();
        line.strip_prefix(key)
            .and_then(|n| n.trim().parse().ok())
            .unwrap_or_else(|| panic!("embedded teapot data: expected '{key} N', got '{line}'"))
    };
    let n_patches = count(lines.next(), "patches");
    let index_rows: Vec<Vec<usize>> = (0..n_patches)
        .map(|_| {
            lines
                .next()
                .expect("embedded teapot data: patch line")
                .split_whitespace()
                .map(|i| i.parse::<usize>().expect("index") - 1)
                .collect()
        })
        .collect();
    let n_points = count(lines.next(), "points");
    let points: Vec<DVec3> = (0..n_points)
        .map(|_| {
            let c: Vec<f64> = lines
                .next()
                .expect("embedded teapot data: point line")
                .split_whitespace()
                .map(|x| x.parse().expect("coordinate"))
                .collect();
            DVec3::new(c[0], c[1], c[2])
        })
        .collect();
    index_rows
        .iter()
        .map(|idx| {
            assert_eq!(idx.len(), 16, "embedded teapot data: 16 indices per patch");
            std::array::from_fn(|r| std::array::from_fn(|c| points[idx[4 * r + c]]))
        })
        .collect()
}

/// Where patch `p` (0-based) sits in its uv group: `(column, row, ncols, nrows)`.
pub fn patch_uv_layout(p: usize) -> (usize, usize, usize, usize) {
    match p {
        0..=11 => (p % 4, p / 4, 4, 3),
        12..=15 => ((p - 12) % 2, (p - 12) / 2, 2, 2),
        16..=19 => ((p - 16) % 2, (p - 16) / 2, 2, 2),
        20..=27 => (p % 4, (p - 20) / 4, 4, 2),
        _ => (p % 4, 0, 4, 1),
    }
}

fn bernstein(t: f64) -> ([f64; 4], [f64; 4]) {
    let s = 1.0 - t;
    (
        [s * s * s, 3.0 * t * s * s, 3.0 * t * t * s, t * t * t],
        [
            -3.0 * s * s,
            3.0 * s * s - 6.0 * t * s,
            6.0 * t * s - 3.0 * t * t,
            3.0 * t * t,
        ],
    )
}

/// Position and the parameter derivatives `(P, dP/ds, dP/dt)` of a patch. Row curves are
/// evaluated first, so on a shared boundary (`s` or `t` in {0, 1}) two patches give
/// bit-identical points.
pub fn eval_patch(patch: &Patch, s: f64, t: f64) -> (DVec3, DVec3, DVec3) {
    let (bs, dbs) = bernstein(s);
    let (bt, dbt) = bernstein(t);
    let mut row = [DVec3::ZERO; 4];
    let mut drow = [DVec3::ZERO; 4];
    for r in 0..4 {
        for c in 0..4 {
            row[r] += bs[c] * patch[r][c];
            drow[r] += dbs[c] * patch[r][c];
        }
    }
    let (mut p, mut ds, mut dt) = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
    for r in 0..4 {
        p += bt[r] * row[r];
        ds += bt[r] * drow[r];
        dt += dbt[r] * row[r];
    }
    (p, ds, dt)
}

/// Outward unit normal of a patch at `(s, t)`; at a degenerate point the limit from the patch
/// interior.
pub fn patch_normal(patch: &Patch, s: f64, t: f64) -> DVec3 {
    let (_, ds, dt) = eval_patch(patch, s, t);
    let n = ds.cross(dt);
    let scale = ds.length_squared().max(dt.length_squared()).max(1e-30);
    if n.length_squared() > 1e-16 * scale * scale {
        return n.normalize();
    }
    let mut delta = 1e-5;
    while delta < 0.5 {
        let (s2, t2) = (
            s + delta * (0.5 - s).signum(),
            t + delta * (0.5 - t).signum(),
        );
        let (_, ds, dt) = eval_patch(patch, s2, t2);
        let n = ds.cross(dt);
        if n.length_squared() > 0.0 && n.is_finite() {
            return n.normalize();
        }
        delta *= 10.0;
    }
    DVec3::Z
}

impl TriangleMesh {
    /// Newell's teapot, each of the 32 patches tessellated into `subdivisions x subdivisions`
    /// quads (two triangles each; triangles collapsed at degenerate corners are dropped), with
    /// per-vertex outward normals, uvs and tangents as described in [`super::teapot`].
    /// Z is up, the base at `z = 0`, height 3.15.
    pub fn teapot(subdivisions: u32) -> TriangleMesh {
        let n = subdivisions.max(1) as usize;
        let patches = patches();
        let per_patch = (n + 1) * (n + 1);
        let total = patches.len() * per_patch;
        let (mut positions, mut normals, mut uvs) = (
            Vec::with_capacity(total),
            Vec::with_capacity(total),
            Vec::with_capacity(total),
        );
        let (mut dpdu, mut dpdv) = (Vec::with_capacity(total), Vec::with_capacity(total));
        let mut indices = Vec::with_capacity(patches.len() * 2 * n * n);
        for (pi, patch) in patches.iter().enumerate() {
            let (col, row, ncols, nrows) = patch_uv_layout(pi);
            let base = positions.len() as u32;
            for j in 0..=n {
                let t = j as f64 / n as f64;
                for i in 0..=n {
                    let s = i as f64 / n as f64;
                    let (p, ds, dt) = eval_patch(patch, s, t);
                    positions.push(p.as_vec3());
                    normals.push(patch_normal(patch, s, t).as_vec3());
                    uvs.push(Vec2::new(
                        (1.0 - (col as f64 + s) / ncols as f64) as f32,
                        (1.0 - (row as f64 + t) / nrows as f64) as f32,
                    ));
                    dpdu.push((ds * -(ncols as f64)).as_vec3());
                    dpdv.push((dt * -(nrows as f64)).as_vec3());
                }
            }
            let v = |i: usize, j: usize| base + (j * (n + 1) + i) as u32;
            for j in 0..n {
                for i in 0..n {
                    // dP/ds x dP/dt is outward: wind s before t.
                    for tri in [
                        [v(i, j), v(i + 1, j), v(i + 1, j + 1)],
                        [v(i, j), v(i + 1, j + 1), v(i, j + 1)],
                    ] {
                        let [a, b, c] = tri.map(|k| positions[k as usize]);
                        if a != b && b != c && a != c {
                            indices.push(tri);
                        }
                    }
                }
            }
        }
        TriangleMesh::new(
            positions,
            indices,
            Some(normals),
            Some(uvs),
            Some((dpdu, dpdv)),
        )
        .expect("the teapot tessellation is a valid mesh")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;

    /// Signed volume by the divergence theorem, `sum over triangles of p0 . (p1 x p2) / 6`.
    fn signed_volume(m: &TriangleMesh) -> f64 {
        m.indices()
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| m.positions()[i as usize].as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    #[test]
    fn has_32_patches_with_uv_groups_covering_the_unit_square() {
        let p = patches();
        assert_eq!(p.len(), 32);
        // Heights 0 to 3.15 as documented.
        let zs: Vec<f64> = p.iter().flatten().flatten().map(|q| q.z).collect();
        assert_eq!(zs.iter().cloned().fold(f64::INFINITY, f64::min), 0.0);
        assert!((zs.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - 3.15).abs() < 1e-12);
        // Every group's cells are covered exactly once.
        for (range, ncols, nrows) in [
            (0..12, 4, 3),
            (12..16, 2, 2),
            (16..20, 2, 2),
            (20..28, 4, 2),
            (28..32, 4, 1),
        ] {
            let mut seen = vec![false; ncols * nrows];
            for pi in range {
                let (c, r, nc, nr) = patch_uv_layout(pi);
                assert_eq!((nc, nr), (ncols, nrows));
                assert!(!seen[r * nc + c]);
                seen[r * nc + c] = true;
            }
            assert!(seen.iter().all(|&x| x));
        }
    }

    #[test]
    fn uv_is_continuous_across_shared_patch_edges() {
        // Neighbouring patches in a group share boundary points: same position, same uv
        // (except across the u seam at 0 = 1).
        let m = TriangleMesh::teapot(4);
        let (pos, uv) = (m.positions(), m.uvs().unwrap());
        let mut matched = 0;
        for a in 0..pos.len() {
            for b in (a + 1)..pos.len() {
                if pos[a] == pos[b]
                    && a / 25 != b / 25
                    && patch_group(a / 25) == patch_group(b / 25)
                {
                    let du = (uv[a].x - uv[b].x).abs();
                    let du = du.min(1.0 - du);
                    if pos[a].truncate().length() > 1e-3 {
                        assert!(
                            du < 1e-6 && (uv[a].y - uv[b].y).abs() < 1e-6,
                            "patches {} {}: {:?} vs {:?} at {:?}",
                            a / 25,
                            b / 25,
                            uv[a],
                            uv[b],
                            pos[a]
                        );
                        matched += 1;
                    }
                }
            }
        }
        assert!(
            matched > 200,
            "only {matched} shared boundary vertices found"
        );
    }

    fn patch_group(p: usize) -> usize {
        match p {
            0..=11 => 0,
            12..=15 => 1,
            16..=19 => 2,
            20..=27 => 3,
            _ => 4,
        }
    }

    #[test]
    fn normals_point_outward_and_volume_converges() {
        // Per group and patch row, rings of constant t around the group have a centroid; the outward
        // normal points away from it. The rim's inner lip (excluded) and the spout tip's lip curl
        // over and face their axis, so a fraction is asked, far above what a flipped group gives.
        let ps = patches();
        for (group, range, ncols, fraction) in [
            ("body", 4..12, 4, 0.95),
            ("handle", 12..16, 2, 0.95),
            ("spout", 16..20, 2, 0.7),
            ("lid", 20..28, 4, 0.95),
            ("bottom", 28..32, 4, 0.95),
        ] {
            let (mut positive, mut total) = (0, 0);
            let rows: Vec<Vec<usize>> = range
                .clone()
                .collect::<Vec<_>>()
                .chunks(ncols)
                .map(|c| c.to_vec())
                .collect();
            for row in rows {
                for k in 1..10 {
                    let t = k as f64 / 10.0;
                    let ring: Vec<(DVec3, DVec3)> = row
                        .iter()
                        .flat_map(|&pi| (0..16).map(move |i| (pi, i as f64 / 16.0)))
                        .map(|(pi, s)| (eval_patch(&ps[pi], s, t).0, patch_normal(&ps[pi], s, t)))
                        .collect();
                    let centroid = ring.iter().map(|(p, _)| *p).sum::<DVec3>() / ring.len() as f64;
                    for (p, n) in &ring {
                        assert!(n.is_finite() && (n.length() - 1.0).abs() < 1e-9);
                        total += 1;
                        if n.dot(*p - centroid) > 0.0 {
                            positive += 1;
                        }
                    }
                }
            }
            assert!(
                positive as f64 > fraction * total as f64,
                "{group}: only {positive} of {total} normals point outward"
            );
        }
        // The geometric normals (winding) agree with the vertex normals.
        let m = TriangleMesh::teapot(8);
        let normals = m.normals().unwrap();
        let mut disagree = 0;
        for tri in m.indices() {
            let [a, b, c] = tri.map(|i| m.positions()[i as usize]);
            let ng = (b - a).cross(c - a).normalize();
            let nv =
                (normals[tri[0] as usize] + normals[tri[1] as usize] + normals[tri[2] as usize])
                    .normalize();
            if ng.dot(nv) < 0.5 {
                disagree += 1;
            }
        }
        assert!(
            disagree <= m.triangle_count() / 500,
            "{disagree} triangles wound against their vertex normals"
        );
        // Divergence theorem: positive (outward) and converging with tessellation.
        let v8 = signed_volume(&m);
        let v32 = signed_volume(&TriangleMesh::teapot(32));
        let v64 = signed_volume(&TriangleMesh::teapot(64));
        assert!(
            v64 > 0.0,
            "signed volume {v64} is negative: normals point inward"
        );
        assert!((v32 - v64).abs() < 1e-3 * v64, "{v32} vs {v64}");
        assert!((v8 - v64).abs() < 2e-2 * v64, "{v8} vs {v64}");
        // A body of revolution of radius ~1.5-2 and height ~3: volume of the order of 20-30.
        assert!(v64 > 15.0 && v64 < 40.0, "{v64}");
    }

    #[test]
    fn no_nan_and_degenerate_corners_have_axis_normals() {
        let m = TriangleMesh::teapot(6);
        let (du, dv) = m.tangents().unwrap();
        for (i, p) in m.positions().iter().enumerate() {
            assert!(
                p.is_finite()
                    && m.normals().unwrap()[i].is_finite()
                    && du[i].is_finite()
                    && dv[i].is_finite()
                    && m.uvs().unwrap()[i].is_finite()
            );
            assert!(
                (m.normals().unwrap()[i].length() - 1.0).abs() < 1e-5,
                "vertex {i} at {p:?}"
            );
        }
        // Knob top (lid patches 21-24 at t = 0) faces up, the bottom centre faces down.
        let ps = patches();
        for (pi, patch) in ps.iter().enumerate().take(24).skip(20) {
            for s in [0.0, 0.3, 1.0] {
                assert!(patch_normal(patch, s, 0.0).z > 0.999, "lid patch {pi}");
            }
        }
        for (pi, patch) in ps.iter().enumerate().skip(28) {
            for s in [0.0, 0.3, 1.0] {
                assert!(patch_normal(patch, s, 0.0).z < -0.999, "bottom patch {pi}");
            }
        }
    }

    #[test]
    fn tangents_match_finite_differences_in_uv() {
        let ps = patches();
        for (pi, patch) in ps.iter().enumerate() {
            let (col, row, ncols, nrows) = patch_uv_layout(pi);
            // Position as a function of (u, v) through the documented mapping.
            let pos = |u: f64, v: f64| {
                let s = (1.0 - u) * ncols as f64 - col as f64;
                let t = (1.0 - v) * nrows as f64 - row as f64;
                eval_patch(patch, s, t).0
            };
            for (s, t) in [(0.3, 0.4), (0.7, 0.8), (0.5, 0.5)] {
                let (u, v) = (
                    1.0 - (col as f64 + s) / ncols as f64,
                    1.0 - (row as f64 + t) / nrows as f64,
                );
                let (_, ds, dt) = eval_patch(patch, s, t);
                let (dpdu, dpdv) = (ds * -(ncols as f64), dt * -(nrows as f64));
                let h = 1e-6;
                let fu = (pos(u + h, v) - pos(u - h, v)) / (2.0 * h);
                let fv = (pos(u, v + h) - pos(u, v - h)) / (2.0 * h);
                assert!(
                    (fu - dpdu).length() <= 1e-5 * (1.0 + fu.length()),
                    "patch {pi}: {fu:?} vs {dpdu:?}"
                );
                assert!(
                    (fv - dpdv).length() <= 1e-5 * (1.0 + fv.length()),
                    "patch {pi}: {fv:?} vs {dpdv:?}"
                );
                // And the tangents agree in orientation with the outward normal.
                assert!(dpdu.cross(dpdv).dot(patch_normal(patch, s, t)) >= 0.0);
            }
        }
        // The mesh stores the same (interpolated at a vertex = exact).
        let m = TriangleMesh::teapot(4);
        let (du, dv) = m.tangents().unwrap();
        let uv = m.uvs().unwrap();
        let k = 25 * 5 + 2 * 5 + 3; // patch 6, t = 2/4, s = 3/4
        let (_, ds, dt) = eval_patch(&ps[5], 0.75, 0.5);
        assert!(
            (du[k].as_dvec3() + 4.0 * ds).length() < 1e-4
                && (dv[k].as_dvec3() + 3.0 * dt).length() < 1e-4
        );
        assert!(
            (uv[k] - Vec2::new(1.0 - (1.0 + 0.75) / 4.0, 1.0 - (1.0 + 0.5) / 3.0)).length() < 1e-6
        );
    }

    #[test]
    fn hits_on_the_teapot_have_finite_frames() {
        use crate::math::Ray;
        use crate::render::geometry::{Geometry, Shape, ShapeGeometry};
        let g = Geometry::new(vec![Shape {
            geometry: ShapeGeometry::Mesh(TriangleMesh::teapot(8)),
            material: 0,
            area_light: None,
        }]);
        let mut hits = 0;
        for i in 0..64 {
            for j in 0..64 {
                let o = Vec3::new(
                    -3.5 + 7.0 * i as f32 / 63.0,
                    -6.0,
                    -0.2 + 3.6 * j as f32 / 63.0,
                );
                if let Some(h) = g.intersect(&Ray::new(o, Vec3::Y)) {
                    hits += 1;
                    for v in [h.p, h.ng, h.ns, h.dpdu, h.dpdv] {
                        assert!(v.is_finite());
                    }
                    assert!(h.uv.is_finite() && h.ng.dot(h.ns) >= 0.0);
                    assert!(h.dpdu.cross(h.dpdv).length() > 0.0);
                }
            }
        }
        assert!(hits > 1000, "{hits}");
    }
}

/// Renders the teapot's shading normals, uv checker and tangent directions to PNGs in the
/// temporary directory, for a visual check: `cargo test -p striae --lib teapot_preview -- --ignored`.
#[cfg(test)]
#[test]
#[ignore]
fn teapot_preview() {
    use crate::math::{Ray, Vec3};
    use crate::render::geometry::{Geometry, Shape, ShapeGeometry};
    let g = Geometry::new(vec![Shape {
        geometry: ShapeGeometry::Mesh(TriangleMesh::teapot(8)),
        material: 0,
        area_light: None,
    }]);
    let (w, h) = (480u32, 360u32);
    let eye = Vec3::new(3.0, -6.5, 4.0);
    let target = Vec3::new(0.2, 0.0, 1.3);
    let fwd = (target - eye).normalize();
    let right = fwd.cross(Vec3::Z).normalize();
    let up = right.cross(fwd);
    let tan_half = 22f32.to_radians().tan();
    let mut images = [
        image::RgbImage::new(w, h),
        image::RgbImage::new(w, h),
        image::RgbImage::new(w, h),
    ];
    for j in 0..h {
        for i in 0..w {
            let x = (2.0 * (i as f32 + 0.5) / w as f32 - 1.0) * tan_half * w as f32 / h as f32;
            let y = (1.0 - 2.0 * (j as f32 + 0.5) / h as f32) * tan_half;
            let ray = Ray::new(eye, (fwd + x * right + y * up).normalize());
            let px = match g.intersect(&ray) {
                None => [[30u8; 3]; 3],
                Some(hit) => {
                    let to8 = |v: Vec3| {
                        [0, 1, 2].map(|k| ((v[k] * 0.5 + 0.5).clamp(0.0, 1.0) * 255.0) as u8)
                    };
                    let front = if hit.ng.dot(ray.d) < 0.0 { 1.0 } else { 0.3 };
                    let check =
                        ((hit.uv.x * 16.0).floor() as i32 + (hit.uv.y * 16.0).floor() as i32) & 1;
                    let c = if check == 0 {
                        Vec3::new(hit.uv.x, hit.uv.y, 0.2)
                    } else {
                        Vec3::new(hit.uv.x, hit.uv.y, 0.2) * 0.4
                    };
                    let uv = [0, 1, 2].map(|k| (c[k] * front * 255.0) as u8);
                    [to8(hit.ns * front), uv, to8(hit.dpdu.normalize())]
                }
            };
            for k in 0..3 {
                images[k].put_pixel(i, j, image::Rgb(px[k]));
            }
        }
    }
    for (k, name) in ["normals", "uv", "dpdu"].iter().enumerate() {
        let path = std::env::temp_dir().join(format!("striae_teapot_{name}.png"));
        images[k].save(&path).unwrap();
        eprintln!("wrote {}", path.display());
    }
}
