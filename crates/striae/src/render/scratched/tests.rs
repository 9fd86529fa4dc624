//! Tests of the scratched BSDF and material: chi-square of the non-delta part at several `wo`
//! (grazing included) with `pdf` and weight consistency, the delta parts' probabilities and
//! weights against independently integrated albedos, energy (BSDF-level furnaces), the
//! mirror-wall delta lobe, layer choice and frames, key validation, and the table cache.

use super::*;
use crate::layers::LayerParams;
use crate::math::{Frame, RayDifferential, Vec2};
use crate::optics::fresnel::FresnelLaw;
use crate::precompute::profile::Profile;
use crate::precompute::table::{ScratchTable, TableParams};
use crate::precompute::trace2d::{FresnelMode, TraceSettings, Walls};
use crate::render::bsdf::{BsdfSample, ConductorIor};
use crate::testing::{chi2_discrete, chi2_sphere, MeanEstimate, SphereGrid};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;
use std::f64::consts::{FRAC_PI_2, PI};
use std::ops::Add;

fn table(profile: &str, walls: Walls, law: FresnelLaw, m: usize) -> Arc<ScratchLobeTable> {
    let trace = TraceSettings {
        walls,
        m,
        n: 800,
        nr: 8,
        seed: 4,
        fresnel_mode: FresnelMode::Seed,
        fresnel_law: law,
        ..TraceSettings::default()
    };
    lobe_table(profile, trace)
}

fn lobe_table(profile: &str, trace: TraceSettings) -> Arc<ScratchLobeTable> {
    let t = ScratchTable::compute(
        &TableParams::new(Profile::parse(profile).unwrap(), trace),
        &|_| {},
    )
    .unwrap();
    Arc::new(ScratchLobeTable::new(t))
}

/// A `fresnel = "walls"` table with 3 exact-groove slices (`groove_slices = 3`).
fn groove(profile: &str, law: FresnelLaw) -> Arc<ScratchLobeTable> {
    let trace = TraceSettings {
        walls: Walls::Diffuse,
        m: 24,
        n: 1600,
        nr: 4,
        seed: 4,
        fresnel_mode: FresnelMode::Walls,
        fresnel_law: law,
        groove_slices: 3,
        ..TraceSettings::default()
    };
    lobe_table(profile, trace)
}

fn groove_schlick() -> Arc<ScratchLobeTable> {
    groove("round:depth=0.4", FresnelLaw::Schlick { n: 1.5 })
}

fn groove_lossless() -> Arc<ScratchLobeTable> {
    groove("v:angle=100", FresnelLaw::None)
}

fn lossless_diffuse() -> Arc<ScratchLobeTable> {
    table("v:angle=100", Walls::Diffuse, FresnelLaw::None, 24)
}

fn schlick_diffuse() -> Arc<ScratchLobeTable> {
    table(
        "round:depth=0.4",
        Walls::Diffuse,
        FresnelLaw::Schlick { n: 1.5 },
        24,
    )
}

/// The `F = 1` conductor (`preset = "none"`).
fn perfect_mirror() -> ConductorIor {
    ConductorIor {
        eta: Rgb::ZERO,
        k: Rgb::ONE,
    }
}

fn dir(theta_deg: f32, phi_deg: f32) -> Vec3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

/// Outgoing directions: normal, oblique, grazing (88 degrees), several azimuths.
fn wos() -> Vec<Vec3> {
    vec![
        dir(0.0, 0.0),
        dir(35.0, 20.0),
        dir(60.0, 200.0),
        dir(88.0, 110.0),
    ]
}

fn lobe(c: f32, beta: f32) -> ScratchLobe {
    ScratchLobe::new(c, beta.cos(), beta.sin())
}

/// `integral f_s cos dwi` of one lobe by quadrature over the scratch frame's `(theta, phi)`,
/// independent of the albedo table.
fn albedo_by_quadrature(t: &ScratchLobeTable, wo_scratch: Vec3) -> f64 {
    let n = 256;
    let mut sum = 0.0;
    for a in 0..n {
        let th = -FRAC_PI_2 + (a as f64 + 0.5) * PI / n as f64;
        for b in 0..n {
            let ph = -FRAC_PI_2 + (b as f64 + 0.5) * PI / n as f64;
            let wi = Vec3::new(
                (th.cos() * ph.sin()) as f32,
                th.sin() as f32,
                (th.cos() * ph.cos()) as f32,
            );
            sum += t.brdf().eval(wo_scratch, wi) * wi.z as f64 * th.cos() * (PI / n as f64).powi(2);
        }
    }
    sum
}

fn sample(b: &ScratchedBsdf, wo: Vec3, rng: &mut Pcg64) -> Option<BsdfSample> {
    b.sample(wo, rng.random(), Vec2::new(rng.random(), rng.random()))
}

#[test]
fn albedo_table_matches_quadrature() {
    for t in [
        lossless_diffuse(),
        schlick_diffuse(),
        groove_schlick(),
        groove_lossless(),
    ] {
        for wo in wos() {
            let a = t.albedo(wo) as f64;
            let q = albedo_by_quadrature(&t, wo);
            assert!(
                (a - q).abs() < 0.01 * q.max(0.02),
                "{wo:?}: table {a} vs quadrature {q}"
            );
        }
    }
    // Lossless walls keep (almost) everything; Schlick glass at normal incidence about 4 %.
    assert!(lossless_diffuse().albedo(Vec3::Z) > 0.97);
    assert!(groove_lossless().albedo(Vec3::Z) > 0.97);
    // Where the noisy table's column sum exceeds 1 the lobe is scaled down to albedo 1.
    let t = lossless_diffuse();
    let b = ScratchedBsdf::new(
        ScratchedBase::Metal {
            ior: perfect_mirror(),
        },
        &t,
        Rgb::ONE,
        &[lobe(1.0, 0.0)],
    );
    for wo in wos() {
        let n = 200;
        let mut q = 0.0;
        for a in 0..n {
            let th = -FRAC_PI_2 + (a as f64 + 0.5) * PI / n as f64;
            for c in 0..n {
                let ph = -FRAC_PI_2 + (c as f64 + 0.5) * PI / n as f64;
                let wi = Vec3::new(
                    (th.cos() * ph.sin()) as f32,
                    th.sin() as f32,
                    (th.cos() * ph.cos()) as f32,
                );
                q += b.eval(wo, wi).x as f64 * wi.z as f64 * th.cos() * (PI / n as f64).powi(2);
            }
        }
        assert!(q <= 1.0 + 2e-3, "{wo:?}: {q}");
    }
    let a = schlick_diffuse().albedo(Vec3::Z);
    assert!(a > 0.03 && a < 0.05, "{a}");
}

#[test]
fn nondelta_sampler_chi2_pdf_and_weight() {
    // The seed's eq. (3) and the exact-groove slices (a function of theta_i).
    for t in [lossless_diffuse(), groove_schlick()] {
        nondelta_sampler_chi2(&t);
    }
}

fn nondelta_sampler_chi2(t: &ScratchLobeTable) {
    let grid = SphereGrid::new(24, 48);
    let mut rng = Pcg64::seed_from_u64(21);
    let glass = ScratchedBase::Glass { eta: 1.5 };
    let metal = ScratchedBase::Metal {
        ior: perfect_mirror(),
    };
    let cases: Vec<(ScratchedBase, Vec<ScratchLobe>)> = vec![
        (glass, vec![lobe(0.7, 0.6)]),
        (glass, vec![lobe(0.3, 0.2), lobe(0.5, 2.1)]), // sum mode: two lobes, two frames
        (metal, vec![lobe(0.8, -1.0)]),
        // Leaned frames (`lean = true`), one lobe and two.
        (glass, vec![lobe(0.7, 0.6).leaned(0.2)]),
        (
            metal,
            vec![lobe(0.3, 0.2).leaned(-0.25), lobe(0.5, 2.1).leaned(0.1)],
        ),
    ];
    for (base, lobes) in &cases {
        let leaned = lobes.iter().any(|l| l.lean != 0.0);
        // A lean cuts the cells at the surface's horizon: finer quadrature finds their slivers.
        let grid = SphereGrid {
            sub: if leaned { 32 } else { grid.sub },
            ..grid
        };
        let b = ScratchedBsdf::new(*base, t, Rgb::ONE, lobes);
        assert!(!b.is_delta());
        for wo in wos() {
            let (mut mismatch, mut bad_weight) = (0, 0);
            let r = chi2_sphere(
                &grid,
                120_000,
                || {
                    let s = sample(&b, wo, &mut rng)?;
                    if s.delta {
                        return None;
                    }
                    let p = b.pdf(wo, s.wi);
                    let (fe, pe) = b.eval_pdf(wo, s.wi);
                    assert!(
                        (pe - p).abs() <= 1e-6 * p
                            && (fe - b.eval(wo, s.wi)).abs().max_element()
                                <= 1e-6 * fe.max_element()
                    );
                    if (p - s.pdf).abs() > 1e-3 * p {
                        mismatch += 1;
                    }
                    let w = b.eval(wo, s.wi) * s.wi.z / p;
                    if (w - s.weight).abs().max_element() > 1e-3 * w.max_element() {
                        bad_weight += 1;
                    }
                    Some(s.wi)
                },
                |w| b.pdf(wo, w) as f64,
            );
            assert_eq!((mismatch, bad_weight), (0, 0), "{base:?} {wo:?}");
            assert!(r.p_value > 1e-3, "{base:?} {wo:?}: {r:?}");
            // The pdf integrates to the non-delta part's probability, sum_k c_k a_k (glass) or
            // sum_k c_k (metal); a leaned lobe loses the part of its lobe that the lean puts
            // below the surface (a few per cent at most at these angles, more at grazing `wo`).
            let expect: f64 = lobes
                .iter()
                .map(|l| {
                    l.coverage as f64
                        * if matches!(base, ScratchedBase::Glass { .. }) {
                            t.scaled_albedo(l.wo_to_scratch(wo)).0 as f64
                        } else {
                            1.0
                        }
                })
                .sum();
            let lost = if !leaned {
                0.0
            } else if wo.z > 0.1 {
                0.06 * expect
            } else {
                0.5 * expect
            };
            assert!(
                r.pdf_mass < expect + 0.01 && r.pdf_mass > expect - lost - 0.01,
                "{base:?} {wo:?}: {} vs {expect}",
                r.pdf_mass
            );
        }
    }
}

