//! Tests of every BSDF: chi-square of the sampler against `pdf` (at several `wo`, grazing and
//! from inside for the dielectrics), sampled pdf == `pdf(wo, wi)`, weight == `f |cos| / pdf`,
//! directional albedo (energy), reciprocity, and the discrete lobe choice of delta BSDFs.

use super::*;
use crate::optics::fresnel;
use crate::testing::{chi2_discrete, chi2_sphere, MeanEstimate, SphereGrid};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

fn dir(theta: f32, phi: f32) -> Vec3 {
    Vec3::new(
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    )
}

/// Outgoing directions: normal, oblique, grazing (89.5 degrees).
fn wos_outside() -> Vec<Vec3> {
    vec![
        dir(0.0, 0.0),
        dir(0.7, 1.0),
        dir(1.3, 2.0),
        dir(89.5f32.to_radians(), -1.2),
    ]
}

/// The same directions from inside (`z < 0`).
fn wos_inside() -> Vec<Vec3> {
    wos_outside()
        .into_iter()
        .map(|w| Vec3::new(w.x, w.y, -w.z))
        .collect()
}

/// The chi-square grid's cells are smallest at its equator and largest at its poles, so
/// directions are tested in a frame whose poles are the local `+-x` axes: lobes around the
/// normal or mirror direction (for `wo` away from the `x` axis) land on fine cells.
fn to_grid(w: Vec3) -> Vec3 {
    Vec3::new(w.y, w.z, w.x)
}

fn from_grid(g: Vec3) -> Vec3 {
    Vec3::new(g.z, g.x, g.y)
}

fn chi2_tilted(
    n: usize,
    sub: usize,
    mut sample: impl FnMut() -> Option<Vec3>,
    pdf: impl Fn(Vec3) -> f64,
) -> crate::testing::Chi2Result {
    let grid = SphereGrid {
        sub,
        ..SphereGrid::new(40, 80)
    };
    chi2_sphere(&grid, n, || sample().map(to_grid), |g| pdf(from_grid(g)))
}

fn rel_close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs()).max(1e-6)
}

/// Draw samples; check each sample's `pdf` against `bsdf.pdf` and its weight against
/// `eval |cos| / pdf`; then chi-square of the directions against `pdf`.
fn check_non_delta(name: &str, bsdf: &Bsdf, wo: Vec3, n: usize, seed: u64) {
    check_non_delta_sub(name, bsdf, wo, n, seed, 0);
}

/// [`check_non_delta`] with at least `min_sub` quadrature points per cell side: a very rough
/// dielectric sends a few samples into the sliver of a cell above the horizon that 8 points
/// miss (an expected count of 0 there fails the test whatever the sampler).
fn check_non_delta_sub(name: &str, bsdf: &Bsdf, wo: Vec3, n: usize, seed: u64, min_sub: usize) {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut bad_pdf = 0;
    let mut bad_weight = 0;
    // Lobes cut by the horizon at grazing angles, and the thin crescent of directions that
    // leave through tilted microfacets beyond the critical angle, need a finer quadrature.
    let sub = if wo.z.abs() < 0.05 {
        48
    } else if wo.z < 0.0 {
        24
    } else {
        8
    }
    .max(min_sub);
    let r = chi2_tilted(
        n,
        sub,
        || {
            let s = bsdf.sample(wo, rng.random(), Vec2::new(rng.random(), rng.random()))?;
            assert!(!s.delta);
            let pdf = bsdf.pdf(wo, s.wi);
            if !rel_close(s.pdf, pdf, 2e-3) {
                bad_pdf += 1;
            }
            let expect = bsdf.eval(wo, s.wi) * s.wi.z.abs() / s.pdf;
            if !(0..3).all(|c| (expect[c] - s.weight[c]).abs() <= 2e-3 * expect[c].max(1.0)) {
                bad_weight += 1;
            }
            Some(s.wi)
        },
        |wi| bsdf.pdf(wo, wi) as f64,
    );
    // A few samples near singular configurations may disagree in the last digits.
    assert!(
        bad_pdf <= n / 10_000,
        "{name} wo {wo:?}: {bad_pdf} sampled pdfs differ from pdf()"
    );
    assert!(
        bad_weight <= n / 10_000,
        "{name} wo {wo:?}: {bad_weight} weights differ from eval cos / pdf"
    );
    assert!(
        r.p_value > 1e-3,
        "{name} wo {wo:?}: chi-square rejects the sampler: {r:?}"
    );
}

/// Monte Carlo directional albedo `integral f |cos| dwi` from the sampler, per channel,
/// with the refraction radiance factor undone (`weight * eta^2`) when `undo_eta` is set.
fn albedo(bsdf: &Bsdf, wo: Vec3, n: usize, seed: u64, undo_eta: bool) -> [MeanEstimate; 3] {
    let mut rng = Pcg64::seed_from_u64(seed);
    let mut m = [MeanEstimate::default(); 3];
    for _ in 0..n {
        let w = match bsdf.sample(wo, rng.random(), Vec2::new(rng.random(), rng.random())) {
            Some(s) => s.weight * if undo_eta { s.eta * s.eta } else { 1.0 },
            None => Rgb::ZERO,
        };
        for c in 0..3 {
            m[c].push(w[c] as f64);
        }
    }
    m
}

#[test]
fn diffuse_sampler_pdf_weight_and_energy() {
    let b = Bsdf::Diffuse(Diffuse::new(Rgb::new(1.0, 0.5, 0.0)));
    for (i, wo) in wos_outside().into_iter().enumerate() {
        check_non_delta("diffuse", &b, wo, 100_000, i as u64);
        let a = albedo(&b, wo, 10_000, 100 + i as u64, false);
        assert!(
            (a[0].mean() - 1.0).abs() < 1e-5 && (a[1].mean() - 0.5).abs() < 1e-5,
            "albedo {a:?}"
        );
        assert_eq!(a[2].mean(), 0.0);
    }
    // Independent of the sampler: quadrature of f cos over the hemisphere gives the albedo.
    let white = Bsdf::Diffuse(Diffuse::new(Rgb::ONE));
    let wo = dir(0.5, 0.1);
    let q: f64 = SphereGrid::new(200, 8)
        .integrate(|wi| (white.eval(wo, wi).x * wi.z.abs()) as f64)
        .iter()
        .sum();
    assert!((q - 1.0).abs() < 1e-3, "diffuse albedo by quadrature {q}");
    // One-sided: nothing from below, nothing towards below.
    assert!(white.sample(-wo, 0.5, Vec2::splat(0.3)).is_none());
    assert_eq!(white.eval(wo, -wo), Rgb::ZERO);
    assert_eq!(white.eval(wo, dir(0.3, 2.0)), white.eval(dir(0.3, 2.0), wo));
}

/// The smooth dielectric picks reflection with probability F (discrete chi-square), reflects
/// and refracts by the laws of reflection and Snell, and is lossless: R + T = 1 once the
/// `1 / eta^2` radiance factor is undone.
#[test]
fn smooth_dielectric_lobes_and_energy() {
    let eta = 1.5f32;
    let b = Bsdf::Dielectric(Dielectric::new(eta));
    assert!(b.is_delta() && b.has_transmission());
    let mut rng = Pcg64::seed_from_u64(5);
    for wo in wos_outside()
        .into_iter()
        .chain(wos_inside())
        .chain([dir(2.5, 0.3)])
    {
        let f = fresnel::dielectric(wo.z as f64, eta as f64);
        let n = 20_000;
        let mut counts = [0u64; 2];
        for _ in 0..n {
            let s = b
                .sample(wo, rng.random(), Vec2::new(rng.random(), rng.random()))
                .expect("always samples");
            assert!(s.delta);
            assert_eq!(b.pdf(wo, s.wi), 0.0);
            assert_eq!(b.eval(wo, s.wi), Rgb::ZERO);
            assert!((s.wi.length() - 1.0).abs() < 1e-5);
            if s.wi.z * wo.z > 0.0 {
                counts[0] += 1;
                assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-6);
                assert!(rel_close(s.pdf, f.r as f32, 1e-5));
                assert_eq!(s.eta, 1.0);
                assert_eq!(s.weight, Rgb::ONE);
            } else {
                counts[1] += 1;
                // Snell: n_o sin_o = n_i sin_i, same plane, opposite side.
                let (n_o, n_i) = if wo.z > 0.0 { (1.0, eta) } else { (eta, 1.0) };
                let sin_o = (1.0 - wo.z * wo.z).sqrt();
                let sin_i = (1.0 - s.wi.z * s.wi.z).max(0.0).sqrt();
                assert!(
                    (n_o * sin_o - n_i * sin_i).abs() < 1e-4,
                    "Snell {wo:?} {:?}",
                    s.wi
                );
                if sin_o > 1e-4 {
                    assert!(
                        wo.x * s.wi.x + wo.y * s.wi.y < 0.0,
                        "refracted to the other side of the normal"
                    );
                }
                assert!(rel_close(s.eta, n_i / n_o, 1e-6));
                assert!(rel_close(s.pdf, 1.0 - f.r as f32, 1e-5));
                // Radiance transport: scaled by (n_o / n_i)^2; undone it is exactly 1.
                assert!(rel_close(s.weight.x, (n_o / n_i).powi(2), 1e-5));
                assert!(rel_close(s.weight.x * s.eta * s.eta, 1.0, 1e-5));
            }
        }
        let expected = [f.r * n as f64, (1.0 - f.r) * n as f64];
        let r = chi2_discrete(&counts, &expected);
        assert!(
            r.p_value > 1e-3,
            "wo {wo:?}: lobe choice {counts:?} vs F = {}: {r:?}",
            f.r
        );
    }
    // Beyond the critical angle from inside: total internal reflection only.
    let wo = dir(std::f32::consts::PI - 0.9, 0.0);
    for u in [0.0, 0.5, 0.999] {
        let s = b.sample(wo, u, Vec2::ZERO).unwrap();
        assert!(s.wi.z < 0.0 && s.pdf == 1.0);
    }
}

