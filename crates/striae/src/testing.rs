//! Statistical test harness shared by unit and scene tests (after Mitsuba 3's `chi2.py` and
//! pbrt-v4's `bsdfs_test.cpp`): chi-square goodness of fit for samplers over the sphere and for
//! discrete distributions, and a mean-with-standard-error for furnace tests.

use crate::math::Vec3;
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Outcome of a chi-square test.
#[derive(Clone, Debug)]
pub struct Chi2Result {
    pub statistic: f64,
    pub dof: usize,
    /// Probability of a statistic at least this large if the sampler matched its pdf.
    pub p_value: f64,
    /// Cells with expected count 0 that received samples (a sure failure: `p_value = 0`).
    pub impossible_hits: u64,
    /// Fraction of the sampled directions' probability mass the pdf accounts for: `sum(expected) / n`.
    pub pdf_mass: f64,
}

/// Pearson's chi-square of observed `counts` against `expected` counts, pooling every cell
/// with fewer than 5 expected into one (pbrt/Mitsuba practice). A cell with zero expected
/// count but observed samples makes the p-value 0.
pub fn chi2_discrete(counts: &[u64], expected: &[f64]) -> Chi2Result {
    assert_eq!(counts.len(), expected.len());
    let mut stat = 0.0;
    let mut dof = 0usize;
    let (mut pool_obs, mut pool_exp) = (0.0f64, 0.0f64);
    let mut impossible = 0u64;
    for (&o, &e) in counts.iter().zip(expected) {
        if e <= 0.0 {
            impossible += o;
            continue;
        }
        if e < 5.0 {
            pool_obs += o as f64;
            pool_exp += e;
        } else {
            stat += (o as f64 - e).powi(2) / e;
            dof += 1;
        }
    }
    if pool_exp > 0.0 {
        stat += (pool_obs - pool_exp).powi(2) / pool_exp;
        dof += 1;
    }
    let dof = dof.saturating_sub(1).max(1);
    let p_value = if impossible > 0 {
        0.0
    } else {
        1.0 - ChiSquared::new(dof as f64).expect("dof > 0").cdf(stat)
    };
    let total: u64 = counts.iter().sum();
    let mass = expected.iter().sum::<f64>() / total.max(1) as f64;
    Chi2Result {
        statistic: stat,
        dof,
        p_value,
        impossible_hits: impossible,
        pdf_mass: mass,
    }
}

/// An equal-area grid on the unit sphere: `n_z` bands in `z = cos theta` over `[-1, 1]` times
/// `n_phi` sectors in `phi` over `[0, 2 pi)`. Every cell has solid angle `4 pi / (n_z n_phi)`.
#[derive(Clone, Copy, Debug)]
pub struct SphereGrid {
    pub n_z: usize,
    pub n_phi: usize,
    /// Midpoint quadrature points per cell side when integrating a pdf.
    pub sub: usize,
}

impl SphereGrid {
    pub fn new(n_z: usize, n_phi: usize) -> Self {
        SphereGrid { n_z, n_phi, sub: 8 }
    }

    pub fn cells(&self) -> usize {
        self.n_z * self.n_phi
    }

    /// The cell holding unit direction `w`.
    pub fn cell_of(&self, w: Vec3) -> usize {
        let z = w.z.clamp(-1.0, 1.0) as f64;
        let iz = (((z + 1.0) * 0.5 * self.n_z as f64) as usize).min(self.n_z - 1);
        let mut phi = (w.y as f64).atan2(w.x as f64);
        if phi < 0.0 {
            phi += 2.0 * std::f64::consts::PI;
        }
        let ip =
            ((phi / (2.0 * std::f64::consts::PI) * self.n_phi as f64) as usize).min(self.n_phi - 1);
        iz * self.n_phi + ip
    }

    /// `integral of pdf over each cell` (midpoint rule, `sub x sub` points per cell).
    pub fn integrate(&self, pdf: impl Fn(Vec3) -> f64) -> Vec<f64> {
        let dz = 2.0 / self.n_z as f64;
        let dphi = 2.0 * std::f64::consts::PI / self.n_phi as f64;
        let s = self.sub;
        let mut out = vec![0.0; self.cells()];
        for iz in 0..self.n_z {
            for ip in 0..self.n_phi {
                let mut acc = 0.0;
                for a in 0..s {
                    let z = -1.0 + (iz as f64 + (a as f64 + 0.5) / s as f64) * dz;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    for b in 0..s {
                        let phi = (ip as f64 + (b as f64 + 0.5) / s as f64) * dphi;
                        let w = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                        acc += pdf(w);
                    }
                }
                out[iz * self.n_phi + ip] = acc * dz * dphi / (s * s) as f64;
            }
        }
        out
    }
}

