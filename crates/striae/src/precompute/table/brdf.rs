//! The 3D scratch BRDF of a table (METHOD.md sections 4 and 6): eq. (3)-(5) evaluated in
//! the scratch frame, its sampler, and the delta-in-theta lobe of mirror walls.

use super::{eq4_r, eq4_t, ScratchTable};
use crate::math::Vec3;
use crate::precompute::angle_bins::AngleBins;
use crate::precompute::groove_slices::GrooveSlices;
use crate::precompute::trace2d::Walls;
use crate::sampling::Distribution1D;
use std::f64::consts::{FRAC_PI_2, PI};

/// A sampled incident direction (scratch frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScratchSample {
    pub wi: Vec3,
    /// `f cos(theta_i)/pdf` for the smooth lobe; for the delta lobe the row's sum term over
    /// its probability: `rho_s cos(phi_i) (pi/M) / pmf`.
    pub weight: f64,
    /// Solid-angle pdf (smooth lobe) or the density in `phi_i` of the delta lobe.
    pub pdf: f64,
    /// Mirror walls: a delta in theta (`theta_i = -theta_o`).
    pub delta: bool,
}

/// One term of the delta lobe's discrete sum (mirror walls, section 6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeltaTerm {
    /// Direction at the bin centre `phi_k`, `theta_i = -theta_o`.
    pub wi: Vec3,
    /// `rho_s(theta_o, phi_o, phi_k) cos(phi_k) pi / M`.
    pub value: f64,
}

/// The 3D scratch BRDF of a table in the scratch frame: `x` across the scratch, `y` along it,
/// `z` the normal; `wo`, `wi` point away from the surface (METHOD.md section 1:
/// `phi = atan2(x, z)`, `theta = asin(y)`). Angles are looked up in the nearest bin
/// (piecewise-constant in `phi_o`, `phi_i`; no interpolation). A table with exact-groove
/// slices is evaluated by them ([`GrooveSlices::rho_at`], a function of `theta_i`, `phi_i`,
/// `phi_o`) instead of eq. (3); the sampler is the same with other rows.
#[derive(Clone, Debug)]
pub struct ScratchBrdf {
    table: ScratchTable,
    delta: bool,
    /// Per `phi_o` bin: distribution over `phi_i` bins of `rho_s(pi/2, phi_o, phi_i) cos(phi_i)`
    /// (with exact-groove slices: of [`GrooveSlices::mean_rho`] times `cos(phi_i)`, the lobe's
    /// `f cos` integrated over `theta_i` in each `phi_i` bin).
    rows: Vec<Distribution1D>,
    /// The exact-groove slices, if the table has them.
    groove: Option<GrooveSlices>,
    /// The `phi` binner of `wo` and `wi` ([`Self::phi_bin`]).
    phi_bins: AngleBins,
    /// The eq. (4) exponent most bins share ([`common_gamma`]), NaN if none is shared widely.
    gamma_common: f64,
    /// `t` and the common `R` of eq. (4) as functions of `wo.y` ([`ThetaGrid`]).
    theta_grid: ThetaGrid,
}

/// Points of the `s = sqrt(1 - |y|)` grid on which `theta_o` and eq. (4)'s `R` are tabulated.
/// In `s`, `t = 2 |asin(y)| / pi = 1 - (4/pi) asin(s / sqrt 2)` is analytic and `R = t^gamma`
/// is smooth for `gamma >= 2`, so linear interpolation on 2049 points is within 3e-8 in `t`
/// and about 1e-6 in `R` (for the seed's `gamma` = 8.55: `|R''| <= 60`, `h^2/8 |R''|`).
pub const THETA_GRID: usize = 2049;

/// `t = 2 |theta_o| / pi` and `R = t^gamma` of eq. (4) as functions of `y = wo.y`, interpolated
/// on [`THETA_GRID`] points of `s = sqrt(1 - |y|)`: a hit needs one `sqrt` instead of an `asin`
/// and a `powf`. The fast path of [`eq4_t`] and [`eq4_r`], tested against them in
/// `tabulated_theta_terms_match_asin_and_powf`.
#[derive(Clone, Debug)]
struct ThetaGrid {
    gamma: f64,
    t: Vec<f64>,
    /// `R` on the grid; empty unless `gamma >= 2` (where `R` is smooth enough to interpolate).
    r: Vec<f64>,
}