/// `integral D(m) cos theta_m dm = 1` (the projected microfacet area is the macro area), by
/// a fine 1D quadrature in theta (isotropic).
#[test]
fn ggx_is_normalised() {
    for alpha in [0.02f32, 0.1, 0.3, 1.0] {
        let g = crate::optics::microfacet::Ggx::isotropic(alpha);
        let n = 200_000;
        let h = std::f64::consts::FRAC_PI_2 / n as f64;
        let total: f64 = (0..n)
            .map(|i| {
                let t = (i as f64 + 0.5) * h;
                g.d(dir(t as f32, 0.3)) as f64 * t.cos() * t.sin() * 2.0 * std::f64::consts::PI * h
            })
            .sum();
        assert!((total - 1.0).abs() < 1e-3, "alpha {alpha}: {total}");
    }
}

/// The visible-normal sampler matches `pdf_visible` (chi-square), and the visible normals'
/// density integrates to 1 (which checks `G1` against `D`: Heitz 2014 eq. 2).
#[test]
fn visible_normal_sampler_chi2() {
    let mut rng = Pcg64::seed_from_u64(11);
    for (alpha, theta) in [(0.15f32, 0.3f32), (0.6, 1.2), (0.9, 1.55)] {
        let g = crate::optics::microfacet::Ggx {
            alpha_x: alpha,
            alpha_y: alpha * 0.7,
        };
        let v = dir(theta, 1.0);
        let r = chi2_tilted(
            200_000,
            8,
            || Some(g.sample_visible(v, Vec2::new(rng.random(), rng.random()))),
            |m| g.pdf_visible(v, m) as f64,
        );
        assert!(r.p_value > 1e-3, "alpha {alpha} theta {theta}: {r:?}");
        assert!(
            (r.pdf_mass - 1.0).abs() < 0.01,
            "alpha {alpha} theta {theta}: {r:?}"
        );
    }
}

fn gold() -> (Rgb, Rgb) {
    let ior = super::ConductorIor::preset("gold").unwrap();
    (ior.eta, ior.k)
}

/// Smooth conductor: one delta lobe at the mirror direction, weight F per channel; the
/// `none` preset (eta = 0, k = 1) reflects everything at every angle.
#[test]
fn smooth_conductor_mirror_and_fresnel() {
    let (eta, k) = gold();
    let b = Bsdf::Conductor(Conductor::new(eta, k));
    let mirror = Bsdf::Conductor(Conductor::new(Rgb::ZERO, Rgb::ONE));
    assert!(b.is_delta() && !b.has_transmission());
    for wo in wos_outside() {
        let s = b.sample(wo, 0.3, Vec2::new(0.2, 0.7)).unwrap();
        assert!(s.delta && s.pdf == 1.0 && s.eta == 1.0);
        assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-6);
        for c in 0..3 {
            let f = fresnel::conductor(wo.z as f64, eta[c] as f64, k[c] as f64) as f32;
            assert!((s.weight[c] - f).abs() < 1e-6);
        }
        assert_eq!(b.eval(wo, s.wi), Rgb::ZERO);
        assert_eq!(b.pdf(wo, s.wi), 0.0);
        let m = mirror.sample(wo, 0.3, Vec2::new(0.2, 0.7)).unwrap();
        assert!(
            (m.weight - Rgb::ONE).abs().max_element() < 1e-6,
            "perfect mirror {:?}",
            m.weight
        );
    }
    assert!(
        b.sample(-dir(0.4, 0.0), 0.5, Vec2::splat(0.5)).is_none(),
        "opaque: nothing from below"
    );
}

/// Rough conductor: chi-square, pdf and weight consistency at several roughnesses and
/// angles (grazing included); albedo <= 1, and close to 1 for the `F = 1` mirror at low
/// roughness (the separable single-scattering model loses energy as alpha grows: Heitz 2016).
#[test]
fn rough_conductor_sampler_and_energy() {
    let (eta, k) = gold();
    let mut seed = 1000;
    for alpha in [0.1f32, 0.3, 0.8] {
        let b = Bsdf::RoughConductor(RoughConductor::new(eta, k, alpha));
        assert!(!b.is_delta() && !b.has_transmission());
        let mirror = Bsdf::RoughConductor(RoughConductor::new(Rgb::ZERO, Rgb::ONE, alpha));
        for wo in wos_outside() {
            seed += 1;
            check_non_delta(
                &format!("rough conductor alpha {alpha}"),
                &b,
                wo,
                200_000,
                seed,
            );
            let a = albedo(&mirror, wo, 20_000, seed + 500, false);
            let m = a[0].mean();
            assert!(
                m <= 1.0 + 3.0 * a[0].std_error(),
                "alpha {alpha} wo {wo:?}: albedo {m}"
            );
            if alpha <= 0.1 && wo.z > 0.5 {
                assert!(m > 0.97, "alpha {alpha} wo {wo:?}: albedo {m}");
            }
        }
    }
}

/// Rough dielectric from outside and from inside: chi-square over both hemispheres (the pdf
/// integrates to the probability the sampler succeeds), pdf and weight consistency; energy
/// with the radiance factor undone <= 1, and near 1 at low roughness away from grazing.
#[test]
fn rough_dielectric_sampler_and_energy() {
    let mut seed = 2000;
    for alpha in [0.1f32, 0.4] {
        for eta in [1.5f32, 1.0 / 1.33] {
            let b = Bsdf::RoughDielectric(RoughDielectric::new(eta, alpha));
            assert!(!b.is_delta() && b.has_transmission());
            for wo in wos_outside().into_iter().chain(wos_inside()) {
                seed += 1;
                check_non_delta(
                    &format!("rough dielectric alpha {alpha} eta {eta}"),
                    &b,
                    wo,
                    200_000,
                    seed,
                );
                let a = albedo(&b, wo, 20_000, seed + 500, true);
                let m = a[0].mean();
                assert!(
                    m <= 1.0 + 3.0 * a[0].std_error(),
                    "alpha {alpha} eta {eta} wo {wo:?}: albedo {m}"
                );
                if alpha <= 0.1 && wo.z.abs() > 0.5 {
                    assert!(m > 0.95, "alpha {alpha} eta {eta} wo {wo:?}: albedo {m}");
                }
            }
        }
    }
}

/// Reciprocity: `f(wo, wi) = f(wi, wo)` for reflection; for transmission the radiance
/// scaling makes `f(wo, wi) / n(wo)^2 = f(wi, wo) / n(wi)^2` (Veach 1997, eq. 5.14).
#[test]
fn reciprocity() {
    let mut rng = Pcg64::seed_from_u64(77);
    let (eta_au, k_au) = gold();
    let eta = 1.5f32;
    // Kulla-Conty's multiple-scattering lobe is symmetric; Turquin's dielectric scaling is not
    // (module `multiscatter`), so it is not here.
    let ms = ConductorCompensation::new(
        ConductorIor {
            eta: eta_au,
            k: k_au,
        },
        0.6,
    );
    let bsdfs = [
        Bsdf::Diffuse(Diffuse::new(Rgb::new(0.3, 0.6, 0.9))),
        Bsdf::RoughConductor(RoughConductor::new(eta_au, k_au, 0.3)),
        Bsdf::RoughDielectric(RoughDielectric::new(eta, 0.3)),
        Bsdf::CompensatedConductor(ms.bsdf()),
    ];
    let mut checked = [0; 4];
    for _ in 0..2000 {
        let a = crate::sampling::square_to_uniform_sphere(Vec2::new(rng.random(), rng.random()));
        let b = crate::sampling::square_to_uniform_sphere(Vec2::new(rng.random(), rng.random()));
        for (i, bsdf) in bsdfs.iter().enumerate() {
            let (fab, fba) = (bsdf.eval(a, b), bsdf.eval(b, a));
            let n = |w: Vec3| {
                if w.z < 0.0 && bsdf.has_transmission() {
                    eta
                } else {
                    1.0
                }
            };
            let (lhs, rhs) = (fab / (n(a) * n(a)), fba / (n(b) * n(b)));
            assert!(
                (lhs - rhs).abs().max_element() <= 1e-3 * lhs.max_element().max(1e-3),
                "{bsdf:?} {a:?} {b:?}: {fab:?} vs {fba:?}"
            );
            if fab.max_element() > 0.0 {
                checked[i] += 1;
            }
        }
    }
    assert!(checked.iter().all(|&c| c > 100), "{checked:?}");
}

