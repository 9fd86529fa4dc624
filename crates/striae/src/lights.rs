//! Light sources and their sampling for next-event estimation (pbrt-v4 chapter 12, Mitsuba 3's
//! `area`, `constant`, `envmap`, `directional` emitters):
//!
//! * [`Light::Area`]: a shape that emits constant radiance from its front side (the side its
//!   geometric normal points to, one-sided as in Mitsuba); sampled uniformly by area
//!   (`Shape::sample_area`) and converted to solid angle, `pdf = pdf_A d^2 / |cos theta_l|`.
//! * [`Light::Environment`]: light from infinitely far away, either constant (sampled uniformly
//!   over the sphere) or an equirectangular map (importance-sampled by `envmap::EnvMap`).
//! * [`Light::Sun`]: a directional (delta) light given by its irradiance on a surface facing it.
//!
//! The integrator picks one light uniformly per shading point (probability `1 / n_lights`).

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::envmap::EnvMap;
use crate::geometry::Shape;
use crate::math::{Rgb, Vec2, Vec3};
use crate::sampling::{square_to_uniform_sphere, UNIFORM_SPHERE_PDF};

/// Light arriving from infinitely far away.
#[derive(Debug)]
pub enum Environment {
    /// The same radiance from every direction.
    Constant { radiance: Rgb },
    /// An equirectangular radiance map (its own orientation and scale applied inside).
    Map(Box<EnvMap>),
}

impl Environment {
    /// Radiance arriving along `-dir` (i.e. seen looking in world direction `dir`).
    #[inline]
    pub fn eval(&self, dir: Vec3) -> Rgb {
        match self {
            Environment::Constant { radiance } => *radiance,
            Environment::Map(m) => m.eval(dir),
        }
    }

    /// Solid-angle density with which [`Environment::sample`] returns `dir`.
    #[inline]
    pub fn pdf(&self, dir: Vec3) -> f32 {
        match self {
            Environment::Constant { .. } => UNIFORM_SPHERE_PDF,
            Environment::Map(m) => m.pdf(dir),
        }
    }

    /// A direction toward the environment, its radiance and density.
    #[inline]
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, Rgb, f32)> {
        match self {
            Environment::Constant { radiance } => {
                Some((square_to_uniform_sphere(u), *radiance, UNIFORM_SPHERE_PDF))
            }
            Environment::Map(m) => Some(m.sample(u)),
        }
    }
}

/// A light source of the scene.
#[derive(Debug)]
pub enum Light {
    /// Shape `shape` emits `radiance` from its front side.
    Area {
        shape: u32,
        radiance: Rgb,
    },
    Environment(Environment),
    /// A directional light: `direction` points **toward** the sun (unit), `irradiance` is the
    /// irradiance on a surface facing it.
    Sun {
        direction: Vec3,
        irradiance: Rgb,
    },
}

/// A light sample seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point toward the light.
    pub wi: Vec3,
    /// Distance to the sampled point (`f32::INFINITY` for environment and sun).
    pub dist: f32,
    /// Radiance arriving (for the sun: irradiance).
    pub radiance: Rgb,
    /// Solid-angle density (1 for the sun, a delta light).
    pub pdf: f32,
    pub delta: bool,
}

impl Light {
    /// Sample light arriving at `p` with the random pair `u`. `None` when the sample carries
    /// nothing (back side of an area light, zero density).
    pub fn sample_li(&self, p: Vec3, u: Vec2, shapes: &[Shape]) -> Option<LightSample> {
        match self {
            Light::Area { shape, radiance } => {
                let (q, n, pdf_area) = shapes[*shape as usize].sample_area(u);
                let d = q - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0) {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let cos_l = -wi.dot(n);
                if cos_l <= 0.0 {
                    return None;
                }
                let pdf = pdf_area * dist2 / cos_l;
                if !(pdf > 0.0 && pdf.is_finite()) {
                    return None;
                }
                Some(LightSample {
                    wi,
                    dist,
                    radiance: *radiance,
                    pdf,
                    delta: false,
                })
            }
            Light::Environment(env) => {
                let (wi, radiance, pdf) = env.sample(u)?;
                if !(pdf > 0.0) {
                    return None;
                }
                Some(LightSample {
                    wi,
                    dist: f32::INFINITY,
                    radiance,
                    pdf,
                    delta: false,
                })
            }
            Light::Sun {
                direction,
                irradiance,
            } => Some(LightSample {
                wi: *direction,
                dist: f32::INFINITY,
                radiance: *irradiance,
                pdf: 1.0,
                delta: true,
            }),
        }
    }

    /// Radiance an area light emits toward `wo` (world, pointing away from the light) at a
    /// point with geometric normal `ng`: its radiance on the front side, 0 behind.
    #[inline]
    pub fn emitted(&self, ng: Vec3, wo: Vec3) -> Rgb {
        match self {
            Light::Area { radiance, .. } if ng.dot(wo) > 0.0 => *radiance,
            _ => Rgb::ZERO,
        }
    }

    /// Solid-angle density with which [`Light::sample_li`] picks the point hit at distance
    /// `dist` along unit `dir` on this area light, whose geometric normal there is `ng`.
    #[inline]
    pub fn area_pdf(&self, shapes: &[Shape], dist: f32, dir: Vec3, ng: Vec3) -> f32 {
        match self {
            Light::Area { shape, .. } => {
                let cos_l = dir.dot(ng).abs();
                if cos_l <= 0.0 {
                    return 0.0;
                }
                dist * dist / (cos_l * shapes[*shape as usize].area())
            }
            _ => 0.0,
        }
    }
}