impl ThetaGrid {
    fn new(gamma: f64) -> Self {
        let t: Vec<f64> = (0..THETA_GRID)
            .map(|k| {
                let s = k as f64 / (THETA_GRID - 1) as f64;
                eq4_t((1.0 - s * s).clamp(-1.0, 1.0).asin())
            })
            .collect();
        let r = if gamma >= 2.0 {
            t.iter().map(|&t| eq4_r(t, gamma)).collect()
        } else {
            Vec::new()
        };
        ThetaGrid { gamma, t, r }
    }

    /// `(t, R)` at `y` (`R` = 0 when `gamma` is NaN).
    #[inline]
    fn at(&self, y: f64) -> (f64, f64) {
        let x = (1.0 - y.abs()).max(0.0).sqrt() * (THETA_GRID - 1) as f64;
        let k = (x as usize).min(THETA_GRID - 2);
        let f = (x - k as f64).clamp(0.0, 1.0);
        let lerp = |v: &[f64]| v[k] + (v[k + 1] - v[k]) * f;
        let t = lerp(&self.t);
        let r = if !self.r.is_empty() {
            lerp(&self.r)
        } else if self.gamma.is_nan() {
            0.0
        } else {
            eq4_r(t, self.gamma)
        };
        (t, r)
    }
}

/// What the lookups of eq. (3)-(4) and the sampler need of `wo` (scratch frame, above the
/// surface), computed once per `wo` by [`ScratchBrdf::wo_terms`] and reused by every lookup
/// with that `wo` (the BSDF evaluates, samples and light-samples one `wo` several times).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WoTerms {
    /// The `phi_o` bin.
    pub o: usize,
    /// `theta_o = asin(wo.y)`.
    pub theta_o: f64,
    /// `t = 2 |theta_o| / pi`, in `[0, 1]`.
    pub t: f64,
    /// `R = (2 |theta_o| / pi)^gamma` of eq. (4) for the common `gamma` (0 if there is none).
    r_common: f64,
}

/// The `gamma` value most bins of a table share, if at least a quarter do (NaN otherwise).
/// In `seed` mode every bin with energy has the same closed-form `gamma` (the Fresnel law's
/// `R_3`), so eq. (4)'s `powf` is computed once per `wo` instead of once per lookup.
fn common_gamma(gamma: &[f64]) -> f64 {
    let mut bits: Vec<u64> = gamma.iter().map(|g| g.to_bits()).collect();
    bits.sort_unstable();
    let (mut best, mut best_n) = (f64::NAN, 0usize);
    for run in bits.chunk_by(|a, b| a == b) {
        if run.len() > best_n {
            best_n = run.len();
            best = f64::from_bits(run[0]);
        }
    }
    if best_n * 4 >= gamma.len().max(1) {
        best
    } else {
        f64::NAN
    }
}

/// `theta = asin(y)` of a unit direction (section 1; its `phi` bin is
/// [`ScratchBrdf::phi_bin`]).
#[inline]
fn theta_of(w: Vec3) -> f64 {
    (w.y as f64).clamp(-1.0, 1.0).asin()
}

#[inline]
fn direction(theta: f64, phi: f64) -> Vec3 {
    let c = theta.cos();
    Vec3::new(
        (c * phi.sin()) as f32,
        theta.sin() as f32,
        (c * phi.cos()) as f32,
    )
}

/// Inverse CDF of the density `(2/pi) cos^2(theta)` on `[-pi/2, pi/2]`:
/// solves `(theta + pi/2 + sin(2 theta)/2) / pi = u` by safeguarded Newton.
#[inline]
fn sample_cos2(u: f64) -> f64 {
    sample_cos2_counted(u).0
}

