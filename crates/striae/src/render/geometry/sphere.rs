//! The analytic sphere (pbrt-v4 `Sphere`, full sphere): exact normals, uv from spherical
//! angles, dP/du and dP/dv. Used for spherical lights and the glass-sphere furnace test.
//!
//! With `phi = atan2(y, x)` in `[0, 2 pi)` and `theta = acos(z / r)` in `[0, pi]` (local
//! coordinates about the centre): `u = phi / (2 pi)`, `v = theta / pi`,
//! `dP/du = 2 pi (-y, x, 0)`, `dP/dv = pi (z cos phi, z sin phi, -r sin theta)`.
//! (`dP/du x dP/dv` points inward; the geometric normal is the outward radial direction.)

use crate::math::{Frame, Ray, Vec2, Vec3, PI};

/// Nearest `t` in `(0, t_max)` where the ray meets the sphere, or `None`.
/// Quadratic solved as in pbrt-v4 (discriminant from `|o - c - (o-c).d d|`, which keeps
/// precision for distant origins) in `f32` with a stable root form.
#[inline]
pub fn intersect_sphere(centre: Vec3, radius: f32, ray: &Ray, t_max: f32) -> Option<f32> {
    let oc = ray.o - centre;
    let a = ray.d.length_squared();
    let b = 2.0 * ray.d.dot(oc);
    let c = oc.length_squared() - radius * radius;
    // b^2 - 4ac = 4a (r^2 - |oc - (oc.d/|d|^2) d|^2)
    let f = oc - (b / (2.0 * a)) * ray.d;
    let disc = 4.0 * a * (radius + f.length()) * (radius - f.length());
    if disc < 0.0 {
        return None;
    }
    let root = disc.sqrt();
    let q = if b < 0.0 {
        -0.5 * (b - root)
    } else {
        -0.5 * (b + root)
    };
    let (mut t0, mut t1) = (q / a, c / q);
    if t0 > t1 {
        std::mem::swap(&mut t0, &mut t1);
    }
    if t0 > 0.0 && t0 < t_max {
        Some(t0)
    } else if t1 > 0.0 && t1 < t_max {
        Some(t1)
    } else {
        None
    }
}

/// Shading data at the point `p` (projected back onto the sphere):
/// `(p, n, uv, dpdu, dpdv)` with `n` the outward normal.
pub fn sphere_surface(centre: Vec3, radius: f32, p: Vec3) -> (Vec3, Vec3, Vec2, Vec3, Vec3) {
    let mut n = (p - centre).normalize_or_zero();
    if n == Vec3::ZERO {
        n = Vec3::Z;
    }
    let local = n * radius;
    let p = centre + local;
    let mut phi = local.y.atan2(local.x);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    let cos_theta = n.z.clamp(-1.0, 1.0);
    let theta = cos_theta.acos();
    let uv = Vec2::new(phi / (2.0 * PI), theta / PI);
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let (sin_phi, cos_phi) = phi.sin_cos();
    let mut dpdu = 2.0 * PI * Vec3::new(-local.y, local.x, 0.0);
    let mut dpdv = PI * Vec3::new(local.z * cos_phi, local.z * sin_phi, -radius * sin_theta);
    if !(dpdu.cross(dpdv).length_squared() > 0.0) {
        // At the poles dP/du vanishes: an arbitrary tangent frame keeps the record usable.
        let f = Frame::from_normal(n);
        dpdu = f.s;
        dpdv = f.t;
    }
    (p, n, uv, dpdu, dpdv)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_sphere_matches_analytic_roots() {
        let c = Vec3::new(1.0, 2.0, 3.0);
        // From outside along -x towards the centre offset by h in y: t = 10 - sqrt(r^2 - h^2).
        for h in [0.0f32, 0.5, 1.2, 1.9] {
            let ray = Ray::new(c + Vec3::new(10.0, h, 0.0), -Vec3::X);
            let t = intersect_sphere(c, 2.0, &ray, f32::INFINITY).unwrap();
            let expect = 10.0 - (4.0 - h * h).sqrt();
            assert!((t - expect).abs() < 1e-4, "h {h}: {t} vs {expect}");
        }
        // Miss, t_max, and from inside (far root).
        assert!(intersect_sphere(
            c,
            2.0,
            &Ray::new(c + Vec3::new(10.0, 2.1, 0.0), -Vec3::X),
            f32::INFINITY
        )
        .is_none());
        assert!(intersect_sphere(
            c,
            2.0,
            &Ray::new(c + Vec3::new(10.0, 0.0, 0.0), -Vec3::X),
            7.9
        )
        .is_none());
        let t = intersect_sphere(
            c,
            2.0,
            &Ray::new(c, Vec3::new(0.0, 0.6, 0.8)),
            f32::INFINITY,
        )
        .unwrap();
        assert!((t - 2.0).abs() < 1e-5);
        // Behind the origin.
        assert!(intersect_sphere(
            c,
            2.0,
            &Ray::new(c + Vec3::new(10.0, 0.0, 0.0), Vec3::X),
            f32::INFINITY
        )
        .is_none());
    }

    #[test]
    fn sphere_derivatives_match_finite_differences() {
        let (c, r) = (Vec3::new(0.5, -1.0, 2.0), 1.5);
        let pos = |u: f32, v: f32| {
            let (phi, theta) = (2.0 * PI * u, PI * v);
            c + r * Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            )
        };
        for (u, v) in [(0.1f32, 0.3f32), (0.7, 0.6), (0.45, 0.9)] {
            let (p, n, uv, dpdu, dpdv) = sphere_surface(c, r, pos(u, v));
            assert!((uv - Vec2::new(u, v)).length() < 1e-4, "{uv:?}");
            assert!(((p - c).normalize() - n).length() < 1e-5);
            let h = 1e-3;
            let fu = (pos(u + h, v) - pos(u - h, v)) / (2.0 * h);
            let fv = (pos(u, v + h) - pos(u, v - h)) / (2.0 * h);
            assert!((fu - dpdu).length() < 1e-2 * fu.length(), "{fu:?} {dpdu:?}");
            assert!((fv - dpdv).length() < 1e-2 * fv.length(), "{fv:?} {dpdv:?}");
        }
        let (_, _, _, dpdu, dpdv) = sphere_surface(c, r, c + Vec3::new(0.0, 0.0, r));
        assert!(dpdu.is_finite() && dpdv.is_finite() && dpdu.cross(dpdv).length() > 0.0);
    }
}