/// Chi-square test of a direction sampler against its claimed solid-angle `pdf`: draw `n`
/// samples (a `None` is a failed sample, counted nowhere), histogram them on `grid`, and
/// compare with `n` times the pdf integrated over each cell. The pdf must integrate to the
/// probability that the sampler succeeds.
pub fn chi2_sphere(
    grid: &SphereGrid,
    n: usize,
    mut sample: impl FnMut() -> Option<Vec3>,
    pdf: impl Fn(Vec3) -> f64,
) -> Chi2Result {
    let mut counts = vec![0u64; grid.cells()];
    for _ in 0..n {
        if let Some(w) = sample() {
            assert!(
                w.is_finite(),
                "sampler returned a non-finite direction {w:?}"
            );
            assert!(
                (w.length() - 1.0).abs() < 1e-3,
                "sampler returned a non-unit direction {w:?}"
            );
            counts[grid.cell_of(w)] += 1;
        }
    }
    let expected: Vec<f64> = grid
        .integrate(pdf)
        .into_iter()
        .map(|p| p * n as f64)
        .collect();
    let mut r = chi2_discrete(&counts, &expected);
    r.pdf_mass = expected.iter().sum::<f64>() / n as f64;
    r
}

/// Running mean and standard error of i.i.d. estimates (for furnace and known-mean tests).
#[derive(Clone, Copy, Debug, Default)]
pub struct MeanEstimate {
    n: u64,
    mean: f64,
    m2: f64,
}

impl MeanEstimate {
    pub fn push(&mut self, x: f64) {
        self.n += 1;
        let d = x - self.mean;
        self.mean += d / self.n as f64;
        self.m2 += d * (x - self.mean);
    }
    pub fn count(&self) -> u64 {
        self.n
    }
    pub fn mean(&self) -> f64 {
        self.mean
    }
    /// Standard error of the mean.
    pub fn std_error(&self) -> f64 {
        if self.n < 2 {
            return f64::INFINITY;
        }
        (self.m2 / (self.n - 1) as f64 / self.n as f64).sqrt()
    }
    /// Whether `target` lies within `z` standard errors (plus an absolute `slack` for
    /// deterministic bias such as float rounding) of the mean.
    pub fn agrees_with(&self, target: f64, z: f64, slack: f64) -> bool {
        (self.mean - target).abs() <= z * self.std_error() + slack
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec2;
    use crate::sampling::{square_to_uniform_sphere, UNIFORM_SPHERE_PDF};
    use rand::{Rng, SeedableRng};

    #[test]
    fn chi2_accepts_a_right_sampler_and_rejects_a_wrong_one() {
        let grid = SphereGrid::new(16, 32);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
        let ok = chi2_sphere(
            &grid,
            100_000,
            || {
                Some(square_to_uniform_sphere(Vec2::new(
                    rng.random(),
                    rng.random(),
                )))
            },
            |_| UNIFORM_SPHERE_PDF as f64,
        );
        assert!(ok.p_value > 0.01, "{ok:?}");
        assert!((ok.pdf_mass - 1.0).abs() < 1e-6);
        // Claim uniform but sample with a slight bias toward +z: must be rejected.
        let bad = chi2_sphere(
            &grid,
            100_000,
            || {
                let u = Vec2::new(rng.random::<f32>().powf(1.1), rng.random());
                Some(square_to_uniform_sphere(u))
            },
            |_| UNIFORM_SPHERE_PDF as f64,
        );
        assert!(bad.p_value < 1e-6, "{bad:?}");
    }

    #[test]
    fn mean_estimate() {
        let mut m = MeanEstimate::default();
        for x in [1.0, 2.0, 3.0, 4.0] {
            m.push(x);
        }
        assert!((m.mean() - 2.5).abs() < 1e-12);
        assert!((m.std_error() - (1.666_666_666_666_666_7f64 / 4.0).sqrt()).abs() < 1e-12);
    }
}