#[test]
fn glass_delta_choices_weights_and_energy() {
    // Schlick-glass scratches: the lobe probabilities against (1 - C) F, sum c a (albedo by
    // quadrature, independent of the table's) and the rest; weights 1 and 1 / eta^2; energy 1.
    // The seed's eq. (3) and the exact-groove slices.
    for t in [schlick_diffuse(), groove_schlick()] {
        glass_delta_choices(&t);
    }
}

fn glass_delta_choices(t: &ScratchLobeTable) {
    let eta = 1.5f32;
    let lobes = [lobe(0.35, 0.4), lobe(0.25, -1.3)];
    let b = ScratchedBsdf::new(ScratchedBase::Glass { eta }, t, Rgb::ONE, &lobes);
    assert!(b.has_transmission());
    let mut rng = Pcg64::seed_from_u64(22);
    for wo in wos() {
        let f = crate::optics::fresnel::dielectric(wo.z as f64, eta as f64).r;
        let p_reflect = (1.0 - 0.6) * f;
        let p_scatter: f64 = lobes
            .iter()
            .map(|l| l.coverage as f64 * albedo_by_quadrature(t, l.to_scratch(wo)))
            .sum();
        let expected = [p_reflect, 1.0 - p_reflect - p_scatter, p_scatter];
        let n = 200_000;
        let mut counts = [0u64; 3];
        let mut energy = MeanEstimate::default();
        for _ in 0..n {
            let s = sample(&b, wo, &mut rng).unwrap();
            let kind = if !s.delta {
                assert!(s.wi.z > 0.0);
                2
            } else if s.wi.z > 0.0 {
                assert!((s.wi - crate::math::reflect_z(wo)).length() < 1e-5);
                assert_eq!(s.weight, Rgb::ONE);
                0
            } else {
                assert!((s.weight.x - 1.0 / (eta * eta)).abs() < 1e-6);
                assert!((s.eta - eta).abs() < 1e-6);
                // Snell: the tangential component shrinks by 1 / eta.
                assert!((s.wi.x + wo.x / eta).abs() < 1e-5 && (s.wi.y + wo.y / eta).abs() < 1e-5);
                1
            };
            counts[kind] += 1;
            // Undo the radiance scaling of refraction: what remains is the energy.
            energy.push((s.weight.x * if kind == 1 { eta * eta } else { 1.0 }) as f64);
        }
        let exp: Vec<f64> = expected.iter().map(|p| p * n as f64).collect();
        let r = chi2_discrete(&counts, &exp);
        assert!(r.p_value > 1e-3, "{wo:?}: {counts:?} vs {exp:?} ({r:?})");
        assert!(
            energy.agrees_with(1.0, 4.0, 1e-3),
            "{wo:?}: energy {} +- {}",
            energy.mean(),
            energy.std_error()
        );
    }
    // From inside the scratched point is the smooth dielectric.
    let inside = Vec3::new(0.3, 0.1, -0.9).normalize();
    assert_eq!(b.eval(inside, Vec3::new(0.0, 0.0, 1.0)), Rgb::ZERO);
    assert_eq!(b.pdf(inside, Vec3::new(0.0, 0.0, -1.0)), 0.0);
    for _ in 0..100 {
        assert!(sample(&b, inside, &mut rng).unwrap().delta);
    }
}

#[test]
fn metal_energy_is_base_plus_scratch_albedo() {
    // F = 1 mirror base: E[weight] = (1 - C) + sum c_k a_k with a_k by quadrature (about 1:
    // the lossless walls keep everything but the bounce cap's share), for the seed's eq. (3)
    // and the exact-groove slices.
    for t in [lossless_diffuse(), groove_lossless()] {
        metal_energy(&t);
    }
}

fn metal_energy(t: &ScratchLobeTable) {
    let lobes = [lobe(0.5, 0.9)];
    let none = perfect_mirror();
    let b = ScratchedBsdf::new(ScratchedBase::Metal { ior: none }, t, Rgb::ONE, &lobes);
    assert!(!b.has_transmission());
    let mut rng = Pcg64::seed_from_u64(23);
    for wo in wos() {
        let expect = 0.5 + 0.5 * albedo_by_quadrature(t, lobes[0].to_scratch(wo)).min(1.0);
        let mut e = MeanEstimate::default();
        for _ in 0..100_000 {
            e.push(sample(&b, wo, &mut rng).map_or(0.0, |s| s.weight.x as f64));
        }
        assert!(
            e.agrees_with(expect, 4.0, 2e-3),
            "{wo:?}: {} vs {expect}",
            e.mean()
        );
        assert!(expect > 0.98);
    }
    // Below the surface nothing is sampled.
    assert!(b
        .sample(Vec3::new(0.0, 0.0, -1.0), 0.5, Vec2::splat(0.5))
        .is_none());
}

#[test]
fn mirror_walls_give_a_delta_in_theta() {
    let t = table("round:depth=0.35", Walls::Specular, FresnelLaw::None, 32);
    for l in [lobe(0.6, 0.8), lobe(0.6, 0.8).leaned(0.15)] {
        mirror_walls_delta(&t, l);
    }
}

fn mirror_walls_delta(t: &ScratchLobeTable, l: ScratchLobe) {
    let none = perfect_mirror();
    let b = ScratchedBsdf::new(ScratchedBase::Metal { ior: none }, t, Rgb::ONE, &[l]);
    assert!(b.is_delta());
    let mut rng = Pcg64::seed_from_u64(24);
    // Not the grazing `wo`: a leaned frame loses part of its lobe below the surface there.
    for wo in wos().into_iter().filter(|w| w.z > 0.1) {
        assert_eq!(b.eval(wo, dir(10.0, 30.0)), Rgb::ZERO);
        assert_eq!(b.pdf(wo, dir(10.0, 30.0)), 0.0);
        let wo_s = l.to_scratch(wo);
        let mut scratch = 0;
        let mut e = MeanEstimate::default();
        for _ in 0..50_000 {
            let Some(s) = sample(&b, wo, &mut rng) else {
                // (A leaned lobe's exit below the surface: no sample.)
                assert!(l.lean != 0.0);
                e.push(0.0);
                scratch += 1;
                continue;
            };
            assert!(s.delta);
            e.push(s.weight.x as f64);
            if (s.wi - crate::math::reflect_z(wo)).length() > 1e-4 {
                scratch += 1;
                let wi_s = l.to_scratch(s.wi);
                // theta_i = -theta_o: the component along the scratch flips sign.
                assert!((wi_s.y + wo_s.y).abs() < 1e-4, "{wi_s:?} {wo_s:?}");
            }
        }
        assert!((scratch as f64 / 50_000.0 - 0.6).abs() < 0.02);
        // Energy: (1 - c) + c sum of the delta terms (lossless mirror walls: about 1; a column
        // sum above 1, from the binning, is scaled back to 1). A lean puts some exits below
        // the surface: the terms whose whole `phi` bin lies above it at least, those with any
        // part above at most.
        let half = PI / (2.0 * t.table().m as f64);
        let above = |d: &crate::precompute::table::DeltaTerm, dphi: f64| {
            let (sin, cos) = (d.wi.x as f64).atan2(d.wi.z as f64).add(dphi).sin_cos();
            let c = (1.0 - (d.wi.y as f64).powi(2)).sqrt();
            let w = Vec3::new((c * sin) as f32, d.wi.y, (c * cos) as f32);
            l.from_scratch(w).z > 0.0
        };
        let terms = t.brdf().delta_terms(wo_s);
        let sum = |keep: &dyn Fn(&crate::precompute::table::DeltaTerm) -> bool| {
            let s: f64 = terms.iter().filter(|d| keep(d)).map(|d| d.value).sum();
            0.4 + 0.6 * s.min(1.0)
        };
        let lo = sum(&|d| above(d, -half) && above(d, half));
        let hi = sum(&|d| above(d, -half) || above(d, half));
        let tol = 4.0 * e.std_error() + 3e-3;
        assert!(
            e.mean() > lo - tol && e.mean() < hi + tol,
            "{} vs {lo}..{hi}",
            e.mean()
        );
        assert!(lo > 0.7, "{lo}");
        if l.lean == 0.0 {
            assert_eq!(lo, hi);
        }
    }
}

/// Smooth glass walls of index 1.5 in `profile`, from a coarse table (the ridge tests read
/// only whether a lobe is there).
fn coarse_glass_walls(profile: &Profile) -> GlassWalls {
    use crate::precompute::wall_table::{WallTable, WallTableParams};
    let table = WallTable::compute(&WallTableParams {
        theta_bins: 2,
        phi_bins: 2,
        bins: 4,
        paths: 200,
        ..WallTableParams::new(profile.clone(), 1.5, 0.0)
    })
    .unwrap();
    GlassWalls::Table(Arc::new(WallLobeTable::new(&table)))
}

