//! The optics every stage shares: Fresnel reflectance (METHOD.md eq. 2 and the exact laws) in
//! `f64` for the precompute and `f32` for the renderer, and the GGX microfacet distribution of
//! rough walls and rough BSDFs.

pub mod fresnel;
pub mod fresnel_f32;
pub mod microfacet;
pub mod microsurface;
