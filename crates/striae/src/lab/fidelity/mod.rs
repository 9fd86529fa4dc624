//! The scratch model against the exact groove (METHOD.md sections 4 and 8.1): how far the
//! table's 3D BRDF (eq. 3, the theta slices blended by eq. 4's `gamma`) is from the
//! goniometer's exact reflected lobe of the same extruded groove.
//!
//! Both sides are put on the goniometer's grid ([`crate::precompute::groove`]: `B x B` bins of
//! `[theta_o, phi_o]` over `[-pi/2, pi/2]`, each the fraction of the incident energy leaving
//! into it):
//!
//! * a model `f(wo, wi)` (without the cosine) is integrated over each bin,
//!   `int f(wo, wi) cos(theta_o) cos(phi_o) dw_o` with `dw_o = cos(theta_o) dtheta dphi`
//!   (section 1), by the midpoint rule on a stratified grid of sub-cells ([`model_histogram`]);
//! * the exact lobe is the mean of `runs` independent goniometer runs, with the standard error
//!   of each bin from their spread ([`reference`]).
//!
//! [`compare`] reports the L1 distance over the hemisphere `sum |model - exact|`, the albedo of
//! each side, and the L1 distance that the goniometer's noise alone gives,
//! `sqrt(2/pi) sum se` (the mean of `|N(0, se)|` summed over bins): a model equal to the exact
//! lobe scores `l1 / noise_l1` about 1, so "off by more than the noise" is that ratio well
//! above 1.
//!
//! [`GrooveSlices`] ([`crate::precompute::groove_slices`]) is the representation that the comparison
//! motivates (docs/fidelity.md), a table option (`groove_slices = S`) of the renderer.

pub mod study;

use crate::precompute::groove::{trace_groove, GonioError, GonioSettings};
pub use crate::precompute::groove_slices::GrooveSlices;
use crate::precompute::profile::Profile;
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};

/// A model BRDF `f(wo, wi)` without the cosine, in the scratch frame of METHOD.md section 1
/// (`x` across the scratch, `y` along it, `z` the normal; both directions point away from the
/// surface; `wi` towards the light).
pub type Model<'a> = dyn Fn([f64; 3], [f64; 3]) -> f64 + Sync + 'a;

/// The unit direction of `(theta, phi)` (section 1: `phi = atan2(x, z)`, `theta = asin(y)`).
#[inline]
pub fn direction(theta: f64, phi: f64) -> [f64; 3] {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    [ct * sp, st, ct * cp]
}

/// The fraction of the energy incident from `(theta_i, phi_i)` that model `f` reflects into
/// each `[theta_o bin, phi_o bin]` of `bins x bins` (row-major, the goniometer's layout).
/// Each bin is split into `q` sub-cells in `theta` and `q * max(1, m / bins)` in `phi`, where
/// `m` is the model's own number of `phi` bins: when `bins` divides `m` no sub-cell straddles
/// a model bin, so the piecewise-constant table is integrated exactly in `phi` and only the
/// smooth factors (cosines, eq. 4's `R`) are approximated by the midpoint rule.
pub fn model_histogram(
    f: &Model,
    theta_i: f64,
    phi_i: f64,
    bins: usize,
    m: usize,
    q: usize,
) -> Vec<f64> {
    let wi = direction(theta_i, phi_i);
    let h = PI / bins as f64;
    let (qt, qp) = (q.max(1), q.max(1) * (m / bins).max(1));
    let (ht, hp) = (h / qt as f64, h / qp as f64);
    (0..bins * bins)
        .into_par_iter()
        .map(|k| {
            let (a, b) = (k / bins, k % bins);
            let (t0, p0) = (-FRAC_PI_2 + a as f64 * h, -FRAC_PI_2 + b as f64 * h);
            let mut sum = 0.0;
            for s in 0..qt {
                let theta = t0 + (s as f64 + 0.5) * ht;
                let ct = theta.cos();
                for r in 0..qp {
                    let wo = direction(theta, p0 + (r as f64 + 0.5) * hp);
                    // cos of wo to the normal times the Jacobian cos(theta).
                    sum += f(wo, wi) * wo[2] * ct;
                }
            }
            sum * ht * hp
        })
        .collect()
}

