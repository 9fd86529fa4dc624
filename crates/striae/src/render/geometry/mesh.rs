//! Triangle meshes: positions, optional per-vertex normals, uvs and tangents (dP/du, dP/dv),
//! with the built-in rectangle and box (the shapes of Mitsuba's `rectangle` and `cube`), the
//! Utah teapot ([`super::teapot`]) and OBJ files ([`super::obj`]).
//!
//! The geometric normal of triangle `(p0, p1, p2)` is `(p1 - p0) x (p2 - p0)` normalised
//! (counter-clockwise is front); every built-in mesh is wound so that it points outward.

use super::{GeometryError, Transform};
use crate::math::{Vec2, Vec3};
use crate::sampling::Distribution1D;
use glam::Mat3;

/// An indexed triangle mesh in world space (transforms are applied at load time).
#[derive(Clone, Debug)]
pub struct TriangleMesh {
    positions: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
    normals: Option<Vec<Vec3>>,
    uvs: Option<Vec<Vec2>>,
    /// Per-vertex `(dP/du, dP/dv)`; when absent they are derived per triangle from the uvs.
    tangents: Option<(Vec<Vec3>, Vec<Vec3>)>,
    /// Triangle choice by area for [`TriangleMesh::sample_area`].
    area_distribution: Distribution1D,
    area: f32,
    /// The per-vertex data above interleaved, one cache line per vertex, for
    /// [`TriangleMesh::surface`] (a hit then reads three lines instead of up to fifteen).
    vertices: Vec<ShadingVertex>,
    /// Per triangle, the gradient of its shading normal field (`Some` only where the normal
    /// varies over some triangle, [`Self::has_curved_normals`]; zero on a flat triangle).
    /// 36 bytes per triangle, traded for a least-squares solve at every delta bounce.
    normal_gradients: Option<Vec<Mat3>>,
}

/// A vertex's position and (where the mesh has them, else zero) normal, uv and tangents.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
struct ShadingVertex {
    p: Vec3,
    n: Vec3,
    uv: Vec2,
    dpdu: Vec3,
    dpdv: Vec3,
}

