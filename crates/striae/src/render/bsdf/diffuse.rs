//! Lambertian reflection: `f = reflectance / pi`, sampled cosine-weighted (Malley's method).

use super::BsdfSample;
use crate::math::{Rgb, Vec2, Vec3, INV_PI};
use crate::sampling::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};

/// A Lambertian reflector with RGB albedo `reflectance` in `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Diffuse {
    pub reflectance: Rgb,
}

impl Diffuse {
    pub fn new(reflectance: Rgb) -> Self {
        Diffuse { reflectance }
    }

    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        self.reflectance * INV_PI
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        cosine_hemisphere_pdf(wi)
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = square_to_cosine_hemisphere(u);
        let pdf = cosine_hemisphere_pdf(wi);
        if pdf <= 0.0 {
            return None;
        }
        // f cos / pdf = (R / pi) cos / (cos / pi) = R.
        Some(BsdfSample {
            wi,
            weight: self.reflectance,
            pdf,
            delta: false,
            eta: 1.0,
            from: None,
        })
    }
}
