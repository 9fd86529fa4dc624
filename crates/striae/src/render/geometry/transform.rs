//! Affine transforms (4x4 matrices kept with their inverse), as pbrt-v4's `Transform` and
//! Mitsuba's `to_world`: points, vectors, and normals (by the inverse transpose).
//!
//! In a scene file a transform is either a list of operations applied **in the order listed**
//! (the first one acts on the object first, as in Mitsuba's XML) or a single operation:
//!
//! ```toml
//! transform = [ { scale = 2.0 }, { rotate = { axis = [0, 0, 1], angle = 30 } }, { translate = [0, 0, 1] } ]
//! transform = { matrix = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 2], [0, 0, 0, 1]] }   # row-major
//! transform = { look_at = { origin = [0, -5, 2], target = [0, 0, 1], up = [0, 0, 1] } }
//! ```
//!
//! `scale` takes a number or `[x, y, z]`. Singular and non-affine matrices are rejected.

use std::fmt;

use glam::{Mat3, Mat4, Vec4};
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::Deserialize;

use super::GeometryError;
use crate::math::Vec3;

/// An invertible affine transform with its inverse.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    m: Mat4,
    inv: Mat4,
}

impl Default for Transform {
    fn default() -> Self {
        Transform::IDENTITY
    }
}

impl Transform {
    pub const IDENTITY: Transform = Transform {
        m: Mat4::IDENTITY,
        inv: Mat4::IDENTITY,
    };

    /// A transform from a matrix (column vectors, `p' = M p`). Rejects non-finite, non-affine
    /// (bottom row not `0 0 0 1`) and singular matrices.
    pub fn from_matrix(m: Mat4) -> Result<Transform, GeometryError> {
        let bad = |reason: &str| GeometryError::BadTransform {
            reason: format!(
                "{reason}: matrix (row-major) {:?}",
                m.transpose().to_cols_array_2d()
            ),
        };
        if !m.is_finite() {
            return Err(bad("non-finite entries"));
        }
        if m.row(3) != Vec4::new(0.0, 0.0, 0.0, 1.0) {
            return Err(bad("not affine (bottom row must be 0 0 0 1)"));
        }
        // In f64, so that the determinant of a large but regular matrix does not overflow.
        let lin = Mat3::from_mat4(m).as_dmat3();
        let det = lin.determinant();
        // Relative to the scale of the matrix, so tiny but regular scales are accepted.
        let scale = lin.x_axis.length() * lin.y_axis.length() * lin.z_axis.length();
        if !(det.abs() > 1e-6 * scale) || scale == 0.0 {
            return Err(bad("singular"));
        }
        let inv = m.inverse();
        if !inv.is_finite() {
            return Err(bad("too large or too small to invert in single precision"));
        }
        Ok(Transform { m, inv })
    }

    /// A transform from a row-major 4x4 matrix, as written in scene files.
    pub fn from_rows(rows: [[f32; 4]; 4]) -> Result<Transform, GeometryError> {
        Transform::from_matrix(Mat4::from_cols_array_2d(&rows).transpose())
    }

    /// Translate by `t`; every component must be finite.
    pub fn translate(t: Vec3) -> Result<Transform, GeometryError> {
        if !t.is_finite() {
            return Err(GeometryError::BadTransform {
                reason: format!("translation {t:?} is not finite"),
            });
        }
        Ok(Transform {
            m: Mat4::from_translation(t),
            inv: Mat4::from_translation(-t),
        })
    }

    /// Scale by `s` per axis; every component must be non-zero and finite.
    pub fn scale(s: Vec3) -> Result<Transform, GeometryError> {
        Transform::from_matrix(Mat4::from_scale(s))
    }

    /// Rotation by `degrees` about `axis` (right-handed: counter-clockwise seen from the tip).
    pub fn rotate(axis: Vec3, degrees: f32) -> Result<Transform, GeometryError> {
        let a = axis.normalize_or_zero();
        if a == Vec3::ZERO || !degrees.is_finite() {
            return Err(GeometryError::BadTransform {
                reason: format!("rotation axis {axis:?} / angle {degrees} is invalid"),
            });
        }
        let m = Mat4::from_axis_angle(a, degrees.to_radians());
        Ok(Transform {
            m,
            inv: m.transpose(),
        })
    }

