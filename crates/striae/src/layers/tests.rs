//! Tests of the layer set against METHOD.md section 5: determinism, coverage ~ pi tau^2,
//! orientation and scratch size measured on rasters, and procedural queries against rasters.

use super::cache::{PixelKey, PIXEL_CLUSTERS};
use super::*;
use crate::testing::MeanEstimate;
use glam::DVec2;
use rand::{Rng, SeedableRng};
use std::f64::consts::PI;

fn params(length: f64, width: f64, threshold: f64, layers: usize) -> LayerParams {
    LayerParams {
        length,
        width,
        threshold,
        layers,
    }
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

#[test]
fn same_seed_gives_bit_identical_layers_whatever_the_thread_count() {
    let p = LayerParams::setting(1).unwrap();
    let a = LayerSet::new(p, 42).unwrap();
    let b = LayerSet::new(p, 42).unwrap();
    let c = LayerSet::new(p, 43).unwrap();
    for k in 0..a.len() {
        assert_eq!(
            a.layers()[k].angle().to_bits(),
            b.layers()[k].angle().to_bits()
        );
        assert_ne!(a.layers()[k].angle(), c.layers()[k].angle());
    }
    let bits = |r: &CoverageRaster| r.level(0).1.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    for k in [0, 5] {
        let one = in_pool(1, || a.rasterize(k, 300).unwrap());
        let many = in_pool(4, || b.rasterize(k, 300).unwrap());
        assert_eq!(bits(&one), bits(&many), "layer {k}");
        assert!(one.mean() > 0.0);
        let other = c.rasterize(k, 300).unwrap();
        assert_ne!(bits(&one), bits(&other));
    }
    // A set with more layers keeps the first ones.
    let more = LayerSet::new(LayerParams { layers: 12, ..p }, 42).unwrap();
    assert_eq!(more.direction(3), a.direction(3));
}

/// Coverage: each layer's measured coverage (raster mean) must match the expected coverage
/// `E(tau)` (exact mean over the hash, `footprint::expected_coverage`) within 4 standard errors
/// of the mean over 16 independent layers; and `E(tau)` is `pi tau^2` less the overlaps, within
/// 3 % at tau = 0.1 (5 % at 0.2). The standard error itself must be small (< 3 % of E), so the
/// test has the power to see a wrong threshold or a wrong stretch.
#[test]
fn coverage_follows_pi_tau_squared() {
    for (tau, rel) in [(0.1, 0.03), (0.2, 0.05)] {
        let set = LayerSet::new(params(0.02, 0.015, tau, 16), 7).unwrap();
        let e = set.expected_coverage();
        assert!(
            (e / (PI * tau * tau) - 1.0).abs() < rel && e < PI * tau * tau,
            "E {e}"
        );
        let mut m = MeanEstimate::default();
        for k in 0..set.len() {
            m.push(set.rasterize(k, 200).unwrap().mean());
        }
        assert!(m.std_error() < 0.03 * e, "se {}", m.std_error());
        assert!(
            m.agrees_with(e, 4.0, 0.0),
            "tau {tau}: measured {} +- {} vs expected {e}",
            m.mean(),
            m.std_error()
        );
    }
}

/// Orientation from a raster: the structure tensor of the coverage image (gradients summed as
/// outer products) has its dominant eigenvector across the scratches, so the scratches run at
/// that angle + pi/2. It must match alpha (mod pi, the raster cannot tell d from -d) within
/// 1° (measured: 0.1° to 0.6°; the box anti-aliasing smears the scratch tips along the texel
/// axes a little). Gradients are derivative-of-Gaussian filters (sigma 2 texels): plain finite differences
/// of lines thinner than their stencil are anisotropic and bias the angle by degrees.
#[test]
fn orientation_measured_on_the_raster_matches_alpha() {
    let set = LayerSet::new(LayerParams::setting(2).unwrap(), 3).unwrap();
    let res = 384;
    let (sigma, rad) = (2.0f64, 8i64);
    let g: Vec<f64> = (-rad..=rad)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let dg: Vec<f64> = (-rad..=rad)
        .zip(&g)
        .map(|(i, w)| -(i as f64) / (sigma * sigma) * w)
        .collect();
    // Separable convolution: kernel kx along x (columns), ky along y (rows).
    let conv = |img: &[f64], kx: &[f64], ky: &[f64]| -> Vec<f64> {
        let mut tmp = vec![0.0; res * res];
        for y in 0..res {
            for x in rad as usize..res - rad as usize {
                tmp[y * res + x] = kx
                    .iter()
                    .enumerate()
                    .map(|(t, w)| w * img[y * res + x + t - rad as usize])
                    .sum();
            }
        }
        let mut out = vec![0.0; res * res];
        for y in rad as usize..res - rad as usize {
            for x in 0..res {
                out[y * res + x] = ky
                    .iter()
                    .enumerate()
                    .map(|(t, w)| w * tmp[(y + t - rad as usize) * res + x])
                    .sum();
            }
        }
        out
    };
    let mut angles = Vec::new();
    for k in 0..6 {
        let r = set.rasterize(k, res).unwrap();
        let img: Vec<f64> = r.level(0).1.iter().map(|&c| c as f64).collect();
        // d/dx of the image is the convolution with -G'; rows run down while v runs up.
        let gx = conv(&img, &dg, &g);
        let gy = conv(&img, &g, &dg);
        let (mut j11, mut j12, mut j22) = (0.0f64, 0.0f64, 0.0f64);
        let m = rad as usize + 1;
        for y in m..res - m {
            for x in m..res - m {
                let (gu, gv) = (-gx[y * res + x], gy[y * res + x]);
                j11 += gu * gu;
                j12 += gu * gv;
                j22 += gv * gv;
            }
        }
        let across = 0.5 * (2.0 * j12).atan2(j11 - j22);
        let along = across + PI / 2.0;
        let alpha = set.layers()[k].angle();
        let diff = (along - alpha).rem_euclid(PI);
        let diff = diff.min(PI - diff);
        assert!(
            diff < 1f64.to_radians(),
            "layer {k}: measured {along} vs alpha {alpha}"
        );
        angles.push(alpha.rem_euclid(PI));
    }
    // The layers really point different ways, so the check covers more than one angle.
    let spread = angles.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
        - angles.iter().cloned().fold(f64::INFINITY, f64::min);
    assert!(spread > 0.5, "angles {angles:?}");
}

/// Size of isolated scratches measured on the raster: connected components of non-zero texels
/// not touching the border; for each, the coverage-weighted covariance gives the major
/// half-axis `a = 2 sqrt(lambda_max)` (a uniform ellipse has variance a^2/4 along its axis) and
/// the summed coverage its area, hence the minor half-axis `b = area / (pi a)` (exact even below
/// a texel, thanks to the anti-aliasing). The medians over all components (merged crossings are
/// rare outliers) must match `2 tau L` and `2 tau W` within 2 % and 4 %.
#[test]
fn scratch_length_and_width_measured_on_the_raster() {
    for (p, res) in [
        (LayerParams::setting(2).unwrap(), 1024),
        (params(0.25, 0.02, 0.15, 1), 512),
    ] {
        let set = LayerSet::new(p, 11).unwrap();
        for k in 0..set.len().min(2) {
            let r = set.rasterize(k, res).unwrap();
            let (mut lengths, mut widths) = (Vec::new(), Vec::new());
            let mut seen = vec![false; res * res];
            for start in 0..res * res {
                if seen[start] || r.level(0).1[start] == 0.0 {
                    continue;
                }
                let (mut stack, mut pix, mut border) = (vec![start], Vec::new(), false);
                seen[start] = true;
                while let Some(i) = stack.pop() {
                    let (x, y) = ((i % res) as i64, (i / res) as i64);
                    pix.push(i);
                    border |= x == 0 || y == 0 || x == res as i64 - 1 || y == res as i64 - 1;
                    for (dx, dy) in [
                        (-1, -1),
                        (0, -1),
                        (1, -1),
                        (-1, 0),
                        (1, 0),
                        (-1, 1),
                        (0, 1),
                        (1, 1),
                    ] {
                        let (nx, ny) = (x + dx, y + dy);
                        if nx >= 0 && ny >= 0 && nx < res as i64 && ny < res as i64 {
                            let n = (ny * res as i64 + nx) as usize;
                            if !seen[n] && r.level(0).1[n] > 0.0 {
                                seen[n] = true;
                                stack.push(n);
                            }
                        }
                    }
                }
                if border {
                    continue;
                }
                let (mut w, mut mu) = (0.0f64, DVec2::ZERO);
                for &i in &pix {
                    let c = r.level(0).1[i] as f64;
                    w += c;
                    mu += c * raster::texel_centre(res, i % res, i / res);
                }
                mu /= w;
                let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
                for &i in &pix {
                    let c = r.level(0).1[i] as f64;
                    let d = raster::texel_centre(res, i % res, i / res) - mu;
                    sxx += c * d.x * d.x;
                    sxy += c * d.x * d.y;
                    syy += c * d.y * d.y;
                }
                let (sxx, sxy, syy) = (sxx / w, sxy / w, syy / w);
                let lmax = 0.5 * (sxx + syy) + (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
                let a = 2.0 * lmax.sqrt();
                let area = w / (res * res) as f64;
                lengths.push(2.0 * a);
                widths.push(2.0 * area / (PI * a));
            }
            let median = |v: &mut Vec<f64>| {
                v.sort_by(|a, b| a.total_cmp(b));
                v[v.len() / 2]
            };
            assert!(lengths.len() > 40, "{} components", lengths.len());
            let (l, w) = (median(&mut lengths), median(&mut widths));
            let (l_ref, w_ref) = (2.0 * p.threshold * p.length, 2.0 * p.threshold * p.width);
            assert!((l / l_ref - 1.0).abs() < 0.02, "length {l} vs {l_ref}");
            assert!((w / w_ref - 1.0).abs() < 0.04, "width {w} vs {w_ref}");
        }
    }
}

/// Procedural queries against the raster. (1) The footprint query over a texel's square equals
/// the raster texel (two independent enumerations of the same exact geometry): within 1e-5.
/// (2) 8 x 8 stratified point queries per texel average to the raster value: zero texels have
/// no scratched sample, and partial texels agree on average within 0.02 (stratification error).
#[test]
fn point_and_footprint_queries_agree_with_the_raster() {
    for (p, res) in [
        (LayerParams::setting(1).unwrap(), 256),
        (LayerParams::setting(2).unwrap(), 128),
        (params(0.05, 0.05, 0.3, 1), 64),
    ] {
        let set = LayerSet::new(p, 5).unwrap();
        let r = set.rasterize(0, res).unwrap();
        let texel = 1.0 / res as f32;
        let (mut worst, mut sum_ss, mut partial) = (0.0f64, 0.0f64, 0usize);
        for y in 0..res {
            for x in 0..res {
                let c = raster::texel_centre(res, x, y);
                let ras = r.get(x, y) as f64;
                let fp = set.coverage(0, c.as_vec2(), Vec2::new(texel, 0.0), Vec2::new(0.0, texel))
                    as f64;
                worst = worst.max((fp - ras).abs());
                let mut hits = 0;
                for sy in 0..8 {
                    for sx in 0..8 {
                        let p =
                            c + DVec2::new(sx as f64 - 3.5, sy as f64 - 3.5) / (8.0 * res as f64);
                        hits += set.layers()[0].is_scratched_at(p) as usize;
                    }
                }
                let ss = hits as f64 / 64.0;
                if ras == 0.0 {
                    assert_eq!(hits, 0, "texel ({x}, {y}) is empty in the raster");
                } else {
                    sum_ss += (ss - ras).abs();
                    partial += 1;
                }
            }
        }
        assert!(worst < 1e-5, "footprint vs raster differ by {worst}");
        assert!(
            partial > 100 && sum_ss / (partial as f64) < 0.02,
            "mean |points - raster| {}",
            sum_ss / partial as f64
        );
    }
}

/// Footprint coverage of random rotated parallelograms (a few texels to a few scratches big)
/// against Monte Carlo over point queries: within 4 binomial standard errors plus 0.005.
/// Also: `coverage_all` and `scratched_mask` agree with the per-layer queries.
#[test]
fn footprint_coverage_matches_point_sampling() {
    let set = LayerSet::new(params(0.1, 0.01, 0.2, 4), 9).unwrap();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
    let mut all = vec![0.0f32; 4];
    let mut nonzero = 0;
    for case in 0..120 {
        let k = case % 4;
        let uv = Vec2::new(rng.random_range(0.1..0.9), rng.random_range(0.1..0.9));
        let s = rng.random_range(0.002f32..0.03);
        let (a, b) = (
            Vec2::new(s, rng.random_range(-s..s)),
            Vec2::new(rng.random_range(-s..s), -s * rng.random_range(0.2..1.0)),
        );
        let cov = set.coverage(k, uv, a, b) as f64;
        set.coverage_all(uv, a, b, &mut all);
        assert_eq!(all[k] as f64, cov);
        let n = 4000;
        let mut hits = 0;
        for _ in 0..n {
            let (s, t) = (rng.random::<f32>() - 0.5, rng.random::<f32>() - 0.5);
            let p = uv + s * a + t * b;
            let hit = set.is_scratched(k, p);
            assert_eq!(hit, set.scratched_mask(p) >> k & 1 == 1);
            hits += hit as usize;
        }
        let mc = hits as f64 / n as f64;
        let se = (mc * (1.0 - mc) / n as f64).sqrt();
        nonzero += (cov > 0.0) as usize;
        assert!(
            (cov - mc).abs() < 4.0 * se + 0.005,
            "case {case}: footprint {cov} vs points {mc}"
        );
    }
    assert!(nonzero > 30);
    // A huge footprint falls back to the expected coverage; a degenerate one is a point query.
    let big = set.coverage(
        0,
        Vec2::splat(0.5),
        Vec2::new(0.5, 0.0),
        Vec2::new(0.0, 0.5),
    ) as f64;
    assert!((big - set.expected_coverage()).abs() < 1e-6);
    let uv = Vec2::new(0.3, 0.7);
    assert_eq!(
        set.coverage(1, uv, Vec2::ZERO, Vec2::ZERO),
        set.is_scratched(1, uv) as u8 as f32
    );
    assert_eq!(
        set.coverage(1, Vec2::new(f32::NAN, 0.0), Vec2::ZERO, Vec2::X),
        0.0
    );
}

/// The ellipse of a scratch: points at 0.99 and 1.01 times the half-axes from a feature point,
/// along and across d, are inside and outside (where no other scratch interferes).
#[test]
fn scratches_are_ellipses_with_half_axes_tau_l_and_tau_w() {
    let set = LayerSet::new(LayerParams::setting(2).unwrap(), 1).unwrap();
    let layer = &set.layers()[2];
    let (hl, hw) = layer.half_axes();
    let d = DVec2::from(layer.direction());
    let n = d.perp();
    let mut checked = 0;
    for j in -20..20 {
        for i in -3..3 {
            let q = layer.noise().feature_point(i, j);
            let f = layer.to_texture(q);
            let alone = (-2..=2).all(|dj| {
                (-2..=2).all(|di| {
                    (di, dj) == (0, 0)
                        || (layer.noise().feature_point(i + di, j + dj) - q).length()
                            > 2.2 * layer.threshold()
                })
            });
            if !alone {
                continue;
            }
            checked += 1;
            for (axis, h) in [(d, hl), (-d, hl), (n, hw), (-n, hw)] {
                assert!(layer.is_scratched_at(f + 0.99 * h * axis));
                assert!(!layer.is_scratched_at(f + 1.01 * h * axis));
            }
        }
    }
    assert!(checked > 100);
}

#[test]
fn mip_chain_averages_coverage() {
    let set = LayerSet::new(LayerParams::setting(2).unwrap(), 2).unwrap();
    for res in [256, 100] {
        let r = set.rasterize(1, res).unwrap();
        let (last, d) = r.level(r.level_count() - 1);
        assert_eq!(last, 1);
        let (n1, l1) = r.level(1);
        assert_eq!(n1, res / 2);
        // Level 1 texel = mean of its 2x2 block.
        let expect = (r.get(6, 8) + r.get(7, 8) + r.get(6, 9) + r.get(7, 9)) / 4.0;
        assert!((l1[4 * n1 + 3] - expect).abs() < 1e-6);
        if res.is_power_of_two() {
            assert!((d[0] as f64 - r.mean()).abs() < 1e-5);
        }
    }
}

#[test]
fn bad_parameters_are_clear_errors() {
    let ok = LayerParams::setting(1).unwrap();
    assert_eq!(ok, params(0.3, 0.001, 0.1, 8));
    assert_eq!(LayerParams::setting(2).unwrap(), params(0.6, 0.01, 0.1, 8));
    assert!(matches!(
        LayerParams::setting(3),
        Err(LayerError::Setting(3))
    ));
    for (p, want) in [
        (LayerParams { length: 0.0, ..ok }, "length"),
        (LayerParams { length: -1.0, ..ok }, "length"),
        (
            LayerParams {
                width: f64::NAN,
                ..ok
            },
            "width",
        ),
        (LayerParams { width: 0.0, ..ok }, "width"),
        (
            LayerParams {
                threshold: 0.0,
                ..ok
            },
            "threshold",
        ),
        (
            LayerParams {
                threshold: 1.5,
                ..ok
            },
            "threshold",
        ),
        (LayerParams { layers: 0, ..ok }, "layers"),
        (LayerParams { layers: 65, ..ok }, "layers"),
    ] {
        let e = LayerSet::new(p, 1).unwrap_err().to_string();
        assert!(e.contains(want), "{e}");
    }
    let set = LayerSet::new(
        LayerParams {
            threshold: 1.0,
            ..ok
        },
        1,
    )
    .unwrap();
    assert!(set.rasterize(0, 0).is_err());
    assert!(set
        .rasterize(0, raster::MAX_RESOLUTION + 1)
        .unwrap_err()
        .to_string()
        .contains("GiB"));
    assert!(matches!(
        set.rasterize(8, 16),
        Err(LayerError::LayerIndex { index: 8, count: 8 })
    ));
    // Serde: the four keys, `layers` optional, unknown keys rejected.
    let p: LayerParams =
        serde_json::from_str(r#"{"length":0.3,"width":0.001,"threshold":0.1}"#).unwrap();
    assert_eq!(p, ok);
    assert!(
        serde_json::from_str::<LayerParams>(r#"{"length":0.3,"width":0.001,"treshold":0.1}"#)
            .is_err()
    );
}

/// The fast footprint query (row-wise cell enumeration, per-disc closed forms when no two
/// candidate discs overlap) against the reference (bounding-box enumeration, exact union of
/// all candidates): equal within 1e-9 over random footprints of both seed settings and a
/// thick-scratch setting (tau 0.45) where discs overlap often, so the union path runs too.
#[test]
fn fast_footprint_coverage_matches_the_reference() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
    let mut compared = 0;
    let mut nonzero = 0;
    for (set_params, scale) in [
        (LayerParams::setting(1).unwrap(), 2e-3f64),
        (LayerParams::setting(2).unwrap(), 6e-3),
        (params(0.05, 0.02, 0.45, 4), 0.05),
    ] {
        let set = LayerSet::new(set_params, 5).unwrap();
        for case in 0..1500 {
            let layer = &set.layers()[case % set.len()];
            let p = DVec2::new(rng.random_range(0.1..0.9), rng.random_range(0.1..0.9));
            let s = scale * rng.random_range(0.05f64..1.0);
            let a = DVec2::new(s, rng.random_range(-s..s));
            let b = DVec2::new(rng.random_range(-s..s), -s * rng.random_range(0.05..1.0));
            let fast = layer.footprint_coverage(p, a, b, layer::MAX_FOOTPRINT_CELLS);
            let reference = layer.footprint_coverage_reference(p, a, b, layer::MAX_FOOTPRINT_CELLS);
            if let (Some(f), Some(r)) = (fast, reference) {
                assert!(
                    (f - r).abs() < 1e-9,
                    "case {case}: fast {f} vs reference {r}"
                );
                compared += 1;
                nonzero += (r > 0.0) as usize;
            } else {
                // The fast path visits a subset of the reference's cells, so it may answer
                // where the reference gives up (too many discs), never the reverse.
                assert!(fast.is_some() || reference.is_none(), "case {case}");
            }
        }
    }
    assert!(
        compared > 3000 && nonzero > 600,
        "{compared} compared, {nonzero} nonzero"
    );
}

/// The closed forms for one disc against a parallelogram (`disc_parallelogram_area`: its
/// segment forms, and the Green's theorem form with one `atan2` for circles that cross both
/// pairs of edge lines; and the triangle decomposition `disc_convex_polygon_area` it replaced)
/// against the exact union kernel on random discs: centres inside, near edges and corners, far
/// outside; parallelograms from thin needles to squares, some inside the disc (circle fully
/// outside the polygon).
#[test]
fn single_disc_closed_forms_match_the_union_kernel() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(12);
    let (mut partial, mut crossing, mut tight) = (0, 0, 0);
    for case in 0..20000 {
        let a = DVec2::new(rng.random_range(-2.0..2.0), rng.random_range(-2.0..2.0));
        let thin = 10f64.powf(rng.random_range(-4.0..0.0));
        let b = DVec2::new(-a.y, a.x) * thin + a * rng.random_range(-1.0..1.0);
        let shape = layer::Parallelogram::new(a, b);
        let poly = shape.poly;
        let r = 10f64.powf(rng.random_range(-2.0..0.5));
        let c = poly[case % 4] * rng.random_range(0.0..1.5)
            + DVec2::new(rng.random_range(-r..r), rng.random_range(-r..r));
        let exact = footprint::union_discs_polygon_area(&[c], r, &poly);
        let fast = layer::disc_parallelogram_area(c, r, &shape);
        let tri = layer::disc_convex_polygon_area(c, r, &poly);
        let tol = 1e-10 * (PI * r * r);
        assert!((fast - exact).abs() < tol, "case {case}: {fast} vs {exact}");
        assert!(
            (tri - exact).abs() < tol,
            "case {case}: triangles {tri} vs {exact}"
        );
        partial += (exact > 0.0 && exact < PI * r * r * 0.999) as usize;
        // The bound `coverage_max` prunes with.
        let bound = layer::disc_parallelogram_area_bound(c, r, &shape);
        assert!(
            exact <= bound * (1.0 + 1e-9) + 1e-12 * shape.area,
            "case {case}: bound {bound} below {exact}"
        );
        tight += (exact > 0.0 && bound < 1.1 * exact) as usize;
        // The Green's theorem form: lines of both pairs cross the circle, some corner outside.
        let dist = shape.planes.map(|(n, d)| (d - n.dot(c)).abs() < r);
        crossing += ((dist[0] || dist[2])
            && (dist[1] || dist[3])
            && shape.planes.iter().all(|&(n, d)| d - n.dot(c) > -r)
            && poly.iter().any(|&v| (v - c).length_squared() > r * r)) as usize;
    }
    assert!(
        partial > 5000 && crossing > 3000 && tight > 5000,
        "{partial} partial, {crossing} crossing, {tight} bounds within 10 %"
    );
}

/// `coverage_reaching` (exact areas given up part way once a layer cannot reach a floor) gives
/// `coverage`'s value bit for bit whenever it gives one, and gives up only below the floor.
#[test]
fn coverage_reaching_is_the_coverage_or_below_the_floor() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(23);
    let (mut kept, mut given_up) = (0, 0);
    for (set_params, scale) in [
        (LayerParams::setting(1).unwrap(), 0.03f32),
        (params(0.05, 0.02, 0.45, 4), 0.2),
    ] {
        let set = LayerSet::new(set_params, 5).unwrap();
        for (uv, a, b) in random_footprints(&mut rng, 300, scale) {
            let (p, da, db) = (uv.as_dvec2(), a.as_dvec2(), b.as_dvec2());
            for layer in set.layers() {
                let mut centres = [DVec2::ZERO; layer::CANDIDATE_ROOM];
                let layer::Candidates::Discs(f) =
                    layer.footprint_candidates(p, da, db, layer::MAX_FOOTPRINT_CELLS, &mut centres)
                else {
                    continue;
                };
                let centres = &centres[..f.n];
                let exact = f.coverage(centres);
                for floor in [
                    0.0,
                    exact * 0.5,
                    exact - 1e-9,
                    exact + 1e-6,
                    exact * 1.5 + 1e-4,
                    rng.random_range(0.0..0.2),
                ] {
                    match f.coverage_reaching(centres, f.bound_area(centres), floor) {
                        Some(c) => {
                            assert_eq!(c.to_bits(), exact.to_bits(), "{c} vs {exact}");
                            kept += 1;
                        }
                        None => {
                            assert!(exact < floor, "gave up on {exact} at floor {floor}");
                            given_up += 1;
                        }
                    }
                    if floor <= exact {
                        assert!(f
                            .coverage_reaching(centres, f.bound_area(centres), floor)
                            .is_some());
                    }
                }
            }
        }
    }
    assert!(
        kept > 2000 && given_up > 1000,
        "{kept} kept, {given_up} given up"
    );
}

/// `coverage_max` keeps the first pass's candidate discs in a pool shared by all layers; layers
/// that do not fit are enumerated again. With large, dense footprints (many discs per layer,
/// more than the pool in all) it still gives `coverage_all`'s largest value and ties.
#[test]
fn coverage_max_with_more_discs_than_its_pool() {
    coverage_max_agrees_beyond_the_pool(0.1..0.2, 100);
}

#[test]
fn coverage_max_with_more_discs_than_one_layer_holds() {
    // Larger footprints: some layers have more than MAX_DISCS candidate discs once the shared
    // pool is full (the layer then takes the expected coverage, as in `coverage_all`; this
    // path once hit an `unreachable!` in `coverage = "sample"` renders).
    coverage_max_agrees_beyond_the_pool(0.3..0.45, 30);
}

/// `coverage_max`'s values `max` have the largest of `coverage_all`'s values `all` and the same
/// layers within 1e-6 of it (the ties the renderer picks from); returns the largest.
fn assert_same_largest_and_ties(all: &[f32], max: &[f32]) -> f32 {
    let best = all.iter().copied().fold(0.0f32, f32::max);
    assert_eq!(max.iter().copied().fold(0.0f32, f32::max), best);
    let tie = |c: f32| c > 0.0 && c >= best - 1e-6;
    for (k, (&a, &m)) in all.iter().zip(max).enumerate() {
        assert_eq!(tie(a), tie(m), "layer {k}: {a} vs {m}");
    }
    best
}

/// `coverage_max` against `coverage_all` on 300 random footprints with edges of the given
/// length; at least `min_overflowed` of them have more candidate discs than the shared pool.
fn coverage_max_agrees_beyond_the_pool(edges: std::ops::Range<f32>, min_overflowed: usize) {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(24);
    let set = LayerSet::new(params(0.05, 0.02, 0.3, 8), 7).unwrap();
    let n = set.len();
    let (mut all, mut max) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut overflowed = 0;
    let mut too_many = 0;
    for _ in 0..300 {
        // (Edges of 0.1 to 0.2: 5-10 noise cells across the scratches, 2-4 along them.)
        let uv = Vec2::new(rng.random_range(0.2..0.8), rng.random_range(0.2..0.8));
        let edge = |rng: &mut rand_pcg::Pcg64| {
            let phi = rng.random_range(0.0..std::f32::consts::TAU);
            Vec2::new(phi.cos(), phi.sin()) * rng.random_range(edges.clone())
        };
        let (a, b) = (edge(&mut rng), edge(&mut rng));
        set.coverage_all(uv, a, b, &mut all);
        set.coverage_max(uv, a, b, &mut max);
        assert_same_largest_and_ties(&all, &max);
        let (p, da, db) = (uv.as_dvec2(), a.as_dvec2(), b.as_dvec2());
        let mut total = 0;
        for layer in set.layers() {
            let mut centres = [DVec2::ZERO; layer::CANDIDATE_ROOM];
            match layer.footprint_candidates(p, da, db, layer::MAX_FOOTPRINT_CELLS, &mut centres) {
                layer::Candidates::Discs(f) => total += f.n,
                layer::Candidates::Done(None) => {
                    // More than MAX_DISCS discs (or too many cells): the pool overflows too.
                    total += CANDIDATE_POOL + 1;
                    too_many += 1;
                }
                _ => {}
            }
        }
        overflowed += (total > CANDIDATE_POOL) as usize;
    }
    assert!(
        overflowed > min_overflowed,
        "{overflowed} footprints beyond the pool"
    );
    if edges.start > 0.25 {
        assert!(too_many > 0, "no layer beyond MAX_DISCS");
    }
}

/// `n` random footprints in `[0.05, 0.95]^2`, sheared and of aspect up to 20, with edges
/// between `scale / 30` and `scale`.
fn random_footprints(rng: &mut rand_pcg::Pcg64, n: usize, scale: f32) -> Vec<(Vec2, Vec2, Vec2)> {
    (0..n)
        .map(|_| {
            let uv = Vec2::new(rng.random_range(0.05..0.95), rng.random_range(0.05..0.95));
            let s = scale * 10f32.powf(rng.random_range(-1.5..0.0));
            let a = Vec2::new(s, rng.random_range(-s..s));
            let b = Vec2::new(rng.random_range(-s..s), -s * rng.random_range(0.05..1.0));
            (uv, a, b)
        })
        .collect()
}

/// `coverage_max` (bounds, then exact areas in decreasing order of bound) gives the same
/// largest coverage and the same layers within 1e-6 of it (the ties the renderer picks from)
/// as the exact coverage of every layer, and each bound is above its exact coverage.
#[test]
fn coverage_max_keeps_the_largest_and_its_ties() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(21);
    let mut pruned = 0;
    let mut compared = 0;
    for (set_params, scale) in [
        (LayerParams::setting(1).unwrap(), 0.03f32),
        (LayerParams::setting(2).unwrap(), 0.05),
        (params(0.05, 0.02, 0.45, 8), 0.2),
    ] {
        let set = LayerSet::new(set_params, 3).unwrap();
        let n = set.len();
        let (mut all, mut max) = (vec![0.0f32; n], vec![0.0f32; n]);
        for (uv, a, b) in random_footprints(&mut rng, 400, scale) {
            set.coverage_all(uv, a, b, &mut all);
            set.coverage_max(uv, a, b, &mut max);
            let best = assert_same_largest_and_ties(&all, &max);
            for k in 0..n {
                let tie = |c: f32| c > 0.0 && c >= best - 1e-6;
                if tie(all[k]) {
                    assert_eq!(all[k], max[k]);
                }
                pruned += (all[k] > 0.0 && max[k] == 0.0) as usize;
                // Bounds.
                let mut centres = [DVec2::ZERO; layer::CANDIDATE_ROOM];
                let layer = &set.layers()[k];
                let (p, da, db) = (uv.as_dvec2(), a.as_dvec2(), b.as_dvec2());
                if let layer::Candidates::Discs(f) =
                    layer.footprint_candidates(p, da, db, layer::MAX_FOOTPRINT_CELLS, &mut centres)
                {
                    let (exact, bound) = (
                        f.coverage(&centres[..f.n]),
                        f.coverage_bound(&centres[..f.n]),
                    );
                    assert!(exact <= bound, "coverage {exact} above its bound {bound}");
                    compared += 1;
                }
            }
        }
    }
    assert!(
        compared > 2000 && pruned > 200,
        "{compared} bounds, {pruned} pruned"
    );
}