impl TriangleMesh {
    /// Validates and builds a mesh: at least one triangle, indices in range, finite data,
    /// attribute arrays as long as `positions`. Non-unit normals are normalised.
    pub fn new(
        positions: Vec<Vec3>,
        indices: Vec<[u32; 3]>,
        normals: Option<Vec<Vec3>>,
        uvs: Option<Vec<Vec2>>,
        tangents: Option<(Vec<Vec3>, Vec<Vec3>)>,
    ) -> Result<TriangleMesh, GeometryError> {
        let bad = |reason: String| Err(GeometryError::BadMesh { reason });
        let n = positions.len();
        if indices.is_empty() {
            return bad("mesh has no triangles".into());
        }
        if let Some(i) = indices.iter().flatten().find(|&&i| i as usize >= n) {
            return bad(format!(
                "vertex index {i} out of range (mesh has {n} vertices)"
            ));
        }
        if positions.iter().any(|p| !p.is_finite()) {
            return bad("non-finite vertex position".into());
        }
        if let Some(ns) = &normals {
            if ns.len() != n {
                return bad(format!("{} normals for {n} vertices", ns.len()));
            }
            if ns.iter().any(|v| !v.is_finite()) {
                return bad("non-finite normal".into());
            }
        }
        if let Some(uv) = &uvs {
            if uv.len() != n {
                return bad(format!("{} uvs for {n} vertices", uv.len()));
            }
            if uv.iter().any(|v| !v.is_finite()) {
                return bad("non-finite uv".into());
            }
        }
        if let Some((du, dv)) = &tangents {
            if du.len() != n || dv.len() != n {
                return bad(format!(
                    "{}/{} tangents for {n} vertices",
                    du.len(),
                    dv.len()
                ));
            }
            if du.iter().chain(dv.iter()).any(|v| !v.is_finite()) {
                return bad("non-finite tangent".into());
            }
        }
        // Zero normals (degenerate data) fall back to the geometric normal at hit time.
        let normals: Option<Vec<Vec3>> =
            normals.map(|ns| ns.into_iter().map(|v| v.normalize_or_zero()).collect());
        let areas: Vec<f64> = indices
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| positions[i as usize].as_dvec3());
                0.5 * (b - a).cross(c - a).length()
            })
            .collect();
        let area = areas.iter().sum::<f64>() as f32;
        let vertices = (0..n)
            .map(|i| ShadingVertex {
                p: positions[i],
                n: normals.as_ref().map_or(Vec3::ZERO, |ns| ns[i]),
                uv: uvs.as_ref().map_or(Vec2::ZERO, |uv| uv[i]),
                dpdu: tangents.as_ref().map_or(Vec3::ZERO, |(du, _)| du[i]),
                dpdv: tangents.as_ref().map_or(Vec3::ZERO, |(_, dv)| dv[i]),
            })
            .collect();
        let normal_gradients = normals.as_ref().and_then(|ns| {
            let curved = indices.iter().any(|t| {
                let [a, b, c] = t.map(|i| ns[i as usize]);
                a != b || b != c
            });
            curved.then(|| {
                let gradient = |t: &[u32; 3]| {
                    let [p0, p1, p2] = t.map(|i| positions[i as usize]);
                    let [n0, n1, n2] = t.map(|i| ns[i as usize]);
                    normal_gradient([p0, p1, p2], [n0, n1, n2])
                };
                indices.iter().map(gradient).collect()
            })
        });
        Ok(TriangleMesh {
            vertices,
            normal_gradients,
            area_distribution: Distribution1D::new(&areas),
            area,
            positions,
            indices,
            normals,
            uvs,
            tangents,
        })
    }

    /// Mitsuba's `rectangle`: the square `[-1, 1]^2` in the `xy` plane, normal `+z`,
    /// `uv = ((x + 1) / 2, (y + 1) / 2)`.
    pub fn rectangle() -> TriangleMesh {
        let positions = vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ];
        let uvs = vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ];
        TriangleMesh::new(positions, vec![[0, 1, 2], [0, 2, 3]], None, Some(uvs), None)
            .expect("valid built-in mesh")
    }

    /// The box `[-1, 1]^3` (the triangles of Mitsuba's `cube`), outward normals, each face with
    /// its own `[0, 1]^2` uv (24 vertices, flat faces). A glass plate is a thinly scaled box.
    /// The faces' uv layout is striae's own, not the `cube`'s (`docs/validation.md`): face
    /// `n` has `u` along the next axis after `n`'s and `v` along `n x u`.
    pub fn cuboid() -> TriangleMesh {
        let mut positions = Vec::with_capacity(24);
        let mut uvs = Vec::with_capacity(24);
        let mut indices = Vec::with_capacity(12);
        for axis in 0..3 {
            for sign in [1.0f32, -1.0] {
                let mut n = Vec3::ZERO;
                n[axis] = sign;
                // (s, t, n) right-handed so s x t = n: counter-clockwise seen from outside.
                let mut s = Vec3::ZERO;
                s[(axis + 1) % 3] = 1.0;
                let t = n.cross(s);
                let base = positions.len() as u32;
                for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    positions.push(n + a * s + b * t);
                    uvs.push(Vec2::new((a + 1.0) / 2.0, (b + 1.0) / 2.0));
                }
                indices.push([base, base + 1, base + 2]);
                indices.push([base, base + 2, base + 3]);
            }
        }
        TriangleMesh::new(positions, indices, None, Some(uvs), None).expect("valid built-in mesh")
    }

    /// The mesh with every vertex, normal and tangent transformed; windings are reversed under
    /// a mirroring transform so geometric normals keep their side. An error where the
    /// transform takes a vertex out of the finite floats (a huge scale of a large mesh).
    pub fn transformed(&self, t: &Transform) -> Result<TriangleMesh, GeometryError> {
        let positions = self.positions.iter().map(|&p| t.point(p)).collect();
        let normals = self.normals.as_ref().map(|ns| {
            ns.iter()
                .map(|&n| t.normal(n).normalize_or_zero())
                .collect()
        });
        let tangents = self.tangents.as_ref().map(|(du, dv)| {
            (
                du.iter().map(|&v| t.vector(v)).collect(),
                dv.iter().map(|&v| t.vector(v)).collect(),
            )
        });
        let indices = if t.swaps_handedness() {
            self.indices.iter().map(|&[a, b, c]| [a, c, b]).collect()
        } else {
            self.indices.clone()
        };
        TriangleMesh::new(positions, indices, normals, self.uvs.clone(), tangents)
    }

    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }
    pub fn indices(&self) -> &[[u32; 3]] {
        &self.indices
    }
    pub fn normals(&self) -> Option<&[Vec3]> {
        self.normals.as_deref()
    }
    pub fn uvs(&self) -> Option<&[Vec2]> {
        self.uvs.as_deref()
    }
    pub fn tangents(&self) -> Option<(&[Vec3], &[Vec3])> {
        self.tangents
            .as_ref()
            .map(|(a, b)| (a.as_slice(), b.as_slice()))
    }
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }
    /// Total surface area.
    pub fn area(&self) -> f32 {
        self.area
    }

    /// The three vertices of triangle `i`.
    #[inline]
    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        self.indices[i].map(|k| self.positions[k as usize])
    }

    /// A point uniform in area over the mesh: a triangle chosen by area, then a uniform point in
    /// it. Returns `(p, geometric normal, pdf per unit area = 1 / area)`.
    #[inline(always)]
    pub fn sample_area(&self, u: Vec2) -> (Vec3, Vec3, f32) {
        let (i, u0) = self.area_distribution.sample_discrete(u.x as f64);
        let b = crate::sampling::square_to_uniform_triangle(Vec2::new(
            (u0 as f32).min(1.0 - f32::EPSILON),
            u.y,
        ));
        let [p0, p1, p2] = self.triangle(i);
        let p = (1.0 - b.x - b.y) * p0 + b.x * p1 + b.y * p2;
        let n = (p1 - p0).cross(p2 - p0).normalize_or_zero();
        (p, n, 1.0 / self.area)
    }

    /// Shading data of triangle `prim` at barycentrics `(b1, b2)` (weights of vertices 1, 2):
    /// `(p, ng, ns, uv, dpdu, dpdv)`. `ns` is put on `ng`'s side; without uvs the uv is the
    /// barycentric pair and the tangents an arbitrary frame around `ng`.
    #[inline(always)]
    pub fn surface(&self, prim: usize, b1: f32, b2: f32) -> (Vec3, Vec3, Vec3, Vec2, Vec3, Vec3) {
        let [v0, v1, v2] = self.indices[prim].map(|k| &self.vertices[k as usize]);
        let b0 = 1.0 - b1 - b2;
        let (p0, p1, p2) = (v0.p, v1.p, v2.p);
        let p = b0 * p0 + b1 * p1 + b2 * p2;
        let cross = (p1 - p0).cross(p2 - p0);
        let mut ng = cross.normalize_or_zero();
        if ng == Vec3::ZERO {
            // Degenerate (zero-area) triangle: any unit normal keeps the record sane.
            ng = Vec3::Z;
        }
        let (uv, mut dpdu, mut dpdv) = if self.uvs.is_some() {
            let (t0, t1, t2) = (v0.uv, v1.uv, v2.uv);
            let uv = b0 * t0 + b1 * t1 + b2 * t2;
            if self.tangents.is_some() {
                (
                    uv,
                    b0 * v0.dpdu + b1 * v1.dpdu + b2 * v2.dpdu,
                    b0 * v0.dpdv + b1 * v1.dpdv + b2 * v2.dpdv,
                )
            } else {
                // pbrt-v4 Triangle::InteractionFromIntersection: solve the 2x2 system.
                let (duv02, duv12) = (t0 - t2, t1 - t2);
                let (dp02, dp12) = (p0 - p2, p1 - p2);
                let det = duv02.x * duv12.y - duv02.y * duv12.x;
                if det.abs() < 1e-12 {
                    (uv, Vec3::ZERO, Vec3::ZERO)
                } else {
                    let inv = 1.0 / det;
                    (
                        uv,
                        (duv12.y * dp02 - duv02.y * dp12) * inv,
                        (duv02.x * dp12 - duv12.x * dp02) * inv,
                    )
                }
            }
        } else {
            (Vec2::new(b1, b2), Vec3::ZERO, Vec3::ZERO)
        };
        if !(dpdu.cross(dpdv).length_squared() > 0.0) || !dpdu.is_finite() || !dpdv.is_finite() {
            let f = crate::math::Frame::from_normal(ng);
            dpdu = f.s;
            dpdv = f.t;
        }
        let mut ns = if self.normals.is_some() {
            (b0 * v0.n + b1 * v1.n + b2 * v2.n).normalize_or_zero()
        } else {
            ng
        };
        if ns == Vec3::ZERO {
            ns = ng;
        }
        if ns.dot(ng) < 0.0 {
            ns = -ns;
        }
        (p, ng, ns, uv, dpdu, dpdv)
    }
}

