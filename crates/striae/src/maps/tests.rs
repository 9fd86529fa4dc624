//! Tests of painted scratch maps (METHOD.md 9.5): the pyramid's means, the doubled-angle
//! filtering, the structure tensor's direction of a painted line, the flow map's decoding, the
//! footprint's level and the errors.

use super::*;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

/// A `width x height` map holding a band of coverage 1 and width `w` texels through the centre
/// at `theta_deg` (from `+x` toward `+y`, in texels), antialiased by 8 x 8 supersampling.
fn band(width: usize, height: usize, theta_deg: f32, w: f32) -> Vec<f32> {
    let (s, c) = theta_deg.to_radians().sin_cos();
    let centre = Vec2::new(width as f32, height as f32) * 0.5;
    let mut out = vec![0.0; width * height];
    for y in 0..height {
        for x in 0..width {
            let mut inside = 0;
            for j in 0..8 {
                for i in 0..8 {
                    let p = Vec2::new(
                        x as f32 + (i as f32 + 0.5) / 8.0,
                        y as f32 + (j as f32 + 0.5) / 8.0,
                    ) - centre;
                    // Distance across the line.
                    if (-s * p.x + c * p.y).abs() < 0.5 * w {
                        inside += 1;
                    }
                }
            }
            out[y * width + x] = inside as f32 / 64.0;
        }
    }
    out
}

/// Angle between two scratch directions in degrees, in `[0, 90]` (a direction has no sign).
fn angle_between(a: Vec2, b: Vec2) -> f32 {
    let c = (a.normalize().dot(b.normalize())).abs().min(1.0);
    c.acos().to_degrees()
}

#[test]
fn each_level_is_the_mean_of_its_four_children() {
    let mut rng = Pcg64::seed_from_u64(3);
    for (w, h) in [(16, 8), (32, 32), (7, 5)] {
        let cov: Vec<f32> = (0..w * h).map(|_| rng.random::<f32>()).collect();
        let flow: Vec<[f32; 2]> = (0..w * h).map(|_| [rng.random(), rng.random()]).collect();
        for flow in [None, Some(&flow[..])] {
            let m = ScratchMap::new(w, h, &cov, flow, 1.0).unwrap();
            let levels = m.levels();
            let last = levels.last().unwrap();
            assert_eq!((last.width, last.height), (1, 1));
            for pair in levels.windows(2) {
                let (fine, coarse) = (&pair[0], &pair[1]);
                assert_eq!(coarse.width, fine.width.div_ceil(2));
                assert_eq!(coarse.height, fine.height.div_ceil(2));
                for j in 0..coarse.height {
                    for i in 0..coarse.width {
                        for k in 0..3 {
                            let mut sum = 0.0f64;
                            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                                let x = (2 * i + dx).min(fine.width - 1);
                                let y = (2 * j + dy).min(fine.height - 1);
                                sum += fine.texels[y * fine.width + x][k] as f64;
                            }
                            let got = coarse.texels[j * coarse.width + i][k] as f64;
                            assert!((got - sum / 4.0).abs() < 1e-6, "{w}x{h} {i},{j},{k}");
                        }
                    }
                }
            }
            // Power-of-two sizes: the 1 x 1 level is the map's mean.
            if w.is_power_of_two() && h.is_power_of_two() {
                let mean = cov.iter().map(|&c| c as f64).sum::<f64>() / cov.len() as f64;
                assert!((last.texels[0][0] as f64 - mean).abs() < 1e-5);
            }
        }
    }
}