/// The rounding of a footprint's shape: edges within about 1/14 and area within 13 %, a rounded
/// shape's key names it, a footprint along the texture axes stays along them, and degenerate or
/// non-finite footprints have no shape.
#[test]
fn footprint_quantization_is_bounded() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(22);
    let cross = |a: Vec2, b: Vec2| a.perp_dot(b);
    let mut same = 0;
    for _ in 0..20000 {
        let s = 10f32.powf(rng.random_range(-6.0..1.0));
        let a = Vec2::new(
            rng.random_range(-1.0f32..1.0),
            rng.random_range(-1.0f32..1.0),
        ) * s;
        let thin = 10f32.powf(rng.random_range(-2.0..0.0));
        let b = a.perp() * thin * rng.random_range(0.5..1.0) + a * rng.random_range(-2.0..2.0);
        let Some((qa, qb, key)) = lattice::quantize(a, b) else {
            panic!("{a:?} {b:?}");
        };
        let (la, lb) = (a.length(), b.length());
        // Lengths to 4 significant bits (1/16), a's direction to 1/64 per component.
        assert!((qa - a).length() <= 0.075 * la, "{a:?} -> {qa:?}");
        assert!(
            (qb - b).length() <= 0.075 * lb + 0.075 * cross(a, b).abs() / la,
            "{b:?} -> {qb:?}"
        );
        let (area, qarea) = (cross(a, b), cross(qa, qb));
        assert!((qarea / area - 1.0).abs() < 0.13, "area {area} -> {qarea}");
        // A tiny perturbation rarely crosses a rounding boundary; with the same key, the same
        // shape.
        let (qa2, qb2, key2) = lattice::quantize(a * (1.0 + 1e-6), b).unwrap();
        if key2 == key {
            assert_eq!((qa2, qb2), (qa, qb));
            same += 1;
        }
    }
    assert!(same > 19000, "{same}");
    let (qa, qb, _) = lattice::quantize(Vec2::new(1e-3, 2e-6), Vec2::new(-3e-6, 5e-4)).unwrap();
    assert_eq!((qa.y, qb.x), (0.0, 0.0));
    assert!(lattice::quantize(Vec2::ZERO, Vec2::Y).is_none());
    assert!(lattice::quantize(Vec2::X, Vec2::X * 2.0).is_none());
    assert!(lattice::quantize(Vec2::new(f32::NAN, 1.0), Vec2::Y).is_none());
}

