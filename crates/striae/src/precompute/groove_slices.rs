//! Exact-groove slices in `theta_i` (METHOD.md sections 4 and 8.1; docs/fidelity.md): a
//! scratch BRDF tabulated from the exact 2.5D groove ([`crate::precompute::groove`]) at a few incident
//! `theta_i`, an alternative to the seed's three `theta_o` slices blended by eq. (4).
//!
//! For Lambertian walls every path leaves the groove from a Lambertian bounce, whose direction
//! has `theta` distributed as `cos^2` whatever came before (METHOD.md section 4): the exact
//! BRDF does not depend on `theta_o` at all, only on `theta_i` (through the Fresnel factor at
//! each wall hit, above all the first) and the two `phi`. So the table is
//! `rho(theta_k, phi_i, phi_o)` for `S` slices at the centres `theta_k = (k + 1/2) (pi/2) / S`
//! and the `M` bin centres of `phi_i`: the goniometer's reflected lobe summed over `theta_o`
//! and normalised by eq. (1'), used as `f = (2/pi) rho` (section 4's unit factor).
//!
//! Between slices it interpolates, linearly in `|theta_i|`, `rho / F(cos theta_i)` (constant
//! beyond the first and last slice) and multiplies by `F(cos theta_i)` again: the first wall
//! hit's Fresnel factor carries most of the steep rise towards grazing incidence, and the
//! ratio left is smooth. Exact for Lambertian walls with any per-hit Fresnel law up to that
//! interpolation, the `phi` bins and the Monte Carlo noise.

use crate::optics::fresnel::FresnelLaw;
use crate::precompute::angle_bins::{bin_centre, AngleBins};
use crate::precompute::groove::{trace_groove, GonioError, GonioSettings, GrooveWalls};
use crate::precompute::profile::Profile;
use std::f64::consts::{FRAC_PI_2, PI};

/// Most slices a table may have (each is an `M x M` array, traced with `M` goniometer runs).
pub const MAX_SLICES: usize = 32;

/// Midpoints per slice interval of the `theta_i` quadrature in [`GrooveSlices::mean_rho`].
const QUADRATURE_PER_SLICE: usize = 256;

/// The slices' `theta_i`, radians: `(k + 1/2) (pi/2) / S`.
pub fn slice_angles(slices: usize) -> Vec<f64> {
    (0..slices)
        .map(|k| (k as f64 + 0.5) * FRAC_PI_2 / slices as f64)
        .collect()
}

/// The exact-groove table (see the module notes): `rho[k][phi_i bin][phi_o bin]`.
#[derive(Clone, Debug)]
pub struct GrooveSlices {
    m: usize,
    /// The slices' `theta_i` ([`slice_angles`]).
    pub theta: Vec<f64>,
    /// `rho`, eq. (1'), `S x M x M` row-major.
    pub rho: Vec<f64>,
    /// `rho / F(cos theta_k)` per slice `k`.
    ratio: Vec<f64>,
    law: FresnelLaw,
    phi_bins: AngleBins,
}

