//! # striae
//!
//! Scratched glass and metal, rendered with a precomputed scratch SV-BRDF.
//! The method is specified in `docs/METHOD.md` (Fuji, Sato, Iwasaki, extending
//! Raymond, Guennebaud, Barla 2016); modules follow its pipeline:
//!
//! ```text
//! profile -> trace2d -> table (slices, gamma, eval, sample)      (METHOD.md sections 2-4, 6)
//! layers (worley, layer set, raster, footprint queries)         (section 5)
//! geometry (shapes, teapot, obj, bvh) -> camera, lights, scene
//! bsdf / material / texture -> integrator -> film (exr, png)    (section 6-7)
//! ```
//!
//! ## Conventions (stated once, used everywhere)
//!
//! * Renderer math is `f32` ([`math::Vec3`] = `glam::Vec3`); the 2D precompute is `f64`.
//! * Colours are linear RGB, [`math::Rgb`].
//! * BSDFs work in a local shading frame with `z` along the shading normal. Both `wo` and
//!   `wi` point **away** from the surface (pbrt's convention); `wo` is given, `wi` sampled.
//! * [`bsdf::Bsdf::eval`] returns `f(wo, wi)` **without** the cosine; `pdf` is per unit solid
//!   angle; a sample's `weight` is `f * |cos theta_i| / pdf`.
//! * Texture space `(u, v)` is `[0, 1]^2`; scratch directions live in texture space and are
//!   carried to 3D through `dP/du`, `dP/dv`.
//! * Every random choice is driven by an explicit seed; the same seed gives bit-identical
//!   output whatever the thread count.

pub mod cache;
pub mod fresnel;
pub mod hash;
pub mod io;
pub mod log;
pub mod math;
pub mod sampling;
pub mod strict_array;
pub mod testing;

// The scratch BRDF precompute (METHOD.md sections 2-4, 6).
pub mod plot;
pub mod profile;
pub mod table;
pub mod trace2d;

// The exact groove (METHOD.md 8.1): shared cross-section geometry, angle bins, the 2.5D tracer.
pub mod angle_bins;
pub(crate) mod cross_section;
pub mod fidelity;
pub mod gonio;
pub mod groove;
pub mod groove_slices;
pub mod wall_table;

// Scratch layers from Worley cell noise (section 5).
pub mod layers;

// The path tracer (sections 6-7).
pub mod bsdf;
pub mod camera;
pub mod envmap;
pub mod film;
pub mod geometry;
pub mod integrator;
pub mod lights;
pub mod material;
pub mod parts;
pub mod sampler;
pub mod scene;
pub mod shading;
pub mod texture;

// Scratched glass and metal (section 6), and the seed's figures (section 7).
pub mod figures;
pub mod scratched;

/// The crate version, stored in every table and image the crate writes.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
