//! Measuring the scratch model: the goniometer of the exact groove (METHOD.md 8.1), the
//! fidelity study of the table against it, the seed's figures (section 7) and the plots; and
//! the arcs of scratch holograms (METHOD.md 9.4) and where they glint.
//! Everything that draws (`plot`, `figures`) needs the feature `plot`, the one user of plotters.

pub mod fidelity;
#[cfg(feature = "plot")]
pub mod figures;
pub mod gonio;
pub mod hologram;
#[cfg(feature = "plot")]
pub mod plot;
