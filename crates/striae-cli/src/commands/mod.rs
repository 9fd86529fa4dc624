pub mod layers;
pub mod mesh;
pub mod plot;
pub mod precompute;
pub mod render;