/// `eval_pdf` agrees with `eval` and `pdf` for every BSDF, both sides, random directions.
#[test]
fn eval_pdf_matches_eval_and_pdf() {
    let mut rng = Pcg64::seed_from_u64(78);
    let (eta_au, k_au) = gold();
    let ms_conductor = ConductorCompensation::new(
        ConductorIor {
            eta: eta_au,
            k: k_au,
        },
        0.6,
    );
    let ms_dielectric = DielectricCompensation::new(1.5, 0.6);
    let bsdfs = [
        Bsdf::Diffuse(Diffuse::new(Rgb::new(0.3, 0.6, 0.9))),
        Bsdf::CompensatedConductor(ms_conductor.bsdf()),
        Bsdf::CompensatedDielectric(ms_dielectric.bsdf()),
        Bsdf::Dielectric(Dielectric::new(1.5)),
        Bsdf::Conductor(Conductor::new(eta_au, k_au)),
        Bsdf::RoughConductor(RoughConductor::new(eta_au, k_au, 0.3)),
        Bsdf::RoughDielectric(RoughDielectric::new(1.5, 0.3)),
        Bsdf::RoughDielectric(RoughDielectric::new(1.0 / 1.33, 0.05)),
    ];
    let mut nonzero = 0;
    for _ in 0..5000 {
        let a = crate::sampling::square_to_uniform_sphere(Vec2::new(rng.random(), rng.random()));
        let b = crate::sampling::square_to_uniform_sphere(Vec2::new(rng.random(), rng.random()));
        for bsdf in &bsdfs {
            let (f, p) = bsdf.eval_pdf(a, b);
            let (f2, p2) = (bsdf.eval(a, b), bsdf.pdf(a, b));
            assert!(
                (f - f2).abs().max_element() <= 1e-4 * f2.max_element().max(1e-3),
                "{bsdf:?}: {f:?} vs {f2:?}"
            );
            assert!(
                (p - p2).abs() <= 1e-4 * p2.max(1e-3),
                "{bsdf:?}: {p} vs {p2}"
            );
            nonzero += (p > 0.0) as usize;
        }
    }
    assert!(nonzero > 5000, "{nonzero}");
}

/// Multiple-scattering compensation (`multiscatter = true`, module `multiscatter`).
mod multiscatter_compensation {
    use super::*;
    use crate::render::bsdf::multiscatter::MU_NODES;

    /// The compensated conductor's mixture sampler (cosine lobe for `f_ms`, visible normals for
    /// `f_ss`): chi-square against the mixture's `pdf`, each sample's pdf and weight against
    /// `pdf()` and `eval cos / pdf`, a coloured conductor, from smooth-ish to very rough.
    #[test]
    fn conductor_sampler_chi2() {
        let (eta, k) = gold();
        let mut seed = 5000;
        for alpha in [0.1f32, 0.5, 1.0] {
            let comp = ConductorCompensation::new(ConductorIor { eta, k }, alpha);
            let b = Bsdf::CompensatedConductor(comp.bsdf());
            assert!(!b.is_delta() && !b.has_transmission());
            for wo in wos_outside() {
                seed += 1;
                check_non_delta(
                    &format!("compensated conductor alpha {alpha}"),
                    &b,
                    wo,
                    200_000,
                    seed,
                );
            }
            assert!(b.sample(-dir(0.4, 0.0), 0.1, Vec2::splat(0.5)).is_none());
            assert_eq!(b.eval(dir(0.4, 0.0), -dir(0.3, 1.0)), Rgb::ZERO);
        }
    }

    /// The compensated dielectric samples as the single-scattering one; its weights and
    /// `eval` carry the `1 / E(mu_o)` scale consistently (checked against `eval cos / pdf`),
    /// from outside and inside. (With the lower index inside, `eta = 1 / 1.33`, seen from
    /// inside at 74 degrees, one to nine of 200k samples land in cells whose pdf integral the
    /// harness puts at 0, at alpha 0.3 to 1, for [`RoughDielectric`] alike, whose sampler
    /// this one is: that ratio is left to `rough_dielectric_sampler_and_energy`.)
    #[test]
    fn dielectric_sampler_chi2() {
        let mut seed = 6000;
        for (alpha, eta) in [(0.3f32, 1.5f32), (0.7, 1.5), (1.0, 1.5)] {
            let comp = DielectricCompensation::new(eta, alpha);
            let b = Bsdf::CompensatedDielectric(comp.bsdf());
            assert!(!b.is_delta() && b.has_transmission());
            for wo in wos_outside().into_iter().chain(wos_inside()) {
                seed += 1;
                check_non_delta_sub(
                    &format!("compensated dielectric alpha {alpha} eta {eta}"),
                    &b,
                    wo,
                    200_000,
                    seed,
                    24,
                );
            }
        }
    }

    const ALPHAS: [f32; 5] = [0.05, 0.2, 0.4, 0.7, 1.0];
    const THETAS_DEG: [f32; 5] = [0.0, 30.0, 60.0, 75.0, 85.0];

    /// Directional albedo with compensation is 1 within noise for an `F = 1` conductor (every
    /// channel) and a lossless dielectric seen from outside and from inside, alpha 0.05 to 1,
    /// theta 0 to 85 degrees. Without it the albedo is the tabulated `E(mu) < 1`, and the loss
    /// at alpha = 1 exceeds 5 % at every angle: the test would catch a compensation that
    /// does nothing.
    #[test]
    fn albedo_is_one_with_compensation_and_e_without() {
        let n = 40_000;
        let mut seed = 7000;
        let mut worst = 0.0f64;
        for alpha in ALPHAS {
            let white = ConductorIor {
                eta: Rgb::ZERO,
                k: Rgb::ONE,
            };
            let conductor = ConductorCompensation::new(white, alpha);
            let dielectric = DielectricCompensation::new(1.5, alpha);
            for theta in THETAS_DEG {
                let w = dir(theta.to_radians(), 0.4);
                let cases = [
                    (
                        "conductor",
                        w,
                        Bsdf::CompensatedConductor(conductor.bsdf()),
                        Bsdf::RoughConductor(conductor.ss),
                        conductor.albedo.eval(w.z),
                    ),
                    (
                        "dielectric outside",
                        w,
                        Bsdf::CompensatedDielectric(dielectric.bsdf()),
                        Bsdf::RoughDielectric(dielectric.ss),
                        dielectric.outside.eval(w.z),
                    ),
                    (
                        "dielectric inside",
                        -w,
                        Bsdf::CompensatedDielectric(dielectric.bsdf()),
                        Bsdf::RoughDielectric(dielectric.ss),
                        dielectric.inside.eval(w.z),
                    ),
                ];
                for (name, wo, ms, ss, e) in cases {
                    seed += 1;
                    let what = format!("{name} alpha {alpha} theta {theta}");
                    let a = albedo(&ms, wo, n, seed, true);
                    for m in &a {
                        assert!(
                            m.agrees_with(1.0, 4.0, 2e-3),
                            "{what}: compensated albedo {} +- {}",
                            m.mean(),
                            m.std_error()
                        );
                        worst = worst.max((m.mean() - 1.0).abs());
                    }
                    let b = albedo(&ss, wo, n, seed + 100_000, true);
                    assert!(
                        b[0].agrees_with(e as f64, 4.0, 2e-3),
                        "{what}: single-scattering albedo {} +- {} vs table {e}",
                        b[0].mean(),
                        b[0].std_error()
                    );
                    if alpha >= 1.0 {
                        assert!(e < 0.95, "{what}: E = {e}");
                    }
                }
            }
        }
        eprintln!("largest |albedo - 1| with compensation: {worst:.2e}");
    }

    /// Kulla-Conty's colour term: a coloured conductor gains less energy from the compensation
    /// than a white one (`F_ms < 1` per channel, the white lobe's `F_ms` being 1).
    #[test]
    fn coloured_conductor_gains_less_than_white() {
        let (eta, k) = gold();
        let comp = ConductorCompensation::new(ConductorIor { eta, k }, 0.8);
        let white = ConductorCompensation::new(
            ConductorIor {
                eta: Rgb::ZERO,
                k: Rgb::ONE,
            },
            0.8,
        );
        let wo = dir(1.0, 0.2);
        let ms = albedo(
            &Bsdf::CompensatedConductor(comp.bsdf()),
            wo,
            40_000,
            11,
            false,
        );
        let ss = albedo(&Bsdf::RoughConductor(comp.ss), wo, 40_000, 11, false);
        let gain_white = 1.0 - white.albedo.eval(wo.z) as f64;
        for c in 0..3 {
            let gain = ms[c].mean() - ss[c].mean();
            assert!(
                gain > 0.0 && gain < gain_white,
                "channel {c}: gain {gain} (white {gain_white})"
            );
            let ratio = comp.ms_scale[c] / white.ms_scale[c];
            assert!(ratio > 0.0 && ratio < 1.0, "channel {c}: F_ms {ratio}");
        }
    }