/// A hit snaps to a tile centre within `1 / (2 TILE_STEPS)` of the footprint, hits near one
/// another snap to the same tile, and the tiled (cached) coverage is exactly the coverage of
/// the tile, whether it came from the cache or not.
#[test]
fn footprint_tiles_contain_their_hits_and_cache_their_exact_coverage() {
    let set = LayerSet::new(LayerParams::setting(1).unwrap(), 4).unwrap();
    let n = set.len();
    let mut rng = rand_pcg::Pcg64::seed_from_u64(23);
    let (mut tiled, mut direct) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut shared = 0;
    let mut cache = CoverageCache::new();
    for (uv, a, b) in random_footprints(&mut rng, 300, 0.02) {
        let tile = lattice::FootprintTile::containing(uv, a, b).unwrap();
        // uv - centre = s a + t b with |s|, |t| <= 1 / (2 TILE_STEPS).
        let d = uv.as_dvec2() - tile.centre;
        let det = tile.a.x * tile.b.y - tile.a.y * tile.b.x;
        let s = (d.x * tile.b.y - d.y * tile.b.x) / det;
        let t = (tile.a.x * d.y - tile.a.y * d.x) / det;
        let half = 0.5 / lattice::TILE_STEPS;
        assert!(s.abs() <= half + 1e-6 && t.abs() <= half + 1e-6, "{s} {t}");
        // A nearby point with the same footprint snaps to the same tile when it is as close.
        let (ds, dt) = (rng.random_range(-half..half), rng.random_range(-half..half));
        let q = (uv.as_dvec2() + tile.a * ds + tile.b * dt).as_vec2();
        let other = lattice::FootprintTile::containing(q, a, b).unwrap();
        if (s + ds).abs() < 0.98 * half && (t + dt).abs() < 0.98 * half {
            assert_eq!(other, tile);
            shared += 1;
        }
        for query in [lattice::TileQuery::Max, lattice::TileQuery::All] {
            for _ in 0..2 {
                cache.tiled(&set, uv, a, b, query, &mut tiled);
                let (c, ta, tb) = (tile.centre.as_vec2(), tile.a.as_vec2(), tile.b.as_vec2());
                set.coverage_query(query, c, ta, tb, lattice::TILE_MAX_CELLS, &mut direct);
                assert_eq!(tiled, direct);
            }
        }
    }
    assert!(shared > 50, "{shared}");
}

