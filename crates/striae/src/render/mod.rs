//! The path tracer (METHOD.md sections 6-7): a scene file becomes geometry, lights and
//! materials; a material's shading gives a BSDF (the scratched ones look their lobes up in each
//! scratch's frame); the integrator traces paths into the film, whole or in parts.

pub mod bsdf;
pub mod cache;
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
pub mod scratched;
pub mod shading;
pub mod texture;
