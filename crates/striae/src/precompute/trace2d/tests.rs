//! Tests of the 2D trace as a whole: energy, closed forms, determinism, settings.

use super::*;

fn small(walls: Walls) -> TraceSettings {
    TraceSettings {
        walls,
        m: 32,
        n: 2000,
        nr: 8,
        ..TraceSettings::default()
    }
}

/// Sum over `phi_o` of `rho_m cos(phi_o) pi/M`: the 2D albedo of row `i`.
fn albedo_2d(rho: &[f64], m: usize, i: usize) -> f64 {
    (0..m)
        .map(|j| rho[i * m + j] * bin_centre(j, m).cos() * PI / m as f64)
        .sum()
}

#[test]
fn lossless_profiles_conserve_energy() {
    for spec in [
        "v:angle=90",
        "round:depth=0.4",
        "trapezoid:depth=0.3,bottom=0.2",
        "v:depth=2",
    ] {
        let p = Profile::parse(spec).unwrap();
        for walls in [Walls::Specular, Walls::Diffuse] {
            let out = trace(&p, &small(walls), &|_| {}).unwrap();
            for i in 0..out.m {
                let a = albedo_2d(&out.rho_m, out.m, i);
                let dropped = out.dropped[i];
                assert!(
                    out.lost[i] == 0.0,
                    "{spec} {walls:?} row {i} lost {}",
                    out.lost[i]
                );
                assert!(
                    (a + dropped - 1.0).abs() < 1e-9,
                    "{spec} {walls:?} row {i}: {a} + {dropped}"
                );
                assert!(
                    dropped < 1e-3,
                    "{spec} {walls:?} row {i}: dropped {dropped}"
                );
            }
        }
    }
}

#[test]
fn albedo_scales_energy() {
    // A flat profile: one bounce each, so the 2D albedo is exactly the facet albedo.
    let s = TraceSettings {
        albedo: 0.7,
        ..small(Walls::Diffuse)
    };
    let out = trace(&Profile::flat(), &s, &|_| {}).unwrap();
    for i in 0..out.m {
        assert!((albedo_2d(&out.rho_m, out.m, i) - 0.7).abs() < 1e-9);
    }
}

#[test]
fn flat_diffuse_is_one_half() {
    // sin(a) uniform: P(phi_o in bin j) = (sin b_{j+1} - sin b_j)/2 ~ cos(phi_j) (pi/M)/2,
    // so eq. (1') gives 1/2 per bin. Compare with the exact bin integral, within MC error.
    let m = 16;
    let s = TraceSettings {
        walls: Walls::Diffuse,
        m,
        n: 4000,
        nr: 16,
        ..TraceSettings::default()
    };
    let out = trace(&Profile::flat(), &s, &|_| {}).unwrap();
    let walks = (s.n * s.nr) as f64;
    let mut max_z = 0.0f64;
    for i in 0..m {
        for j in 0..m {
            let lo = -FRAC_PI_2 + j as f64 * PI / m as f64;
            let hi = lo + PI / m as f64;
            let p = (hi.sin() - lo.sin()) / 2.0;
            let norm = m as f64 / (PI * bin_centre(j, m).cos());
            let expect = p * norm;
            let sigma = (p * (1.0 - p) / walks).sqrt() * norm;
            let z = (out.rho_m[i * m + j] - expect) / sigma;
            max_z = max_z.max(z.abs());
            // And the binning approximation is close to 1/2.
            assert!((expect - 0.5).abs() < 0.01, "{expect}");
        }
    }
    assert!(max_z < 5.0, "max |z| = {max_z}");
}

#[test]
fn flat_mirror_reflects_into_mirror_bin() {
    let s = small(Walls::Specular);
    let out = trace(&Profile::flat(), &s, &|_| {}).unwrap();
    let m = s.m;
    for i in 0..m {
        for j in 0..m {
            let v = out.rho_m[i * m + j];
            if j == m - 1 - i {
                assert!((v * bin_centre(j, m).cos() * PI / m as f64 - 1.0).abs() < 1e-12);
            } else {
                assert_eq!(v, 0.0);
            }
        }
    }
}