/// A pixel's footprint coverage: the first camera hit of a pixel gets the exact coverage of
/// the footprint centred on its estimate of the pixel centre; the pixel's later hits whose
/// estimate agrees within the tolerance get the same values without working out their
/// footprint, farther ones (a silhouette, a seam, curved glass) a footprint of their own about
/// their own estimate (up to `PIXEL_CLUSTERS`, then their tile), another shape or pixel a
/// fresh exact value.
#[test]
fn pixel_footprint_coverage_is_the_exact_coverage_of_the_pixel_centre() {
    let set = LayerSet::new(LayerParams::setting(2).unwrap(), 9).unwrap();
    let n = set.len();
    let cells = lattice::TILE_MAX_CELLS;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(41);
    let (mut got, mut want) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut nonzero = 0;
    let mut cache = CoverageCache::new();
    for (uv, a, b) in random_footprints(&mut rng, 200, 0.05) {
        cache.start_pixel();
        let key = |shape| PixelKey { shape, chain: 0 };
        for query in [lattice::TileQuery::Max, lattice::TileQuery::All] {
            let exact = |set: &LayerSet, c: Vec2, out: &mut [f32]| {
                set.coverage_query(query, c, a, b, cells, out)
            };
            // The first hit, a quarter pixel right of the centre.
            let offset = Vec2::new(0.25, -0.125);
            let centre = uv - offset.x * a - offset.y * b;
            cache.of_pixel(&set, uv, || (a, b), key(3), offset, query, &mut got);
            exact(&set, centre, &mut want);
            assert_eq!(got, want);
            nonzero += want.iter().any(|&c| c > 0.0) as usize;
            // A later hit of the pixel on the same surface: the same values, and no footprint
            // worked out for it.
            let offset2 = Vec2::new(-0.4, 0.3);
            let uv2 = centre + offset2.x * a + offset2.y * b;
            let unused = || -> (Vec2, Vec2) { panic!("a shared footprint needs no differentials") };
            cache.of_pixel(&set, uv2, unused, key(3), offset2, query, &mut got);
            assert_eq!(got, want);
            // A hit whose centre estimate is half a footprint away: a footprint of its own,
            // exact about its own estimate, which a later hit near that estimate shares.
            let far = uv2 + 0.5 * a;
            cache.of_pixel(&set, far, || (a, b), key(3), offset2, query, &mut got);
            exact(&set, far - offset2.x * a - offset2.y * b, &mut want);
            assert_eq!(got, want);
            cache.of_pixel(
                &set,
                far + 0.2 * b,
                unused,
                key(3),
                offset2,
                query,
                &mut got,
            );
            assert_eq!(got, want);
            // Up to `PIXEL_CLUSTERS` footprints per pixel and chain; a hit far from all of
            // them then takes its tile.
            for j in 2..PIXEL_CLUSTERS {
                let uv3 = uv2 + j as f32 * a;
                cache.of_pixel(&set, uv3, || (a, b), key(3), offset2, query, &mut got);
                exact(&set, uv3 - offset2.x * a - offset2.y * b, &mut want);
                assert_eq!(got, want);
            }
            let beyond = uv2 + 10.0 * a;
            cache.of_pixel(&set, beyond, || (a, b), key(3), offset2, query, &mut got);
            cache.tiled(&set, beyond, a, b, query, &mut want);
            assert_eq!(got, want);
            // Another shape in the same pixel: exact again, about its own centre.
            cache.of_pixel(&set, far, || (a, b), key(4), offset2, query, &mut got);
            exact(&set, far - offset2.x * a - offset2.y * b, &mut want);
            assert_eq!(got, want);
        }
        // The next pixel shares nothing with this one: the hit that shared the first
        // footprint above now works out its own.
        cache.start_pixel();
        let asked = std::cell::Cell::new(false);
        let offset2 = Vec2::new(-0.4, 0.3);
        let uv2 = uv - 0.25 * a + 0.125 * b + offset2.x * a + offset2.y * b;
        let footprint = || {
            asked.set(true);
            (a, b)
        };
        cache.of_pixel(
            &set,
            uv2,
            footprint,
            key(3),
            offset2,
            lattice::TileQuery::Max,
            &mut got,
        );
        assert!(
            asked.get(),
            "a new pixel reused the previous pixel's footprint"
        );
    }
    assert!(nonzero > 50, "{nonzero}");
}

