//! The scratch BRDF table: theta slices, gamma, the 3D BRDF and its sampler (METHOD.md
//! sections 4 and 6), and the `.npz` file that stores it.
//!
//! [`ScratchTable::compute`] traces a profile ([`crate::precompute::trace2d`]), applies Fresnel per theta
//! slice (`seed` mode: `rho_s(theta) = rho_m F(cos theta)`, the seed's assumption; `walls` mode:
//! Fresnel at every wall hit, [Raymond16]) and fits `gamma` per bin by eq. (4).
//! [`ScratchBrdf`] evaluates the 3D BRDF by eq. (3) with the `2/pi` unit factor of section 4
//! and samples it as section 6 prescribes; for mirror walls it is the delta-in-theta lobe.
//! With `groove_slices = S` a table also carries the exact groove's BRDF at `S` slices of
//! `theta_i` ([`crate::precompute::groove_slices`]), which [`ScratchBrdf`] then evaluates instead of eq. (3).
//! The file layout is documented in `docs/table-format.md`.
//!
//! This file holds the table and its computation; `file.rs` the file (parameters record and
//! hash, archive checks, save and load), `brdf.rs` the 3D BRDF of eq. (3)-(5) and its sampler.

mod brdf;
mod file;
#[cfg(test)]
mod tests;

pub use brdf::{DeltaTerm, ScratchBrdf, ScratchSample, WoTerms, THETA_GRID};
pub(crate) use file::check_npz_sizes;
pub use file::{TableError, TableParams, FORMAT_VERSION};

use crate::precompute::groove::GonioSettings;
use crate::precompute::groove_slices::GrooveSlices;
use crate::precompute::trace2d::{self, bin_centre, FresnelMode, COS_THETA_SLICES};
use ndarray::{Array2, Array3};
use std::f64::consts::PI;

/// A precomputed scratch BRDF. Arrays are row-major `[phi_i bin][phi_o bin]`.
#[derive(Clone, Debug, PartialEq)]
pub struct ScratchTable {
    pub params: TableParams,
    /// `M`.
    pub m: usize,
    /// Bin centres `phi_k = -pi/2 + (k + 1/2) pi / M`.
    pub phi: Vec<f64>,
    /// `rho_m`, `M x M`, eq. (1'), no Fresnel.
    pub rho_m: Vec<f64>,
    /// `rho_s(theta)` for [`THETA_SLICES`](trace2d::THETA_SLICES), `3 x M x M`.
    pub rho_s: Vec<f64>,
    /// Eq. (4) exponent per bin, `M x M`.
    pub gamma: Vec<f64>,
    /// Per `phi_i`: energy fraction dropped by the bounce cap.
    pub dropped: Vec<f64>,
    /// `rho` of the exact-groove slices ([`crate::precompute::groove_slices`]), `S x M x M` for
    /// `S = params.trace.groove_slices`; empty without them.
    pub groove_rho: Vec<f64>,
    /// The striae version that computed it.
    pub version: String,
}

/// The `gamma` used where eq. (4) is degenerate: equal slices (`|rho(pi/2) - rho(0)|` below
/// `1e-12` of their size, e.g. empty bins) or `R_3` outside `(0, 1)` (non-monotone in theta,
/// possible in `walls` mode). `gamma = 1` is a linear blend in `|theta_o|`.
pub const GAMMA_FALLBACK: f64 = 1.0;

/// Eq. (4): `gamma = ln(R_3) / ln(2/3)`, `R_3 = (rho(pi/3) - rho(0)) / (rho(pi/2) - rho(0))`,
/// with the fallback [`GAMMA_FALLBACK`].
pub fn fit_gamma(rho0: f64, rho3: f64, rho2: f64) -> f64 {
    let den = rho2 - rho0;
    if den.abs() <= 1e-12 * (rho0.abs() + rho2.abs()) || den == 0.0 {
        return GAMMA_FALLBACK;
    }
    let r3 = (rho3 - rho0) / den;
    if r3 > 0.0 && r3 < 1.0 && r3.is_finite() {
        r3.ln() / (2.0f64 / 3.0).ln()
    } else {
        GAMMA_FALLBACK
    }
}