    /// Mitsuba's `look_at`: maps the local frame to one at `origin` whose `+z` looks at
    /// `target` and whose `+y` is `up` made orthogonal (camera-to-world for a camera).
    pub fn look_at(origin: Vec3, target: Vec3, up: Vec3) -> Result<Transform, GeometryError> {
        let dir = (target - origin).normalize_or_zero();
        let left = up.cross(dir).normalize_or_zero();
        if dir == Vec3::ZERO || left == Vec3::ZERO {
            return Err(GeometryError::BadTransform {
                reason: format!(
                    "look_at with origin {origin:?}, target {target:?}, up {up:?} is degenerate"
                ),
            });
        }
        let new_up = dir.cross(left);
        let m = Mat4::from_cols(
            left.extend(0.0),
            new_up.extend(0.0),
            dir.extend(0.0),
            origin.extend(1.0),
        );
        Transform::from_matrix(m)
    }

    /// `self ∘ first`: applies `first`, then `self`.
    pub fn compose(&self, first: &Transform) -> Transform {
        Transform {
            m: self.m * first.m,
            inv: first.inv * self.inv,
        }
    }

    /// Applies `self`, then `next`.
    pub fn then(&self, next: &Transform) -> Transform {
        next.compose(self)
    }

    pub fn inverse(&self) -> Transform {
        Transform {
            m: self.inv,
            inv: self.m,
        }
    }

    pub fn matrix(&self) -> Mat4 {
        self.m
    }

    pub fn inverse_matrix(&self) -> Mat4 {
        self.inv
    }

    pub fn point(&self, p: Vec3) -> Vec3 {
        self.m.transform_point3(p)
    }

    pub fn vector(&self, v: Vec3) -> Vec3 {
        self.m.transform_vector3(v)
    }

    /// A normal, by the inverse transpose (not normalised).
    pub fn normal(&self, n: Vec3) -> Vec3 {
        Mat3::from_mat4(self.inv).transpose() * n
    }

    /// Whether the transform mirrors (negative determinant): triangle windings must then be
    /// reversed to keep geometric normals outward.
    pub fn swaps_handedness(&self) -> bool {
        Mat3::from_mat4(self.m).determinant() < 0.0
    }

    pub fn is_identity(&self) -> bool {
        self.m == Mat4::IDENTITY
    }
}

impl std::ops::Mul for Transform {
    type Output = Transform;
    /// `a * b` applies `b` first (matrix order).
    fn mul(self, rhs: Transform) -> Transform {
        self.compose(&rhs)
    }
}

/// One operation of a scene-file transform.
#[derive(Clone, Debug, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum TransformOp {
    #[serde(deserialize_with = "crate::strict_array::exact")]
    Translate([f32; 3]),
    Scale(ScaleSpec),
    Rotate {
        #[serde(deserialize_with = "crate::strict_array::exact")]
        axis: [f32; 3],
        angle: f32,
    },
    LookAt {
        #[serde(deserialize_with = "crate::strict_array::exact")]
        origin: [f32; 3],
        #[serde(deserialize_with = "crate::strict_array::exact")]
        target: [f32; 3],
        #[serde(deserialize_with = "crate::strict_array::exact")]
        up: [f32; 3],
    },
    /// Row-major 4x4.
    #[serde(deserialize_with = "crate::strict_array::matrix")]
    Matrix([[f32; 4]; 4]),
}

/// A uniform or per-axis scale.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged, expecting = "a number or an [x, y, z] array")]
pub enum ScaleSpec {
    Uniform(f32),
    PerAxis([f32; 3]),
}

impl TransformOp {
    pub fn to_transform(&self) -> Result<Transform, GeometryError> {
        match self {
            TransformOp::Translate(t) => Transform::translate(Vec3::from(*t)),
            TransformOp::Scale(ScaleSpec::Uniform(s)) => Transform::scale(Vec3::splat(*s)),
            TransformOp::Scale(ScaleSpec::PerAxis(s)) => Transform::scale(Vec3::from(*s)),
            TransformOp::Rotate { axis, angle } => Transform::rotate(Vec3::from(*axis), *angle),
            TransformOp::LookAt { origin, target, up } => {
                Transform::look_at(Vec3::from(*origin), Vec3::from(*target), Vec3::from(*up))
            }
            TransformOp::Matrix(rows) => Transform::from_rows(*rows),
        }
    }
}

/// Applies the operations in the order listed (the first acts on the object first). Each
/// operation is regular on its own; their product must also stay finite (two scales of 1e30
/// overflow).
pub fn transform_from_ops(ops: &[TransformOp]) -> Result<Transform, GeometryError> {
    let mut t = Transform::IDENTITY;
    for op in ops {
        t = t.then(&op.to_transform()?);
    }
    if !(t.m.is_finite() && t.inv.is_finite()) {
        return Err(GeometryError::BadTransform {
            reason: format!(
                "the operations' product overflows: matrix (row-major) {:?}",
                t.m.transpose().to_cols_array_2d()
            ),
        });
    }
    Ok(t)
}