/// Hits the pixel's samples reach through different chains of delta bounces keep apart: a
/// chain's first hit is exact about its own centre even where another chain's footprint lies
/// within the tolerance, and each chain's entry outlives the others' insertions (up to the
/// cache's size), so its later hits share its own value.
#[test]
fn pixel_footprint_coverage_keeps_chains_of_bounces_apart() {
    let set = LayerSet::new(LayerParams::setting(2).unwrap(), 9).unwrap();
    let n = set.len();
    let cells = lattice::TILE_MAX_CELLS;
    let mut rng = rand_pcg::Pcg64::seed_from_u64(43);
    let (mut got, mut want) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut distinct = 0;
    let mut cache = CoverageCache::new();
    for (uv, a, b) in random_footprints(&mut rng, 200, 0.05) {
        cache.start_pixel();
        let key = |chain| PixelKey { shape: 3, chain };
        let query = lattice::TileQuery::Max;
        let exact = |c: Vec2, out: &mut [f32]| set.coverage_query(query, c, a, b, cells, out);
        let offset = Vec2::ZERO;
        // Chain 1 fills its entry about uv.
        cache.of_pixel(&set, uv, || (a, b), key(1), offset, query, &mut got);
        let first = got.clone();
        // Chains 2..=4 (less than the cache holds) a fifth of a footprint away: each exact
        // about its own centre, not chain 1's value.
        let near = uv + 0.2 * a;
        exact(near, &mut want);
        for chain in 2..=4 {
            cache.of_pixel(&set, near, || (a, b), key(chain), offset, query, &mut got);
            assert_eq!(got, want);
        }
        distinct += (want != first) as usize;
        // Chain 1 again, near its own centre: its stored value.
        cache.of_pixel(&set, near, || (a, b), key(1), offset, query, &mut got);
        assert_eq!(got, first);
    }
    assert!(distinct > 20, "{distinct}");
}

