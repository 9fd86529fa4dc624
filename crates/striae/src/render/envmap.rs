//! An equirectangular (latitude-longitude) environment map, importance-sampled by luminance
//! times `sin theta` with a piecewise-constant [`Distribution2D`] (pbrt-v4's
//! `ImageInfiniteLight` idea; Mitsuba 3's `envmap` emitter samples the same density).
//!
//! ## Direction <-> texture mapping (Mitsuba 3's `envmap`, checked against its source)
//!
//! World `+y` is up. For a unit direction `d` (pointing from the scene towards the
//! environment), in the map's local frame:
//!
//! ```text
//! u = atan2(d.x, -d.z) / (2 pi)   (wrapped to [0, 1))      v = acos(d.y) / pi
//! d = (sin(theta) sin(phi), cos(theta), -sin(theta) cos(phi)),  phi = 2 pi u, theta = pi v
//! ```
//!
//! so `-z` is at `u = 0`, `+x` at `u = 1/4`, `+z` at `u = 1/2`, `-x` at `u = 3/4`, and image
//! row 0 is the zenith. Like Mitsuba, the image's pixels are treated as *samples on a grid*:
//! pixel `(x, y)` sits at `u = (x + 1/2) / W`, `v = y / (H - 1)` (pixel centres across, the
//! first and last rows at the poles, columns wrap), and radiance is bilinear between them.
//! (Mitsuba 3.9's `envmap` shifts `u` by this half texel, `half_texel()`; with pixel `x` at
//! `u = x / W` the sky seen directly differs from Mitsuba's by up to 5 %: `docs/validation.md`,
//! "Conventions the comparison pins down".) An optional rotation maps world directions to the map's
//! frame (Mitsuba's `to_world`).
//!
//! Sampling: cell `(i, j)` of the `W x (H - 1)` bilinear patches gets weight (mean corner
//! luminance) `* sin(theta_centre)`, positive wherever the radiance is; a sample picks a
//! cell and a uniform point in it, then maps to the sphere; the solid-angle density is
//! `p(u, v) / (2 pi^2 sin theta)`.

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::math::{luminance, Rgb, Vec2, Vec3, PI};
use crate::render::texture::{RgbImage, TextureError};
use crate::sampling::Distribution2D;
use glam::Mat3;
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum EnvMapError {
    #[error("environment map: {0}")]
    Image(#[from] TextureError),
    #[error("environment map `{name}` is {width} x {height} pixels; it needs at least 1 x 2")]
    TooSmall {
        name: String,
        width: usize,
        height: usize,
    },
    #[error("environment map `{name}` holds a negative or non-finite value at pixel ({x}, {y})")]
    BadPixel { name: String, x: usize, y: usize },
    #[error("environment map `scale` = {0}: must be finite and >= 0")]
    BadScale(f32),
}

/// An equirectangular environment light.
#[derive(Clone, Debug)]
pub struct EnvMap {
    image: RgbImage,
    scale: f32,
    /// World -> map frame (the inverse of `to_world`).
    to_local: Mat3,
    to_world: Mat3,
    distribution: Distribution2D,
    /// Half a pixel in `u`, `0.5 / W`: the offset between map and grid coordinates.
    half_texel: f32,
}

/// The map-frame direction for texture coordinates `(u, v)`.
#[inline]
pub fn uv_to_direction(uv: Vec2) -> Vec3 {
    let (sin_p, cos_p) = (2.0 * PI * uv.x).sin_cos();
    let (sin_t, cos_t) = (PI * uv.y).sin_cos();
    Vec3::new(sin_t * sin_p, cos_t, -sin_t * cos_p)
}

/// Texture coordinates in `[0, 1)^2` of a unit map-frame direction.
#[inline]
pub fn direction_to_uv(d: Vec3) -> Vec2 {
    let mut u = d.x.atan2(-d.z) * (0.5 / PI);
    if u < 0.0 {
        u += 1.0;
    }
    if u >= 1.0 {
        u = 0.0;
    }
    Vec2::new(u, d.y.clamp(-1.0, 1.0).acos() / PI)
}

impl EnvMap {
    /// Load an EXR (or PNG, decoded from sRGB) latitude-longitude map.
    pub fn load(path: &Path) -> Result<Self, EnvMapError> {
        let image = RgbImage::load(path, None)?;
        Self::from_image(image, &path.display().to_string())
    }

    /// An environment map from an in-memory row-major RGB array (row 0 = zenith).
    pub fn from_rgb(width: usize, height: usize, pixels: Vec<Rgb>) -> Result<Self, EnvMapError> {
        if width < 1 || height < 2 || pixels.len() != width * height {
            return Err(EnvMapError::TooSmall {
                name: "<memory>".into(),
                width,
                height,
            });
        }
        Self::from_image(RgbImage::new(width, height, pixels), "<memory>")
    }

    /// A uniform environment of radiance `c` (a 1 x 65 map: 64 bands in theta make the
    /// sampling density nearly uniform over the sphere).
    pub fn constant(c: Rgb) -> Result<Self, EnvMapError> {
        Self::from_rgb(1, 65, vec![c; 65])
    }

    fn from_image(image: RgbImage, name: &str) -> Result<Self, EnvMapError> {
        let (w, h) = (image.width, image.height);
        if w < 1 || h < 2 {
            return Err(EnvMapError::TooSmall {
                name: name.into(),
                width: w,
                height: h,
            });
        }
        for (i, p) in image.pixels.iter().enumerate() {
            if !p.is_finite() || p.min_element() < 0.0 {
                return Err(EnvMapError::BadPixel {
                    name: name.into(),
                    x: i % w,
                    y: i / w,
                });
            }
        }
        let lum = |x: usize, y: usize| luminance(image.pixels[y * w + (x % w)]) as f64;
        let mut weights = Vec::with_capacity(w * (h - 1));
        for j in 0..h - 1 {
            let sin_theta = (std::f64::consts::PI * (j as f64 + 0.5) / (h - 1) as f64).sin();
            for i in 0..w {
                let mean = 0.25 * (lum(i, j) + lum(i + 1, j) + lum(i, j + 1) + lum(i + 1, j + 1));
                weights.push(mean * sin_theta);
            }
        }
        let distribution = Distribution2D::new(&weights, w, h - 1);
        Ok(EnvMap {
            image,
            scale: 1.0,
            to_local: Mat3::IDENTITY,
            to_world: Mat3::IDENTITY,
            distribution,
            half_texel: 0.5 / w as f32,
        })
    }

    /// Multiply every radiance by `scale` (Mitsuba's `scale`).
    pub fn with_scale(mut self, scale: f32) -> Result<Self, EnvMapError> {
        if !(scale.is_finite() && scale >= 0.0) {
            return Err(EnvMapError::BadScale(scale));
        }
        self.scale = scale;
        Ok(self)
    }

    /// Orient the map: `to_world` (a rotation) takes map-frame directions to world ones.
    pub fn with_rotation(mut self, to_world: Mat3) -> Self {
        self.to_world = to_world;
        self.to_local = to_world.transpose();
        self
    }

    pub fn width(&self) -> usize {
        self.image.width
    }

    pub fn height(&self) -> usize {
        self.image.height
    }

    /// `u` of the pixel grid (pixel `x` at `x / W`) for map coordinate `u` (pixel `x` at
    /// `(x + 1/2) / W`), wrapped to `[0, 1)`; [`EnvMap::grid_to_map_u`] inverts it.
    #[inline]
    fn map_to_grid_u(&self, u: f32) -> f32 {
        let g = u - self.half_texel;
        if g < 0.0 {
            g + 1.0
        } else {
            g
        }
    }

    #[inline]
    fn grid_to_map_u(&self, g: f32) -> f32 {
        let u = g + self.half_texel;
        if u >= 1.0 {
            u - 1.0
        } else {
            u
        }
    }

    /// Bilinear radiance at map coordinates `uv`, pixels on a grid (see the module comment).
    #[inline]
    fn lookup(&self, uv: Vec2) -> Rgb {
        let (w, h) = (self.image.width, self.image.height);
        let x = self.map_to_grid_u(uv.x) * w as f32;
        let y = (uv.y * (h - 1) as f32).clamp(0.0, (h - 1) as f32);
        let (x0, y0) = (x.floor(), y.floor().min((h - 2) as f32));
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = self
            .image
            .texel(x0, y0)
            .lerp(self.image.texel(x0 + 1, y0), fx);
        let b = self
            .image
            .texel(x0, y0 + 1)
            .lerp(self.image.texel(x0 + 1, y0 + 1), fx);
        a.lerp(b, fy) * self.scale
    }

    /// Radiance arriving from world direction `dir` (unit, pointing towards the environment).
    #[inline]
    pub fn eval(&self, dir: Vec3) -> Rgb {
        self.lookup(direction_to_uv(self.to_local * dir))
    }

    /// A world direction towards the environment, its radiance and solid-angle density.
    /// The density is 0 (radiance 0) only for an all-black map's degenerate samples.
    #[inline]
    pub fn sample(&self, u: Vec2) -> (Vec3, Rgb, f32) {
        let ([x, y], pdf_uv) = self.distribution.sample([u.x as f64, u.y as f64]);
        let uv = Vec2::new(self.grid_to_map_u(x as f32), y as f32);
        let local = uv_to_direction(uv);
        let sin_theta = (PI * uv.y).sin();
        let dir = self.to_world * local;
        if !(sin_theta > 0.0) || !(pdf_uv > 0.0) {
            return (dir, Rgb::ZERO, 0.0);
        }
        let pdf = pdf_uv as f32 / (2.0 * PI * PI * sin_theta);
        (dir, self.lookup(uv), pdf)
    }

    /// Solid-angle density with which [`EnvMap::sample`] returns world direction `dir`.
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        let uv = direction_to_uv(self.to_local * dir);
        let sin_theta = (PI * uv.y).sin();
        if !(sin_theta > 0.0) {
            return 0.0;
        }
        let g = self.map_to_grid_u(uv.x);
        self.distribution.pdf([g as f64, uv.y as f64]) as f32 / (2.0 * PI * PI * sin_theta)
    }

    /// Radiance averaged over the sphere of directions (for choosing among lights by power).
    pub fn mean_radiance(&self) -> Rgb {
        // Integrate the bilinear radiance exactly in u, and by sin-weighted midpoints in v.
        let (w, h) = (self.image.width, self.image.height);
        let mut acc = glam::DVec3::ZERO;
        let mut norm = 0.0;
        for j in 0..h - 1 {
            let sin_t = (std::f64::consts::PI * (j as f64 + 0.5) / (h - 1) as f64).sin();
            for i in 0..w {
                let c = (0..2).flat_map(|dy| (0..2).map(move |dx| (dx, dy)));
                let mean: Rgb = c
                    .map(|(dx, dy)| self.image.texel((i + dx) as i64, (j + dy) as i64))
                    .sum::<Rgb>()
                    * 0.25;
                acc += mean.as_dvec3() * sin_t;
                norm += sin_t;
            }
        }
        (acc / norm).as_vec3() * self.scale
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{chi2_sphere, MeanEstimate, SphereGrid};
    use rand::{Rng, SeedableRng};

    /// A map with a smooth gradient, a bright "sun" and a black band.
    fn test_map(w: usize, h: usize) -> EnvMap {
        let mut px = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let mut c = Rgb::new(0.2 + x as f32 / w as f32, 0.5, 1.0 - y as f32 / h as f32);
                if (x, y) == (w / 3, h / 4) || (x, y) == (w / 3 + 1, h / 4) {
                    c = Rgb::splat(200.0);
                }
                if y == h * 3 / 4 {
                    c = Rgb::ZERO;
                }
                px.push(c);
            }
        }
        EnvMap::from_rgb(w, h, px).unwrap()
    }

    #[test]
    fn mapping_round_trips_and_matches_mitsuba() {
        // Axis directions (Mitsuba's envmap: u = atan2(x, -z) / 2pi, v = acos(y) / pi).
        let close = |a: Vec2, b: Vec2| (a - b).length() < 1e-5;
        assert!(close(
            direction_to_uv(Vec3::new(0.0, 0.0, -1.0)),
            Vec2::new(0.0, 0.5)
        ));
        assert!(close(direction_to_uv(Vec3::X), Vec2::new(0.25, 0.5)));
        assert!(close(direction_to_uv(Vec3::Z), Vec2::new(0.5, 0.5)));
        assert!(close(direction_to_uv(-Vec3::X), Vec2::new(0.75, 0.5)));
        assert!(
            (direction_to_uv(Vec3::Y).y).abs() < 1e-6,
            "zenith at v = 0 (row 0)"
        );
        assert!((direction_to_uv(-Vec3::Y).y - 1.0).abs() < 1e-6);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        for _ in 0..1000 {
            let uv = Vec2::new(rng.random(), rng.random::<f32>() * 0.98 + 0.01);
            let d = uv_to_direction(uv);
            assert!((d.length() - 1.0).abs() < 1e-5);
            let back = direction_to_uv(d);
            let du = (back.x - uv.x).abs();
            assert!(
                du.min(1.0 - du) < 1e-4 && (back.y - uv.y).abs() < 1e-4,
                "{uv:?} -> {back:?}"
            );
        }
        // Grid-sampled pixels: pixel (x, y) is at ((x + 1/2) / W, y / (H - 1)), as in
        // Mitsuba 3.9's `envmap` (`half_texel`).
        let m = test_map(16, 9);
        // (Rows 0 and H - 1 are the poles, where u is undefined.)
        for (x, y) in [(0, 1), (5, 2), (15, 7), (5, 4)] {
            let d = uv_to_direction(Vec2::new((x as f32 + 0.5) / 16.0, y as f32 / 8.0));
            let want = m.image.pixels[y * 16 + x];
            assert!(
                (m.eval(d) - want).abs().max_element() < 1e-3 * want.max_element().max(1.0),
                "({x}, {y})"
            );
        }
        // A rotation about y by 90 degrees moves -z (u = 0) to -x.
        let r = m
            .clone()
            .with_rotation(Mat3::from_rotation_y(std::f32::consts::FRAC_PI_2));
        let d = Vec3::new(0.3, 0.5, -0.8).normalize();
        assert!(
            (r.eval(Mat3::from_rotation_y(std::f32::consts::FRAC_PI_2) * d) - m.eval(d)).length()
                < 1e-4
        );
    }

    /// Chi-square of the sampler against `pdf`, sampled pdf == `pdf(dir)`, radiance ==
    /// `eval(dir)`, and `E[L / pdf]` equals the integral of `L` (quadrature): the density is
    /// normalised and positive wherever the radiance is.
    #[test]
    fn sampler_chi2_and_unbiased() {
        let m = test_map(32, 17).with_rotation(Mat3::from_rotation_x(0.4));
        let mut rng = rand_pcg::Pcg64::seed_from_u64(2);
        let mut est = MeanEstimate::default();
        let n = 300_000;
        // The pdf is piecewise constant: a fine quadrature keeps its jumps from biasing the
        // expected counts.
        let grid = SphereGrid {
            sub: 24,
            ..SphereGrid::new(40, 80)
        };
        let mut pdf_mismatch = 0;
        let r = chi2_sphere(
            &grid,
            n,
            || {
                let (d, l, pdf) = m.sample(Vec2::new(rng.random(), rng.random()));
                assert!(pdf > 0.0);
                // Samples on a cell edge may round into the neighbouring cell.
                if (m.pdf(d) - pdf).abs() > 2e-3 * pdf {
                    pdf_mismatch += 1;
                }
                assert!((l - m.eval(d)).abs().max_element() <= 1e-3 * l.max_element().max(1.0));
                est.push((luminance(l) / pdf) as f64);
                Some(d)
            },
            |d| m.pdf(d) as f64,
        );
        assert!(r.p_value > 1e-3, "{r:?}");
        assert!(
            pdf_mismatch <= n / 2000,
            "{pdf_mismatch} sampled pdfs differ from pdf(dir)"
        );
        let integral: f64 = SphereGrid {
            sub: 8,
            ..SphereGrid::new(100, 200)
        }
        .integrate(|d| luminance(m.eval(d)) as f64)
        .iter()
        .sum();
        assert!(
            est.agrees_with(integral, 4.0, 3e-3 * integral),
            "E[L/pdf] = {} +- {} vs {integral}",
            est.mean(),
            est.std_error()
        );
        let mean = luminance(m.mean_radiance()) as f64 * 4.0 * std::f64::consts::PI;
        assert!(
            (mean - integral).abs() < 0.02 * integral,
            "{mean} vs {integral}"
        );
    }

    #[test]
    fn constant_map_is_uniform_and_exr_loads() {
        let m = EnvMap::constant(Rgb::new(1.0, 2.0, 3.0))
            .unwrap()
            .with_scale(2.0)
            .unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let mut est = MeanEstimate::default();
        for _ in 0..10_000 {
            let (d, l, pdf) = m.sample(Vec2::new(rng.random(), rng.random()));
            assert!((l - Rgb::new(2.0, 4.0, 6.0)).abs().max_element() < 1e-5);
            assert!((m.eval(d) - l).abs().max_element() < 1e-5);
            if d.y.abs() < 0.8 {
                assert!((pdf * 4.0 * PI - 1.0).abs() < 0.05, "nearly uniform: {pdf}");
            }
            est.push((l.x / pdf) as f64);
        }
        assert!(
            est.agrees_with(2.0 * 4.0 * std::f64::consts::PI, 4.0, 1e-4),
            "{est:?}"
        );
        let dir = std::env::temp_dir().join(format!("striae-envmap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("sky.exr");
        exr::prelude::write_rgb_file(&path, 4, 3, |x, y| (x as f32, y as f32, 0.5f32)).unwrap();
        let m = EnvMap::load(&path).unwrap();
        assert_eq!((m.width(), m.height()), (4, 3));
        assert!(
            (m.eval(uv_to_direction(Vec2::new(2.5 / 4.0, 0.5))) - Rgb::new(2.0, 1.0, 0.5)).length()
                < 1e-4
        );
        // Halfway between pixel columns 3 and 0 (the wrap, u = 0 = 1): their mean.
        assert!(
            (m.eval(uv_to_direction(Vec2::new(0.0, 0.5))) - Rgb::new(1.5, 1.0, 0.5)).length()
                < 1e-4
        );
        let e = EnvMap::load(&dir.join("missing.exr"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.exr"), "{e}");
        std::fs::write(dir.join("bad.exr"), b"garbage").unwrap();
        let e = EnvMap::load(&dir.join("bad.exr")).unwrap_err().to_string();
        assert!(e.contains("bad.exr"), "{e}");
        assert!(EnvMap::from_rgb(4, 1, vec![Rgb::ONE; 4]).is_err());
        assert!(EnvMap::from_rgb(1, 2, vec![Rgb::ONE, Rgb::splat(f32::NAN)]).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