    /// The tables are deterministic (built twice, equal) and smooth-to-rough ordered: more
    /// roughness, less single scattering, at every tabulated cosine.
    #[test]
    fn tables_are_deterministic_and_ordered() {
        let a = DielectricCompensation::new(1.5, 0.5);
        assert_eq!(a, DielectricCompensation::new(1.5, 0.5));
        let white = ConductorIor {
            eta: Rgb::ZERO,
            k: Rgb::ONE,
        };
        let (lo, hi) = (
            ConductorCompensation::new(white, 0.2),
            ConductorCompensation::new(white, 0.8),
        );
        for i in 0..MU_NODES {
            let mu = (i as f32 + 0.5) / MU_NODES as f32;
            assert!(lo.albedo.eval(mu) > hi.albedo.eval(mu), "mu {mu}");
        }
        assert!(lo.albedo.average() > hi.albedo.average());
    }
}

/// The lobes the scratched BSDFs share: empty lobes dropped, coverages clamped to 1 and
/// rescaled to sum at most 1; `pick` maps `[start, start + C)` onto the lobes in order.
#[test]
fn covered_lobes_normalise_and_pick() {
    use super::scratched::CoveredLobes;
    let lobe = |coverage| ScratchLobe::new(coverage, 1.0, 0.0);
    let l = CoveredLobes::new(&[lobe(0.2), lobe(0.0), lobe(0.3)]);
    assert_eq!(l.as_slice().len(), 2);
    assert!((l.total() - 0.5).abs() < 1e-7);
    let (k, u) = l.pick(0.15, 0.1);
    assert!(k == 0 && (u - 0.25).abs() < 1e-6, "{k} {u}");
    let (k, u) = l.pick(0.45, 0.1);
    assert!(k == 1 && (u - 0.5).abs() < 1e-5, "{k} {u}");
    // What rounding leaves past `start + C` goes to the last lobe.
    assert_eq!(l.pick(0.7, 0.1), (1, 1.0));
    let full = CoveredLobes::new(&[lobe(1.5), lobe(0.5)]);
    assert!((full.total() - 1.0).abs() < 1e-7);
    assert!((full.as_slice()[0].coverage - 2.0 / 3.0).abs() < 1e-6);
    assert!(CoveredLobes::new(&[lobe(0.0)]).is_empty());
}

mod scratched_glass {
    //! The dielectric-wall scratched glass (METHOD.md 8.1-8.2): sampler against its pdf from
    //! both sides, lossless energy, `eval` normalised independently of the sampler, and the
    //! reciprocity of the groove's lobes.

    use super::*;
    use crate::precompute::profile::Profile;
    use crate::precompute::wall_table::{WallTable, WallTableParams};
    use std::f32::consts::{FRAC_PI_2, PI};
    use std::sync::Arc;

    fn wall_table(roughness: f64, grid: usize, bins: usize, paths: u64) -> WallTable {
        let p = WallTableParams {
            theta_bins: grid,
            phi_bins: grid,
            bins,
            paths,
            ..WallTableParams::new(Profile::parse("round:depth=0.5").unwrap(), 1.5, roughness)
        };
        WallTable::compute(&p).unwrap()
    }

    /// A small table; smooth walls' boxes one exit bin wide, which the quadratures resolve
    /// (the shipped box is tested by `smooth_walls_leave_at_the_exact_angle`).
    fn table(roughness: f64, grid: usize, bins: usize, paths: u64) -> GlassWalls {
        GlassWalls::Table(Arc::new(WallLobeTable::with_smooth_box(
            &wall_table(roughness, grid, bins, paths),
            PI / bins as f32,
        )))
    }

    /// Two crossing scratches covering 0.3 and 0.25 of the footprint.
    pub(super) fn lobes() -> [ScratchLobe; 2] {
        let (s, c) = 0.4f32.sin_cos();
        let (s2, c2) = 2.1f32.sin_cos();
        [ScratchLobe::new(0.3, c, s), ScratchLobe::new(0.25, c2, s2)]
    }

    /// [`lobes`] with leaned frames (`lean = true`), and how far the pdf's mass may fall below
    /// the coverage (the part of the lobes that the leans put across the surface).
    pub(super) fn lobe_sets() -> [([ScratchLobe; 2], f32); 2] {
        let [a, b] = lobes();
        [(lobes(), 0.0), ([a.leaned(0.12), b.leaned(-0.08)], 0.04)]
    }

    fn wos() -> Vec<Vec3> {
        let mut w = wos_outside();
        w.pop(); // grazing: the chi-square grid cannot resolve its thin lobes
        w.extend(wos_inside().into_iter().take(3));
        w
    }

    /// Samples: their directions pass a chi-square test against `pdf` (which integrates to
    /// the groove lobes' probability `C`); smooth and rough walls, from outside and inside.
    /// Rough walls' non-delta samples' `pdf` and weight match `pdf()` and `eval cos / pdf`;
    /// smooth walls' weights are the one-slice estimate's, `s` times the slice's energy (the
    /// module notes), which a lossless groove's slices make exactly `s`.
    #[test]
    fn sampler_matches_pdf_from_both_sides() {
        for (rough, (lobes, lost)) in [0.0, 0.3]
            .into_iter()
            .flat_map(|r| lobe_sets().map(|l| (r, l)))
        {
            let t = table(rough, 3, 8, 4000);
            let bsdf = Bsdf::ScratchedGlass(ScratchedGlassBsdf::new(1.5, &t, &lobes));
            for (i, wo) in wos().into_iter().enumerate() {
                let mut rng = Pcg64::seed_from_u64(900 + i as u64);
                let (mut bad_pdf, mut bad_weight) = (0, 0);
                let n = 200_000;
                // Smooth walls' thin boxes in theta, and the cells a lean cuts at the
                // horizon, need a fine quadrature of the cells.
                let r = chi2_tilted(
                    n,
                    if rough == 0.0 || lost > 0.0 { 32 } else { 12 },
                    || {
                        let s =
                            bsdf.sample(wo, rng.random(), Vec2::new(rng.random(), rng.random()))?;
                        if s.delta {
                            return None;
                        }
                        if rough == 0.0 {
                            // `s` undone: `eta^2` is `1 / s` for each lobe and side.
                            let lossless = s.weight.x * s.eta * s.eta;
                            bad_weight += !rel_close(lossless, 1.0, 1e-4) as usize;
                            bad_pdf += !(s.pdf > 0.0) as usize;
                            return Some(s.wi);
                        }
                        let (f, pdf) = bsdf.eval_pdf(wo, s.wi);
                        bad_pdf += !rel_close(s.pdf, pdf, 2e-3) as usize;
                        let expect = f.x * s.wi.z.abs() / s.pdf;
                        bad_weight += !rel_close(expect, s.weight.x, 2e-3) as usize;
                        Some(s.wi)
                    },
                    |wi| bsdf.pdf(wo, wi) as f64,
                );
                assert!(
                    bad_pdf <= n / 10_000,
                    "rough {rough} wo {wo:?}: {bad_pdf} pdfs"
                );
                assert!(
                    bad_weight <= n / 10_000,
                    "rough {rough} wo {wo:?}: {bad_weight}"
                );
                assert!(
                    r.p_value > 1e-3 && r.pdf_mass < 0.57 && r.pdf_mass > 0.53 - lost as f64,
                    "rough {rough} lost {lost} wo {wo:?}: {r:?}"
                );
            }
        }
    }

    /// Smooth walls with the shipped box: every groove sample leaves within the box around the
    /// exact exit angle of METHOD.md 8.1 (`beta = n w.y` conserved,
    /// [`crate::precompute::wall_table::exit_theta`]), reflected and transmitted, from both sides; a lossless
    /// groove's sampled weights still average 1. Traced grooves (`lobes = "traced"`, no table)
    /// leave at the exact angle itself, and have no density to evaluate.
    #[test]
    fn smooth_walls_leave_at_the_exact_angle() {
        let table = wall_table(0.0, 3, 8, 4000);
        let t = WallLobeTable::new(&table);
        let half = 0.5 * t.row_width();
        smooth_walls_leave_at(&GlassWalls::Table(Arc::new(t)), half);
        let traced = TracedGroove::new(&table.params);
        smooth_walls_leave_at(&GlassWalls::Traced(Arc::new(traced)), 0.0);
    }

    /// Samples of smooth walls `walls` leave within `half` of the exact exit angle.
    fn smooth_walls_leave_at(walls: &GlassWalls, half: f32) {
        assert!(walls.smooth());
        let lobe = lobes()[0];
        let bsdf = Bsdf::ScratchedGlass(ScratchedGlassBsdf::new(1.5, walls, &[lobe]));
        for (i, wo) in wos().into_iter().enumerate() {
            let side = (wo.z < 0.0) as usize;
            let theta_i = lobe.to_scratch(wo).y.asin() as f64;
            let mut rng = Pcg64::seed_from_u64(300 + i as u64);
            let mut seen = [0; 2];
            for _ in 0..20_000 {
                let u = Vec2::new(rng.random(), rng.random());
                let Some(s) = bsdf.sample(wo, rng.random(), u).filter(|s| !s.delta) else {
                    continue;
                };
                let l = ((s.wi.z < 0.0) != (side == 1)) as usize;
                seen[l] += 1;
                let exit =
                    crate::precompute::wall_table::exit_theta(2 * side + l, theta_i, 1.5) as f32;
                let exit = exit.clamp(-FRAC_PI_2 + half, FRAC_PI_2 - half);
                let theta = lobe.to_scratch(s.wi).y.clamp(-1.0, 1.0).asin();
                assert!(
                    (theta - exit).abs() <= half * 1.01 + 1e-5,
                    "wo {wo:?} lobe {l}: theta {theta} against {exit} +- {half}"
                );
            }
            // The groove is 0.3 of the footprint and both lobes carry energy.
            assert!(
                seen[0] + seen[1] > 5000 && seen[1] > 0,
                "wo {wo:?}: {seen:?}"
            );
            let a = albedo(&bsdf, wo, 100_000, 170 + i as u64, true)[0];
            assert!(a.agrees_with(1.0, 4.0, 1e-3), "wo {wo:?}: {a:?}");
            if let GlassWalls::Traced(_) = walls {
                let wi = lobe.from_scratch(Vec3::new(0.3, 0.1, -0.95).normalize());
                assert_eq!(bsdf.eval_pdf(wo, wi).1, 0.0);
            }
        }
    }

