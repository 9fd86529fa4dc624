//! Geometry: shapes (triangle meshes from OBJ, the built-in Utah teapot, box, rectangle,
//! sphere), transforms, and the BVH that intersects rays with them.
//! (Skeleton: the hit record is fixed here so the integrator and the shapes agree on it.)

use crate::math::{Vec2, Vec3};

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