/// A 90-degree mirror V-groove (depth 1/2): left wall L `z = -x - 1/2` (x <= 0), right
/// wall R `z = x - 1/2`. Reflection off L maps `(dx, dz) -> (-dz, -dx)`, off R
/// `(dx, dz) -> (dz, dx)`; two reflections (one off each wall) give `-d`: retroreflection,
/// `phi_o = phi_i` exactly. Take `0 < phi < pi/4`, direction `d = -(sin phi, cos phi)`,
/// entry `x0` uniform in [-1/2, 1/2].
/// * The ray crosses `x = 0` at `z = -x0 cot phi`, above the bottom iff `x0 < tan(phi)/2`:
///   then it hits L first (case A), else R first (case B).
/// * Case B: off R it travels `(-cos phi, -sin phi)`, must hit L, leaves as `(sin phi,
///   cos phi)`; along that direction `z - x` grows, so it never meets R again: retro.
/// * Case A: L is hit at `s = (x0 + 1/2)/(sin phi + cos phi)`, `xh + 1/2 = (x0 + 1/2) cos
///   phi / (sin phi + cos phi)`; it then travels `(cos phi, sin phi)` and reaches z = 0 at
///   `x = xh + (xh + 1/2) cot phi`, which is `<= 1/2` (escape after one bounce, out at
///   `phi_o = pi/2 - phi`, another bin) iff `x0 + 1/2 <= tan phi`; otherwise it hits R and
///   leaves retroreflected (steep, moving away from both walls).
///
/// Retroreflected fraction: `(1/2 - tan(phi)/2) + (tan(phi)/2 - (tan(phi) - 1/2)) =
/// 1 - tan(phi)`; for `phi >= pi/4` both ranges are empty: 0. By symmetry, for any phi:
/// `max(0, 1 - tan |phi|)`.
#[test]
fn mirror_v_groove_retroreflects_the_two_wall_fraction() {
    let m = 64;
    let s = TraceSettings {
        walls: Walls::Specular,
        m,
        n: 20_000,
        ..TraceSettings::default()
    };
    let out = trace(&Profile::parse("v:angle=90").unwrap(), &s, &|_| {}).unwrap();
    for i in 0..m {
        let phi = bin_centre(i, m);
        let retro = out.rho_m[i * m + i] * phi.cos() * PI / m as f64;
        let expect = (1.0 - phi.abs().tan()).max(0.0);
        // Stratified entries: error at most a couple of strata.
        assert!(
            (retro - expect).abs() < 3.0 / s.n as f64,
            "phi {phi}: {retro} vs {expect}"
        );
    }
}

#[test]
fn deterministic_across_thread_counts() {
    let p = Profile::parse("round:depth=0.35").unwrap();
    let s = TraceSettings {
        m: 16,
        n: 600,
        nr: 4,
        fresnel_mode: FresnelMode::Walls,
        seed: 42,
        ..TraceSettings::default()
    };
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| trace(&p, &s, &|_| {}).unwrap())
    };
    let a = run(1);
    let b = run(3);
    assert_eq!(a, b);
    // And a different seed changes the output.
    let c = trace(
        &p,
        &TraceSettings {
            seed: 43,
            ..s.clone()
        },
        &|_| {},
    )
    .unwrap();
    assert_ne!(a.rho_m, c.rho_m);
}

#[test]
fn walls_fresnel_for_mirrors_at_grazing_slice_is_lossless() {
    // Slice theta = pi/2 has incidence cosine 0: Schlick gives F = 1, so the slice equals
    // rho_m; slice 0 of a flat mirror is exactly F(cos phi_i).
    let s = TraceSettings {
        fresnel_mode: FresnelMode::Walls,
        ..small(Walls::Specular)
    };
    let out = trace(&Profile::flat(), &s, &|_| {}).unwrap();
    let m = s.m;
    let w = out.rho_walls.unwrap();
    for i in 0..m {
        for j in 0..m {
            assert_eq!(w[2 * m * m + i * m + j], out.rho_m[i * m + j]);
            let f = crate::optics::fresnel::schlick(1.5, bin_centre(i, m).cos());
            assert!(
                (w[i * m + j] - f * out.rho_m[i * m + j]).abs()
                    < 1e-9 * out.rho_m[i * m + j].max(1.0)
            );
        }
    }
}

#[test]
fn invalid_settings_rejected() {
    let p = Profile::flat();
    let base = small(Walls::Diffuse);
    for s in [
        TraceSettings {
            m: 0,
            ..base.clone()
        },
        TraceSettings {
            n: 0,
            ..base.clone()
        },
        TraceSettings {
            nr: 0,
            ..base.clone()
        },
        TraceSettings {
            albedo: 1.5,
            ..base.clone()
        },
        TraceSettings {
            albedo: f64::NAN,
            ..base.clone()
        },
        TraceSettings {
            max_bounces: 0,
            ..base.clone()
        },
        TraceSettings {
            fresnel_law: FresnelLaw::Schlick { n: -1.0 },
            ..base.clone()
        },
        TraceSettings {
            fresnel_law: FresnelLaw::Conductor {
                eta: 0.2,
                k: f64::INFINITY,
            },
            ..base.clone()
        },
    ] {
        assert!(trace(&p, &s, &|_| {}).is_err(), "{s:?}");
    }
}