/// [`sample_cos2`] and the Newton iterations it took. It stops as soon as the step falls below
/// 1e-15 (or the residual is exactly 0), before the bracket check: a converged iterate sits on
/// an end of its bracket, and testing it against the bracket first would turn the last steps
/// into bisection (26 iterations on average instead of 4.6, each with a `sin` and a `cos`).
fn sample_cos2_counted(u: f64) -> (f64, u32) {
    let target = u.clamp(0.0, 1.0) * PI - FRAC_PI_2;
    let (mut lo, mut hi) = (-FRAC_PI_2, FRAC_PI_2);
    let mut t = 0.5 * target; // g(t) = t + sin(2t)/2 is within [t, 2t]-ish; any start works.
    for iteration in 1..=60 {
        let (sin_2t, cos_2t) = (2.0 * t).sin_cos();
        let g = t + 0.5 * sin_2t - target;
        if g == 0.0 {
            return (t, iteration);
        }
        if g > 0.0 {
            hi = t;
        } else {
            lo = t;
        }
        // g'(t) = 1 + cos(2t) = 2 cos^2(t).
        let dg = 1.0 + cos_2t;
        let step = if dg > 1e-300 { g / dg } else { f64::INFINITY };
        if step.abs() < 1e-15 {
            return (t - step, iteration);
        }
        let next = t - step;
        t = if next > lo && next < hi {
            next
        } else {
            0.5 * (lo + hi)
        };
    }
    (t, 60)
}

impl ScratchBrdf {
    pub fn new(table: ScratchTable) -> Self {
        let m = table.m;
        let delta = table.params.trace.walls == Walls::Specular;
        let groove = (!table.groove_rho.is_empty()).then(|| {
            GrooveSlices::from_rho(m, table.groove_rho.clone(), table.params.trace.fresnel_law)
        });
        let mean = groove.as_ref().map(GrooveSlices::mean_rho);
        let rows = (0..m)
            .map(|o| {
                let w: Vec<f64> = (0..m)
                    .map(|i| match &mean {
                        Some(mean) => mean[i * m + o] * table.phi[i].cos(),
                        None => table.slice(2, i, o) * table.phi[i].cos(),
                    })
                    .collect();
                Distribution1D::new(&w)
            })
            .collect();
        let gamma_common = common_gamma(&table.gamma);
        let theta_grid = ThetaGrid::new(gamma_common);
        ScratchBrdf {
            table,
            delta,
            rows,
            groove,
            phi_bins: AngleBins::new(m),
            gamma_common,
            theta_grid,
        }
    }

    /// The `gamma` most bins share (NaN if none), see [`WoTerms`].
    pub fn gamma_common(&self) -> f64 {
        self.gamma_common
    }

    /// The `wo`-dependent part of every lookup (`wo` in the scratch frame with `wo.z > 0`):
    /// its `phi_o` bin, and `theta_o` with eq. (4)'s `t` and common `R` from [`ThetaGrid`].
    #[inline]
    pub fn wo_terms(&self, wo: Vec3) -> WoTerms {
        let o = self.phi_bin(wo.x as f64, wo.z as f64);
        let y = wo.y as f64;
        let (t, r_common) = self.theta_grid.at(y);
        WoTerms {
            o,
            theta_o: (t * FRAC_PI_2).copysign(y),
            t,
            r_common,
        }
    }

    /// [`ScratchTable::rho`]`(theta_o, i, o)` with `theta_o`, `o` from `wt`.
    #[inline]
    pub fn rho_at(&self, wt: &WoTerms, i: usize) -> f64 {
        let t = &self.table;
        let o = wt.o;
        let g = t.gamma[i * t.m + o];
        let r = if g == self.gamma_common {
            wt.r_common
        } else {
            eq4_r(wt.t, g)
        };
        r * t.slice(2, i, o) + (1.0 - r) * t.slice(0, i, o)
    }

    /// `rho(wo, wi)` for `wi` in `phi_i` bin `i`: eq. (3) ([`Self::rho_at`]) or, with
    /// exact-groove slices, theirs at `theta_i` of `wi`.
    #[inline]
    fn rho_wi(&self, wt: &WoTerms, i: usize, wi: Vec3) -> f64 {
        match &self.groove {
            None => self.rho_at(wt, i),
            Some(g) => g.rho_at(wi.y as f64, i, wt.o),
        }
    }

    /// The exact-groove slices, if the table has them.
    pub fn groove(&self) -> Option<&GrooveSlices> {
        self.groove.as_ref()
    }

    /// The `phi` bin of a direction above the surface (`z > 0`), `phi = atan2(x, z)`
    /// ([`AngleBins::bin_xz`]: no `atan2`, the lookups of eq. (3) and of the sampler run several
    /// times per scratched hit).
    #[inline]
    pub fn phi_bin(&self, x: f64, z: f64) -> usize {
        self.phi_bins.bin_xz(x, z)
    }