impl TriangleMesh {
    /// Whether the mesh has vertex normals that differ across some triangle, so that its
    /// shading normal varies ([`Self::shading_normal_steps`]); a box's or a rectangle's does not.
    pub fn has_curved_normals(&self) -> bool {
        self.normal_gradients.is_some()
    }

    /// The change of triangle `prim`'s shading normal field for each step `dp` in its plane
    /// (see [`normal_gradient`]), on the geometric normal's side like [`Self::surface`]'s
    /// normal; zero on a flat triangle. `None` for a mesh whose normals never vary (no
    /// vertex normals, or flat ones everywhere: boxes, rectangles). For the ray differentials
    /// of a delta bounce (`shading::spawn_differentials`).
    #[inline]
    pub fn shading_normal_steps(&self, prim: usize, dp: [Vec3; 2]) -> Option<[Vec3; 2]> {
        let gradient = self.normal_gradients.as_ref()?[prim];
        Some(dp.map(|dp| gradient * dp))
    }
}

/// The gradient of a triangle's interpolated shading normal in its plane, the matrix `G`
/// with `dn = G dp = (n1 - n0) (grad b1 . dp) + (n2 - n0) (grad b2 . dp)` for a step `dp`:
/// the barycentric interpolation of the unit vertex normals differentiated along the step
/// (Igehy 1999's `dn/dx`; the interpolated normal's length, within a fraction of a per cent
/// of 1 for a smooth mesh, is not divided out). Its sign puts `dn` on the geometric
/// normal's side, as [`TriangleMesh::surface`] puts the normal. Zero for a flat or
/// degenerate triangle. Computed once per triangle at load time: per bounce it is then one
/// matrix product instead of a least-squares solve over three vertices.
fn normal_gradient([p0, p1, p2]: [Vec3; 3], [n0, n1, n2]: [Vec3; 3]) -> Mat3 {
    let (e1, e2) = (p1 - p0, p2 - p0);
    let (a11, a12, a22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let det = a11 * a22 - a12 * a12;
    if (n0 == n1 && n1 == n2) || !(det > 0.0) || !det.is_finite() {
        return Mat3::ZERO;
    }
    // Gradients of b1, b2 in the plane: dp = db1 e1 + db2 e2 in least squares.
    let (g1, g2) = ((a22 * e1 - a12 * e2) / det, (a11 * e2 - a12 * e1) / det);
    let side = if (n0 + n1 + n2).dot(e1.cross(e2)) < 0.0 {
        -1.0
    } else {
        1.0
    };
    let (d1, d2) = (side * (n1 - n0), side * (n2 - n0));
    // The sum of the outer products d1 g1^T + d2 g2^T, column by column.
    let gradient = Mat3::from_cols(
        d1 * g1.x + d2 * g2.x,
        d1 * g1.y + d2 * g2.y,
        d1 * g1.z + d2 * g2.z,
    );
    if gradient.is_finite() {
        gradient
    } else {
        Mat3::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rectangle_and_box_are_outward_with_right_areas() {
        let r = TriangleMesh::rectangle();
        assert!((r.area() - 4.0).abs() < 1e-6);
        for i in 0..2 {
            let (_, ng, ns, _, dpdu, dpdv) = r.surface(i, 0.2, 0.3);
            assert!((ng - Vec3::Z).length() < 1e-6 && ns == ng);
            assert!(
                (dpdu - Vec3::new(2.0, 0.0, 0.0)).length() < 1e-5
                    && (dpdv - Vec3::new(0.0, 2.0, 0.0)).length() < 1e-5
            );
        }
        let b = TriangleMesh::cuboid();
        assert!((b.area() - 24.0).abs() < 1e-5);
        for i in 0..12 {
            let (p, ng, ..) = b.surface(i, 0.3, 0.3);
            // Outward: the normal is the face's axis and points the way of p.
            assert!(ng.dot(p) > 0.99, "face {i}: p {p:?} ng {ng:?}");
        }
    }

    #[test]
    fn rejects_bad_meshes() {
        assert!(TriangleMesh::new(vec![Vec3::ZERO; 3], vec![], None, None, None).is_err());
        assert!(TriangleMesh::new(vec![Vec3::ZERO; 3], vec![[0, 1, 3]], None, None, None).is_err());
        assert!(TriangleMesh::new(
            vec![Vec3::ZERO; 3],
            vec![[0, 1, 2]],
            Some(vec![Vec3::Z; 2]),
            None,
            None
        )
        .is_err());
        assert!(TriangleMesh::new(vec![Vec3::NAN; 3], vec![[0, 1, 2]], None, None, None).is_err());
    }

    #[test]
    fn transform_out_of_the_finite_floats_is_an_error() {
        let far = TriangleMesh::new(
            vec![Vec3::new(3e38, 0.0, 0.0), Vec3::Y, Vec3::Z],
            vec![[0, 1, 2]],
            None,
            None,
            None,
        )
        .unwrap();
        let t = Transform::scale(Vec3::splat(10.0)).unwrap();
        assert!(matches!(
            far.transformed(&t),
            Err(GeometryError::BadMesh { .. })
        ));
    }

    #[test]
    fn mirroring_transform_keeps_normals_outward() {
        let t = Transform::scale(Vec3::new(-1.0, 2.0, 0.5)).unwrap();
        let b = TriangleMesh::cuboid().transformed(&t).unwrap();
        for i in 0..12 {
            let (p, ng, ..) = b.surface(i, 0.3, 0.3);
            assert!(ng.dot(p) > 0.0, "face {i}: p {p:?} ng {ng:?}");
        }
        assert!((b.area() - 2.0 * (2.0 * 4.0 + 2.0 * 1.0 + 4.0 * 1.0)).abs() < 1e-4);
    }
}