    /// A lossless groove in lossless glass: the sampled weights, with refraction's radiance
    /// factor undone, average 1 from either side, smooth walls and rough ones (which walk
    /// their microsurface, METHOD.md 9.7).
    /// And, independent of the sampler, the quadrature of `eval |cos|` over the sphere gives
    /// the groove's share `C (R + s T)` with `R + T` the table's (1 for smooth walls). Leaned
    /// lobes (`lean = true`) lose what their leans put across the surface and gain nothing.
    #[test]
    fn lossless_energy_and_eval_normalisation() {
        for (rough, (lobes, lost)) in [0.0, 0.3]
            .into_iter()
            .flat_map(|r| lobe_sets().map(|l| (r, l)))
        {
            let t = table(rough, 3, 8, 4000);
            let glass = ScratchedGlassBsdf::new(1.5, &t, &lobes);
            let bsdf = Bsdf::ScratchedGlass(glass);
            for (i, wo) in wos().into_iter().enumerate() {
                let a = albedo(&bsdf, wo, 100_000, 70 + i as u64, true)[0];
                if lost > 0.0 {
                    // Leaned lobes: what the leans put across the surface is lost, nothing
                    // gained.
                    assert!(
                        a.mean() < 1.0 + 4.0 * a.std_error() + 1e-6
                            && a.mean() > 0.75 - lost as f64,
                        "rough {rough} wo {wo:?}: {a:?}"
                    );
                } else {
                    assert!(
                        a.agrees_with(1.0, 4.0, 1e-3),
                        "rough {rough} wo {wo:?}: {a:?}"
                    );
                }
                // Quadrature with the radiance factor undone on the far side.
                let s2 = if wo.z > 0.0 { 1.5f64 * 1.5 } else { 1.0 / 2.25 };
                let q: f64 = SphereGrid {
                    sub: 16,
                    ..SphereGrid::new(100, 200)
                }
                .integrate(|wi| {
                    let undo = if (wi.z > 0.0) == (wo.z > 0.0) {
                        1.0
                    } else {
                        s2
                    };
                    (bsdf.eval(wo, wi).x * wi.z.abs()) as f64 * undo
                })
                .iter()
                .sum();
                if rough == 0.0 && lost == 0.0 {
                    assert!((q - 0.55).abs() < 0.01, "wo {wo:?}: {q} vs 0.55");
                } else {
                    assert!(q > 0.4 - lost as f64 && q < 0.56, "wo {wo:?}: {q}");
                }
            }
        }
    }

    /// Reciprocity of the groove's lobes read from the table (METHOD.md 8.1): `f(a, b) = f(b,
    /// a)` for reflection and `f(a, b) / n_a^2 = f(b, a) / n_b^2` for transmission, at incident
    /// grid points that are exit-bin centres (4 x 4 grid, 12 bins), rough walls, within the
    /// trace's noise and the bins' averaging (the table is reciprocal only as far as its bins
    /// resolve the lobes).
    #[test]
    fn groove_lobes_are_reciprocal() {
        let t = table(0.4, 4, 12, 400_000);
        let one = [ScratchLobe::new(1.0, 1.0, 0.0)];
        let b = ScratchedGlassBsdf::new(1.5, &t, &one);
        let centre = |i: usize| -FRAC_PI_2 + (i as f32 + 0.5) * PI / 4.0;
        // The scratch frame's (theta, phi) to the shading frame (x = b = (0, -1, 0) for
        // beta = 0: `to_scratch` gives x = -w.y, y = w.x).
        let dir = |ti: usize, pi: usize, up: bool| {
            let (st, ct) = centre(ti).sin_cos();
            let (sp, cp) = centre(pi).sin_cos();
            let z = if up { ct * cp } else { -ct * cp };
            Vec3::new(st, -ct * sp, z)
        };
        let mut checked = 0;
        for (ta, pa, tb, pb) in [(1, 1, 2, 2), (1, 2, 1, 1), (2, 1, 1, 1), (1, 2, 2, 2)] {
            for (up_a, up_b) in [(true, true), (false, false), (true, false), (false, true)] {
                let (wa, wb) = (dir(ta, pa, up_a), dir(tb, pb, up_b));
                let n2 = |up: bool| if up { 1.0 } else { 2.25f32 };
                let (x, y) = (b.eval(wa, wb).x / n2(up_a), b.eval(wb, wa).x / n2(up_b));
                if x.max(y) < 0.008 {
                    continue;
                }
                checked += 1;
                // The main lobe within 12 %; its tails within 2x: there a lobe changes much
                // within a 15-degree bin, and a bin in the glass spans a wider cone in the air,
                // so the bin averages of the two directions differ.
                let tol = if x.max(y) > 0.1 { 0.12 } else { 0.5 };
                assert!(
                    (x - y).abs() < tol * x.max(y),
                    "{:?} <-> {:?} ({up_a}, {up_b}): {x} vs {y}",
                    (ta, pa),
                    (tb, pb)
                );
            }
        }
        assert!(checked >= 8, "{checked}");
    }
}

mod scratched_metal {
    //! Scratched metal with rough walls (METHOD.md 8.1): the sampler against its pdf, the
    //! energy of a white conductor against the table's own fractions, `eval` normalised by
    //! quadrature, and one-sidedness.

    use super::scratched_glass::{lobe_sets, lobes};
    use super::*;
    use crate::optics::fresnel::FresnelLaw;
    use crate::precompute::profile::Profile;
    use crate::precompute::wall_table::{WallTable, WallTableParams};

    fn wall_table(law: FresnelLaw) -> WallTable {
        let p = WallTableParams {
            theta_bins: 3,
            phi_bins: 4,
            bins: 8,
            paths: 4000,
            ..WallTableParams::specular(Profile::parse("v:angle=100").unwrap(), law, 0.3)
        };
        WallTable::compute(&p).unwrap()
    }

    fn white() -> ConductorIor {
        ConductorIor {
            eta: Rgb::ZERO,
            k: Rgb::ONE,
        }
    }

    /// The albedo of the groove's reflected lobe at `wo` (scratch frame), from the traced
    /// table's interpolation (`WallTable::lobes_at`, in `f64`), not the render form.
    fn table_albedo(t: &WallTable, wo_s: Vec3) -> f64 {
        let mut out = std::array::from_fn(|_| Vec::new());
        let theta = (wo_s.y as f64).asin();
        let phi = (wo_s.x as f64).atan2(wo_s.z as f64);
        t.lobes_at(theta, phi, &mut out);
        out[0].iter().sum()
    }

    /// The groove reflects at most what arrives, and most of it (no Fresnel loss, GGX's
    /// single-scattering loss only); nothing is transmitted or seen from inside.
    #[test]
    fn groove_lobe_albedo_is_at_most_one() {
        let t = wall_table(FresnelLaw::None);
        for ti in 0..t.theta_i.len() {
            for pi in 0..t.phi_i.len() {
                let r: f64 = t.slice(0, ti, pi).iter().sum();
                assert!(r <= 1.0 + 1e-9 && r > 0.7, "({ti}, {pi}): R {r}");
                for l in 1..4 {
                    assert!(t.slice(l, ti, pi).iter().all(|&m| m == 0.0));
                }
            }
        }
        // Gold at every wall hit reflects less than the lossless walls, everywhere.
        let (eta, k) = gold();
        let law = FresnelLaw::Conductor {
            eta: eta.x as f64,
            k: k.x as f64,
        };
        let g = wall_table(law);
        for (a, b) in g.lobes[0].chunks(64).zip(t.lobes[0].chunks(64)) {
            let (a, b): (f64, f64) = (a.iter().sum(), b.iter().sum());
            assert!(a < b && a > 0.5 * b, "{a} vs {b}");
        }
    }

    /// Non-delta samples' `pdf` and weight match `pdf()` and `eval cos / pdf`; their directions
    /// pass a chi-square test against `pdf`, which integrates to the groove lobes' share `C`.
    #[test]
    fn sampler_matches_pdf() {
        let wt = wall_table(FresnelLaw::None);
        let t = WallLobeTable::new(&wt);
        let (eta, k) = gold();
        for (lobes, lost) in lobe_sets() {
            let b = ScratchedMetalBsdf::new(
                ConductorIor { eta, k },
                Rgb::new(1.0, 0.8, 0.4),
                &t,
                &lobes,
            );
            sampler_matches_pdf_of(Bsdf::ScratchedMetal(b), lost);
        }
    }

