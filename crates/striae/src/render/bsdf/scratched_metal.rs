//! Scratched metal with rough walls (METHOD.md 8.1, `walls = "specular"` with `roughness > 0`):
//! a smooth conductor mixed with the reflected lobe of a groove whose walls are GGX-rough
//! conductors, `f = (1 - C) f_mirror + tint sum_k c_k f_groove,k` (`C = sum_k c_k`, the
//! footprint coverages).
//!
//! The metal keeps the seed's model ([`super::ScratchedBsdf`] for mirror walls): the smooth
//! base reflects with its RGB Fresnel, the groove carries the table's scalar Fresnel law at
//! every wall hit (traced into the table, [`crate::precompute::wall_table::WallKind::Specular`]) times
//! the material's `tint`. Only the lobe changes: rough walls spread it in `theta_o` (and lose
//! what single-scattering GGX drops), so it depends on `theta_o` and is read from the 4D wall
//! table's `r_out` lobe ([`WallLobeTable`], with `wo` as the incident direction: rough
//! conductors are reciprocal), as [`super::ScratchedGlassBsdf`] reads its four lobes.
//!
//! Sampling (as the seed's metal): the base mirror with probability `1 - C` (weight `F(wo)`),
//! groove lobe `k` with `c_k`, then a slice, an exit bin and a point in it from the table. The
//! density of the non-delta part is `sum_k c_k pdf_k`, the value `pdf` returns. The BSDF is
//! opaque: 0 unless `wo.z > 0` and `wi.z > 0`.

use super::scratched::CoveredLobes;
use super::{BsdfSample, Conductor, ConductorIor, ScratchLobe, WallLobeTable};
use crate::math::{Rgb, Vec2, Vec3};

/// Scratched metal with rough walls at one hit (see the module notes).
#[derive(Clone, Copy, Debug)]
pub struct ScratchedMetalBsdf<'a> {
    /// The smooth base's complex index.
    pub ior: ConductorIor,
    /// RGB factor on the groove lobe (the base's colour, as the seed's metal).
    pub tint: Rgb,
    pub table: &'a WallLobeTable,
    lobes: CoveredLobes,
}

impl<'a> ScratchedMetalBsdf<'a> {
    /// This BSDF with its sampling's lobe number read within `share` ([`super::LobeShare`]).
    #[inline(always)]
    pub fn in_share(mut self, share: super::LobeShare) -> Self {
        self.lobes = self.lobes.in_share(share);
        self
    }

    /// `lobes` with coverages `c_k >= 0` ([`CoveredLobes`]).
    pub fn new(
        ior: ConductorIor,
        tint: Rgb,
        table: &'a WallLobeTable,
        lobes: &[ScratchLobe],
    ) -> Self {
        ScratchedMetalBsdf {
            ior,
            tint,
            table,
            lobes: CoveredLobes::new(lobes),
        }
    }

    /// `(tint sum_k c_k f_k, sum_k c_k pdf_k)` for `wo`, `wi` both above the surface.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        if !(wo.z > 0.0 && wi.z > 0.0) {
            return (Rgb::ZERO, 0.0);
        }
        let mut sum = (0.0f32, 0.0f32);
        for lobe in self.lobes.as_slice() {
            let Some((wi_s, lean)) = lobe.wi_to_scratch(wi) else {
                continue;
            };
            let corners = self.table.corners(lobe.wo_to_scratch(wo));
            let (f, pdf) = self.table.eval_pdf(&corners, wi_s);
            sum = (
                sum.0 + lobe.coverage * f * lean,
                sum.1 + lobe.coverage * pdf,
            );
        }
        (self.tint * sum.0, sum.1)
    }

    /// `u_lobe` picks the base mirror or a groove lobe and, rescaled, the lobe's slice; `u`
    /// the direction in it.
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let u_lobe = self.lobes.lobe_number(u_lobe);
        if !(wo.z > 0.0) {
            return None;
        }
        let base = 1.0 - self.lobes.total();
        if u_lobe < base || self.lobes.is_empty() {
            // The smooth conductor's mirror sample (weight `F(wo)`), chosen with `1 - C`.
            let mirror = Conductor { ior: self.ior }.sample(wo)?;
            return Some(BsdfSample {
                pdf: base,
                ..mirror
            });
        }
        let (k, u0) = self.lobes.pick(u_lobe, base);
        let lobe = &self.lobes.as_slice()[k];
        let corners = self.table.corners(lobe.wo_to_scratch(wo));
        let wi = lobe.wi_from_scratch(self.table.sample(&corners, u0, u)?.0)?;
        let (f, pdf) = self.eval_pdf(wo, wi);
        (pdf > 0.0).then(|| BsdfSample::reflected(wi, f, pdf))
    }
}