#[test]
fn doubled_angles_keep_opposite_directions_and_cancel_perpendicular_ones() {
    // Two texels of coverage 1, their flow directions at `theta` and `theta + delta`.
    let rg = |theta: f32| {
        let (s, c) = theta.sin_cos();
        [0.5 * (c + 1.0), 0.5 * (s + 1.0)]
    };
    for theta_deg in [0.0f32, 30.0, 75.0, 120.0] {
        let theta = theta_deg.to_radians();
        let expect = Vec2::new(theta.cos(), theta.sin());
        // Opposite: the same scratch. Averaged as vectors they would cancel.
        let flow = [rg(theta), rg(theta + std::f32::consts::PI)];
        let m = ScratchMap::new(2, 1, &[1.0, 1.0], Some(&flow), 1.0).unwrap();
        let s = MapSample::from_texel(m.levels()[1].texels[0]);
        assert_eq!(s.coverage, 1.0);
        assert!((s.anisotropy() - 1.0).abs() < 1e-5, "{}", s.anisotropy());
        assert!(angle_between(s.direction(), expect) < 0.01, "{theta_deg}");
        // Perpendicular: no anisotropy.
        let flow = [rg(theta), rg(theta + std::f32::consts::FRAC_PI_2)];
        let m = ScratchMap::new(2, 1, &[1.0, 1.0], Some(&flow), 1.0).unwrap();
        let s = MapSample::from_texel(m.levels()[1].texels[0]);
        assert!(s.anisotropy() < 1e-5, "{}", s.anisotropy());
        // Weighted by coverage: 3/4 of one and 1/4 of the perpendicular, anisotropy 1/2.
        let m = ScratchMap::new(2, 1, &[0.75, 0.25], Some(&flow), 1.0).unwrap();
        let s = MapSample::from_texel(m.levels()[1].texels[0]);
        assert!((s.coverage - 0.5).abs() < 1e-6);
        assert!((s.anisotropy() - 0.5).abs() < 1e-5);
        assert!(angle_between(s.direction(), expect) < 0.01);
    }
    // The drawn directions' doubled-angle mean is the filtered orientation.
    let s = MapSample {
        coverage: 1.0,
        orientation: Vec2::new(0.0, 0.4),
    };
    let n = 20000;
    let mean = (0..n)
        .map(|i| doubled(s.draw_direction((i as f32 + 0.5) / n as f32)))
        .fold(Vec2::ZERO, |a, b| a + b)
        / n as f32;
    assert!((mean - s.orientation).length() < 2e-3, "{mean:?}");
}