/// The exact reflected lobe: the mean of independent goniometer runs and its standard error.
#[derive(Clone, Debug, PartialEq)]
pub struct Reference {
    pub bins: usize,
    /// Mean fraction per `[theta_o bin, phi_o bin]`.
    pub mean: Vec<f64>,
    /// Standard error of each bin's mean (sample standard deviation over the runs / sqrt(runs)).
    pub se: Vec<f64>,
    /// Mean reflected albedo and its standard error.
    pub albedo: f64,
    pub albedo_se: f64,
}

/// Run the goniometer `runs >= 2` times with seeds `s.seed + k` (each `s.paths` paths) and
/// average (on the current rayon pool).
pub fn reference(
    profile: &Profile,
    s: &GonioSettings,
    runs: usize,
) -> Result<Reference, GonioError> {
    let runs = runs.max(2);
    let outs = (0..runs)
        .map(|k| {
            let sk = GonioSettings {
                seed: s.seed.wrapping_add(k as u64),
                ..s.clone()
            };
            trace_groove(profile, &sk, &|_| {})
        })
        .collect::<Result<Vec<_>, _>>()?;
    let n = runs as f64;
    let stats = |v: &mut dyn Iterator<Item = f64>| {
        let xs: Vec<f64> = v.collect();
        let mean = xs.iter().sum::<f64>() / n;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, (var / n).sqrt())
    };
    let (mean, se): (Vec<f64>, Vec<f64>) = (0..s.bins * s.bins)
        .map(|j| stats(&mut outs.iter().map(|o| o.reflected[j])))
        .unzip();
    let (albedo, albedo_se) = stats(&mut outs.iter().map(|o| o.albedo_r));
    Ok(Reference {
        bins: s.bins,
        mean,
        se,
        albedo,
        albedo_se,
    })
}

/// A model's lobe against the exact one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Comparison {
    /// `sum over bins |model - exact|`, a fraction of the incident energy.
    pub l1: f64,
    /// The L1 distance the goniometer's noise alone gives: `sqrt(2/pi) sum se`.
    pub noise_l1: f64,
    pub albedo_model: f64,
    pub albedo_exact: f64,
    pub albedo_se: f64,
}

impl Comparison {
    /// `albedo_model - albedo_exact`.
    pub fn albedo_err(&self) -> f64 {
        self.albedo_model - self.albedo_exact
    }
}