/// The material's BSDF at `ctx`, with a cache of its own.
fn bsdf_of<'a>(m: &'a ScratchedMaterial, ctx: &ShadingContext) -> Bsdf<'a> {
    m.bsdf(ctx, &mut CoverageCache::new())
}

fn wide_layers(k: usize, seed: u64) -> LayerSet {
    LayerSet::new(
        LayerParams {
            length: 0.3,
            width: 0.05,
            threshold: 0.3,
            layers: k,
        },
        seed,
    )
    .unwrap()
}

/// A hit on the plane `z = 0` with `dP/du = x`, `dP/dv = y`, whose ray differentials (offset
/// rays parallel to the central one, `footprint` apart) give `duvdx = (footprint, 0)`,
/// `duvdy = (0, footprint)` exactly.
fn flat_ctx(uv: Vec2, footprint: f32, wo: Vec3, u_layer: f32) -> ShadingContext {
    ShadingContext {
        pixel: None,
        origin_depth: f32::INFINITY,
        p: Vec3::ZERO,
        uv,
        rd: Some(RayDifferential {
            rx_o: Vec3::new(footprint, 0.0, 1.0),
            rx_d: -Vec3::Z,
            ry_o: Vec3::new(0.0, footprint, 1.0),
            ry_d: -Vec3::Z,
        }),
        dpdu: Vec3::X,
        dpdv: Vec3::Y,
        frame: Frame {
            s: Vec3::X,
            t: Vec3::Y,
            n: Vec3::Z,
        },
        ng: Vec3::Z,
        u_layer,
        wo,
    }
}

#[test]
fn layer_choice_frames_and_ties() {
    let t = lossless_diffuse();
    let layers = wide_layers(4, 7);
    let m = ScratchedMaterial::new(
        ScratchedBase::Glass { eta: 1.5 },
        Rgb::ONE,
        t.clone(),
        layers.clone(),
        LayerMix::Max,
        CoverageMode::Footprint,
    );
    let sum = ScratchedMaterial::new(
        ScratchedBase::Glass { eta: 1.5 },
        Rgb::ONE,
        t,
        layers.clone(),
        LayerMix::Sum,
        CoverageMode::Footprint,
    );
    let mut rng = Pcg64::seed_from_u64(25);
    let (mut plain, mut scratched, mut ties_seen) = (0, 0, 0);
    for _ in 0..4000 {
        let uv = Vec2::new(rng.random(), rng.random());
        let mask = layers.scratched_mask(uv);
        // A point footprint: coverage is 1 in every layer whose scratch holds the point.
        match bsdf_of(&m, &flat_ctx(uv, 0.0, Vec3::Z, 0.5)) {
            Bsdf::Dielectric(_) => {
                assert_eq!(mask, 0, "{uv:?}");
                plain += 1;
            }
            Bsdf::Scratched(b) => {
                assert_ne!(mask, 0);
                scratched += 1;
                assert_eq!(b.lobes().len(), 1);
                let l = b.lobes()[0];
                assert_eq!(l.coverage, 1.0);
                // The lobe's t is the direction of one of the covering layers (flat frame:
                // dP/du = x, dP/dv = y).
                assert!((0..4).any(|k| mask & (1 << k) != 0 && {
                    let d = layers.direction(k);
                    (l.cos - d[0] as f32).abs() < 1e-5 && (l.sin - d[1] as f32).abs() < 1e-5
                }));
                if mask.count_ones() >= 2 {
                    ties_seen += 1;
                    // Every covering layer is chosen for some u_layer, and only those.
                    let mut chosen = 0u64;
                    for i in 0..64 {
                        let Bsdf::Scratched(b) =
                            bsdf_of(&m, &flat_ctx(uv, 0.0, Vec3::Z, (i as f32 + 0.5) / 64.0))
                        else {
                            panic!()
                        };
                        let l = b.lobes()[0];
                        let k = (0..4).find(|&k| {
                            let d = layers.direction(k);
                            (l.cos - d[0] as f32).abs() < 1e-5 && (l.sin - d[1] as f32).abs() < 1e-5
                        });
                        chosen |= 1 << k.unwrap();
                    }
                    assert_eq!(chosen, mask);
                    // Sum mode combines them all, normalised to a total of 1.
                    let Bsdf::Scratched(b) = bsdf_of(&sum, &flat_ctx(uv, 0.0, Vec3::Z, 0.5)) else {
                        panic!()
                    };
                    assert_eq!(b.lobes().len(), mask.count_ones() as usize);
                    assert!((b.total_coverage() - 1.0).abs() < 1e-6);
                }
                // Seen from inside, the same point is smooth glass.
                assert!(matches!(
                    bsdf_of(&m, &flat_ctx(uv, 0.0, -Vec3::Z, 0.5)),
                    Bsdf::Dielectric(_)
                ));
            }
            other => panic!("{other:?}"),
        }
    }
    assert!(
        plain > 100 && scratched > 100 && ties_seen > 5,
        "{plain} {scratched} {ties_seen}"
    );
    // Point coverage: the scratch test at the hit, whatever the footprint (the same choice as a
    // zero footprint).
    let point = ScratchedMaterial::new(
        ScratchedBase::Glass { eta: 1.5 },
        Rgb::ONE,
        lossless_diffuse(),
        layers.clone(),
        LayerMix::Max,
        CoverageMode::Point,
    );
    for _ in 0..500 {
        let uv = Vec2::new(rng.random(), rng.random());
        let u = rng.random::<f32>();
        let a = bsdf_of(&point, &flat_ctx(uv, 0.05, Vec3::Z, u));
        let b = bsdf_of(&m, &flat_ctx(uv, 0.0, Vec3::Z, u));
        match (a, b) {
            (Bsdf::Dielectric(_), Bsdf::Dielectric(_)) => {}
            (Bsdf::Scratched(a), Bsdf::Scratched(b)) => assert_eq!(a.lobes(), b.lobes()),
            (a, b) => panic!("{a:?} vs {b:?}"),
        }
    }
    // A footprint: the chosen coverage is the largest of the layers' exact coverages of the
    // footprint tile holding the hit (`layers::lattice`).
    for _ in 0..300 {
        let uv = Vec2::new(rng.random(), rng.random());
        let mut cov = [0.0f32; 4];
        let (dx, dy) = (Vec2::new(0.02, 0.0), Vec2::new(0.0, 0.02));
        let tile = crate::layers::lattice::FootprintTile::containing(uv, dx, dy).unwrap();
        let (c, a, b) = (tile.centre.as_vec2(), tile.a.as_vec2(), tile.b.as_vec2());
        layers.coverage_all_within(c, a, b, crate::layers::lattice::TILE_MAX_CELLS, &mut cov);
        let best = cov.iter().copied().fold(0.0, f32::max);
        match bsdf_of(&m, &flat_ctx(uv, 0.02, Vec3::Z, 0.3)) {
            Bsdf::Scratched(b) => assert_eq!(b.lobes()[0].coverage, best),
            _ => assert_eq!(best, 0.0),
        }
    }
}

/// The shading frame's side is chosen from [`Material::has_transmission`] before the BSDF is
/// built (`Material::shade`): that must agree with the BSDF every material gives, scratched
/// glass and metal seen from either side, on and off their scratches.
#[test]
fn material_transmission_matches_its_bsdf() {
    use crate::render::geometry::SurfaceHit;
    use crate::render::material::{HitView, Material};
    use crate::render::scene::materials::MaterialDesc;
    let hit = SurfaceHit::flat;
    let view = |wo: Vec3| HitView {
        wo,
        rd: None,
        u_layer: Some(0.5),
        pixel: None,
        origin_depth: f32::INFINITY,
    };
    for text in [
        "type = \"dielectric\"\nior = 1.5",
        "type = \"dielectric\"\nior = 1.5\nroughness = 0.2",
        "type = \"conductor\"\npreset = \"gold\"",
        "type = \"conductor\"\npreset = \"Al\"\nroughness = 0.3",
        "type = \"diffuse\"",
    ] {
        let desc: MaterialDesc = toml::from_str(text).unwrap();
        let m = desc.prepare(std::path::Path::new(".")).unwrap();
        let (_, bsdf) = m.shade(
            &hit(Vec2::new(0.3, 0.6)),
            view(Vec3::Z),
            &mut CoverageCache::new(),
        );
        assert_eq!(m.has_transmission(), bsdf.has_transmission(), "{text}");
    }
    let mirror = perfect_mirror();
    let layers = wide_layers(4, 7);
    let mut rng = Pcg64::seed_from_u64(31);
    for (base, transmits) in [
        (ScratchedBase::Glass { eta: 1.5 }, true),
        (ScratchedBase::Metal { ior: mirror }, false),
    ] {
        let scratched = ScratchedMaterial::new(
            base,
            Rgb::ONE,
            lossless_diffuse(),
            layers.clone(),
            LayerMix::Max,
            CoverageMode::Point,
        );
        let m = Material::Scratched(Box::new(scratched.clone()));
        assert_eq!(m.has_transmission(), transmits);
        let mut hits = 0;
        for _ in 0..400 {
            let uv = Vec2::new(rng.random(), rng.random());
            let wo = dir(80.0 * rng.random::<f32>(), 360.0 * rng.random::<f32>());
            for wo in [wo, -wo] {
                let bsdf = bsdf_of(&scratched, &flat_ctx(uv, 0.0, wo, 0.5));
                hits += matches!(bsdf, Bsdf::Scratched(_)) as usize;
                assert_eq!(
                    bsdf.has_transmission(),
                    transmits,
                    "{base:?} at {uv}, wo {wo}"
                );
                let u_layer = m.reads_hit_context(wo, Vec3::Z).then_some(0.5);
                let (_, bsdf) = m.shade(
                    &hit(uv),
                    HitView {
                        u_layer,
                        ..view(wo)
                    },
                    &mut CoverageCache::new(),
                );
                assert_eq!(bsdf.has_transmission(), transmits);
            }
        }
        assert!(hits > 20, "{base:?}: {hits} scratched hits");
    }
}

