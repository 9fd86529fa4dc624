//! # striae
//!
//! Scratched glass and metal, rendered with a precomputed scratch SV-BRDF.
//! The method is specified in `docs/METHOD.md` (Fuji, Sato, Iwasaki, extending
//! Raymond, Guennebaud, Barla 2016); modules follow its pipeline:
//!
//! ```text
//! optics      Fresnel (eq. 2, exact dielectric and conductor), GGX          (below every stage)
//! precompute  profile -> cross_section -> trace2d -> table                 (METHOD.md 2-4, 6)
//!             groove (the exact 2.5D groove) -> groove_slices, wall_table   (8.1-8.2)
//! curves      svg / patterns -> stroke -> curve set, footprint queries      (9.1-9.2)
//! layers      worley -> layer set, raster, footprint queries, caches       (5)
//! maps        painted scratch maps: coverage and orientation pyramids      (9.5)
//! render      geometry, camera, lights, scene -> material, scratched, bsdf
//!             -> integrator -> film, parts                                  (6-7)
//! lab         gonio, fidelity, figures, plot: measuring the model         (7-8)
//! ```
//!
//! Each stage imports only the stages above it in this list (and the shared `math`, `hash`,
//! `sampling`, `io`, `log`).
//!
//! ## Conventions (stated once, used everywhere)
//!
//! * Renderer math is `f32` ([`math::Vec3`] = `glam::Vec3`); the 2D precompute is `f64`.
//! * Colours are linear RGB, [`math::Rgb`].
//! * BSDFs work in a local shading frame with `z` along the shading normal. Both `wo` and
//!   `wi` point **away** from the surface (pbrt's convention); `wo` is given, `wi` sampled.
//! * [`render::bsdf::Bsdf::eval`] returns `f(wo, wi)` **without** the cosine; `pdf` is per unit solid
//!   angle; a sample's `weight` is `f * |cos theta_i| / pdf`.
//! * Texture space `(u, v)` is `[0, 1]^2`; scratch directions live in texture space and are
//!   carried to 3D through `dP/du`, `dP/dv`.
//! * Every random choice is driven by an explicit seed; the same seed gives bit-identical
//!   output whatever the thread count.

pub mod hash;
pub mod io;
pub mod log;
pub mod math;
pub mod memory;
pub mod sampling;
pub mod strict_array;
#[cfg(any(test, feature = "testing"))]
pub mod testing;

// Fresnel equations and the GGX microfacet distribution, shared by the precompute's tracers and
// the renderer's BSDFs.
pub mod optics;

// The scratch BRDF and the exact groove (METHOD.md sections 2-4, 8.1-8.2).
pub mod precompute;

// Scratches as curves: SVG strokes, swirls and circles, tapered, dashed and worn (section 9).
pub mod curves;

// Scratch layers from Worley cell noise (section 5), and the render workers' coverage caches.
pub mod layers;

// Painted scratch maps: coverage and orientation pyramids (section 9.5).
pub mod maps;

// The path tracer (sections 6-7).
pub mod render;

// The goniometer, the fidelity study, the seed's figures and plots (sections 7-8).
pub mod lab;

/// The crate version, stored in every table and image the crate writes.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
