//! Measuring the scratch model: the goniometer of the exact groove (METHOD.md 8.1), the
//! fidelity study of the table against it, the seed's figures (section 7) and the plots.

pub mod fidelity;
pub mod figures;
pub mod gonio;
pub mod plot;
