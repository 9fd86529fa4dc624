pub mod figures;
pub mod gonio;
pub mod layers;
pub mod plot;
pub mod precompute;
pub mod render;