/// The lane-wise point test answers as each layer's own `F1 < tau` test, bit for bit: both
/// settings (9 layers: a full group of eight and one more), a direction per scratch, and a
/// threshold above 1/2 (tested one by one), at random points in and beyond the texture and at
/// points near scratch edges.
#[test]
fn lane_point_test_matches_each_layers_test() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(17);
    let sets = [
        LayerSet::new(
            LayerParams {
                layers: 9,
                ..LayerParams::setting(1).unwrap()
            },
            3,
        )
        .unwrap(),
        LayerSet::new(
            LayerParams {
                layers: 9,
                ..LayerParams::setting(2).unwrap()
            },
            4,
        )
        .unwrap(),
        LayerSet::with_orientation(LayerParams::setting(2).unwrap(), 5, Orientation::Random)
            .unwrap(),
        LayerSet::new(params(0.3, 0.02, 0.7, 3), 6).unwrap(),
    ];
    for (s, set) in sets.iter().enumerate() {
        let mut hits = 0;
        for n in 0..200_000 {
            let uv = if n % 2 == 0 {
                Vec2::new(rng.random_range(-0.5..1.5), rng.random_range(-0.5..1.5))
            } else {
                // Near a hit of the previous point: scratch edges.
                Vec2::new(rng.random_range(0.4..0.41), rng.random_range(0.6..0.601))
            };
            let expect = (0..set.len()).fold(0u64, |m, k| {
                m | (set.layers()[k].is_scratched(uv) as u64) << k
            });
            assert_eq!(set.scratched_mask(uv), expect, "set {s} at {uv:?}");
            hits += (expect != 0) as usize;
        }
        assert!(hits > 1000, "set {s}: {hits} scratched points");
    }
}

