//! Small shared math types for the renderer: vectors, colours, rays and orthonormal frames.

pub use glam::{DVec2, DVec3, Vec2, Vec3};

/// Linear RGB radiance or reflectance.
pub type Rgb = glam::Vec3;

pub const PI: f32 = std::f32::consts::PI;
pub const INV_PI: f32 = std::f32::consts::FRAC_1_PI;

/// A ray `o + t d`, `t` in `(0, t_max)`. `d` need not be unit length, but every ray the
/// renderer makes has a unit `d`.
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub o: Vec3,
    pub d: Vec3,
    pub t_max: f32,
}

impl Ray {
    pub fn new(o: Vec3, d: Vec3) -> Self {
        Ray {
            o,
            d,
            t_max: f32::INFINITY,
        }
    }
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + t * self.d
    }
}

/// Offset rays for one pixel step in x and in y (pbrt's ray differentials), carried to every
/// hit so texture lookups (the scratch layers) can filter over the pixel footprint.
#[derive(Clone, Copy, Debug)]
pub struct RayDifferential {
    pub rx_o: Vec3,
    pub rx_d: Vec3,
    pub ry_o: Vec3,
    pub ry_d: Vec3,
}

impl RayDifferential {
    /// Both offset rays equal to `ray`: a zero footprint, for a path whose differentials no
    /// material reads.
    pub fn along(ray: &Ray) -> Self {
        RayDifferential {
            rx_o: ray.o,
            rx_d: ray.d,
            ry_o: ray.o,
            ry_d: ray.d,
        }
    }
}

/// An orthonormal frame `(s, t, n)`; local coordinates are `(x, y, z)` along `(s, t, n)`.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    /// A frame around `n` with an arbitrary but continuous tangent (Duff et al. 2017).
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }

    /// A frame around `n` whose `s` axis is `tangent` made orthogonal to `n` (Gram-Schmidt).
    /// Falls back to [`Frame::from_normal`] when the tangent is (nearly) parallel to `n`.
    pub fn from_normal_tangent(n: Vec3, tangent: Vec3) -> Self {
        let s = tangent - n * n.dot(tangent);
        let len2 = s.length_squared();
        if !(len2 > 1e-12 && len2.is_finite()) {
            return Frame::from_normal(n);
        }
        let s = s / len2.sqrt();
        Frame {
            s,
            t: n.cross(s),
            n,
        }
    }

    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// Reflect `w` about the `z` axis of a local frame (mirror direction, both pointing away).
#[inline]
pub fn reflect_z(w: Vec3) -> Vec3 {
    Vec3::new(-w.x, -w.y, w.z)
}

/// Reflect `w` about the unit normal `n` (both pointing away from the surface).
#[inline(always)]
pub fn reflect(w: Vec3, n: Vec3) -> Vec3 {
    2.0 * w.dot(n) * n - w
}

/// Luminance of a linear Rec.709 colour.
#[inline]
pub fn luminance(c: Rgb) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal_and_invert() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.4, 0.5).normalize(),
            Vec3::new(0.0, 0.0, -0.9999).normalize(),
        ] {
            for f in [
                Frame::from_normal(n),
                Frame::from_normal_tangent(n, Vec3::new(1.0, 2.0, 3.0)),
            ] {
                assert!((f.s.length() - 1.0).abs() < 1e-5);
                assert!((f.t.length() - 1.0).abs() < 1e-5);
                assert!(
                    f.s.dot(f.t).abs() < 1e-5
                        && f.s.dot(f.n).abs() < 1e-5
                        && f.t.dot(f.n).abs() < 1e-5
                );
                assert!((f.s.cross(f.t) - f.n).length() < 1e-4, "right-handed");
                let v = Vec3::new(0.2, -0.7, 0.4);
                assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
            }
        }
    }
}
