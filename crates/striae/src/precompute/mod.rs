//! The scratch BRDF, precomputed from the groove's cross-section (METHOD.md sections 2-4), and
//! the exact 2.5D groove it is measured against and that renders glass walls (section 8.1-8.2).
//!
//! ```text
//! profile::Profile -> cross_section::CrossSection   the groove's walls as segments (shared)
//!   trace2d        the 2D tracer, eq. (1'), binned by angle_bins -> table::ScratchTable
//!   table          the table file, gamma (eq. 4), the 3D scratch BRDF (eq. 3-5), its sampler
//!   groove         the exact 2.5D groove tracer (8.1) -> groove_slices (a table option),
//!   crossing       two crossing grooves' union traced in 3D (8.3), for traced glass walls
//!                  wall_table (the four lobes of dielectric walls, 8.2)
//! ```

pub mod angle_bins;
pub(crate) mod cross_section;
pub mod crossing;
pub mod groove;
pub mod groove_slices;
pub mod profile;
pub mod table;
pub mod trace2d;
pub mod wall_table;