#[test]
fn scratch_frame_follows_dpdu_dpdv() {
    // A sheared parametrisation: t = d.x dP/du + d.y dP/dv, projected and normalised.
    let t = lossless_diffuse();
    let layers = LayerSet::new(
        LayerParams {
            length: 0.3,
            width: 0.05,
            threshold: 1.0,
            layers: 1,
        },
        3,
    )
    .unwrap();
    let d = layers.direction(0);
    let m = ScratchedMaterial::new(
        ScratchedBase::Glass { eta: 1.5 },
        Rgb::ONE,
        t,
        layers,
        LayerMix::Max,
        CoverageMode::Footprint,
    );
    let mut ctx = flat_ctx(Vec2::splat(0.5), 0.0, Vec3::Z, 0.5);
    ctx.dpdu = Vec3::new(2.0, 0.0, 0.3);
    ctx.dpdv = Vec3::new(1.0, 1.0, 0.0);
    let Bsdf::Scratched(b) = bsdf_of(&m, &ctx) else {
        panic!("tau = 1 covers every point")
    };
    let t3 = ctx.dpdu * d[0] as f32 + ctx.dpdv * d[1] as f32;
    let expect = Vec2::new(t3.x, t3.y).normalize();
    let l = b.lobes()[0];
    assert!((l.cos - expect.x).abs() < 1e-5 && (l.sin - expect.y).abs() < 1e-5);
    // The scratch frame is orthonormal and right-handed: b = t x n.
    let x = l.from_scratch(Vec3::X);
    let y = l.from_scratch(Vec3::Y);
    assert!((y - Vec3::new(expect.x, expect.y, 0.0)).length() < 1e-5);
    assert!((x - y.cross(Vec3::Z)).length() < 1e-5);
    let w = Vec3::new(0.3, -0.5, 0.8);
    assert!((l.from_scratch(l.to_scratch(w)) - w).length() < 1e-6);
}

/// `lean = true` tilts a scratch's frame as the walls of its tapered groove (METHOD.md 8.3: the
/// profile scaled to the local width `2 w_0 sqrt(1 - (s/l)^2)`, depth in proportion) lean:
/// the walls' normals of the leaned frame are those of the tapered V groove's height field
/// (by finite differences) within a tenth of the unleaned frame's error, at points either side
/// of the scratches' middles, on a face scaled by 2; no lean at the middle; none without the
/// option.
#[test]
fn lean_follows_the_tapered_groove() {
    let profile = "v:angle=100";
    let t = lossless_diffuse();
    assert_eq!(t.table().params.profile.spec, profile);
    let depth = Profile::parse(profile).unwrap().depth();
    let params = LayerParams {
        length: 0.3,
        width: 0.05,
        threshold: 0.3,
        layers: 1,
    };
    let layers = LayerSet::new(params, 3).unwrap();
    let none = perfect_mirror();
    let material = |lean| {
        ScratchedMaterial::new(
            ScratchedBase::Metal { ior: none },
            Rgb::ONE,
            t.clone(),
            layers.clone(),
            LayerMix::Max,
            CoverageMode::Point,
        )
        .with_lean(lean)
    };
    let (leaned, plain) = (material(true), material(false));
    let scratches = layers.scratches(glam::DVec2::splat(0.3), glam::DVec2::splat(0.7));
    let mut checked = 0;
    for sc in &scratches {
        for s_l in [-0.7, -0.4, 0.0, 0.4, 0.7] {
            let uv = sc.centre + sc.direction * (s_l * sc.half_length);
            if layers.scratch_at(0, uv).map(|x| x.centre) != Some(sc.centre) {
                continue; // another scratch's ellipse is nearer here
            }
            let mut ctx = flat_ctx(uv.as_vec2(), 0.0, dir(30.0, 40.0), 0.5);
            ctx.dpdu = Vec3::X * 2.0;
            ctx.dpdv = Vec3::Y * 2.0;
            let frame = |m: &ScratchedMaterial| match bsdf_of(m, &ctx) {
                Bsdf::Scratched(b) => b.lobes()[0],
                _ => panic!("the hit lies on the scratch"),
            };
            let (l_lean, l_plain) = (frame(&leaned), frame(&plain));
            assert_eq!(l_plain.lean, 0.0);
            // The tapered V in world units along t = the scratch's direction, b = t x n:
            // `h(x, s) = -2 depth w(s) (1 - |x| / w(s))`, `w(s) = 2 w_0 sqrt(1 - (s / 2l)^2)`.
            let (l, w0) = (2.0 * sc.half_length, 2.0 * sc.half_width);
            let w = |s: f64| w0 * (1.0 - (s / l).powi(2)).sqrt();
            let h = |x: f64, s: f64| -2.0 * depth * w(s) * (1.0 - x.abs() / w(s));
            let tw = Vec3::new(sc.direction.x as f32, sc.direction.y as f32, 0.0);
            let bw = tw.cross(Vec3::Z);
            let s0 = s_l * l;
            for side in [-1.0, 1.0] {
                let x = side * 0.5 * w(s0);
                let e = 1e-6 * l;
                let hx = (h(x + e, s0) - h(x - e, s0)) / (2.0 * e);
                let hs = (h(x, s0 + e) - h(x, s0 - e)) / (2.0 * e);
                let exact = (bw * -hx as f32 + tw * -hs as f32 + Vec3::Z).normalize();
                // The extruded groove's wall normal in the scratch frame.
                let wall = Vec3::new(-side as f32 * 2.0 * depth as f32, 0.0, 1.0).normalize();
                let err = |lobe: &ScratchLobe| lobe.from_scratch(wall).angle_between(exact);
                let (e_lean, e_plain) = (err(&l_lean), err(&l_plain));
                if s_l == 0.0 {
                    assert!(e_lean < 1e-3 && e_plain < 1e-3, "{e_lean} {e_plain}");
                } else {
                    assert!(e_plain > 0.02, "{s_l}: {e_plain}");
                    assert!(e_lean < 0.1 * e_plain, "{s_l}: {e_lean} vs {e_plain}");
                }
            }
            checked += 1;
        }
    }
    assert!(checked >= 10, "{checked}");
}

/// The point a leaned lobe takes beside its scratch is drawn in proportion to the scratch's
/// width: chi-square of `place_by_width` against the semicircle law's CDF, `(x sqrt(1 - x^2)
/// + asin x)`, over the whole scratch and over pieces of it (one at a tip).
#[test]
fn lean_places_follow_the_scratch_width() {
    let cdf = |x: f64| x * (1.0 - x * x).max(0.0).sqrt() + x.clamp(-1.0, 1.0).asin();
    let mut rng = Pcg64::seed_from_u64(31);
    for (lo, hi) in [(-1.0, 1.0), (0.2, 0.9), (-0.999, -0.5), (0.95, 1.0)] {
        let bins = 20;
        let n = 100_000;
        let mut counts = vec![0u64; bins];
        for _ in 0..n {
            let u = rng.random();
            let x = lean::place_by_width(lo, hi, u);
            assert!(
                x >= lo - 1e-9 && x <= hi + 1e-9,
                "{x} outside {lo}..{hi} ({u})"
            );
            let b = (((x - lo) / (hi - lo)) * bins as f64) as usize;
            counts[b.min(bins - 1)] += 1;
        }
        let edge = |k: usize| lo + (hi - lo) * k as f64 / bins as f64;
        let total = cdf(hi) - cdf(lo);
        let expected: Vec<f64> = (0..bins)
            .map(|k| n as f64 * (cdf(edge(k + 1)) - cdf(edge(k))) / total)
            .collect();
        let r = chi2_discrete(&counts, &expected);
        assert!(r.p_value > 1e-3, "{lo}..{hi}: {r:?}");
    }
    // `G^-1` itself inverts `G` everywhere, the ends included.
    for k in 0..=1000 {
        let g = -FRAC_PI_2 + PI * k as f64 / 1000.0;
        let phi = lean::area_inverse(g);
        let back = lean::area_up_to(phi);
        assert!((back - g).abs() < 1e-9, "{g}: {phi} gives {back}");
    }
}

/// Only the coverage modes that filter over the footprint ask the integrator for ray
/// differentials (it skips them when no material reads them).
#[test]
fn point_coverage_needs_no_ray_differentials() {
    let layers = LayerSet::new(LayerParams::setting(2).unwrap(), 1).unwrap();
    for (mode, reads) in [
        (CoverageMode::Footprint, true),
        (CoverageMode::Sample, true),
        (CoverageMode::Point, false),
    ] {
        let m = ScratchedMaterial::new(
            ScratchedBase::Glass { eta: 1.5 },
            Rgb::ONE,
            lossless_diffuse(),
            layers.clone(),
            LayerMix::Max,
            mode,
        );
        assert_eq!(m.reads_footprint(), reads, "{mode:?}");
        let m = crate::render::material::Material::Scratched(Box::new(m));
        assert_eq!(m.reads_footprint(), reads, "{mode:?}");
    }
}

