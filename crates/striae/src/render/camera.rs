//! The perspective camera: a pinhole or a thin lens (pbrt-v4 `PerspectiveCamera`), placed by
//! look-at, generating primary rays with their ray differentials (one pixel step in x and y,
//! pbrt's `GenerateRayDifferential`) so every hit knows its pixel footprint.
//!
//! Conventions (keep them when describing the same scene to Mitsuba 3):
//! * `fov` is the **vertical** field of view in degrees (Mitsuba: `fov_axis = "y"`).
//! * World space is right-handed; `up` gives the image's up direction; image `x` grows to
//!   the right of the view direction (`forward x up`), image row 0 is the top.
//! * Film positions are continuous pixel coordinates: pixel `(i, j)` covers `[i, i+1) x [j, j+1)`.

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::math::{Frame, Ray, RayDifferential, Vec2, Vec3};
use crate::sampling::square_to_concentric_disk;

/// A perspective camera, optionally with a thin lens.
#[derive(Clone, Debug)]
pub struct PerspectiveCamera {
    position: Vec3,
    /// `s` = right, `t` = up, `n` = forward (view direction).
    frame: Frame,
    width: u32,
    height: u32,
    /// Half-extent of the image plane at distance 1, vertically and horizontally.
    tan_half_y: f32,
    tan_half_x: f32,
    lens_radius: f32,
    focus_distance: f32,
    /// World-space change of the unnormalised camera direction (`camera_dir`) for one pixel
    /// step right and one pixel step down (pinhole ray differentials).
    step_x_world: Vec3,
    step_y_world: Vec3,
}

/// Why a camera could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CameraError {
    #[error("camera position and look_at coincide")]
    DegenerateView,
    #[error("camera up vector is parallel to the view direction")]
    DegenerateUp,
    #[error("fov = {0} must lie in (0, 180) degrees")]
    BadFov(f32),
    #[error("image size {0} x {1} must be at least 1 x 1")]
    BadResolution(u32, u32),
    #[error("thin lens needs aperture_radius >= 0 and focus_distance > 0 (got {0}, {1})")]
    BadLens(f32, f32),
}

