pub mod figures;
pub mod layers;
pub mod plot;
pub mod precompute;
pub mod render;