/// [`ScratchedBsdf::at_wo`]'s cache of the first lobe's `wo` terms changes no result: eval, pdf
/// and samples with the cached `wo` (and with another `wo`) are bit-identical to the BSDF
/// without the cache.
#[test]
fn wo_cache_changes_no_result() {
    let t = schlick_diffuse();
    let glass = ScratchedBase::Glass { eta: 1.5 };
    let lobes = [lobe(0.4, 0.3), lobe(0.5, 1.9)];
    let plain = ScratchedBsdf::new(glass, &t, Rgb::ONE, &lobes);
    let mut rng = Pcg64::seed_from_u64(5);
    for wo in wos() {
        let cached = plain.at_wo(wo);
        for probe in [wo, dir(20.0, 75.0)] {
            for _ in 0..200 {
                let wi = dir(rng.random_range(0.0..179.0), rng.random_range(0.0..360.0));
                assert_eq!(plain.eval_pdf(probe, wi), cached.eval_pdf(probe, wi));
                let (u, v) = (rng.random(), Vec2::new(rng.random(), rng.random()));
                let (a, b) = (plain.sample(probe, u, v), cached.sample(probe, u, v));
                assert_eq!(format!("{a:?}"), format!("{b:?}"), "{wo:?} {probe:?}");
            }
        }
    }
}

#[test]
fn union_mix_scales_coverages_to_their_union() {
    use super::union_scale;
    // Two halves: union 3/4 of a sum of 1; one layer alone keeps its coverage.
    assert!((union_scale(&[0.5, 0.5]) - 0.75).abs() < 1e-6);
    assert_eq!(union_scale(&[0.3, 0.0, 0.0]), 1.0);
    assert_eq!(union_scale(&[0.0, 0.0]), 1.0);
    // Eight layers of 3 %: a union of 21.6 %, not 24 %.
    let s = union_scale(&[0.03; 8]) * 0.24;
    assert!((s - 0.2163).abs() < 1e-3, "{s}");
}

/// Dielectric walls seen from inside: a hit beside a groove's opening meets its ridge when
/// the light arrives grazing enough. The renderer's capsule search along the ray finds the
/// ridges that enumerating every scratch nearby and meeting the ray with each groove's local
/// cross-section finds, hit for hit, on a face mapped 1:1 and on one mapped at twice the scale
/// with its frame turned, on the ray's way to the hit and, under total internal reflection,
/// on its way on from it, mirrored; the band each scratch adds is `k - 1` of its area each way
/// (`k` the round groove's intercept in closed form, as `profile`'s
/// `ridge_band_of_a_round_groove`); none below the angle at which the arc's end tangent hides
/// the ridge, nor from outside.
#[test]
fn ridges_meet_grazing_light_from_inside() {
    use glam::DVec2;
    let profile = Profile::parse("round:depth=0.3,segments=256").unwrap();
    let walls = coarse_glass_walls(&profile);
    let layers = LayerSet::new(
        LayerParams {
            length: 0.3,
            width: 0.05,
            threshold: 0.1,
            layers: 1,
        },
        3,
    )
    .unwrap();
    let d = DVec2::from(layers.direction(0));
    let m = ScratchedMaterial::with_model(
        ScratchedBase::Glass { eta: 1.5 },
        Rgb::ONE,
        ScratchModel::DielectricWalls(walls),
        layers,
        LayerMix::Max,
        CoverageMode::Footprint,
    );
    // The scratches near `uv` met beside their openings by the ray back along `wo` (local
    // frame = texture axes).
    let truth = |uv: DVec2, wo: Vec3| {
        let r = 0.1;
        let near = m
            .layers
            .scratches(uv - DVec2::splat(r), uv + DVec2::splat(r));
        near.iter()
            .filter(|sc| {
                let v = uv - sc.centre;
                let s = v.dot(sc.direction) / sc.half_length;
                let half_width = sc.half_width * (1.0 - s * s).max(0.0).sqrt();
                // The scratch frame's `x`, `b = t x n` (METHOD.md section 1).
                let across = -sc.direction.perp();
                let dx = wo.x as f64 * across.x + wo.y as f64 * across.y;
                let x = v.dot(across) / (2.0 * half_width);
                half_width > 0.0 && x.abs() >= 0.5 && profile.ray_meets_ridge(x, dx, wo.z as f64)
            })
            .count()
    };
    // The scratches' area per unit area (the texture repeats over the unit square).
    let area: f64 = m
        .layers
        .scratches(DVec2::ZERO, DVec2::ONE)
        .iter()
        .filter(|s| s.centre.cmpge(DVec2::ZERO).all() && s.centre.cmplt(DVec2::ONE).all())
        .map(|s| PI * s.half_length * s.half_width)
        .sum();
    let (sag, n) = (0.3f64, 200_000);
    let r = (0.25 + sag * sag) / (2.0 * sag);
    let alpha = (0.5 / r).asin();
    for deg in [20.0f64, 40.0, 60.0, 75.0, 85.0] {
        let a = deg.to_radians();
        let tir = 1.5 * a.sin() > 1.0;
        let k = if a <= FRAC_PI_2 - alpha {
            1.0
        } else {
            (0.5 * a.cos() + r - (r - sag) * a.sin()) / a.cos()
        };
        // Light from inside leaning across the scratches: `wo` points back into the glass.
        let wo =
            Vec3::new(-d.y as f32, d.x as f32, 0.0) * a.sin() as f32 - Vec3::Z * a.cos() as f32;
        let mut rng = Pcg64::seed_from_u64(9);
        let (mut found, mut met, mut pairs) = ([0usize; 2], 0usize, 0usize);
        for _ in 0..n {
            let uv = Vec2::new(rng.random(), rng.random());
            let mut count = truth(uv.as_dvec2(), wo);
            if tir {
                count += truth(uv.as_dvec2(), Vec3::new(-wo.x, -wo.y, wo.z));
            }
            pairs += count;
            if m.layers.scratched_mask(uv) != 0 {
                continue;
            }
            let u = rng.random();
            let want = count > 0;
            met += want as usize;
            let flat = flat_ctx(uv, 0.0, wo, u);
            // The same face at twice the scale, its frame turned a quarter.
            let frame = Frame {
                s: Vec3::Y,
                t: -Vec3::X,
                n: Vec3::Z,
            };
            let turned = ShadingContext {
                dpdu: Vec3::Y * 2.0,
                dpdv: -Vec3::X * 2.0,
                wo: frame.s * wo.x + frame.t * wo.y + frame.n * wo.z,
                frame,
                ..flat
            };
            for (f, ctx) in found.iter_mut().zip([flat, turned]) {
                let ridge = matches!(bsdf_of(&m, &ctx), Bsdf::ScratchedGlass(_));
                assert!(!ridge || want, "{deg} degrees at {uv:?}: no ridge there");
                *f += ridge as usize;
                let up = ShadingContext {
                    wo: ctx.wo - ctx.frame.n * (2.0 * ctx.wo.dot(ctx.frame.n)),
                    ..ctx
                };
                assert!(!matches!(bsdf_of(&m, &up), Bsdf::ScratchedGlass(_)));
            }
        }
        assert_eq!(found, [met; 2], "{deg} degrees: ridges found of {met}");
        let band = pairs as f64 / n as f64 / area;
        let sigma = (pairs.max(1) as f64).sqrt() / n as f64 / area;
        let expect = if tir { 2.0 } else { 1.0 } * (k - 1.0);
        assert!(
            (band - expect).abs() < 4.0 * sigma + 0.02 * expect,
            "{deg} degrees: band {band} against {expect} (sigma {sigma})"
        );
    }
}