impl PerspectiveCamera {
    /// A camera at `position` looking at `look_at`, `fov_y_deg` the vertical field of view,
    /// rendering a `width x height` image. `lens_radius = 0` is a pinhole.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        position: Vec3,
        look_at: Vec3,
        up: Vec3,
        fov_y_deg: f32,
        width: u32,
        height: u32,
        lens_radius: f32,
        focus_distance: f32,
    ) -> Result<Self, CameraError> {
        if width == 0 || height == 0 {
            return Err(CameraError::BadResolution(width, height));
        }
        if !(fov_y_deg > 0.0 && fov_y_deg < 180.0) {
            return Err(CameraError::BadFov(fov_y_deg));
        }
        if !(lens_radius >= 0.0 && focus_distance > 0.0 && focus_distance.is_finite()) {
            return Err(CameraError::BadLens(lens_radius, focus_distance));
        }
        let forward = look_at - position;
        if !(forward.length_squared() > 0.0) {
            return Err(CameraError::DegenerateView);
        }
        let forward = forward.normalize();
        let right = forward.cross(up);
        if !(right.length_squared() > 1e-12) {
            return Err(CameraError::DegenerateUp);
        }
        let right = right.normalize();
        let true_up = right.cross(forward);
        let tan_half_y = (0.5 * fov_y_deg.to_radians()).tan();
        let tan_half_x = tan_half_y * width as f32 / height as f32;
        let step_x_world = right * (2.0 * tan_half_x / width as f32);
        let step_y_world = true_up * (-2.0 * tan_half_y / height as f32);
        Ok(PerspectiveCamera {
            position,
            frame: Frame {
                s: right,
                t: true_up,
                n: forward,
            },
            width,
            height,
            tan_half_y,
            tan_half_x,
            lens_radius,
            focus_distance,
            step_x_world,
            step_y_world,
        })
    }

    pub fn resolution(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    pub fn position(&self) -> Vec3 {
        self.position
    }

    /// Whether every ray leaves from [`Self::position`] (no thin lens).
    pub fn is_pinhole(&self) -> bool {
        self.lens_radius == 0.0
    }

    /// Direction (camera space, unnormalised, z = 1) through continuous film position `film`.
    #[inline(always)]
    fn camera_dir(&self, film: Vec2) -> Vec3 {
        let sx = (2.0 * film.x / self.width as f32 - 1.0) * self.tan_half_x;
        let sy = (1.0 - 2.0 * film.y / self.height as f32) * self.tan_half_y;
        Vec3::new(sx, sy, 1.0)
    }

    /// Ray through `film` with the lens sample `u_lens` (ignored for a pinhole).
    #[inline(always)]
    fn ray_through(&self, film: Vec2, lens: Vec2) -> Ray {
        let d = self.camera_dir(film);
        if self.lens_radius > 0.0 {
            // Thin lens: the ray from the lens point through the in-focus point (z = focus).
            let p_lens = Vec3::new(lens.x, lens.y, 0.0);
            let p_focus = d * self.focus_distance;
            let dir = (p_focus - p_lens).normalize();
            Ray::new(
                self.position + self.frame.to_world(p_lens),
                self.frame.to_world(dir),
            )
        } else {
            Ray::new(self.position, self.frame.to_world(d.normalize()))
        }
    }

    /// The primary ray through continuous film position `film` (pixels, row 0 on top), with
    /// the lens sample `u_lens` in `[0,1)^2`, and its differentials one pixel to the right and
    /// one pixel down (same lens point). Always inlined: out of line it ran outside the render
    /// loop's AVX2 copy, at about 5 % of a scratched render.
    #[inline(always)]
    pub fn generate_ray(&self, film: Vec2, u_lens: Vec2) -> (Ray, RayDifferential) {
        // A pinhole skips the disk warp (its sin/cos cost ~1% of a render).
        let lens = if self.lens_radius > 0.0 {
            self.lens_radius * square_to_concentric_disk(u_lens)
        } else {
            Vec2::ZERO
        };
        if self.lens_radius > 0.0 {
            let ray = self.ray_through(film, lens);
            let rx = self.ray_through(film + Vec2::X, lens);
            let ry = self.ray_through(film + Vec2::Y, lens);
            return (
                ray,
                RayDifferential {
                    rx_o: rx.o,
                    rx_d: rx.d,
                    ry_o: ry.o,
                    ry_d: ry.d,
                },
            );
        }
        // Pinhole: the offset directions are `d + step` for the one-pixel steps of
        // `camera_dir`, carried to world space by linearity (`to_world(d) + to_world(step)`,
        // the steps precomputed) and normalised; the central ray is `ray_through`'s, bit for
        // bit. The offsets agree with `ray_through(film + 1, ..)` up to rounding.
        let d = self.camera_dir(film);
        let ray = Ray::new(self.position, self.frame.to_world(d.normalize()));
        let dw = self.frame.to_world(d);
        (
            ray,
            RayDifferential {
                rx_o: self.position,
                rx_d: (dw + self.step_x_world).normalize(),
                ry_o: self.position,
                ry_d: (dw + self.step_y_world).normalize(),
            },
        )
    }

    /// The primary ray of [`PerspectiveCamera::generate_ray`] without its differentials (the
    /// same ray, bit for bit).
    #[inline(always)]
    pub fn generate_ray_only(&self, film: Vec2, u_lens: Vec2) -> Ray {
        let lens = if self.lens_radius > 0.0 {
            self.lens_radius * square_to_concentric_disk(u_lens)
        } else {
            Vec2::ZERO
        };
        self.ray_through(film, lens)
    }

    /// The lane form of [`Self::generate_ray_only`] for a pinhole ([`Self::is_pinhole`]): the
    /// world directions of the rays through the film positions `(x[k], y[k])`, bit for bit
    /// the one-ray form's (the same operations in the same order, one over all the lanes at
    /// each step; test `pinhole_lanes_equal_one_ray_at_a_time`). The rays start at
    /// [`Self::position`].
    #[inline(always)]
    pub fn pinhole_directions<const L: usize>(&self, x: &[f32; L], y: &[f32; L]) -> [[f32; L]; 3] {
        let mut out = [[0.0f32; L]; 3];
        for k in 0..L {
            // `ray_through`'s pinhole direction, lane by lane.
            let d = self.camera_dir(Vec2::new(x[k], y[k])).normalize();
            let d = self.frame.to_world(d);
            for (o, c) in out.iter_mut().zip(d.to_array()) {
                o[k] = c;
            }
        }
        out
    }

    /// The film position a world direction from the camera centre projects to, if it is in
    /// front of the camera (used by tests to check the conventions).
    pub fn project(&self, dir: Vec3) -> Option<Vec2> {
        let l = self.frame.to_local(dir);
        if l.z <= 0.0 {
            return None;
        }
        let sx = l.x / l.z / self.tan_half_x;
        let sy = l.y / l.z / self.tan_half_y;
        Some(Vec2::new(
            (sx + 1.0) * 0.5 * self.width as f32,
            (1.0 - sy) * 0.5 * self.height as f32,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pinhole_lanes_equal_one_ray_at_a_time() {
        let c = cam(0.0);
        let x: [f32; 8] = std::array::from_fn(|k| k as f32 * 13.37 + 0.25);
        let y: [f32; 8] = std::array::from_fn(|k| 47.9 - k as f32 * 5.1);
        let d = c.pinhole_directions(&x, &y);
        for k in 0..8 {
            let ray = c.generate_ray_only(Vec2::new(x[k], y[k]), Vec2::splat(0.3));
            assert_eq!(ray.o, c.position());
            let lane = [d[0][k], d[1][k], d[2][k]];
            assert_eq!(
                lane.map(f32::to_bits),
                ray.d.to_array().map(f32::to_bits),
                "lane {k}"
            );
        }
    }

    fn cam(lens: f32) -> PerspectiveCamera {
        PerspectiveCamera::new(
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::ZERO,
            Vec3::Y,
            60.0,
            200,
            100,
            lens,
            5.0,
        )
        .unwrap()
    }

    #[test]
    fn centre_ray_looks_at_target_and_fov_is_vertical() {
        let c = cam(0.0);
        let (r, _) = c.generate_ray(Vec2::new(100.0, 50.0), Vec2::splat(0.5));
        assert!((r.d - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        // Top edge of the image is 30 degrees above the axis.
        let (r, _) = c.generate_ray(Vec2::new(100.0, 0.0), Vec2::splat(0.5));
        assert!((r.d.y.atan2(-r.d.z).to_degrees() - 30.0).abs() < 1e-3);
        // Right of the image is +x (forward = -z, up = +y).
        let (r, _) = c.generate_ray(Vec2::new(199.0, 50.0), Vec2::splat(0.5));
        assert!(r.d.x > 0.0);
        // project() inverts generate_ray.
        let p = c.project(r.d).unwrap();
        assert!((p - Vec2::new(199.0, 50.0)).length() < 1e-3);
    }

    #[test]
    fn pinhole_differentials_are_the_rays_one_pixel_over() {
        // The pinhole's offset rays (world steps added by linearity) agree with the rays
        // through the film positions one pixel right and one pixel down, and the central ray
        // is exactly `ray_through`'s.
        let c = cam(0.0);
        for film in [
            Vec2::new(0.0, 0.0),
            Vec2::new(100.3, 50.7),
            Vec2::new(199.9, 99.9),
            Vec2::new(13.0, 77.5),
        ] {
            let (r, rd) = c.generate_ray(film, Vec2::splat(0.5));
            assert_eq!(r.d, c.ray_through(film, Vec2::ZERO).d);
            assert_eq!(r.d, c.generate_ray_only(film, Vec2::splat(0.5)).d);
            let rx = c.ray_through(film + Vec2::X, Vec2::ZERO);
            let ry = c.ray_through(film + Vec2::Y, Vec2::ZERO);
            assert_eq!((rd.rx_o, rd.ry_o), (rx.o, ry.o));
            assert!((rd.rx_d - rx.d).length() < 1e-6, "{film}");
            assert!((rd.ry_d - ry.d).length() < 1e-6, "{film}");
            assert!(
                (rd.rx_d - r.d).length() > 1e-3,
                "a pixel step moves the ray"
            );
        }
    }

    #[test]
    fn thin_lens_focuses_on_the_focus_plane() {
        let c = cam(0.3);
        let film = Vec2::new(37.0, 81.0);
        let (a, _) = c.generate_ray(film, Vec2::new(0.1, 0.2));
        let (b, _) = c.generate_ray(film, Vec2::new(0.9, 0.7));
        assert!((a.o - b.o).length() > 0.05);
        // Both rays meet on the plane z = 0 (distance 5 along the view axis).
        let pa = a.at(-a.o.z / a.d.z);
        let pb = b.at(-b.o.z / b.d.z);
        assert!((pa - pb).length() < 1e-4, "{pa} {pb}");
    }

    #[test]
    fn bad_cameras_are_rejected() {
        assert_eq!(
            PerspectiveCamera::new(Vec3::ZERO, Vec3::ZERO, Vec3::Y, 40.0, 8, 8, 0.0, 1.0)
                .unwrap_err(),
            CameraError::DegenerateView
        );
        assert_eq!(
            PerspectiveCamera::new(Vec3::ZERO, Vec3::Y, Vec3::Y, 40.0, 8, 8, 0.0, 1.0).unwrap_err(),
            CameraError::DegenerateUp
        );
        assert!(
            PerspectiveCamera::new(Vec3::ZERO, Vec3::X, Vec3::Y, 180.0, 8, 8, 0.0, 1.0).is_err()
        );
    }
}