/// `scratch_at` names the scratch that covers a scratched point: the point lies in its
/// ellipse, for the seed's layers and for randomly oriented ones; and every scratch it names
/// is one of the enumeration's (`scratches`), the explicit geometry's objects.
#[test]
fn scratch_at_names_the_covering_scratch() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(17);
    for orientation in [Orientation::Layer, Orientation::Random] {
        let set =
            LayerSet::with_orientation(LayerParams::setting(2).unwrap(), 3, orientation).unwrap();
        let mut found = 0;
        for _ in 0..20_000 {
            let uv = DVec2::new(rng.random_range(0.0..1.0), rng.random_range(0.0..1.0));
            let mask = set.scratched_mask(uv.as_vec2());
            for k in (0..set.len()).filter(|k| mask >> k & 1 == 1) {
                let s = set.scratch_at(k, uv).unwrap();
                let v = uv - s.centre;
                let (x, y) = (s.direction.dot(v), s.direction.perp_dot(v));
                let n2 = (x / s.half_length).powi(2) + (y / s.half_width).powi(2);
                assert!(n2 < 1.0 + 1e-9, "{orientation:?} layer {k} at {uv:?}: {n2}");
                assert_eq!(s.layer, k);
                if orientation == Orientation::Layer {
                    let near = set.scratches(uv, uv);
                    assert!(near.contains(&s), "{uv:?}: {s:?} not enumerated");
                }
                found += 1;
            }
        }
        assert!(found > 1000, "{orientation:?}: {found}");
    }
}