    fn sampler_matches_pdf_of(bsdf: Bsdf, lost: f32) {
        assert!(!bsdf.is_delta() && !bsdf.has_transmission());
        let mut outside = wos_outside();
        outside.pop(); // grazing: the chi-square grid cannot resolve its thin lobes
        for (i, wo) in outside.into_iter().enumerate() {
            let mut rng = Pcg64::seed_from_u64(300 + i as u64);
            let (mut bad_pdf, mut bad_weight) = (0, 0);
            let n = 200_000;
            let r = chi2_tilted(
                n,
                12,
                || {
                    let s = bsdf.sample(wo, rng.random(), Vec2::new(rng.random(), rng.random()))?;
                    if s.delta {
                        return None;
                    }
                    let (f, pdf) = bsdf.eval_pdf(wo, s.wi);
                    bad_pdf += !rel_close(s.pdf, pdf, 2e-3) as usize;
                    let expect = f.y * s.wi.z / s.pdf;
                    bad_weight += !rel_close(expect, s.weight.y, 2e-3) as usize;
                    Some(s.wi)
                },
                |wi| bsdf.pdf(wo, wi) as f64,
            );
            assert!(bad_pdf <= n / 10_000, "wo {wo:?}: {bad_pdf} pdfs");
            assert!(bad_weight <= n / 10_000, "wo {wo:?}: {bad_weight} weights");
            assert!(
                r.p_value > 1e-3 && r.pdf_mass < 0.57 && r.pdf_mass > 0.53 - lost as f64,
                "lost {lost} wo {wo:?}: {r:?}"
            );
        }
    }

    /// A white conductor (`F = 1`, lossless walls): the sampled weights average `(1 - C) +
    /// sum_k c_k a_k(wo)` with `a_k` the traced table's albedo at `wo` in lobe `k`'s frame;
    /// the quadrature of `eval cos` gives the groove part alone, independently of the
    /// sampler; a tint scales the groove part only. One-sided: nothing from or to below.
    #[test]
    fn white_conductor_energy_and_eval_normalisation() {
        let wt = wall_table(FresnelLaw::None);
        let t = WallLobeTable::new(&wt);
        let tint = Rgb::new(1.0, 0.5, 0.25);
        let bsdf = Bsdf::ScratchedMetal(ScratchedMetalBsdf::new(white(), tint, &t, &lobes()));
        for (i, wo) in wos_outside().into_iter().enumerate() {
            let groove: f64 = lobes()
                .iter()
                .map(|l| l.coverage as f64 * table_albedo(&wt, l.to_scratch(wo)))
                .sum();
            let a = albedo(&bsdf, wo, 100_000, 500 + i as u64, false);
            let want = 1.0 - 0.55 + groove;
            assert!(
                a[0].agrees_with(want, 4.0, 2e-3),
                "wo {wo:?}: {a:?} vs {want}"
            );
            let blue = 1.0 - 0.55 + 0.25 * groove;
            assert!(
                a[2].agrees_with(blue, 4.0, 2e-3),
                "wo {wo:?}: {a:?} vs {blue}"
            );
            let q: f64 = SphereGrid {
                sub: 8,
                ..SphereGrid::new(100, 200)
            }
            .integrate(|wi| (bsdf.eval(wo, wi).x * wi.z.abs()) as f64)
            .iter()
            .sum();
            assert!((q - groove).abs() < 0.01, "wo {wo:?}: {q} vs {groove}");
            assert!(bsdf.sample(-wo, 0.9, Vec2::splat(0.4)).is_none());
            assert_eq!(bsdf.eval(wo, Vec3::new(wo.x, wo.y, -wo.z)), Rgb::ZERO);
        }
    }
}

/// glTF's metallic-roughness BSDF ([`Pbr`]): chi-square of the mixture sampler, sampled pdf
/// and weight against `pdf` and `eval`, energy over its parameters, and the two limits that
/// must be existing models exactly (all-transmission: the dielectric; white metal: the
/// perfect rough mirror).
mod pbr {
    use super::*;
    use crate::optics::fresnel_f32;
    use std::sync::OnceLock;