impl GrooveSlices {
    /// Trace `slices` values of `theta_i` times `m` values of `phi_i` (the bin centres), each
    /// with `base.paths` paths of the goniometer with diffuse walls, the Fresnel law, bounce cap
    /// and seed of `base` (its walls, angles and bins are replaced; run `k m + i` has the seed
    /// `base.seed + k m + i`). `progress(paths)` hears each run's paths as they are traced.
    pub fn compute(
        profile: &Profile,
        base: &GonioSettings,
        m: usize,
        slices: usize,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<Self, GonioError> {
        for (key, n, max) in [("slices", slices, MAX_SLICES), ("slice-m", m, 4096)] {
            if !(1..=max).contains(&n) {
                return Err(GonioError {
                    key,
                    value: n.to_string(),
                    why: if max == MAX_SLICES {
                        "must be in 1..=32"
                    } else {
                        "must be in 1..=4096"
                    },
                });
            }
        }
        let theta = slice_angles(slices);
        let mut rho = Vec::with_capacity(slices * m * m);
        for (k, &theta_i) in theta.iter().enumerate() {
            for i in 0..m {
                let s = GonioSettings {
                    walls: GrooveWalls::Diffuse,
                    theta_i,
                    phi_i: bin_centre(i, m),
                    bins: m,
                    seed: base.seed.wrapping_add((k * m + i) as u64),
                    ..base.clone()
                };
                let out = trace_groove(profile, &s, progress)?;
                rho.extend((0..m).map(|j| {
                    let frac: f64 = (0..m).map(|a| out.reflected[a * m + j]).sum();
                    frac * m as f64 / (PI * bin_centre(j, m).cos())
                }));
            }
        }
        Ok(Self::from_rho(m, rho, base.fresnel_law))
    }

    /// The table of `rho` (`S x M x M`, `S = rho.len() / M^2` slices at [`slice_angles`]) under
    /// the walls' Fresnel law `law`.
    pub fn from_rho(m: usize, rho: Vec<f64>, law: FresnelLaw) -> Self {
        let slices = rho.len() / (m * m).max(1);
        let theta = slice_angles(slices);
        let ratio = rho
            .chunks(m * m)
            .zip(&theta)
            .flat_map(|(slice, t)| {
                let fresnel = law.reflectance(t.cos()).max(1e-12);
                slice.iter().map(move |r| r / fresnel)
            })
            .collect();
        GrooveSlices {
            m,
            theta,
            rho,
            ratio,
            law,
            phi_bins: AngleBins::new(m),
        }
    }

    /// The number of `phi` bins.
    pub fn m(&self) -> usize {
        self.m
    }

    /// The number of slices `S`.
    pub fn slices(&self) -> usize {
        self.theta.len()
    }

    /// The slices `k`, `k + 1` and the weight of `k + 1` of the linear interpolation at
    /// `t = |theta_i|` (clamped to the first and last slice).
    #[inline]
    fn bracket(&self, t: f64) -> (usize, usize, f64) {
        let s = self.theta.len();
        let x = (t * (s as f64 / FRAC_PI_2) - 0.5).clamp(0.0, (s - 1) as f64);
        let k = (x as usize).min(s.saturating_sub(2));
        ((k), (k + 1).min(s - 1), x - k as f64)
    }

    /// `rho(theta_i, phi_i bin i, phi_o bin o)` with `y = sin(theta_i)` (`wi.y` in the scratch
    /// frame): the interpolated ratio times `F(cos theta_i)`.
    #[inline]
    pub fn rho_at(&self, y: f64, i: usize, o: usize) -> f64 {
        let y = y.clamp(-1.0, 1.0);
        let (k0, k1, w) = self.bracket(y.asin().abs());
        let mm = self.m * self.m;
        let at = i * self.m + o;
        let ratio = (1.0 - w) * self.ratio[k0 * mm + at] + w * self.ratio[k1 * mm + at];
        let cos_theta_i = (1.0 - y * y).max(0.0).sqrt();
        ratio * self.law.reflectance(cos_theta_i)
    }

    /// `f(wo, wi)` without the cosine (0 below the surface), `f64` directions in the scratch
    /// frame (METHOD.md section 1).
    pub fn eval(&self, wo: [f64; 3], wi: [f64; 3]) -> f64 {
        if wo[2] <= 0.0 || wi[2] <= 0.0 {
            return 0.0;
        }
        let (i, o) = (
            self.phi_bins.bin_xz(wi[0], wi[2]),
            self.phi_bins.bin_xz(wo[0], wo[2]),
        );
        2.0 / PI * self.rho_at(wi[1], i, o)
    }

    /// Per `[phi_i bin][phi_o bin]`: `int (2/pi) cos^2(theta_i) rho(theta_i, .) dtheta_i` over
    /// `[-pi/2, pi/2]`, the mean of `rho` under the section 6 sampling density of `theta_i`.
    /// `sum_i` of it times `int_bin(i) cos(phi) dphi` is the lobe's directional albedo at
    /// `phi_o` (`integral f cos dw_i`, `dw = cos(theta) dtheta dphi`). The integral is the
    /// midpoint rule on [`QUADRATURE_PER_SLICE`] points per slice interval, folded into one
    /// weight per slice (the interpolation is linear in the slices).
    pub fn mean_rho(&self) -> Vec<f64> {
        let s = self.theta.len();
        let q = QUADRATURE_PER_SLICE * s;
        let h = FRAC_PI_2 / q as f64;
        let mut weight = vec![0.0f64; s];
        for p in 0..q {
            let t = (p as f64 + 0.5) * h;
            // Both signs of theta_i: 2 (2/pi) cos^2 F h.
            let c = 4.0 / PI * t.cos().powi(2) * self.law.reflectance(t.cos()) * h;
            let (k0, k1, w) = self.bracket(t);
            weight[k0] += (1.0 - w) * c;
            weight[k1] += w * c;
        }
        let mm = self.m * self.m;
        (0..mm)
            .map(|at| (0..s).map(|k| weight[k] * self.ratio[k * mm + at]).sum())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec3;
    use crate::precompute::table::{ScratchBrdf, ScratchTable, TableError, TableParams};
    use crate::precompute::trace2d::{FresnelMode, TraceSettings, Walls};

    fn params(slices: usize) -> TableParams {
        TableParams::new(
            Profile::parse("v:angle=90").unwrap(),
            TraceSettings {
                walls: Walls::Diffuse,
                m: 8,
                n: 500,
                nr: 2,
                fresnel_mode: FresnelMode::Walls,
                groove_slices: slices,
                ..TraceSettings::default()
            },
        )
    }

    /// The slices travel through the file; a table without them keeps its parameter record
    /// (so its hash) and its arrays; a file whose parameters ask for slices it lacks is refused.
    #[test]
    fn slices_round_trip_and_leave_seed_tables_alone() {
        let dir = std::env::temp_dir().join(format!("striae-groove-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let t = ScratchTable::compute(&params(2), &|_| {}).unwrap();
        assert_eq!(t.groove_rho.len(), 2 * 8 * 8);
        let f = dir.join("g.npz");
        t.save(&f).unwrap();
        assert_eq!(ScratchTable::load(&f).unwrap(), t);
        let seed = params(0);
        assert!(seed.to_json().get("groove_slices").is_none());
        assert_eq!(params(2).to_json()["groove_slices"], 2);
        assert_ne!(seed.hash(), params(2).hash());
        let plain = ScratchTable::compute(&seed, &|_| {}).unwrap();
        assert!(plain.groove_rho.is_empty());
        // The seed-model arrays are the same with or without the slices.
        assert_eq!(plain.rho_s, t.rho_s);
        let lacking = ScratchTable {
            groove_rho: Vec::new(),
            ..t
        };
        lacking.save(&f).unwrap();
        let e = ScratchTable::load(&f).unwrap_err();
        assert!(
            matches!(
                e,
                TableError::MissingKey {
                    key: "groove_theta",
                    ..
                }
            ),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    /// At a slice's own `theta_i` the renderer's BRDF is that slice's traced `rho` (times
    /// `2/pi`), whatever `theta_o`; beyond the last slice the ratio to `F` is held.
    #[test]
    fn the_brdf_is_the_traced_slice_at_its_angle() {
        let t = ScratchTable::compute(&params(3), &|_| {}).unwrap();
        let law = t.params.trace.fresnel_law;
        let rho = t.groove_rho.clone();
        let b = ScratchBrdf::new(t);
        let m = 8;
        let dir = |theta: f64, phi: f64| {
            Vec3::new(
                (theta.cos() * phi.sin()) as f32,
                theta.sin() as f32,
                (theta.cos() * phi.cos()) as f32,
            )
        };
        let (i, o) = (2, 5);
        let (phi_i, phi_o) = (bin_centre(i, m), bin_centre(o, m));
        for (k, &theta) in slice_angles(3).iter().enumerate() {
            let want = 2.0 / PI * rho[(k * m + i) * m + o];
            for theta_o in [-1.2, 0.0, 0.7] {
                for sign in [1.0, -1.0] {
                    let f = b.eval(dir(theta_o, phi_o), dir(sign * theta, phi_i));
                    assert!(
                        (f - want).abs() <= 1e-5 * want,
                        "{k} {theta_o}: {f} vs {want}"
                    );
                }
            }
        }
        let last = slice_angles(3)[2];
        let grazing: f64 = 1.5;
        let want = 2.0 / PI * rho[(2 * m + i) * m + o] / law.reflectance(last.cos())
            * law.reflectance(grazing.cos());
        let f = b.eval(dir(0.3, phi_o), dir(grazing, phi_i));
        assert!((f - want).abs() <= 1e-4 * want, "{f} vs {want}");
        assert!(f > 2.0 / PI * rho[(2 * m + i) * m + o]);
    }
}