/// The capsule test: bit `k` iff a feature point of layer `k` lies within `tau` of the
/// segment in noise space (against enumerating the cells around it), so every scratched point
/// of the segment sets its layer's bit; segments from a fraction of a scratch's width to many
/// cells across (split into pieces; beyond `MAX_PIECES` a layer may only answer "maybe"), in
/// every direction; randomly oriented layers always answer "maybe".
#[test]
fn capsule_mask_finds_the_scratches_a_segment_reaches() {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(23);
    let sets = [
        LayerSet::new(LayerParams::setting(2).unwrap(), 4).unwrap(),
        LayerSet::new(
            LayerParams {
                threshold: 0.45,
                ..LayerParams::setting(1).unwrap()
            },
            5,
        )
        .unwrap(),
    ];
    for set in &sets {
        let mut hits = 0;
        for n in 0..4000 {
            let uv = DVec2::new(rng.random_range(0.0..1.0), rng.random_range(0.0..1.0));
            // Lengths from a fraction of a scratch's width to several cells across.
            let (w, l) = (set.params().width, set.params().length);
            let reach = [0.3 * w, 3.0 * w, 0.5 * l, 3.0 * l][n % 4];
            let a: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let v = DVec2::new(a.cos(), a.sin()) * reach;
            let mask = set.capsule_mask(uv, v);
            for (k, layer) in set.layers().iter().enumerate() {
                let (q0, q1) = (layer.to_noise(uv), layer.to_noise(uv + v));
                let tau = layer.threshold();
                let (lo, hi) = (q0.min(q1) - tau, q0.max(q1) + tau);
                let mut want = false;
                for j in worley::floor_i64(lo.y)..=worley::floor_i64(hi.y) {
                    for i in worley::floor_i64(lo.x)..=worley::floor_i64(hi.x) {
                        let f = layer.noise().feature_point(i, j);
                        let d = q1 - q0;
                        let t = ((f - q0).dot(d) / d.length_squared()).clamp(0.0, 1.0);
                        let e = (q0 + d * t - f).length();
                        assert!((e - tau).abs() > 1e-9, "borderline");
                        want |= e < tau;
                    }
                }
                let bit = mask >> k & 1 == 1;
                if n % 4 < 3 {
                    assert_eq!(bit, want, "layer {k} at {uv:?} along {v:?}");
                } else {
                    assert!(bit || !want, "layer {k} at {uv:?} along {v:?}");
                }
                hits += want as usize;
                for s in 0..=16 {
                    let p = uv + v * (s as f64 / 16.0);
                    assert!(!layer.is_scratched_at(p) || want, "layer {k}: {p:?}");
                }
            }
        }
        assert!(hits > 500, "{hits}");
    }
    let random =
        LayerSet::with_orientation(LayerParams::setting(2).unwrap(), 5, Orientation::Random)
            .unwrap();
    assert_eq!(
        random.capsule_mask(DVec2::splat(0.3), DVec2::X * 1e-3),
        (1 << random.len()) - 1
    );
}

/// The curves' footprint tiles (`CoverageCache::curves_tiled`): each curve's coverage is the
/// exact coverage of the hit's tile, and a tile's value does not depend on which query came
/// first or the query's own random number (so renders stay bit-identical across thread counts).
#[test]
fn curve_tiles_are_their_tiles_exact_coverage_whatever_the_query_order() {
    use crate::curves::patterns::Pattern;
    use crate::curves::stroke::StrokeStyle;
    use crate::curves::CurveSet;
    let swirl = Pattern::Swirl {
        count: 200,
        radius: [0.05, 0.3],
        arc: [30.0, 120.0],
        width: 0.004,
        seed: 2,
    };
    let set = CurveSet::new(
        &swirl.polylines(&StrokeStyle::default()).unwrap(),
        glam::DVec2::ONE,
    )
    .unwrap();
    let (dx, dy) = (Vec2::new(0.006, 0.001), Vec2::new(-0.002, 0.007));
    let pts: Vec<Vec2> = (0..400)
        .map(|i| {
            let (a1, a2) = (0.754_877_7f32, 0.569_840_3f32);
            Vec2::new((0.5 + a1 * i as f32) % 1.0, (0.5 + a2 * i as f32) % 1.0)
        })
        .collect();
    let (mut c1, mut c2) = (CoverageCache::new(), CoverageCache::new());
    let a: Vec<_> = pts
        .iter()
        .map(|&p| c1.curves_tiled(&set, p, dx, dy, 0.3))
        .collect();
    let mut b: Vec<_> = pts
        .iter()
        .rev()
        .map(|&p| c2.curves_tiled(&set, p, dx, dy, 0.9))
        .collect();
    b.reverse();
    assert_eq!(a, b);
    let mut covered = 0;
    for (p, hits) in pts.iter().zip(&a) {
        let tile = super::lattice::FootprintTile::containing(*p, dx, dy).unwrap();
        let exact = set.footprint(tile.centre, tile.a, tile.b, 0.5);
        let cov = |h: &crate::curves::CurveHits| {
            h.iter().map(|x| (x.curve, x.coverage)).collect::<Vec<_>>()
        };
        assert_eq!(cov(hits), cov(&exact));
        covered += !hits.is_empty() as usize;
    }
    assert!(covered > 20, "{covered} of 400 tiles hold a curve");
}