    /// The specular layer's albedo table for `eta` 1.5 or 2.4, built once for all the tests.
    fn layer(eta: f32) -> &'static LayerAlbedo {
        static TABLES: OnceLock<[LayerAlbedo; 2]> = OnceLock::new();
        let [a, b] = TABLES.get_or_init(|| [LayerAlbedo::new(1.5), LayerAlbedo::new(2.4)]);
        match eta {
            1.5 => a,
            2.4 => b,
            _ => panic!("no table for eta {eta}"),
        }
    }

    fn pbr(base: Rgb, metallic: f32, transmission: f32, alpha: f32) -> Pbr<'static> {
        Pbr::new(
            base,
            metallic,
            transmission,
            layer(1.5),
            alpha,
            alpha,
            transmission > 0.0 && metallic < 1.0,
        )
    }

    #[test]
    fn sampler_matches_pdf_for_rough_parameter_sets() {
        let sets = [
            ("metal rough", pbr(Rgb::new(0.9, 0.6, 0.3), 1.0, 0.0, 0.3)),
            ("plastic rough", pbr(Rgb::new(0.8, 0.2, 0.1), 0.0, 0.0, 0.2)),
            ("half metal", pbr(Rgb::new(0.5, 0.7, 0.9), 0.5, 0.0, 0.5)),
            ("glass rough", pbr(Rgb::new(1.0, 0.8, 0.5), 0.0, 1.0, 0.3)),
            ("mixed", pbr(Rgb::new(0.7, 0.7, 0.4), 0.3, 0.5, 0.4)),
            (
                "anisotropic metal",
                Pbr::new(Rgb::splat(0.9), 1.0, 0.0, layer(1.5), 0.5, 0.15, false),
            ),
            (
                "anisotropic glass",
                Pbr::new(Rgb::ONE, 0.0, 1.0, layer(1.5), 0.4, 0.15, true),
            ),
        ];
        let mut seed = 9000;
        for (name, b) in sets {
            let bsdf = Bsdf::Pbr(b);
            assert_eq!(bsdf.has_transmission(), b.transmits);
            assert!(!bsdf.is_delta());
            let inside = if b.transmits { wos_inside() } else { vec![] };
            for wo in wos_outside().into_iter().chain(inside) {
                seed += 1;
                // The anisotropic lobes are narrow across: a finer quadrature.
                let sub = if name.starts_with("anisotropic") {
                    24
                } else {
                    0
                };
                check_non_delta_sub(name, &bsdf, wo, 200_000, seed, sub);
            }
        }
    }

    /// The lane vertex's form of the BSDF gives the scalar form's bits: `eval_pdf` with the
    /// layer table read from a copy of two rows ([`LayerRows`]), and `sample_at` against
    /// `sample` (the same numbers as the lane vertex hands them: the cosine lobe's direction
    /// and the visible normal's azimuth made beforehand), rough and smooth, opaque and
    /// transmitting, `wo` outside and inside.
    #[test]
    fn lane_form_equals_the_scalar_bit_for_bit() {
        use crate::optics::microfacet::visible_azimuth;
        use crate::sampling::square_to_cosine_hemisphere;
        fn bits(s: Option<BsdfSample>) -> Option<[u32; 9]> {
            s.map(|s| {
                let [a, b, c] = s.wi.to_array().map(f32::to_bits);
                let [d, e, f] = s.weight.to_array().map(f32::to_bits);
                [
                    a,
                    b,
                    c,
                    d,
                    e,
                    f,
                    s.pdf.to_bits(),
                    s.delta as u32,
                    s.eta.to_bits(),
                ]
            })
        }
        let mut rng = Pcg64::seed_from_u64(77);
        let (mut sampled, mut diffuse, mut refracted, mut from_inside) = (0, 0, 0, 0);
        let (mut delta, mut delta_refracted) = (0, 0);
        for n in 0..80_000 {
            let base = Rgb::new(rng.random(), rng.random(), rng.random());
            // Plastic, metal and mixes; opaque, glass and partly transmitting.
            let metallic = match n % 3 {
                0 => 0.0,
                1 => 1.0,
                _ => rng.random(),
            };
            let transmission = match n % 4 {
                0 | 1 => 0.0,
                2 => 1.0,
                _ => rng.random(),
            };
            // `PbrMaterial::has_transmission`.
            let transmits = transmission > 0.0 && metallic < 1.0;
            // Smooth one time in seven.
            let smooth = n % 7 == 0;
            let alpha_t = rng.random_range(1e-4f32..1.0);
            let alpha_b = if n % 2 == 0 {
                alpha_t
            } else {
                rng.random_range(1e-4f32..1.0)
            };
            let (alpha_t, alpha_b) = if smooth {
                (0.0, 0.0)
            } else {
                (alpha_t, alpha_b)
            };
            let eta = if n % 5 == 0 { 2.4 } else { 1.5 };
            let b = Pbr::new(
                base,
                metallic,
                transmission,
                layer(eta),
                alpha_t,
                alpha_b,
                transmits,
            );
            let rows = LayerRows::of(b.layer, b.layer_node);
            let lane = Pbr {
                layer: &rows,
                base_color: b.base_color,
                metallic: b.metallic,
                transmission: b.transmission,
                eta: b.eta,
                distribution: b.distribution,
                smooth: b.smooth,
                transmits: b.transmits,
                layer_node: b.layer_node,
                diffuse_norm: b.diffuse_norm,
            };
            // Mostly above the surface, some below (where only a transmitting BSDF gives).
            let wo = dir(rng.random_range(0.0..2.2), rng.random_range(0.0..6.3));
            let wi = dir(rng.random_range(0.0..3.2), rng.random_range(0.0..6.3));
            let (f, pdf) = b.eval_pdf(wo, wi);
            let (f_lane, pdf_lane) = lane.eval_pdf(wo, wi);
            assert_eq!(
                f.to_array().map(f32::to_bits),
                f_lane.to_array().map(f32::to_bits)
            );
            assert_eq!(pdf.to_bits(), pdf_lane.to_bits(), "{b:?} {wo} {wi}");
            let (u_lobe, u) = (rng.random(), Vec2::new(rng.random(), rng.random()));
            let s = b.sample(wo, u_lobe, u);
            let cosine_dir = square_to_cosine_hemisphere(u);
            let s_lane = lane.sample_at(wo, u_lobe, cosine_dir, u.x, visible_azimuth(u.y));
            assert_eq!(bits(s), bits(s_lane), "{b:?} {wo} {u_lobe} {u}");
            assert_eq!(b.smooth, smooth);
            sampled += s.is_some() as u32;
            delta += s.is_some_and(|s| s.delta) as u32;
            delta_refracted += s.is_some_and(|s| s.delta && s.wi.z * wo.z < 0.0) as u32;
            diffuse += s.is_some_and(|s| s.wi == cosine_dir) as u32;
            refracted += s.is_some_and(|s| s.wi.z * wo.z < 0.0) as u32;
            from_inside += s.is_some_and(|_| wo.z < 0.0) as u32;
        }
        // Every lobe sampled, from both sides, and some samples refused.
        assert!(
            diffuse > 5_000 && sampled - diffuse - refracted > 5_000,
            "{diffuse} {sampled}"
        );
        assert!(
            refracted > 5_000 && from_inside > 2_000,
            "{refracted} {from_inside}"
        );
        assert!(sampled < 76_000, "{sampled}");
        // The smooth lobes, mirrored and refracted.
        assert!(
            delta - delta_refracted > 2_000 && delta_refracted > 1_000,
            "{delta} {delta_refracted}"
        );
    }

    /// Clear smooth glass (all transmission, no metal, `alpha = 0`), as the lane vertex takes
    /// it: a delta BSDF whose samples are [`Dielectric`]'s bit for bit, the refraction's weight
    /// times the base colour, from outside and from inside (in the surface it gives none).
    #[test]
    fn clear_smooth_glass_samples_as_the_tinted_dielectric_bit_for_bit() {
        let mut rng = Pcg64::seed_from_u64(78);
        let (mut mirrored, mut refracted) = (0, 0);
        for n in 0..20_000 {
            let base = Rgb::new(rng.random(), rng.random(), rng.random());
            let eta = if n % 3 == 0 { 2.4 } else { 1.5 };
            let b = Pbr::new(base, 0.0, 1.0, layer(eta), 0.0, 0.0, true);
            assert!(Bsdf::Pbr(b).is_delta());
            let wo = dir(rng.random_range(0.0..3.1), rng.random_range(0.0..6.3));
            let u_lobe = rng.random();
            let s = b.sample(wo, u_lobe, Vec2::new(rng.random(), rng.random()));
            let d = Dielectric::new(eta).sample(wo, u_lobe).map(|mut d| {
                if d.wi.z * wo.z < 0.0 {
                    d.weight = base * d.weight.x;
                }
                d
            });
            let bits = |s: Option<BsdfSample>| {
                s.map(|s| {
                    let v = [s.wi.to_array(), s.weight.to_array()].concat();
                    let v: Vec<u32> = v.into_iter().map(f32::to_bits).collect();
                    (v, s.pdf.to_bits(), s.delta, s.eta.to_bits())
                })
            };
            assert_eq!(bits(s), bits(d), "{eta} {base} {wo} {u_lobe}");
            let s = s.expect("a smooth interface always samples");
            mirrored += (s.wi.z * wo.z > 0.0) as u32;
            refracted += (s.wi.z * wo.z < 0.0) as u32;
        }
        assert!(
            mirrored > 500 && refracted > 10_000,
            "{mirrored} {refracted}"
        );
        // The one difference, which the lane vertex keeps: `wo` in the surface.
        let b = Pbr::new(Rgb::ONE, 0.0, 1.0, layer(1.5), 0.0, 0.0, true);
        for wo in [Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.6, 0.8, -0.0)] {
            assert!(b.sample(wo, 0.5, Vec2::splat(0.5)).is_none());
            assert!(Dielectric::new(1.5).sample(wo, 0.5).is_some());
        }
    }

    /// Smooth (`alpha = 0`) with a diffuse lobe: the delta reflection and refraction are
    /// chosen with their discrete probabilities, weight times probability is the lobe's
    /// reflectance, and the diffuse samples follow `pdf` (which integrates to their share).
    #[test]
    fn smooth_mixture_delta_lobes_and_diffuse_sampler() {
        let b = pbr(Rgb::new(0.8, 0.5, 0.2), 0.2, 0.4, 0.0);
        let bsdf = Bsdf::Pbr(b);
        assert!(!bsdf.is_delta() && bsdf.has_transmission());
        assert!(Bsdf::Pbr(pbr(Rgb::ONE, 0.0, 1.0, 0.0)).is_delta());
        assert!(Bsdf::Pbr(pbr(Rgb::ONE, 1.0, 0.0, 0.0)).is_delta());
        for (k, wo) in wos_outside().into_iter().enumerate() {
            let mut rng = Pcg64::seed_from_u64(300 + k as u64);
            let fd = fresnel_f32::dielectric(wo.z, 1.5).0;
            let r = ((1.0f32 - wo.z) * 1.0).powi(5);
            let metal = Rgb::new(0.8, 0.5, 0.2) + (Rgb::ONE - Rgb::new(0.8, 0.5, 0.2)) * r;
            let refl = metal * 0.2 + Rgb::splat(0.8 * fd);
            let trans = Rgb::new(0.8, 0.5, 0.2) * (0.8 * 0.4 * (1.0 - fd));
            let mut counts = [0u64; 3];
            let n = 100_000;
            let r = chi2_tilted(
                n,
                8,
                || {
                    let s = bsdf.sample(wo, rng.random(), Vec2::new(rng.random(), rng.random()))?;
                    if s.delta {
                        if s.wi.z > 0.0 {
                            counts[0] += 1;
                            assert!((s.wi - Vec3::new(-wo.x, -wo.y, wo.z)).length() < 1e-5);
                            assert!((s.weight * s.pdf - refl).abs().max_element() < 1e-5);
                        } else {
                            counts[1] += 1;
                            let eta2 = 1.0 / (1.5f32 * 1.5);
                            assert!((s.weight * s.pdf - trans * eta2).abs().max_element() < 1e-5);
                        }
                        return None;
                    }
                    counts[2] += 1;
                    assert!(rel_close(s.pdf, bsdf.pdf(wo, s.wi), 1e-4));
                    let w = bsdf.eval(wo, s.wi) * s.wi.z / s.pdf;
                    assert!((w - s.weight).abs().max_element() < 1e-4);
                    Some(s.wi)
                },
                |wi| bsdf.pdf(wo, wi) as f64,
            );
            assert!(r.p_value > 1e-3, "wo {wo:?}: {r:?}");
            // The lobes are chosen in proportion to their weights at wo.
            let mean = |c: Rgb| (c.x + c.y + c.z) / 3.0;
            let w_d = 0.8 * 0.6 * (1.0 - fd) * mean(Rgb::new(0.8, 0.5, 0.2));
            let w_m = 0.2 * mean(metal) + 0.8 * (fd + 0.4 * (1.0 - fd));
            let p_d = (w_d / (w_d + w_m)) as f64;
            let rho = (mean(metal) * 0.2 + 0.8 * fd)
                / (mean(metal) * 0.2 + 0.8 * fd + 0.8 * 0.4 * (1.0 - fd));
            let expected = [
                (1.0 - p_d) * rho as f64 * n as f64,
                (1.0 - p_d) * (1.0 - rho as f64) * n as f64,
                p_d * n as f64,
            ];
            let d = chi2_discrete(&counts, &expected);
            assert!(d.p_value > 1e-3, "wo {wo:?}: {counts:?} vs {expected:?}");
        }
    }

    /// Energy: the directional albedo (radiance factor undone) is at most 1 over metallic,
    /// transmission and roughness, for white and coloured bases and two IORs; all-metal white
    /// and all-glass white smooth surfaces are lossless (white furnace), rough ones lose only
    /// what single scattering loses.
    #[test]
    fn albedo_is_at_most_one_for_all_parameters() {
        let mut seed = 12_000;
        for ior in [1.5f32, 2.4] {
            for metallic in [0.0f32, 0.5, 1.0] {
                for transmission in [0.0f32, 0.5, 1.0] {
                    for roughness in [0.0f32, 0.3, 0.7, 1.0] {
                        let alpha = roughness * roughness;
                        let b = Pbr::new(
                            Rgb::ONE,
                            metallic,
                            transmission,
                            layer(ior),
                            alpha,
                            alpha,
                            transmission > 0.0 && metallic < 1.0,
                        );
                        let bsdf = Bsdf::Pbr(b);
                        let inside = if b.transmits { wos_inside() } else { vec![] };
                        for wo in wos_outside().into_iter().chain(inside) {
                            seed += 1;
                            let a = albedo(&bsdf, wo, 20_000, seed, true);
                            let m = a[0].mean();
                            let what = format!(
                                "ior {ior} metallic {metallic} transmission {transmission} roughness {roughness} wo {wo:?}"
                            );
                            assert!(m <= 1.0 + 4.0 * a[0].std_error() + 1e-4, "{what}: {m}");
                            let lossless = roughness == 0.0
                                && (metallic == 1.0 || (transmission == 1.0 && metallic == 0.0));
                            if lossless {
                                assert!((m - 1.0).abs() < 1e-4, "{what}: {m}");
                            }
                            // White plastic of IOR 1.5 seen above 45 degrees keeps most of the
                            // light (at IOR 2.4 its Fresnel reflection inside loses more).
                            if ior == 1.5 && metallic == 0.0 && transmission == 0.0 && wo.z > 0.7 {
                                assert!(m > 0.8, "{what}: {m}");
                            }
                        }
                    }
                }
            }
        }
    }

    /// `metallic = 1`, white base: Schlick's Fresnel is 1, so the BSDF is the rough perfect
    /// mirror (`RoughConductor` with `eta = 0, k = 1`), its values and its single-scattering
    /// albedo.
    #[test]
    fn white_metal_is_the_rough_perfect_mirror() {
        let mut rng = Pcg64::seed_from_u64(77);
        for alpha in [0.05f32, 0.3, 0.8] {
            let p = pbr(Rgb::ONE, 1.0, 0.0, alpha);
            let c = RoughConductor::new(Rgb::ZERO, Rgb::ONE, alpha);
            for _ in 0..2000 {
                let wo = dir(
                    rng.random::<f32>() * 1.5,
                    rng.random::<f32>() * std::f32::consts::TAU,
                );
                let wi = dir(
                    rng.random::<f32>() * 1.5,
                    rng.random::<f32>() * std::f32::consts::TAU,
                );
                let (fp, pp) = p.eval_pdf(wo, wi);
                let (fc, pc) = c.eval_pdf(wo, wi);
                assert!(rel_close(pp, pc, 1e-5), "{pp} vs {pc}");
                for k in 0..3 {
                    assert!(rel_close(fp[k], fc[k], 1e-5), "{fp} vs {fc}");
                }
            }
            for wo in wos_outside() {
                let a = albedo(&Bsdf::Pbr(p), wo, 50_000, 5, false)[0];
                let b = albedo(&Bsdf::RoughConductor(c), wo, 50_000, 5, false)[0];
                assert!(
                    (a.mean() - b.mean()).abs() < 1e-4,
                    "{} vs {}",
                    a.mean(),
                    b.mean()
                );
            }
        }
    }

    /// `metallic = 0, transmission = 1`: the dielectric, its refracted part tinted by the base
    /// colour; `eval` and `pdf` equal [`RoughDielectric`]'s within 1e-6 (relative) from both
    /// sides, and the smooth one samples as [`Dielectric`] does.
    #[test]
    fn all_transmission_is_the_dielectric_tinted() {
        let base = Rgb::new(1.0, 0.6, 0.3);
        let mut rng = Pcg64::seed_from_u64(78);
        for alpha in [0.05f32, 0.3, 0.9] {
            let p = pbr(base, 0.0, 1.0, alpha);
            let d = RoughDielectric::new(1.5, alpha);
            let mut compared = 0;
            for _ in 0..4000 {
                let wo = dir(
                    rng.random::<f32>() * std::f32::consts::PI,
                    rng.random::<f32>() * std::f32::consts::TAU,
                );
                let wi = dir(
                    rng.random::<f32>() * std::f32::consts::PI,
                    rng.random::<f32>() * std::f32::consts::TAU,
                );
                let (fp, pp) = p.eval_pdf(wo, wi);
                let (fd, pd) = d.eval_pdf(wo, wi);
                assert!(rel_close(pp, pd, 1e-6), "pdf {pp} vs {pd}");
                let tint = if wo.z * wi.z < 0.0 { base } else { Rgb::ONE };
                for k in 0..3 {
                    assert!(rel_close(fp[k], fd[k] * tint[k], 1e-6), "{fp} vs {fd}");
                }
                compared += (pd > 0.0) as u32;
            }
            assert!(compared > 1000);
        }
        let p = Bsdf::Pbr(pbr(base, 0.0, 1.0, 0.0));
        let d = Bsdf::Dielectric(Dielectric::new(1.5));
        for wo in wos_outside().into_iter().chain(wos_inside()) {
            for u in [0.01f32, 0.03, 0.2, 0.5, 0.99] {
                let (a, b) = (p.sample(wo, u, Vec2::ZERO), d.sample(wo, u, Vec2::ZERO));
                let (a, b) = (a.unwrap(), b.unwrap());
                assert_eq!((a.wi, a.pdf, a.delta, a.eta), (b.wi, b.pdf, b.delta, b.eta));
                let tint = if a.wi.z * wo.z < 0.0 { base } else { Rgb::ONE };
                assert!((a.weight - b.weight * tint).abs().max_element() < 1e-6);
            }
        }
    }

    /// The specular layer's albedo table: at `alpha = 0` it is the exact Fresnel reflectance
    /// `F(mu)` and its average `F_avg`; at `alpha > 0` it matches a Monte Carlo estimate of the
    /// reflection lobe alone (a black base: no diffuse lobe).
    #[test]
    fn layer_albedo_is_fresnel_when_smooth_and_the_reflection_lobe_when_rough() {
        for eta in [1.5f32, 2.4] {
            let t = layer(eta);
            for j in 0..=200 {
                let mu = j as f32 / 200.0;
                let f = fresnel::dielectric(mu as f64, eta as f64).r;
                assert!(
                    (t.eval(mu, 0.0) as f64 - f).abs() < 1e-4,
                    "eta {eta} mu {mu}: {} vs {f}",
                    t.eval(mu, 0.0)
                );
            }
            let n = 100_000;
            let f_avg: f64 = (0..n)
                .map(|j| {
                    let mu = (j as f64 + 0.5) / n as f64;
                    2.0 * fresnel::dielectric(mu, eta as f64).r * mu
                })
                .sum::<f64>()
                / n as f64;
            assert!(
                (t.average(0.0) as f64 - f_avg).abs() < 1e-4,
                "eta {eta}: {} vs {f_avg}",
                t.average(0.0)
            );
        }
        let mut seed = 14_000;
        for alpha in [0.1f32, 0.25, 0.4, 0.64, 1.0] {
            let b = pbr(Rgb::ZERO, 0.0, 0.0, alpha);
            for wo in wos_outside() {
                seed += 1;
                let a = albedo(&Bsdf::Pbr(b), wo, 200_000, seed, false)[0];
                let e = layer(1.5).eval(wo.z, alpha) as f64;
                assert!(
                    (a.mean() - e).abs() < 4.0 * a.std_error() + 3e-3,
                    "alpha {alpha} wo {wo:?}: table {e} vs sampled {a:?}"
                );
            }
        }
    }

    /// Reciprocal albedo scaling: a white base under the non-transmitting dielectric layer
    /// reflects `E(mu_o)` specularly and `1 - E(mu_o)` diffusely, so its albedo is 1 (up to the
    /// table's error against the lobe it tabulates, a few 1e-3 at most): the diffuse lobe makes
    /// up exactly what the specular layer does not reflect, at every roughness.
    #[test]
    fn white_plastic_albedo_is_one_at_every_roughness() {
        let mut seed = 15_000;
        for alpha in [0.0f32, 0.1, 0.4, 1.0] {
            let b = pbr(Rgb::ONE, 0.0, 0.0, alpha);
            let wos = wos_outside()
                .into_iter()
                .chain([dir(0.3, 0.5), dir(1.5, 0.5)]);
            for wo in wos {
                seed += 1;
                let a = albedo(&Bsdf::Pbr(b), wo, 200_000, seed, false)[0];
                let tol = if alpha == 0.0 {
                    1e-3
                } else {
                    4.0 * a.std_error() + 3e-3
                };
                assert!(
                    (a.mean() - 1.0).abs() < tol,
                    "alpha {alpha} wo {wo:?}: {a:?}"
                );
            }
        }
        // Smooth, `eval` is the diffuse lobe alone: its albedo by quadrature is `1 - F(mu_o)`.
        let b = pbr(Rgb::ONE, 0.0, 0.0, 0.0);
        for wo in wos_outside() {
            let q: f64 = SphereGrid::new(200, 8)
                .integrate(|wi| (b.eval(wo, wi).x * wi.z.abs()) as f64)
                .iter()
                .sum();
            let e = fresnel_f32::dielectric(wo.z, 1.5).0 as f64;
            assert!(
                (q - (1.0 - e)).abs() < 1e-3,
                "wo {wo:?}: {q} vs {}",
                1.0 - e
            );
        }
    }
}
