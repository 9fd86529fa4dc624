//! BSDFs in a local shading frame (`z` = shading normal; `wo`, `wi` point away).
//! (Skeleton: the sample record is fixed here so materials and the integrator agree on it.)

use crate::math::{Rgb, Vec3};

/// One sampled incident direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Sampled direction, local frame, unit length, pointing away from the surface.
    pub wi: Vec3,
    /// `f(wo, wi) |cos theta_i| / pdf` (for a delta lobe: the lobe's weight).
    pub weight: Rgb,
    /// Solid-angle density of `wi` (for a delta lobe: the discrete probability of choosing it).
    pub pdf: f32,
    /// Whether `wi` came from a delta (specular) lobe, which light sampling cannot reach.
    pub delta: bool,
    /// Relative index of refraction `n_i / n_o` crossed by the sample (1 for reflection),
    /// used to keep Russian roulette independent of the radiance scaling at refraction.
    pub eta: f32,
}
