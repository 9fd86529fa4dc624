//! Geometry: shapes (triangle meshes from OBJ, the built-in Utah teapot, box, rectangle,
//! analytic sphere), affine transforms, and the BVH that intersects rays with them
//! (`docs/ARCHITECTURE.md`, "Hits" and "Geometry").
//!
//! * [`transform`]: 4x4 affine transforms, scene-file syntax.
//! * [`mesh`]: [`TriangleMesh`] with the rectangle and box; [`obj`] loads OBJ files (tobj);
//!   [`teapot`] tessellates Newell's 32 Bezier patches with per-vertex uv and tangents.
//! * [`sphere`]: the analytic sphere.
//! * [`carve`]: explicit scratch grooves carved into planar faces (METHOD.md 8.3).
//! * [`bvh`]: [`Geometry`], the BVH (an 8-wide SSE BVH, `bvh8`, by default) with the fast or the
//!   watertight ray-triangle test ([`TriangleTest`]).
//! * [`uv_footprint`]: texture-space footprint of a pixel from ray differentials (pbrt-v4).

// `!(x > y)` is used on purpose: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod bvh;
mod bvh8;
pub mod carve;
pub mod mesh;
pub mod obj;
pub mod sphere;
pub mod teapot;
pub mod transform;

use std::path::PathBuf;

pub use bvh::{BvhKind, Geometry, TriangleTest};
pub use bvh8::PACKET;
pub use mesh::TriangleMesh;
pub use transform::Transform;

use crate::math::{RayDifferential, Vec2, Vec3, PI};

/// The relative distance a new ray's origin is moved off the surface it leaves
/// ([`offset_origin_by`]): above float error at any position.
pub const OFFSET: f32 = 1e-4;
/// The same for the faces and walls of explicit scratch grooves ([`carve`]), whose features
/// are 2e-4 of the face's size for the seed's setting 1: small enough to leave a groove's
/// wall without crossing the groove, still 20 times the float error of a hit's position.
pub const CARVED_OFFSET: f32 = 2e-6;

/// The largest coordinate a point of the scene may have (a scene file's points and vectors,
/// an OBJ file's vertices). Beyond it `f32` positions are spaced more than 1e8 apart and
/// squared distances overflow, so a combined check downstream would fail and blame another
/// key.
pub const MAX_COORDINATE: f32 = 1e15;

/// Moves a ray origin off the surface at `p` (geometric normal `ng`) toward the side `dir`
/// leaves to, by `rel (1 + max |p_i|)`: scaled with the magnitude of `p` to stay above float
/// error.
#[inline]
pub fn offset_origin_by(p: Vec3, ng: Vec3, dir: Vec3, rel: f32) -> Vec3 {
    let eps = rel * (1.0 + p.abs().max_element());
    if dir.dot(ng) >= 0.0 {
        p + eps * ng
    } else {
        p - eps * ng
    }
}

/// Everything the renderer needs to know about a ray-surface intersection.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Hit point in world space.
    pub p: Vec3,
    /// Unit geometric normal as the primitive defines it (outward for closed shapes; never
    /// flipped toward the ray: inside/outside is decided from it per hit).
    pub ng: Vec3,
    /// Unit shading normal (interpolated), in the same hemisphere as `ng`.
    pub ns: Vec3,
    /// Texture coordinates.
    pub uv: Vec2,
    /// Partial derivatives of the position with respect to `u` and `v` (not normalised).
    pub dpdu: Vec3,
    pub dpdv: Vec3,
    /// Index of the shape in the scene's shape list.
    pub shape: u32,
    /// Index of the primitive (triangle) within the shape.
    pub prim: u32,
}

#[cfg(test)]
impl SurfaceHit {
    /// A hit at the origin of the plane `z = 0` (normal `+z`, `dp/du = x`, `dp/dv = y`) at
    /// texture coordinates `uv`, for tests of materials.
    pub(crate) fn flat(uv: Vec2) -> Self {
        SurfaceHit {
            t: 1.0,
            p: Vec3::ZERO,
            ng: Vec3::Z,
            ns: Vec3::Z,
            uv,
            dpdu: Vec3::X,
            dpdv: Vec3::Y,
            shape: 0,
            prim: 0,
        }
    }
}

/// Errors from building geometry: bad files, meshes and transforms.
#[derive(Debug, thiserror::Error)]
pub enum GeometryError {
    #[error("cannot load OBJ file {path}: {message}")]
    ObjLoad { path: PathBuf, message: String },
    #[error("OBJ file {path} contains no triangles")]
    ObjEmpty { path: PathBuf },
    #[error("OBJ file {path}: {reason}")]
    ObjInvalid { path: PathBuf, reason: String },
    #[error("invalid mesh: {reason}")]
    BadMesh { reason: String },
    #[error("invalid transform: {reason}")]
    BadTransform { reason: String },
    #[error("invalid sphere: centre {centre:?}, radius {radius} (radius must be finite and > 0)")]
    BadSphere { centre: Vec3, radius: f32 },
}