/// Curves seen from inside dielectric-walled glass meet grazing light beside their openings
/// as layers do (METHOD.md 8.1, 9.1): hit for hit, the ridge search finds the straight V
/// groove exactly where its closed form says. A ray back along `wo` from `|x|` widths off the
/// axis, running toward it with `k = |wo_x| / |wo_z|` across per unit depth, meets a V of
/// depth ratio `D` iff `1/2 <= |x| <= k D` (the near wall's lowest point is the last it can
/// meet); under total internal reflection on both sides, mirrored, else on the side it comes
/// from. A worn curve (depth ratio 1/2) halves `D`; none is met from outside.
#[test]
fn curves_meet_grazing_light_beside_their_openings() {
    use crate::curves::{CurveSet, Polyline};
    use glam::{DVec2, DVec3};
    let profile = Profile::parse("v:depth=0.3").unwrap();
    let walls = coarse_glass_walls(&profile);
    let (angle, hw) = (0.4f64, 0.02);
    let (axis, across) = (DVec2::from_angle(angle), DVec2::from_angle(angle).perp());
    let (a, b) = (
        DVec2::splat(0.5) - 0.45 * axis,
        DVec2::splat(0.5) + 0.45 * axis,
    );
    for wear in [1.0, 0.5] {
        let line = Polyline {
            depths: vec![wear; 2],
            ..Polyline::uniform(vec![a, b], hw)
        };
        let curves = CurveSet::new(&[line], DVec2::ONE).unwrap();
        let m = ScratchedMaterial::with_model(
            ScratchedBase::Glass { eta: 1.5 },
            Rgb::ONE,
            ScratchModel::DielectricWalls(walls.clone()),
            LayerSet::none(),
            LayerMix::Union,
            CoverageMode::Footprint,
        )
        .with_curves(Some(Arc::new(curves)));
        let depth = 0.3 * wear;
        let mut rng = Pcg64::seed_from_u64(11);
        let mut met = 0;
        for (deg, turn) in [
            (50.0f64, 0.0f64),
            (65.0, 0.3),
            (75.0, 1.2),
            (85.0, 0.1),
            (85.0, 2.5),
        ] {
            let (t, h) = (deg.to_radians(), angle + FRAC_PI_2 + turn);
            let wo = DVec3::new(t.sin() * h.cos(), t.sin() * h.sin(), -t.cos());
            let tir = 1.5 * t.sin() > 1.0;
            let dx = DVec2::new(wo.x, wo.y).dot(across);
            let k = dx.abs() / -wo.z;
            for _ in 0..20_000 {
                let x = rng.random_range(-4.0..4.0);
                let uv = DVec2::splat(0.5)
                    + across * (2.0 * hw * x)
                    + axis * rng.random_range(-0.3..0.3);
                // Toward the axis on the way in (`x` and `dx` of opposite signs), or on the way
                // on under total internal reflection.
                let toward = x * dx < 0.0 || tir;
                let want = x.abs() >= 0.5 && x.abs() <= k * depth && toward;
                let edge = (x.abs() - 0.5).abs().min((x.abs() - k * depth).abs()) < 1e-6;
                if x.abs() < 0.5 || edge {
                    continue;
                }
                let ctx = flat_ctx(uv.as_vec2(), 0.0, wo.as_vec3(), rng.random());
                let ridge = matches!(bsdf_of(&m, &ctx), Bsdf::ScratchedGlass(_));
                assert_eq!(
                    ridge, want,
                    "wear {wear}, {deg} degrees, turn {turn}, x {x}"
                );
                met += ridge as usize;
                if want && x * dx < 0.0 {
                    // On the way in the ray meets the near wall this deep (world units): one
                    // that began shallower (`origin_depth`) never met it, and under total
                    // internal reflection the ray on from the hit runs away from the groove.
                    let z = hw * (2.0 * x.abs() - 1.0) / (k - 0.5 / depth);
                    for (f, met_within) in [(0.98, false), (1.02, true)] {
                        let within = ShadingContext {
                            origin_depth: (f * z) as f32,
                            ..ctx
                        };
                        let ridge = matches!(bsdf_of(&m, &within), Bsdf::ScratchedGlass(_));
                        assert_eq!(
                            ridge, met_within,
                            "wear {wear}, {deg} degrees, x {x}, f {f}"
                        );
                    }
                }
                let up = ShadingContext {
                    wo: Vec3::new(ctx.wo.x, ctx.wo.y, -ctx.wo.z),
                    ..ctx
                };
                assert!(!matches!(bsdf_of(&m, &up), Bsdf::ScratchedGlass(_)));
            }
        }
        assert!(met > 1000, "wear {wear}: {met} ridges met");
    }
}

/// Light a traced groove sends down into the glass from below the surface meets the next
/// groove where its line runs through that groove's walls (METHOD.md 8.3, light between
/// grooves; [`ScratchedMaterial::groove_below`]): a straight V curve of depth 0.3 and light
/// leaving a point `z` below the surface `x` widths across from its axis, falling toward it a
/// width across `s` widths deep (less steep than the V's walls): it meets the near wall where
/// the line is still above the V's point when it reaches the axis, `z + s |x| < 0.3`, and never
/// heading away; the groove is placed where the line crosses the surface, traced from the
/// light's depth, and mirrors the light (beyond the critical angle) off that wall, losslessly,
/// where the line meets it.
#[test]
fn light_sent_down_meets_the_groove_below_it() {
    use crate::curves::{CurveSet, Polyline};
    use crate::render::bsdf::TracedGroove;
    use glam::{DVec2, DVec3};
    let profile = Profile::parse("v:depth=0.3").unwrap();
    let params = crate::precompute::wall_table::WallTableParams::new(profile, 1.5, 0.0);
    let walls = GlassWalls::Traced(Arc::new(TracedGroove::new(&params)));
    let (angle, hw) = (0.4f64, 0.02);
    let (axis, across) = (DVec2::from_angle(angle), DVec2::from_angle(angle).perp());
    let line = Polyline::uniform(
        vec![
            DVec2::splat(0.5) - 0.45 * axis,
            DVec2::splat(0.5) + 0.45 * axis,
        ],
        hw,
    );
    let curves = CurveSet::new(&[line], DVec2::ONE).unwrap();
    let m = ScratchedMaterial::with_model(
        ScratchedBase::Glass { eta: 1.5 },
        Rgb::ONE,
        ScratchModel::DielectricWalls(walls),
        LayerSet::none(),
        LayerMix::Union,
        CoverageMode::Point,
    )
    .with_curves(Some(Arc::new(curves)));
    let width = 2.0 * hw;
    let (across3, axis3) = (across.extend(0.0), axis.extend(0.0));
    let mut rng = Pcg64::seed_from_u64(12);
    let (mut met, mut passed) = (0, 0);
    for _ in 0..4000 {
        // Falling toward the axis (or away from it), `s` deep a width across, `psi` to it.
        let s = rng.random_range(0.05..0.4f64);
        let psi = rng.random_range(0.3..FRAC_PI_2);
        let away = rng.random::<f64>() < 0.2;
        let h = if away { -1.0 } else { 1.0 };
        let d =
            (across3 * (h * psi.sin()) + axis3 * psi.cos()) + DVec3::new(0.0, 0.0, -s * psi.sin());
        let wi = d.normalize();
        let (x, z) = (
            rng.random_range(-1.5..-0.55f64),
            rng.random_range(0.01..0.25f64),
        );
        let uv = DVec2::splat(0.5) + across * (width * x) + axis * rng.random_range(-0.2..0.2);
        let ctx = flat_ctx(uv.as_vec2(), 0.0, -wi.as_vec3(), 0.5);
        let from = Vec3::new(0.0, 0.0, -(z * width) as f32);
        let want = !away && z + s * x.abs() < 0.3;
        if (z + s * x.abs() - 0.3).abs() < 1e-3 {
            continue;
        }
        let below = m.groove_below(&ctx, from, wi.as_vec3(), 0.5);
        assert_eq!(below.is_some(), want, "x {x}, z {z}, s {s}, away {away}");
        let Some(below) = below else {
            passed += 1;
            continue;
        };
        met += 1;
        // Placed where the line crosses the surface, from the light's depth.
        let place = below.lobe.place.unwrap();
        assert!((place.width - width as f32).abs() < 1e-5, "{place:?}");
        assert!(
            (place.at.abs() - (-x + z / s) as f32).abs() < 1e-3,
            "{place:?}, x {x}"
        );
        assert_eq!(below.depth, -from.z);
        // Mirrored off the near wall, whose normal (into the void, up toward the axis) is
        // `(0.3, 0.5)` across and up.
        let out = below.sample(wi.as_vec3(), rng.random()).unwrap();
        assert_eq!(out.weight, Rgb::ONE);
        let n = (across3 * 0.3 + DVec3::Z * 0.5).normalize();
        let want = wi - 2.0 * wi.dot(n) * n;
        assert!(
            (out.wi.as_dvec3() - want).length() < 1e-4,
            "{:?} against {want:?}",
            out.wi
        );
        // On, down from the wall: where the line meets it, below the light's depth.
        let on = out.from.expect("it leaves the wall below the surface");
        assert!(out.wi.z < 0.0 && -on.z > -from.z, "{on:?} from {from:?}");
    }
    assert!(met > 1000 && passed > 1000, "met {met}, passed {passed}");
}

/// Hits from inside glass with dielectric walls read `u_layer` but not the footprint
/// (`reads_footprint_at`, which lets the integrator leave their ray differentials unworked):
/// their BSDF is the same with no differentials as with any footprint. From outside the
/// footprint counts; the seed's glass and the metal read it from outside only where they read
/// anything.
#[test]
fn inside_hits_read_no_footprint() {
    let walls = coarse_glass_walls(&Profile::parse("v:angle=90").unwrap());
    let glass = ScratchedMaterial::with_model(
        ScratchedBase::Glass { eta: 1.5 },
        Rgb::ONE,
        ScratchModel::DielectricWalls(walls),
        wide_layers(4, 5),
        LayerMix::Max,
        CoverageMode::Footprint,
    );
    let mut rng = Pcg64::seed_from_u64(77);
    let (mut covered, mut differs) = (0, 0);
    for _ in 0..300 {
        let uv = Vec2::new(rng.random(), rng.random());
        let wo = dir(70.0 * rng.random::<f32>(), 360.0 * rng.random::<f32>());
        assert!(glass.reads_hit_context(-wo, Vec3::Z) && !glass.reads_footprint_at(-wo, Vec3::Z));
        assert!(glass.reads_footprint_at(wo, Vec3::Z));
        let none = ShadingContext {
            rd: None,
            ..flat_ctx(uv, 0.0, -wo, 0.5)
        };
        let inside = format!("{:?}", bsdf_of(&glass, &none));
        assert_eq!(
            inside,
            format!("{:?}", bsdf_of(&glass, &flat_ctx(uv, 0.2, -wo, 0.5)))
        );
        covered += matches!(bsdf_of(&glass, &none), Bsdf::ScratchedGlass(_)) as usize;
        let outside = |f| format!("{:?}", bsdf_of(&glass, &flat_ctx(uv, f, wo, 0.5)));
        differs += (outside(0.0) != outside(0.2)) as usize;
    }
    assert!(covered > 20 && differs > 20, "{covered} {differs}");
    for base in [
        ScratchedBase::Glass { eta: 1.5 },
        ScratchedBase::Metal {
            ior: perfect_mirror(),
        },
    ] {
        let m = ScratchedMaterial::new(
            base,
            Rgb::ONE,
            lossless_diffuse(),
            wide_layers(2, 1),
            LayerMix::Max,
            CoverageMode::Footprint,
        );
        assert!(m.reads_footprint_at(Vec3::Z, Vec3::Z));
        let point = ScratchedMaterial {
            coverage: CoverageMode::Point,
            ..m.clone()
        };
        assert!(!point.reads_footprint_at(Vec3::Z, Vec3::Z));
    }
}