/// Compare a model histogram ([`model_histogram`]) with the exact lobe.
pub fn compare(model: &[f64], r: &Reference) -> Comparison {
    assert_eq!(model.len(), r.mean.len(), "histograms of different grids");
    Comparison {
        l1: model.iter().zip(&r.mean).map(|(a, b)| (a - b).abs()).sum(),
        noise_l1: (2.0 / PI).sqrt() * r.se.iter().sum::<f64>(),
        albedo_model: model.iter().sum(),
        albedo_exact: r.albedo,
        albedo_se: r.albedo_se,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::fresnel::FresnelLaw;
    use crate::precompute::angle_bins::bin_centre;
    use crate::precompute::groove::GrooveWalls;
    use crate::precompute::groove_slices::slice_angles;
    use crate::precompute::table::{ScratchBrdf, ScratchTable, TableParams};
    use crate::precompute::trace2d::{FresnelMode, TraceSettings, Walls};

    fn table(spec: &str, law: FresnelLaw, m: usize) -> ScratchBrdf {
        table_with(
            spec,
            TraceSettings {
                walls: Walls::Diffuse,
                m,
                n: 20_000,
                nr: 20,
                fresnel_mode: FresnelMode::Seed,
                fresnel_law: law,
                ..TraceSettings::default()
            },
        )
    }

    fn table_with(spec: &str, trace: TraceSettings) -> ScratchBrdf {
        let p = TableParams::new(Profile::parse(spec).unwrap(), trace);
        ScratchBrdf::new(ScratchTable::compute(&p, &|_| {}).unwrap())
    }

    fn gonio(law: FresnelLaw, theta_i: f64, phi_i: f64, bins: usize) -> GonioSettings {
        GonioSettings {
            walls: GrooveWalls::Diffuse,
            fresnel_law: law,
            theta_i,
            phi_i,
            paths: 120_000,
            bins,
            ..GonioSettings::default()
        }
    }

    /// A constant (Lambertian) BRDF `rho / pi`: each bin holds, in closed form,
    /// `(rho/pi) int cos^2(theta) dtheta int cos(phi) dphi` over the bin, and the sum is `rho`.
    #[test]
    fn quadrature_matches_the_lambertian_closed_form() {
        let rho = 0.7;
        let f = move |_: [f64; 3], _: [f64; 3]| rho / PI;
        let b = 12;
        let h = model_histogram(&f, 0.4, -0.3, b, 48, 6);
        let edge = |k: usize| -FRAC_PI_2 + k as f64 * PI / b as f64;
        let int_cos2 = |a: f64, c: f64| (c - a) / 2.0 + ((2.0 * c).sin() - (2.0 * a).sin()) / 4.0;
        for (k, v) in h.iter().enumerate() {
            let (a, j) = (k / b, k % b);
            let want =
                rho / PI * int_cos2(edge(a), edge(a + 1)) * (edge(j + 1).sin() - edge(j).sin());
            // The midpoint rule's relative error grows where cos^2 vanishes (|theta| -> 90).
            assert!(
                (v - want).abs() < 1e-3 * want + 5e-6,
                "bin {k}: {v} vs {want}"
            );
        }
        let total: f64 = h.iter().sum();
        assert!((total - rho).abs() < 1e-4, "albedo {total}");
    }

    /// Lossless Lambertian walls: the table's BRDF is the exact one (METHOD.md 4), so at the
    /// slices' angles its lobe is within the goniometer's noise; a table of another profile
    /// (a deliberately wrong model) is far outside it.
    #[test]
    fn exact_for_lossless_lambertian_walls_and_a_wrong_model_fails() {
        let (m, b) = (16, 16);
        let right = table("v:angle=90", FresnelLaw::None, m);
        let wrong = table("v:angle=60", FresnelLaw::None, m);
        let p = Profile::parse("v:angle=90").unwrap();
        // phi_i at a table bin centre, as the table was traced.
        let phi_i = bin_centre(11, m);
        for theta_i in [0.0, PI / 3.0] {
            let r = reference(&p, &gonio(FresnelLaw::None, theta_i, phi_i, b), 4).unwrap();
            let good = compare(
                &model_histogram(&study::table_model(&right), theta_i, phi_i, b, m, 4),
                &r,
            );
            let bad = compare(
                &model_histogram(&study::table_model(&wrong), theta_i, phi_i, b, m, 4),
                &r,
            );
            assert!(good.l1 < 1.3 * good.noise_l1, "theta_i {theta_i}: {good:?}");
            // The table's eq. (1') weighs each bin by the cosine at its centre, so integrated
            // exactly its albedo is `1 - h^2/24` (h = pi/M): 1.6e-3 at M = 16.
            assert!(
                good.albedo_err().abs() < 4.0 * good.albedo_se + 2.5e-3,
                "{good:?}"
            );
            assert!(bad.l1 > 2.5 * bad.noise_l1, "theta_i {theta_i}: {bad:?}");
        }
    }

    /// With Schlick Fresnel at every wall hit the seed's one factor per path is measurably
    /// wrong, while the renderer's BRDF of a table with exact-groove slices
    /// (`groove_slices = 2`) is right at its own `theta_i`.
    #[test]
    fn per_hit_fresnel_separates_the_seed_model_from_groove_slices() {
        let (m, b) = (16, 16);
        let law = FresnelLaw::Schlick { n: 1.5 };
        let seed = table("v:angle=90", law, m);
        let p = Profile::parse("v:angle=90").unwrap();
        let base = gonio(law, 0.0, 0.0, b);
        assert_eq!(
            GrooveSlices::compute(&p, &base, 0, 2, &|_| {})
                .unwrap_err()
                .key,
            "slice-m"
        );
        let slices = table_with(
            "v:angle=90",
            TraceSettings {
                walls: Walls::Diffuse,
                m,
                n: 60_000,
                nr: 1,
                fresnel_mode: FresnelMode::Walls,
                fresnel_law: law,
                groove_slices: 2,
                ..TraceSettings::default()
            },
        );
        assert_eq!(slices.groove().unwrap().slices(), 2);
        let (theta_i, phi_i) = (slice_angles(2)[1], bin_centre(5, m));
        let r = reference(&p, &gonio(law, theta_i, phi_i, b), 4).unwrap();
        let good = compare(
            &model_histogram(&study::table_model(&slices), theta_i, phi_i, b, m, 4),
            &r,
        );
        let bad = compare(
            &model_histogram(&study::table_model(&seed), theta_i, phi_i, b, m, 4),
            &r,
        );
        assert!(good.l1 < 1.5 * good.noise_l1, "{good:?}");
        assert!(bad.l1 > 3.0 * bad.noise_l1, "{bad:?}");
    }
}
