use super::*;
use crate::math::Vec3;
use crate::testing::{chi2_sphere, SphereGrid};
use rand::{Rng, SeedableRng};

fn dir(theta_deg: f64, phi_deg: f64) -> [f64; 3] {
    let (st, ct) = theta_deg.to_radians().sin_cos();
    let (sp, cp) = phi_deg.to_radians().sin_cos();
    [st * cp, st * sp, ct]
}

fn to_vec3(w: [f64; 3]) -> Vec3 {
    Vec3::new(w[0] as f32, w[1] as f32, w[2] as f32)
}

/// The isotropic GGX distribution of normals, written out here from Walter et al. 2007 eq. 33.
fn ggx_d(alpha: f64, m: [f64; 3]) -> f64 {
    if m[2] <= 0.0 {
        return 0.0;
    }
    let c2 = m[2] * m[2];
    let t2 = (1.0 - c2) / c2;
    let a2 = alpha * alpha;
    a2 / (PI * c2 * c2 * (a2 + t2).powi(2))
}

fn ggx_lambda(alpha: f64, w: [f64; 3]) -> f64 {
    let c2 = w[2] * w[2];
    0.5 * (-1.0 + (1.0 + alpha * alpha * (1.0 - c2) / c2).sqrt())
}

/// The sampler of visible normals against its density `max(0, v.m) D(m) / ((1 + Lambda(v))
/// v.z)` (Heitz 2018 eq. 1, whose normalisation holds for `v` below the horizon with the signed
/// `Lambda`), for views above and below the horizon: the walk meets facets from below.
#[test]
fn visible_normals_follow_their_density_from_above_and_below() {
    let grid = SphereGrid::new(32, 64);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
    for alpha in [0.3, 0.6, 1.0] {
        let s = Microsurface::new(alpha);
        for theta in [0.0, 40.0, 80.0, 100.0, 140.0] {
            let v = dir(theta, 30.0);
            let area = (1.0 + s.lambda(v)) * v[2];
            let r = chi2_sphere(
                &grid,
                200_000,
                || Some(to_vec3(s.sample_visible(v, rng.random(), rng.random()))),
                |m| {
                    let m = [m.x as f64, m.y as f64, m.z as f64];
                    dot(v, m).max(0.0) * ggx_d(alpha, m) / area
                },
            );
            assert!(
                r.p_value > 1e-3 && (r.pdf_mass - 1.0).abs() < 0.01,
                "alpha {alpha}, theta {theta}: {r:?}"
            );
        }
    }
}

/// The walk's first event is the single-scattering BSDF with height-correlated masking and
/// shadowing (Heitz16 sec. 5.3): the directions of the walks that leave after one event
/// follow `D(h) / (4 cos_i (1 + Lambda(wi) + Lambda(wo)))`, written out independently here.
#[test]
fn first_event_is_the_height_correlated_single_scattering_lobe() {
    let grid = SphereGrid::new(32, 64);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
    for (alpha, theta) in [(0.2, 30.0), (0.5, 0.0), (0.5, 60.0), (1.0, 75.0)] {
        let s = Microsurface::new(alpha);
        let wi = dir(theta, 0.0);
        let r = chi2_sphere(
            &grid,
            200_000,
            || {
                let mut u = || rng.random::<f64>();
                let e = s.walk_conductor(wi, |_| 1.0, &mut u)?;
                (e.order == 1).then(|| to_vec3(e.w))
            },
            |o| {
                let o = [o.x as f64, o.y as f64, o.z as f64];
                if o[2] <= 0.0 {
                    return 0.0;
                }
                let h = normalize([wi[0] + o[0], wi[1] + o[1], wi[2] + o[2]]);
                let g2 = 1.0 / (1.0 + ggx_lambda(alpha, wi) + ggx_lambda(alpha, o));
                ggx_d(alpha, h) * g2 / (4.0 * wi[2])
            },
        );
        assert!(r.p_value > 1e-3, "alpha {alpha}, theta {theta}: {r:?}");
    }
}