/// Worn curves (METHOD.md 9.2): a curve of depth ratio 1/2 reads the table of its profile
/// worn to 1/2, which is the table of the half-deep profile (a V 0.5 deep worn to 1/2 is the V
/// 0.25 deep, the same table by its hash); between two tables, the lobe is their linear
/// interpolation over `u_layer`.
#[test]
fn worn_curves_read_the_worn_profiles_table() {
    use crate::render::scene::materials::MaterialDesc;
    let material = |profile: &str, depth: &str| {
        let text = format!(
            "type = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"\n[scratches]\nprofile = \"{profile}\"\nwalls = \"diffuse\"\nm = 32\nn = 400\npolylines = [{{ points = [[0.0, 0.5], [1.0, 0.5]], widths = [0.2, 0.2], depths = [{depth}, {depth}] }}]"
        );
        let MaterialDesc::Scratched(s) = toml::from_str::<MaterialDesc>(&text).unwrap() else {
            panic!()
        };
        s.prepare(std::path::Path::new(".")).unwrap()
    };
    assert_eq!(
        Profile::parse("v:depth=0.5")
            .unwrap()
            .worn(0.5)
            .unwrap()
            .points,
        Profile::parse("v:depth=0.25").unwrap().points
    );
    let worn = material("v:depth=0.5", "0.5");
    let shallow = material("v:depth=0.25", "1.0");
    let full = material("v:depth=0.5", "1.0");
    let eval = |m: &ScratchedMaterial, u: f32, wo: Vec3, wi: Vec3| {
        let ctx = flat_ctx(Vec2::new(0.5, 0.5), 1e-4, wo, u);
        bsdf_of(m, &ctx).eval(wo, wi)
    };
    let wo = dir(40.0, 20.0);
    let mut differs = false;
    for wi in [dir(30.0, 200.0), dir(60.0, 160.0), dir(10.0, 90.0)] {
        for u in [0.1, 0.6] {
            let (a, b) = (eval(&worn, u, wo, wi), eval(&shallow, u, wo, wi));
            assert_eq!(a.to_array(), b.to_array(), "worn to 1/2 vs the half-deep V");
            differs |= (eval(&full, u, wo, wi) - a).abs().max_element() > 1e-4;
        }
    }
    assert!(differs, "the worn lobe differs from the unworn one");
    // Depth 0.6, between the tables of 0.5 and 0.75: the mean over u_layer is the linear
    // interpolation, 0.4 of the way from 0.5 to 0.75.
    let mid = material("v:depth=0.5", "0.6");
    let (lo, hi) = (
        material("v:depth=0.5", "0.5"),
        material("v:depth=0.5", "0.75"),
    );
    let wi = dir(30.0, 200.0);
    let n = 4096;
    let mean = (0..n)
        .map(|k| eval(&mid, (k as f32 + 0.5) / n as f32, wo, wi))
        .fold(Vec3::ZERO, |s, x| s + x)
        / n as f32;
    let want = eval(&lo, 0.3, wo, wi) * 0.6 + eval(&hi, 0.3, wo, wi) * 0.4;
    assert!(
        (mean - want).abs().max_element() <= 2e-3 * want.max_element(),
        "{mean} vs {want}"
    );
}