#[test]
fn the_structure_tensor_runs_along_a_painted_line() {
    for theta_deg in [0.0f32, 17.0, 45.0, 60.0, 90.0, 133.0, 170.0] {
        for width in [3.0f32, 12.0] {
            let (w, h) = (128, 128);
            let cov = band(w, h, theta_deg, width);
            let m = ScratchMap::new(w, h, &cov, None, 1.0).unwrap();
            assert_eq!(m.frame(), DirectionFrame::Uv);
            let expect = Vec2::new(theta_deg.to_radians().cos(), theta_deg.to_radians().sin());
            // Every texel of the band near the centre, and the band's filtered mean.
            let mut worst = 0.0f32;
            for y in 40..88 {
                for x in 40..88 {
                    if cov[y * w + x] < 0.5 {
                        continue;
                    }
                    let uv = Vec2::new((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
                    let s = m.at_point(uv);
                    worst = worst.max(angle_between(s.direction(), expect));
                    assert!(
                        s.anisotropy() > 0.9,
                        "{theta_deg} {width}: {}",
                        s.anisotropy()
                    );
                }
            }
            eprintln!("theta {theta_deg}, width {width}: worst {worst} degrees");
            assert!(
                worst < 1.0,
                "theta {theta_deg}, width {width}: {worst} degrees"
            );
            // Seen from far: 8 texels a pixel.
            let f = m.filtered(
                Vec2::splat(0.5),
                Vec2::new(8.0 / 128.0, 0.0),
                Vec2::new(0.0, 8.0 / 128.0),
            );
            assert!(
                angle_between(f.direction(), expect) < 2.0,
                "{theta_deg}: {:?}",
                f.direction()
            );
        }
    }
    // A non-square map: the level sets' direction on uv.
    let (w, h) = (256, 64);
    let cov = band(w, h, 30.0, 4.0);
    let m = ScratchMap::new(w, h, &cov, None, 1.0).unwrap();
    let t = Vec2::new(
        30f32.to_radians().cos() / w as f32,
        30f32.to_radians().sin() / h as f32,
    );
    let s = m.at_point(Vec2::splat(0.5));
    assert!(
        angle_between(s.direction(), t) < 2.0,
        "{:?} vs {t:?}",
        s.direction()
    );
}

#[test]
fn flow_maps_decode_2rg_minus_1() {
    assert_eq!(flow_direction([1.0, 0.5]), Vec2::new(1.0, 0.0));
    assert_eq!(flow_direction([0.5, 1.0]), Vec2::new(0.0, 1.0));
    assert_eq!(flow_direction([0.0, 0.5]), Vec2::new(-1.0, 0.0));
    assert_eq!(flow_direction([0.25, 0.75]), Vec2::new(-0.5, 0.5));
    // A map with a flow map at 90 degrees: the direction is v, whatever the map's structure
    // (here a band along u).
    let (w, h) = (32, 32);
    let cov = band(w, h, 0.0, 4.0);
    let flow = vec![[0.5, 1.0]; w * h];
    let m = ScratchMap::new(w, h, &cov, Some(&flow), 1.0).unwrap();
    assert_eq!(m.frame(), DirectionFrame::Tangent);
    let s = m.at_point(Vec2::splat(0.5));
    assert!(angle_between(s.direction(), Vec2::Y) < 1e-3);
    // A zero flow vector (rg = 1/2) carries no direction.
    let m = ScratchMap::new(1, 1, &[1.0], Some(&[[0.5, 0.5]]), 1.0).unwrap();
    assert_eq!(m.at_point(Vec2::splat(0.5)).anisotropy(), 0.0);
}

#[test]
fn the_footprint_picks_the_level_and_the_scale_tiles() {
    let (w, h) = (64, 64);
    let cov: Vec<f32> = (0..w * h).map(|i| ((i % w) / 8 % 2) as f32).collect();
    let m = ScratchMap::new(w, h, &cov, None, 1.0).unwrap();
    let px = |t: f32| (Vec2::new(t / 64.0, 0.0), Vec2::new(0.0, t / 64.0));
    for (t, level) in [
        (0.5, 0.0),
        (1.0, 0.0),
        (2.0, 1.0),
        (4.0, 2.0),
        (8.0, 3.0),
        (1e6, 6.0),
    ] {
        let (a, b) = px(t);
        assert!((m.level_of(a, b) - level).abs() < 1e-5, "{t}");
    }
    // Stripes 8 texels wide seen 16 texels a pixel: half covered.
    let (a, b) = px(16.0);
    let s = m.filtered(Vec2::new(0.3, 0.7), a, b);
    assert!((s.coverage - 0.5).abs() < 1e-5, "{}", s.coverage);
    // Point lookups hit the stripes; `map_scale = 2` repeats them twice as often.
    let at = |m: &ScratchMap, u: f32| m.at_point(Vec2::new(u, 0.5)).coverage;
    assert_eq!(at(&m, 12.0 / 64.0), 1.0);
    assert_eq!(at(&m, 4.0 / 64.0), 0.0);
    let m2 = ScratchMap::new(w, h, &cov, None, 2.0).unwrap();
    assert_eq!(at(&m2, 6.0 / 64.0), 1.0);
    assert_eq!(at(&m2, 2.0 / 64.0), 0.0);
    // The map repeats.
    assert_eq!(at(&m, 12.0 / 64.0 + 3.0), 1.0);
}

#[test]
fn bad_values_sizes_and_scales_are_errors_naming_the_pixel() {
    let e = ScratchMap::new(2, 2, &[0.0, 0.5, 1.5, 0.0], None, 1.0).unwrap_err();
    assert!(
        matches!(
            e,
            MapError::Pixel {
                image: "map",
                x: 0,
                y: 1,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("(0, 1)"), "{e}");
    let e = ScratchMap::new(2, 1, &[f32::NAN, 0.0], None, 1.0).unwrap_err();
    assert!(matches!(e, MapError::Pixel { x: 0, y: 0, .. }), "{e}");
    let flow = [[0.5, 0.5], [0.5, -0.1]];
    let e = ScratchMap::new(2, 1, &[1.0, 1.0], Some(&flow), 1.0).unwrap_err();
    assert!(
        matches!(
            e,
            MapError::Pixel {
                image: "direction",
                x: 1,
                y: 0,
                ..
            }
        ),
        "{e}"
    );
    let e = ScratchMap::new(2, 1, &[1.0, 1.0], Some(&flow[..1]), 1.0).unwrap_err();
    assert!(e.to_string().contains("map's size"), "{e}");
    assert!(ScratchMap::new(0, 1, &[], None, 1.0).is_err());
    for s in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e300] {
        assert!(matches!(
            ScratchMap::new(1, 1, &[1.0], None, s).unwrap_err(),
            MapError::Scale(_)
        ));
    }
    let big = (crate::io::MAX_IMAGE_PIXELS as usize).isqrt() + 1;
    let e = ScratchMap::new(big, big, &[], None, 1.0).unwrap_err();
    assert!(e.to_string().contains("limit"), "{e}");
}