    pub fn table(&self) -> &ScratchTable {
        &self.table
    }

    /// Mirror walls: the lobe is a delta in theta; use [`ScratchBrdf::sample`] and
    /// [`ScratchBrdf::delta_terms`], `eval`/`pdf` return 0.
    pub fn is_delta(&self) -> bool {
        self.delta
    }

    /// `f(wo, wi)` of the smooth lobe, without the cosine: `(2/pi) rho_s(wo, wi)` by eq. (3)
    /// (section 4's unit factor). 0 for the delta lobe or either direction below the surface.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> f64 {
        self.eval_pdf(wo, wi).0
    }

    /// Solid-angle pdf of [`ScratchBrdf::sample`] (smooth lobe): `p(phi_i) (2/pi) cos(theta_i)`,
    /// from `p(phi_i, theta_i) = p(phi_i) (2/pi) cos^2(theta_i)` and `dw = cos(theta) dtheta dphi`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f64 {
        self.eval_pdf(wo, wi).1
    }

    /// [`Self::eval`] and [`Self::pdf`] together, each angle computed once.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (f64, f64) {
        if self.delta || wo.z <= 0.0 || wi.z <= 0.0 {
            return (0.0, 0.0);
        }
        self.eval_pdf_at(&self.wo_terms(wo), wi)
    }

    /// [`Self::eval`] with the `wo` terms of [`Self::wo_terms`] (`wo.z > 0`): the first half
    /// of [`Self::eval_pdf_at`], for callers that need no density (light sampling of a delta
    /// light).
    #[inline]
    pub fn eval_at(&self, wt: &WoTerms, wi: Vec3) -> f64 {
        if self.delta || wi.z <= 0.0 {
            return 0.0;
        }
        2.0 / PI * self.rho_wi(wt, self.phi_bin(wi.x as f64, wi.z as f64), wi)
    }

    /// [`Self::eval_pdf`] with the `wo` terms of [`Self::wo_terms`] (`wo.z > 0`).
    #[inline]
    pub fn eval_pdf_at(&self, wt: &WoTerms, wi: Vec3) -> (f64, f64) {
        if self.delta || wi.z <= 0.0 {
            return (0.0, 0.0);
        }
        let m = self.table.m;
        let i = self.phi_bin(wi.x as f64, wi.z as f64);
        let f = 2.0 / PI * self.rho_wi(wt, i, wi);
        let row = &self.rows[wt.o];
        if row.integral() <= 0.0 {
            return (f, 0.0);
        }
        // cos(theta_i) = sqrt(1 - y^2) for theta_i = asin(y) in [-pi/2, pi/2]; the density of
        // phi_i in its bin is the row's pmf times M / pi.
        let y = (wi.y as f64).clamp(-1.0, 1.0);
        let cos_theta_i = (1.0 - y * y).sqrt();
        let p_phi = row.pmf(i) * m as f64 / PI;
        (f, p_phi * 2.0 / PI * cos_theta_i)
    }

    /// Section 6: `phi_i` from the row CDF of `rho_s(pi/2, phi_o, .) cos(phi_i)`, then
    /// `theta_i` with density `(2/pi) cos^2` (smooth lobe) or `theta_i = -theta_o` (delta).
    /// `None` where `wo` is below the surface or the row carries no energy.
    pub fn sample(&self, wo: Vec3, u: [f64; 2]) -> Option<ScratchSample> {
        if wo.z <= 0.0 {
            return None;
        }
        self.sample_at(&self.wo_terms(wo), u)
    }

    /// [`Self::sample`] with the `wo` terms of [`Self::wo_terms`] (`wo.z > 0`).
    #[inline]
    pub fn sample_at(&self, wt: &WoTerms, u: [f64; 2]) -> Option<ScratchSample> {
        let m = self.table.m;
        let theta_o = wt.theta_o;
        let row = &self.rows[wt.o];
        if row.integral() <= 0.0 {
            return None;
        }
        if self.delta {
            let (k, du) = row.sample_discrete(u[0]);
            let pmf = row.pmf(k);
            let phi_i = -FRAC_PI_2 + (k as f64 + du) * PI / m as f64;
            let wi = direction(-theta_o, phi_i);
            let value = self.rho_at(wt, k) * phi_i.cos() * PI / m as f64;
            return Some(ScratchSample {
                wi,
                weight: value / pmf,
                pdf: pmf * m as f64 / PI,
                delta: true,
            });
        }
        let (x, _, _) = row.sample_continuous(u[0]);
        let phi_i = -FRAC_PI_2 + x * PI;
        let theta_i = sample_cos2(u[1]);
        let wi = direction(theta_i, phi_i);
        if wi.z <= 0.0 {
            return None;
        }
        let (f, pdf) = self.eval_pdf_at(wt, wi);
        if pdf <= 0.0 {
            return None;
        }
        Some(ScratchSample {
            wi,
            weight: f * wi.z as f64 / pdf,
            pdf,
            delta: false,
        })
    }

    /// The delta lobe's probability of choosing `phi_i` bin `k` for `wo` (mirror walls).
    pub fn delta_pmf(&self, wo: Vec3, k: usize) -> f64 {
        let row = &self.rows[self.phi_bin(wo.x as f64, wo.z as f64)];
        if row.integral() <= 0.0 {
            0.0
        } else {
            row.pmf(k)
        }
    }

    /// The discrete-phi form of the delta lobe (section 6): `L_r(wo) = sum_k value_k L_i(wi_k)`
    /// with `theta_i = -theta_o`. Empty if `wo` is below the surface.
    pub fn delta_terms(&self, wo: Vec3) -> Vec<DeltaTerm> {
        if wo.z <= 0.0 {
            return Vec::new();
        }
        let m = self.table.m;
        let theta_o = theta_of(wo);
        let o = self.phi_bin(wo.x as f64, wo.z as f64);
        (0..m)
            .map(|k| {
                let phi = self.table.phi[k];
                DeltaTerm {
                    wi: direction(-theta_o, phi),
                    value: self.table.rho(theta_o, k, o) * phi.cos() * PI / m as f64,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::precompute::profile::Profile;
    use crate::precompute::table::tests::params;
    use crate::precompute::table::TableParams;
    use crate::precompute::trace2d::bin_of;
    use crate::precompute::trace2d::{FresnelMode, TraceSettings};
    use crate::testing::{chi2_discrete, chi2_sphere, MeanEstimate, SphereGrid};
    use rand::{Rng, SeedableRng};

    #[test]
    fn tabulated_theta_terms_match_asin_and_powf() {
        // `wo_terms` interpolates t = 2|theta_o|/pi and eq. (4)'s R over s = sqrt(1 - |y|):
        // against the exact asin / powf (and `rho_at` against `rho`) on random directions and
        // at the ends (normal incidence, grazing along the scratch).
        let t = ScratchTable::compute(
            &params("v:angle=90", Walls::Diffuse, FresnelMode::Seed),
            &|_| {},
        )
        .unwrap();
        let brdf = ScratchBrdf::new(t);
        let gc = brdf.gamma_common();
        assert!(gc >= 2.0, "seed mode has one closed-form gamma: {gc}");
        let m = brdf.table().m;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(8);
        let mut dirs: Vec<Vec3> = (0..50_000)
            .map(|_| {
                let v = Vec3::new(
                    rng.random::<f32>() * 2.0 - 1.0,
                    rng.random::<f32>() * 2.0 - 1.0,
                    rng.random::<f32>(),
                );
                v.normalize()
            })
            .filter(|v| v.z > 0.0)
            .collect();
        dirs.extend([
            Vec3::Z,
            Vec3::new(0.0, 1.0, 1e-6),
            Vec3::new(0.0, -1.0, 1e-6),
        ]);
        let (mut worst_t, mut worst_r, mut worst_rho) = (0.0f64, 0.0f64, 0.0f64);
        for wo in dirs {
            let wt = brdf.wo_terms(wo);
            let theta = theta_of(wo);
            let t_exact = eq4_t(theta);
            worst_t = worst_t.max((wt.t - t_exact).abs());
            assert!((wt.theta_o - theta).abs() < 1e-7, "{wo}");
            worst_r = worst_r.max((wt.r_common - eq4_r(t_exact, gc)).abs());
            for i in [0, m / 3, m / 2, m - 1] {
                let (a, b) = (brdf.rho_at(&wt, i), brdf.table().rho(theta, i, wt.o));
                worst_rho = worst_rho.max((a - b).abs() / b.abs().max(1e-3));
            }
        }
        assert!(worst_t < 5e-8, "t: {worst_t}");
        assert!(worst_r < 5e-6, "R: {worst_r}");
        assert!(worst_rho < 5e-6, "rho: {worst_rho}");
    }

    #[test]
    fn flat_diffuse_is_lambertian_in_3d() {
        // Section 4: a flat diffuse profile gives rho_m ~ 1/2, so f_r = (2/pi)(1/2) F = F/pi.
        let s = TraceSettings {
            walls: Walls::Diffuse,
            m: 8,
            n: 4000,
            nr: 16,
            ..TraceSettings::default()
        };
        let t = ScratchTable::compute(&TableParams::new(Profile::flat(), s), &|_| {}).unwrap();
        let brdf = ScratchBrdf::new(t);
        let wo = Vec3::new(0.3, 0.0, 1.0).normalize();
        let wi = Vec3::new(-0.2, 0.0, 1.0).normalize();
        let f = brdf.eval(wo, wi);
        let expect = crate::optics::fresnel::schlick(1.5, 1.0) / PI;
        assert!((f - expect).abs() < 0.03 * expect, "{f} vs {expect}");
    }

    fn smooth_brdf() -> ScratchBrdf {
        let s = TraceSettings {
            walls: Walls::Diffuse,
            m: 32,
            n: 1000,
            nr: 8,
            seed: 5,
            ..TraceSettings::default()
        };
        ScratchBrdf::new(
            ScratchTable::compute(
                &TableParams::new(Profile::parse("v:angle=100").unwrap(), s),
                &|_| {},
            )
            .unwrap(),
        )
    }

    fn dir_from(theta_deg: f64, phi_deg: f64) -> Vec3 {
        direction(theta_deg.to_radians(), phi_deg.to_radians())
    }

    #[test]
    fn smooth_sampler_chi2_and_pdf_consistency() {
        let brdf = smooth_brdf();
        let grid = SphereGrid::new(24, 48);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        for (t, p) in [
            (0.0, 0.0),
            (30.0, 40.0),
            (-50.0, -70.0),
            (80.0, 85.0),
            (10.0, -88.0),
        ] {
            let wo = dir_from(t, p);
            let mut mismatch = 0;
            let r = chi2_sphere(
                &grid,
                150_000,
                || {
                    let s = brdf.sample(wo, [rng.random(), rng.random()])?;
                    let q = brdf.pdf(wo, s.wi);
                    if (q - s.pdf).abs() > 1e-3 * s.pdf {
                        mismatch += 1;
                    }
                    Some(s.wi)
                },
                |w| brdf.pdf(wo, w),
            );
            assert_eq!(mismatch, 0, "wo {t},{p}");
            assert!(r.p_value > 1e-3, "wo ({t}, {p}): {r:?}");
            assert!((r.pdf_mass - 1.0).abs() < 0.01, "{r:?}");
        }
    }

    /// The atan2-free `phi` bin equals `bin_of(atan2(x, z))` for random directions above the
    /// surface, grazing ones included, except where the two sit within rounding of a boundary.
    #[test]
    fn phi_bin_matches_atan2_binning() {
        let brdf = smooth_brdf();
        let m = brdf.table().m;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(31);
        let mut differ = 0;
        for case in 0..200_000 {
            let z: f64 = if case % 10 == 0 {
                rng.random_range(1e-7..1e-3)
            } else {
                rng.random()
            };
            let x: f64 = rng.random_range(-1.0..1.0);
            let reference = bin_of(x.atan2(z), m);
            let fast = brdf.phi_bin(x, z);
            if fast != reference {
                // Only at a boundary: both angles within 1e-12 of it.
                let boundary = -FRAC_PI_2 + fast.max(reference) as f64 * PI / m as f64;
                assert!(
                    (x.atan2(z) - boundary).abs() < 1e-12,
                    "case {case}: {fast} vs {reference}"
                );
                differ += 1;
            }
        }
        assert!(differ < 5, "{differ}");
        // Every bin's centre direction lands in that bin.
        for k in 0..m {
            let phi = -FRAC_PI_2 + (k as f64 + 0.5) * PI / m as f64;
            assert_eq!(brdf.phi_bin(phi.sin(), phi.cos()), k);
        }
    }

    #[test]
    fn smooth_sampler_weights_integrate_f_cos() {
        // E[weight] = integral f cos dw, computed independently by quadrature over (theta, phi).
        let brdf = smooth_brdf();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(12);
        for (t, p) in [(20.0, 10.0), (70.0, -60.0)] {
            let wo = dir_from(t, p);
            let mut est = MeanEstimate::default();
            for _ in 0..40_000 {
                est.push(
                    brdf.sample(wo, [rng.random(), rng.random()])
                        .map_or(0.0, |s| s.weight),
                );
            }
            let n = 400;
            let mut quad = 0.0;
            for a in 0..n {
                let th = -FRAC_PI_2 + (a as f64 + 0.5) * PI / n as f64;
                for b in 0..n {
                    let ph = -FRAC_PI_2 + (b as f64 + 0.5) * PI / n as f64;
                    let wi = direction(th, ph);
                    quad += brdf.eval(wo, wi) * wi.z as f64 * th.cos() * (PI / n as f64).powi(2);
                }
            }
            assert!(
                est.agrees_with(quad, 4.0, 2e-3),
                "{} +- {} vs {quad}",
                est.mean(),
                est.std_error()
            );
            assert!(quad > 0.02 && quad < 1.0, "{quad}");
        }
    }

    #[test]
    fn delta_sampler_chi2_and_energy() {
        let s = TraceSettings {
            walls: Walls::Specular,
            m: 32,
            n: 2000,
            seed: 5,
            ..TraceSettings::default()
        };
        let brdf = ScratchBrdf::new(
            ScratchTable::compute(
                &TableParams::new(Profile::parse("round:depth=0.4").unwrap(), s),
                &|_| {},
            )
            .unwrap(),
        );
        assert!(brdf.is_delta());
        let m = 32;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(13);
        for (t, p) in [(0.0, 10.0), (45.0, -30.0), (85.0, 80.0)] {
            let wo = dir_from(t, p);
            assert_eq!(brdf.eval(wo, wo), 0.0);
            let n = 100_000;
            let mut counts = vec![0u64; m];
            let mut est = MeanEstimate::default();
            for _ in 0..n {
                let s = brdf.sample(wo, [rng.random(), rng.random()]).unwrap();
                assert!(s.delta);
                let th = theta_of(s.wi);
                assert!((th + t.to_radians()).abs() < 1e-5, "theta_i = -theta_o");
                let k = brdf.phi_bin(s.wi.x as f64, s.wi.z as f64);
                counts[k] += 1;
                assert!((s.pdf - brdf.delta_pmf(wo, k) * m as f64 / PI).abs() < 1e-9);
                est.push(s.weight);
            }
            let expected: Vec<f64> = (0..m).map(|k| brdf.delta_pmf(wo, k) * n as f64).collect();
            let r = chi2_discrete(&counts, &expected);
            assert!(r.p_value > 1e-3, "{r:?}");
            // E[weight] = sum of the discrete terms (up to cos varying inside a bin).
            let sum: f64 = brdf.delta_terms(wo).iter().map(|d| d.value).sum();
            assert!(
                est.agrees_with(sum, 4.0, 2e-3 * sum),
                "{} vs {sum}",
                est.mean()
            );
            assert!(sum <= 1.0 + 1e-9);
        }
    }

    #[test]
    fn cos2_inverse_cdf() {
        let mut iterations = 0;
        let n = 10_000;
        for k in 0..=n {
            let u = k as f64 / n as f64;
            let (t, its) = sample_cos2_counted(u);
            let cdf = (t + FRAC_PI_2 + 0.5 * (2.0 * t).sin()) / PI;
            assert!((cdf - u).abs() < 1e-12, "{u}: {t} {cdf}");
            assert!((-FRAC_PI_2..=FRAC_PI_2).contains(&t), "{u}: {t}");
            iterations += its;
        }
        // Newton converges quadratically: about 5 steps from the start `target / 2` (the
        // steep ends need a few bisections). A converged iterate that fell back to bisection
        // would take 26 steps on average.
        let mean = iterations as f64 / (n + 1) as f64;
        assert!(mean < 6.0, "{mean} iterations on average");
    }
}