/// A painted map's lobe (METHOD.md 9.5): its coverage is the map's, and a flow map's direction
/// `2 rg - 1` is carried along the unit tangents `dP/du / |dP/du|`, `dP/dv / |dP/dv|` into the
/// shading plane (glTF `KHR_materials_anisotropy`), on a sheared, unequally scaled
/// parametrisation; without a flow map, the structure's direction is a texture direction.
#[test]
fn a_flow_map_turns_the_maps_lobe_in_the_tangent_frame() {
    use crate::maps::ScratchMap;
    let t = lossless_diffuse();
    let material = |map: ScratchMap| {
        ScratchedMaterial::new(
            ScratchedBase::Metal {
                ior: perfect_mirror(),
            },
            Rgb::ONE,
            t.clone(),
            LayerSet::none(),
            LayerMix::Union,
            CoverageMode::Footprint,
        )
        .with_map(Some(Arc::new(map)), 1.0)
    };
    let mut ctx = flat_ctx(Vec2::splat(0.5), 0.0, Vec3::Z, 0.5);
    ctx.dpdu = Vec3::new(2.0, 0.0, 0.3);
    ctx.dpdv = Vec3::new(1.0, 1.0, 0.0);
    let (tu, tv) = (ctx.dpdu.normalize(), ctx.dpdv.normalize());
    for (rg, d) in [
        ([0.5f32, 1.0f32], Vec2::new(0.0, 1.0)),
        ([1.0, 0.5], Vec2::new(1.0, 0.0)),
        ([0.0, 0.0], Vec2::new(-1.0, -1.0)),
        ([0.25, 0.9], Vec2::new(-0.5, 0.8)),
    ] {
        let m = material(ScratchMap::new(1, 1, &[0.75], Some(&[rg]), 1.0).unwrap());
        let Bsdf::Scratched(b) = bsdf_of(&m, &ctx) else {
            panic!("the map covers every point")
        };
        assert_eq!(b.lobes().len(), 1);
        let l = b.lobes()[0];
        assert!((l.coverage - 0.75).abs() < 1e-6, "{}", l.coverage);
        let t3 = tu * d.x + tv * d.y;
        let expect = Vec2::new(t3.x, t3.y).normalize();
        // A scratch has no sign.
        let dot = l.cos * expect.x + l.sin * expect.y;
        assert!(
            dot.abs() > 1.0 - 1e-5,
            "{rg:?}: ({}, {}) vs {expect:?}",
            l.cos,
            l.sin
        );
    }
    // No flow map: a band along u reads along dP/du (a texture direction).
    let (w, h) = (32, 32);
    let cov: Vec<f32> = (0..w * h)
        .map(|i| {
            if (14..18).contains(&(i / w)) {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let m = material(ScratchMap::new(w, h, &cov, None, 1.0).unwrap());
    let Bsdf::Scratched(b) = bsdf_of(&m, &ctx) else {
        panic!("the band covers the centre")
    };
    let l = b.lobes()[0];
    let expect = Vec2::new(ctx.dpdu.x, ctx.dpdu.y).normalize();
    assert!((l.cos * expect.x + l.sin * expect.y).abs() > 1.0 - 1e-5);
}

/// `layer_mix = "stochastic"` is `union` in expectation: over the pick's number `u_layer`
/// its BSDF's value averages `union`'s at a footprint that several layers' scratches share,
/// and its sampling, which reads the same number within the pick's share (the integrator
/// gives the bounce's lobe number to both), gives `union`'s estimate of the reflected and the
/// transmitted light and of the light toward a cone of directions. Reading the number afresh
/// instead (no share) would tie the component to the layer and fail.
#[test]
fn stochastic_mix_is_union_in_expectation() {
    let t = schlick_diffuse();
    let layers = wide_layers(4, 7);
    let material = |mix| {
        ScratchedMaterial::new(
            ScratchedBase::Glass { eta: 1.5 },
            Rgb::ONE,
            t.clone(),
            layers.clone(),
            mix,
            CoverageMode::Footprint,
        )
    };
    let (union, stochastic) = (material(LayerMix::Union), material(LayerMix::Stochastic));
    let wo = dir(40.0, 70.0);
    // A footprint that three or more layers' scratches cover, unequally.
    let mut rng = Pcg64::seed_from_u64(3);
    let ctx = loop {
        let uv = Vec2::new(rng.random(), rng.random());
        let ctx = flat_ctx(uv, 0.08, wo, 0.5);
        if let Bsdf::Scratched(b) = bsdf_of(&union, &ctx) {
            let c: Vec<f32> = b.lobes().iter().map(|l| l.coverage).collect();
            if c.len() >= 3 && c.iter().any(|&x| (x - c[0]).abs() > 0.05) {
                break ctx;
            }
        }
    };
    let at = |u: f32| ShadingContext { u_layer: u, ..ctx };
    let n = 20_000;
    let us = |k: usize| (k as f32 + 0.5) / n as f32;
    // Values.
    let b_union = bsdf_of(&union, &ctx);
    for wi in [dir(30.0, 200.0), dir(60.0, 10.0), dir(20.0, 120.0)] {
        let want = b_union.eval(wo, wi);
        let mean = (0..n)
            .map(|k| bsdf_of(&stochastic, &at(us(k))).eval(wo, wi))
            .fold(Rgb::ZERO, |s, x| s + x)
            / n as f32;
        assert!(
            (mean - want).abs().max_element() <= 2e-3 * want.max_element(),
            "{wi}: {mean} vs {want}"
        );
    }
    // Sampling: reflected, transmitted, a cone (within 50 degrees of `(0.5, -0.3, 0.8)`) and
    // the reflected light's spread, with the means' standard errors.
    let cone = Vec3::new(0.5, -0.3, 0.8).normalize();
    let tally = |b: &Bsdf, u_lobe: f32, u: Vec2, out: &mut [[f64; 2]; 4]| {
        if let Some(s) = b.sample(wo, u_lobe, u) {
            let w = s.weight.x as f64;
            let mut add = |i: usize| {
                out[i][0] += w;
                out[i][1] += w * w;
            };
            add((s.wi.z < 0.0) as usize);
            if s.wi.dot(cone) > 50f32.to_radians().cos() {
                add(2);
            }
            // The reflected light's spread along x against y: each layer's scratches spread
            // it across their own direction.
            if s.wi.z > 0.0 {
                let a = w * (s.wi.x * s.wi.x - s.wi.y * s.wi.y) as f64;
                out[3][0] += a;
                out[3][1] += a * a;
            }
        }
    };
    let n = 200_000;
    let us = |k: usize| (k as f32 + 0.5) / n as f32;
    let (mut want, mut got) = ([[0.0f64; 2]; 4], [[0.0f64; 2]; 4]);
    let mut rng = Pcg64::seed_from_u64(11);
    for k in 0..n {
        let u = us(k);
        let d = Vec2::new(rng.random(), rng.random());
        tally(&b_union, u, d, &mut want);
        tally(&bsdf_of(&stochastic, &at(u)), u, d, &mut got);
    }
    let n = n as f64;
    let mean_se = |x: [f64; 2]| (x[0] / n, ((x[1] / n - (x[0] / n).powi(2)) / n).sqrt());
    for i in 0..4 {
        let ((w, sw), (g, sg)) = (mean_se(want[i]), mean_se(got[i]));
        let sigma = (sw * sw + sg * sg).sqrt();
        assert!(
            (g - w).abs() < 4.0 * sigma + 1e-4 * w.abs(),
            "{i}: {g} vs {w} (sigma {sigma})"
        );
    }
    // The component is independent of the pick: on a mirror base, each picked layer's
    // samples take the base's mirror direction with probability `1 - C`.
    let metal = ScratchedMaterial::new(
        ScratchedBase::Metal {
            ior: perfect_mirror(),
        },
        Rgb::ONE,
        t.clone(),
        layers.clone(),
        LayerMix::Stochastic,
        CoverageMode::Footprint,
    );
    let mirror = Vec3::new(-wo.x, -wo.y, wo.z);
    let n = 20_000;
    let mut by_layer: Vec<([u32; 2], u32, u32)> = Vec::new();
    let mut coverage = 0.0;
    for k in 0..n {
        let u = (k as f32 + 0.5) / n as f32;
        let Bsdf::Scratched(b) = bsdf_of(&metal, &at(u)) else {
            panic!("the footprint is scratched")
        };
        let l = b.lobes()[0];
        coverage = l.coverage;
        let key = [l.cos.to_bits(), l.sin.to_bits()];
        let s = Bsdf::Scratched(b).sample(wo, u, Vec2::new(rng.random(), rng.random()));
        let base = s.is_some_and(|s| (s.wi - mirror).length() < 1e-6) as u32;
        match by_layer.iter_mut().find(|e| e.0 == key) {
            Some(e) => (e.1, e.2) = (e.1 + 1, e.2 + base),
            None => by_layer.push((key, 1, base)),
        }
    }
    assert!(by_layer.len() >= 3, "{}", by_layer.len());
    let p = 1.0 - coverage as f64;
    for (_, count, base) in by_layer {
        let sigma = (p * (1.0 - p) / count as f64).sqrt();
        let f = base as f64 / count as f64;
        assert!((f - p).abs() < 4.0 * sigma, "{f} of {count} vs {p}");
    }
}

/// [`crossing_partner`] draws what a point covered by independent scratches meets: no partner
/// with probability `P_1 / C` (exactly one scratch, given one or more), else one of the others
/// in proportion to its coverage (chi-square over the outcomes, for footprint coverages and a
/// point test's 0 or 1); one candidate never has one.
#[test]
fn crossing_partner_draws_the_chance_of_two_scratches() {
    let cases: [&[(f32, usize)]; 3] = [
        &[(0.2, 0), (0.5, 3), (0.1, 7)],
        &[(0.05, 1), (0.03, 2)],
        &[(1.0, 0), (1.0, 4), (1.0, 5)],
    ];
    let n = 200_000u32;
    for all in cases {
        let p_none_given = |_: usize| {
            let open = |skip: usize| -> f64 {
                all.iter()
                    .enumerate()
                    .filter(|(j, _)| *j != skip)
                    .map(|(_, x)| 1.0 - x.0 as f64)
                    .product()
            };
            let union = 1.0 - open(usize::MAX);
            let one: f64 = (0..all.len()).map(|k| all[k].0 as f64 * open(k)).sum();
            one / union
        };
        for &(_, i) in all {
            let mut counts = vec![0u64; all.len() + 1];
            for k in 0..n {
                let u = (k as f32 + 0.5) / n as f32;
                match crossing_partner(all, i, u) {
                    None => counts[all.len()] += 1,
                    Some((c, j)) => {
                        let at = all.iter().position(|x| x.1 == j).unwrap();
                        assert_ne!(j, i, "{all:?}: a scratch crossing itself");
                        assert_eq!(c, all[at].0);
                        counts[at] += 1;
                    }
                }
            }
            let none = p_none_given(i);
            let others: f64 = all.iter().filter(|x| x.1 != i).map(|x| x.0 as f64).sum();
            let mut expected: Vec<f64> = all
                .iter()
                .map(|x| {
                    if x.1 == i {
                        0.0
                    } else {
                        n as f64 * (1.0 - none) * x.0 as f64 / others
                    }
                })
                .collect();
            expected.push(n as f64 * none);
            let r = chi2_discrete(&counts, &expected);
            assert!(
                r.p_value > 1e-4,
                "{all:?} slot {i}: {counts:?} vs {expected:?}: {r:?}"
            );
        }
    }
    assert_eq!(crossing_partner(&[(0.7, 2)], 2, 0.3), None);
}

/// [`ScratchLobe::crossed_by`]: the other scratch's across axis in this lobe's scratch frame,
/// the frame's own `x` for a parallel scratch and `-y`/`+y` a quarter turn either way.
#[test]
fn crossed_by_gives_the_partner_axis_in_the_scratch_frame() {
    let at = |beta: f32| ScratchLobe::new(0.5, beta.cos(), beta.sin());
    for beta in [0.0f32, 0.7, 2.0] {
        let l = at(beta);
        let close = |a: [f32; 2], b: [f32; 2]| (a[0] - b[0]).abs() + (a[1] - b[1]).abs() < 1e-5;
        assert!(close(l.crossed_by(&at(beta)).cross, [1.0, 0.0]));
        // The other's `b = t' x n` against this frame's `(b, t)`.
        for turn in [0.4f32, FRAC_PI_2 as f32, 2.5] {
            let c = l.crossed_by(&at(beta + turn)).cross;
            let v = l.to_scratch(Vec3::new((beta + turn).sin(), -(beta + turn).cos(), 0.0));
            assert!(
                close(c, [v.x, v.y]),
                "beta {beta} turn {turn}: {c:?} vs {v:?}"
            );
        }
    }
}

/// Under footprint coverage a curve's lobe on glass with dielectric walls sends its paths on
/// from the curve, not from the hit beside it (`curve_spawn`): every lobe sample from a hit
/// whose footprint the line crosses goes on from a point in the line's opening, level with the
/// hit along the line; the base's samples, and every sample under `coverage = "point"`, go on
/// from the hit.
#[test]
fn footprint_lobes_go_on_from_the_covering_curve() {
    use crate::curves::{CurveSet, Polyline};
    use glam::DVec2;
    let profile = Profile::parse("v:depth=0.3").unwrap();
    let walls = coarse_glass_walls(&profile);
    let angle = 0.4f64;
    let (axis, across) = (DVec2::from_angle(angle), DVec2::from_angle(angle).perp());
    let line = Polyline::uniform(
        vec![
            DVec2::splat(0.5) - 0.45 * axis,
            DVec2::splat(0.5) + 0.45 * axis,
        ],
        0.01,
    );
    let curves = Arc::new(CurveSet::new(&[line], DVec2::ONE).unwrap());
    let material = |coverage| {
        ScratchedMaterial::with_model(
            ScratchedBase::Glass { eta: 1.5 },
            Rgb::ONE,
            ScratchModel::DielectricWalls(walls.clone()),
            LayerSet::none(),
            LayerMix::Union,
            coverage,
        )
        .with_curves(Some(curves.clone()))
    };
    let (footprint, point) = (
        material(CoverageMode::Footprint),
        material(CoverageMode::Point),
    );
    let mut rng = Pcg64::seed_from_u64(5);
    let (mut lobes, mut bases) = (0, 0);
    for _ in 0..4000 {
        // Beside the line or on it, within the footprint (0.1 across) of the line.
        let off = rng.random_range(-0.04..0.04);
        let uv = DVec2::splat(0.5) + across * off + axis * rng.random_range(-0.2..0.2);
        let wo = dir(rng.random_range(0.0..80.0), rng.random_range(0.0..360.0));
        let ctx = flat_ctx(uv.as_vec2(), 0.1, wo, rng.random());
        let u = Vec2::new(rng.random(), rng.random());
        let Some(s) = bsdf_of(&footprint, &ctx).sample(wo, rng.random(), u) else {
            continue;
        };
        if s.delta {
            assert_eq!(s.from, None, "a base sample goes on from the hit");
            bases += 1;
            continue;
        }
        let from = s.from.expect("a lobe sample goes on from the curve");
        assert_eq!(from.z, 0.0);
        let q = uv + DVec2::new(from.x as f64, from.y as f64);
        assert!(!curves.at_point(q).is_empty(), "{uv} + {from} off the line");
        assert!(
            (q - uv).dot(axis).abs() < 1e-6,
            "not level with the hit: {uv} {q}"
        );
        lobes += 1;
        // The point test's hit on the line goes on from itself.
        if !curves.at_point(uv).is_empty() {
            if let Some(s) = bsdf_of(&point, &ctx).sample(wo, rng.random(), u) {
                assert_eq!(s.from, None);
            }
        }
    }
    assert!(
        lobes > 200 && bases > 200,
        "{lobes} lobe and {bases} base samples"
    );
}