/// Facets that lose nothing make a microsurface that loses nothing: a conductor with `F = 1`
/// and a dielectric, from either side, leave every walk (none reaches [`MAX_ORDER`]), up for
/// the conductor, with weight 1; a conductor's weight is the product of its facets'
/// reflectances, so `F = 0.5` halves a single-scattering walk.
#[test]
fn lossless_facets_make_a_lossless_surface() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
    let mut u = || rng.random::<f64>();
    for alpha in [0.05, 0.2, 0.5, 1.0] {
        let s = Microsurface::new(alpha);
        for theta in [0.0, 30.0, 60.0, 85.0, 89.0] {
            let wi = dir(theta, 10.0);
            let mut orders = 0u64;
            for _ in 0..20_000 {
                let e = s.walk_conductor(wi, |_| 1.0, &mut u).unwrap();
                assert!(e.w[2] > 0.0 && e.weight == 1.0, "{alpha} {theta}: {e:?}");
                orders += e.order as u64;
                let half = s.walk_conductor(wi, |_| 0.5, &mut u).unwrap();
                assert_eq!(half.weight, 0.5f64.powi(half.order as i32));
                for eta in [1.5, 1.0 / 1.5] {
                    let e = s.walk_dielectric(wi, eta, &mut u).unwrap();
                    assert!(e.weight == 1.0 && e.w[2] != 0.0, "{alpha} {theta}: {e:?}");
                }
            }
            let mean = orders as f64 / 20_000.0;
            assert!((1.0..3.0).contains(&mean), "{alpha} {theta}: {mean}");
        }
    }
}

/// A direction uniform (in solid angle) in the cone of half-angle `half` degrees around `axis`.
fn in_cone(axis: [f64; 3], half: f64, u0: f64, u1: f64) -> [f64; 3] {
    let c = 1.0 - u0 * (1.0 - half.to_radians().cos());
    let s = (1.0 - c * c).sqrt();
    let (sp, cp) = (2.0 * PI * u1).sin_cos();
    let t = if axis[2].abs() < 0.9 {
        [0.0, 0.0, 1.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let x = normalize(cross(axis, t));
    let y = cross(axis, x);
    normalize([
        s * cp * x[0] + s * sp * y[0] + c * axis[0],
        s * cp * x[1] + s * sp * y[1] + c * axis[1],
        s * cp * x[2] + s * sp * y[2] + c * axis[2],
    ])
}

/// The flux from cone `a` (light arriving from its directions, radiance 1) into cone `b`, per
/// unit solid angle of `a`: the mean of `|cos_i| 1[exit in b] weight` over directions uniform in
/// `a`. Reciprocity makes `flux(a -> b)` and `flux(b -> a)` equal (scaled by `n_b^2 / n_a^2`
/// through an interface), whatever the cones' sizes.
fn flux(
    walk: &mut impl FnMut([f64; 3]) -> Option<WalkExit>,
    a: [f64; 3],
    b: [f64; 3],
    half: f64,
    n: usize,
    u: &mut impl FnMut() -> f64,
) -> f64 {
    let cos_half = half.to_radians().cos();
    let mut sum = 0.0;
    for _ in 0..n {
        let wi = in_cone(a, half, u(), u());
        if let Some(e) = walk(wi) {
            if dot(e.w, b) > cos_half {
                sum += wi[2].abs() * e.weight;
            }
        }
    }
    sum / n as f64
}

/// Multiple scattering keeps the Smith model's reciprocity (Heitz16 sec. 6.4), which no event
/// of the walk states on its own: the flux from one cone of directions into another equals the
/// flux back for the conductor (a rough copper-like Schlick law), and is `n_o^2 / n_i^2 = 2.25`
/// times it through glass of index 1.5 (generalised reciprocity), for `alpha` 0.3 and 0.8.
#[test]
fn multiple_scattering_is_reciprocal() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(6);
    let mut rng_dir = rand_pcg::Pcg64::seed_from_u64(7);
    let mut u = || rng.random::<f64>();
    let mut v = || rng_dir.random::<f64>();
    let n = 1_000_000;
    let copper = |c: f64| crate::optics::fresnel::schlick(8.0, c);
    // Air above, glass below: `a` in the air, `c` in the glass. From the glass, the frame is
    // flipped so that the glass is above (index ratio 1 / 1.5).
    let flip = |w: [f64; 3]| [w[0], w[1], -w[2]];
    let (a, b, c) = (dir(20.0, 0.0), dir(65.0, 120.0), dir(150.0, 200.0));
    for alpha in [0.3, 0.8] {
        let s = Microsurface::new(alpha);
        let ab = flux(
            &mut |w| s.walk_conductor(w, copper, &mut u),
            a,
            b,
            10.0,
            n,
            &mut v,
        );
        let ba = flux(
            &mut |w| s.walk_conductor(w, copper, &mut u),
            b,
            a,
            10.0,
            n,
            &mut v,
        );
        assert!((ab / ba - 1.0).abs() < 0.03, "conductor {alpha}: {ab} {ba}");
        let ac = flux(
            &mut |w| s.walk_dielectric(w, 1.5, &mut u),
            a,
            c,
            10.0,
            n,
            &mut v,
        );
        let ca = flux(
            &mut |w| s.walk_dielectric(w, 1.0 / 1.5, &mut u),
            flip(c),
            flip(a),
            10.0,
            n,
            &mut v,
        );
        assert!(
            (ac / ca / 2.25 - 1.0).abs() < 0.03,
            "dielectric {alpha}: {ac} {ca}"
        );
    }
}