impl<'de> Deserialize<'de> for Transform {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct TransformVisitor;
        impl<'de> Visitor<'de> for TransformVisitor {
            type Value = Transform;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a list of transform operations or one operation (translate, scale, rotate, look_at, matrix)")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Transform, A::Error> {
                let mut ops = Vec::new();
                while let Some(op) = seq.next_element::<TransformOp>()? {
                    ops.push(op);
                }
                transform_from_ops(&ops).map_err(de::Error::custom)
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Transform, A::Error> {
                let op = TransformOp::deserialize(de::value::MapAccessDeserializer::new(map))?;
                op.to_transform().map_err(de::Error::custom)
            }
        }
        deserializer.deserialize_any(TransformVisitor)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn operations_and_inverse() {
        let t = Transform::scale(Vec3::new(2.0, 1.0, 1.0))
            .unwrap()
            .then(&Transform::rotate(Vec3::Z, 90.0).unwrap())
            .then(&Transform::translate(Vec3::new(0.0, 0.0, 1.0)).unwrap());
        // (1,0,0) -> scale (2,0,0) -> rotate (0,2,0) -> translate (0,2,1)
        assert!(close(t.point(Vec3::X), Vec3::new(0.0, 2.0, 1.0)));
        assert!(close(t.vector(Vec3::X), Vec3::new(0.0, 2.0, 0.0)));
        assert!(close(
            t.inverse().point(t.point(Vec3::new(0.3, -1.0, 2.0))),
            Vec3::new(0.3, -1.0, 2.0)
        ));
        assert!((t.matrix() * t.inverse_matrix()).abs_diff_eq(Mat4::IDENTITY, 1e-5));
    }

    #[test]
    fn normals_stay_perpendicular_under_nonuniform_scale() {
        let t = Transform::scale(Vec3::new(3.0, 1.0, 0.5))
            .unwrap()
            .then(&Transform::rotate(Vec3::new(1.0, 1.0, 0.0), 33.0).unwrap());
        let tangent = Vec3::new(1.0, -1.0, 0.0);
        let n = Vec3::new(1.0, 1.0, 2.0); // perpendicular to tangent
        assert!(tangent.dot(n).abs() < 1e-6);
        assert!(t.vector(tangent).dot(t.normal(n)).abs() < 1e-5);
    }

    #[test]
    fn rejects_singular_non_affine_and_non_finite() {
        assert!(Transform::scale(Vec3::new(1.0, 0.0, 1.0)).is_err());
        assert!(Transform::from_rows([
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0, 1.0]
        ])
        .is_err());
        assert!(Transform::from_rows([
            [1.0, 2.0, 0.0, 0.0],
            [2.0, 4.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0]
        ])
        .is_err());
        assert!(Transform::rotate(Vec3::ZERO, 10.0).is_err());
        assert!(Transform::look_at(Vec3::ZERO, Vec3::Z, Vec3::Z).is_err());
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert!(Transform::translate(Vec3::new(0.0, bad, 1.0)).is_err());
            assert!(Transform::scale(Vec3::new(1.0, bad, 1.0)).is_err());
        }
        assert!(Transform::translate(Vec3::new(1.0, -2.0, 3.0)).is_ok());
    }

    #[test]
    fn look_at_points_z_at_target() {
        let t = Transform::look_at(Vec3::new(0.0, -5.0, 2.0), Vec3::new(0.0, 0.0, 2.0), Vec3::Z)
            .unwrap();
        assert!(close(t.point(Vec3::ZERO), Vec3::new(0.0, -5.0, 2.0)));
        assert!(close(t.vector(Vec3::Z), Vec3::Y));
        assert!(close(t.vector(Vec3::Y), Vec3::Z));
    }

    #[test]
    fn deserializes_lists_and_single_operations() {
        #[derive(Deserialize)]
        struct S {
            transform: Transform,
        }
        let s: S =
            toml::from_str("transform = [ { scale = 2.0 }, { translate = [1, 0, 0] } ]").unwrap();
        assert!(close(s.transform.point(Vec3::X), Vec3::new(3.0, 0.0, 0.0)));
        let s: S = toml::from_str(
            "transform = { matrix = [[1, 0, 0, 5], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]] }",
        )
        .unwrap();
        assert!(close(
            s.transform.point(Vec3::ZERO),
            Vec3::new(5.0, 0.0, 0.0)
        ));
        let s: S = toml::from_str("transform = [ { rotate = { axis = [0, 0, 1], angle = 90 } } ]")
            .unwrap();
        assert!(close(s.transform.point(Vec3::X), Vec3::Y));
        let err = toml::from_str::<S>("transform = [ { scale = [1, 0, 1] } ]")
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("singular"), "{err}");
        let err = toml::from_str::<S>("transform = [ { shear = 1 } ]")
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("shear"), "{err}");
    }
}