/// The surface of a shape, in world space.
// One per shape, so the size difference costs nothing; boxing the mesh would add an
// indirection at every hit.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum ShapeGeometry {
    Mesh(TriangleMesh),
    Sphere { centre: Vec3, radius: f32 },
}

impl ShapeGeometry {
    /// A sphere, validated.
    pub fn sphere(centre: Vec3, radius: f32) -> Result<ShapeGeometry, GeometryError> {
        if !(radius > 0.0 && radius.is_finite() && centre.is_finite()) {
            return Err(GeometryError::BadSphere { centre, radius });
        }
        Ok(ShapeGeometry::Sphere { centre, radius })
    }

    /// The geometry under `t`. A sphere accepts only similarity transforms (rotation,
    /// translation, uniform scale): anything else is an error, as an ellipsoid is not a sphere.
    pub fn transformed(&self, t: &Transform) -> Result<ShapeGeometry, GeometryError> {
        match self {
            ShapeGeometry::Mesh(m) => Ok(ShapeGeometry::Mesh(m.transformed(t)?)),
            ShapeGeometry::Sphere { centre, radius } => {
                let axes = [t.vector(Vec3::X), t.vector(Vec3::Y), t.vector(Vec3::Z)];
                let s = axes[0].length();
                let similar = axes.iter().all(|a| (a.length() - s).abs() <= 1e-4 * s)
                    && axes[0].dot(axes[1]).abs() <= 1e-4 * s * s
                    && axes[1].dot(axes[2]).abs() <= 1e-4 * s * s
                    && axes[0].dot(axes[2]).abs() <= 1e-4 * s * s;
                if !similar {
                    return Err(GeometryError::BadTransform {
                        reason: format!("a sphere can only be rotated, translated and uniformly scaled, not by {:?}", t.matrix().transpose().to_cols_array_2d()),
                    });
                }
                ShapeGeometry::sphere(t.point(*centre), radius * s)
            }
        }
    }
}

/// A shape of the scene: its surface, material index and optional area-light index.
#[derive(Clone, Debug)]
pub struct Shape {
    pub geometry: ShapeGeometry,
    pub material: u32,
    pub area_light: Option<u32>,
}

impl Shape {
    /// Surface area (world space).
    pub fn area(&self) -> f32 {
        match &self.geometry {
            ShapeGeometry::Mesh(m) => m.area(),
            ShapeGeometry::Sphere { radius, .. } => 4.0 * PI * radius * radius,
        }
    }

    /// A point uniform in area: `(p, unit outward normal, pdf per unit area = 1 / area)`.
    /// Meshes choose a triangle by area (`sampling::Distribution1D`), then a uniform point in it.
    #[inline(always)]
    pub fn sample_area(&self, u: Vec2) -> (Vec3, Vec3, f32) {
        match &self.geometry {
            ShapeGeometry::Mesh(m) => m.sample_area(u),
            ShapeGeometry::Sphere { centre, radius } => {
                let n = crate::sampling::square_to_uniform_sphere(u);
                (*centre + *radius * n, n, 1.0 / self.area())
            }
        }
    }
}

/// Texture-space derivatives `(du/dx, dv/dx)` and `(du/dy, dv/dy)` of a pixel step, from the
/// ray differentials (pbrt-v4 `SurfaceInteraction::ComputeDifferentials`): the offset rays are
/// intersected with the tangent plane at the hit, and `dp = dpdu du + dpdv dv` is solved for
/// `(du, dv)` by least squares. Zero when degenerate (offset rays parallel to the plane).
pub fn uv_footprint(hit: &SurfaceHit, rd: &RayDifferential) -> (Vec2, Vec2) {
    let n = hit.ng;
    let d = -n.dot(hit.p);
    let offset = |o: Vec3, dir: Vec3| -> Option<Vec3> {
        let t = (-n.dot(o) - d) / n.dot(dir);
        if t.is_finite() {
            Some(o + t * dir)
        } else {
            None
        }
    };
    let (Some(px), Some(py)) = (offset(rd.rx_o, rd.rx_d), offset(rd.ry_o, rd.ry_d)) else {
        return (Vec2::ZERO, Vec2::ZERO);
    };
    let (dpdx, dpdy) = (px - hit.p, py - hit.p);
    let (a00, a01, a11) = (
        hit.dpdu.dot(hit.dpdu),
        hit.dpdu.dot(hit.dpdv),
        hit.dpdv.dot(hit.dpdv),
    );
    let det = a00 * a11 - a01 * a01;
    let inv_det = if det != 0.0 && (1.0 / det).is_finite() {
        1.0 / det
    } else {
        0.0
    };
    let solve = |dp: Vec3| -> Vec2 {
        let (b0, b1) = (hit.dpdu.dot(dp), hit.dpdv.dot(dp));
        let r = Vec2::new(
            (a11 * b0 - a01 * b1) * inv_det,
            (a00 * b1 - a01 * b0) * inv_det,
        );
        if r.is_finite() {
            r.clamp(Vec2::splat(-1e8), Vec2::splat(1e8))
        } else {
            Vec2::ZERO
        }
    };
    (solve(dpdx), solve(dpdy))
}

#[cfg(test)]
mod tests;