impl ScratchTable {
    /// Trace and assemble a table (sections 3-4). `progress(done_walks)` is called from worker
    /// threads; the total is `params.trace.total_paths()`.
    pub fn compute(
        params: &TableParams,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<Self, TableError> {
        let out = trace2d::trace(&params.profile, &params.trace, progress)?;
        let m = out.m;
        let mm = m * m;
        let rho_s = match (params.trace.fresnel_mode, out.rho_walls) {
            (FresnelMode::Walls, Some(w)) => w,
            _ => {
                // The seed's assumption: rho_s(theta) = rho_m F(n, cos theta).
                let law = params.trace.fresnel_law;
                let mut v = Vec::with_capacity(3 * mm);
                for c in COS_THETA_SLICES {
                    let f = law.reflectance(c);
                    v.extend(out.rho_m.iter().map(|r| r * f));
                }
                v
            }
        };
        let gamma = (0..mm)
            .map(|k| fit_gamma(rho_s[k], rho_s[mm + k], rho_s[2 * mm + k]))
            .collect();
        let groove_rho = Self::compute_groove(params, progress)?;
        Ok(ScratchTable {
            params: params.clone(),
            m,
            phi: (0..m).map(|k| bin_centre(k, m)).collect(),
            rho_m: out.rho_m,
            rho_s,
            gamma,
            dropped: out.dropped,
            groove_rho,
            version: crate::VERSION.to_string(),
        })
    }

    /// The exact-groove slices' `rho` (empty for `groove_slices = 0`): `N N_r` goniometer
    /// paths per slice and `phi_i` bin with the table's Fresnel law, bounce cap and seed.
    fn compute_groove(
        params: &TableParams,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<Vec<f64>, TableError> {
        let t = &params.trace;
        if t.groove_slices == 0 {
            return Ok(Vec::new());
        }
        let base = GonioSettings {
            fresnel_law: t.fresnel_law,
            paths: t.n as u64 * t.nr as u64,
            max_bounces: t.max_bounces,
            seed: t.seed,
            ..GonioSettings::default()
        };
        let g = GrooveSlices::compute(&params.profile, &base, t.m, t.groove_slices, progress)
            .map_err(TableError::Groove)?;
        Ok(g.rho)
    }

    /// Per `phi_i` row: the 2D albedo `sum_j rho_m cos(phi_j) pi/M` (eq. 1' makes it <= 1).
    pub fn albedo_2d(&self) -> Vec<f64> {
        let m = self.m;
        (0..m)
            .map(|i| {
                (0..m)
                    .map(|j| self.rho_m[i * m + j] * self.phi[j].cos() * PI / m as f64)
                    .sum()
            })
            .collect()
    }

    /// `rho_s` slice `c` at `[phi_i bin i][phi_o bin o]`.
    #[inline]
    pub fn slice(&self, c: usize, i: usize, o: usize) -> f64 {
        self.rho_s[(c * self.m + i) * self.m + o]
    }

    /// Eq. (3)-(4): `rho_s(theta_o, phi_o, phi_i) = R rho_s(pi/2) + (1 - R) rho_s(0)`,
    /// `R = (2 |theta_o| / pi)^gamma`, for bins `i` (phi_i) and `o` (phi_o).
    #[inline]
    pub fn rho(&self, theta_o: f64, i: usize, o: usize) -> f64 {
        let r = eq4_r(eq4_t(theta_o), self.gamma[i * self.m + o]);
        r * self.slice(2, i, o) + (1.0 - r) * self.slice(0, i, o)
    }

    /// [`Self::rho`] at the `theta_o` points `theta_k` for the fixed bins `(i, o)`, one value per
    /// point, with `R` from `r_common` where this bin's `gamma` is `gamma_common` (bit for bit
    /// what `rho` gives: the same `powf`, computed once per point instead of once per bin).
    #[inline]
    pub fn rho_at_points(
        &self,
        i: usize,
        o: usize,
        t: &[f64],
        gamma_common: f64,
        r_common: &[f64],
        out: &mut [f64],
    ) {
        let g = self.gamma[i * self.m + o];
        let (s2, s0) = (self.slice(2, i, o), self.slice(0, i, o));
        let common = g == gamma_common;
        for k in 0..t.len() {
            let r = if common { r_common[k] } else { eq4_r(t[k], g) };
            out[k] = r * s2 + (1.0 - r) * s0;
        }
    }

    /// Convenience: `Array2` views for callers that prefer ndarray.
    pub fn rho_m_array(&self) -> Array2<f64> {
        Array2::from_shape_vec((self.m, self.m), self.rho_m.clone()).expect("shape")
    }

    pub fn rho_s_array(&self) -> Array3<f64> {
        Array3::from_shape_vec((3, self.m, self.m), self.rho_s.clone()).expect("shape")
    }
}

/// `t = min(2 |theta_o| / pi, 1)` of eq. (4).
#[inline]
pub(crate) fn eq4_t(theta_o: f64) -> f64 {
    (2.0 * theta_o.abs() / PI).min(1.0)
}

/// `R = t^gamma` of eq. (4) (0 at `t = 0`).
#[inline]
pub(crate) fn eq4_r(t: f64, g: f64) -> f64 {
    if t == 0.0 {
        0.0
    } else {
        t.powf(g)
    }
}
