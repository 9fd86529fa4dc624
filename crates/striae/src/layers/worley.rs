//! Tileable 2D Worley cell noise [Worley96] (METHOD.md section 5): one feature point per unit
//! cell at a hashed position, so the noise is reproducible from a seed and tiles with a
//! power-of-two period. Returns F1 and F2 (distances to the nearest and second-nearest feature
//! points, Euclidean), the nearest feature point and its cell.
//!
//! Cell `(i, j)` is the square `[i, i+1) x [j, j+1)`; its feature point is `(i, j) + o(i, j)` with
//! the offset `o` uniform in `[0, 1)^2`, a hash of `(i mod P, j mod P, seed)`. The search is exact:
//! the 3x3 block around the query, then the ring of 16 cells at distance 2 pruned by their
//! distance to the query (a feature point in the ring can be the nearest when the own cell's
//! point sits in a far corner; nothing beyond the ring can matter, because F2 < 2 always).

use super::LayerError;
use crate::hash::{mix64, unit_from_u32};
use glam::DVec2;

/// The result of one Worley lookup.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorleySample {
    /// Distance to the nearest feature point (Worley's F1).
    pub f1: f64,
    /// Distance to the second-nearest feature point (F2).
    pub f2: f64,
    /// The nearest feature point, in noise coordinates.
    pub nearest: DVec2,
    /// The (unwrapped) cell `[i, j]` holding the nearest feature point; `[i mod P, j mod P]` is
    /// its id within one period.
    pub cell: [i64; 2],
}

/// `floor(x)` as an integer without a libm call (baseline x86-64 has no `roundsd`); `|x| < 2^62`.
#[inline(always)]
pub(crate) fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    t - ((t as f64) > x) as i64
}

/// `floor(x)` as a float and as an integer, `|x| < 2^51`, in float arithmetic alone: adding
/// `1.5 * 2^52` rounds `x` to an integer held in the sum's low mantissa bits, a step down where
/// that rounded up. [`floor_i64`]'s value, where a vector of AVX2 has no conversion between
/// 64-bit integers and floats.
#[inline(always)]
pub(crate) fn floor_pair(x: f64) -> (f64, i64) {
    const SHIFT: f64 = 6_755_399_441_055_744.0;
    let y = x + SHIFT;
    let r = y - SHIFT;
    let n = y.to_bits() as i64 - SHIFT.to_bits() as i64;
    if r > x {
        (r - 1.0, n - 1)
    } else {
        (r, n)
    }
}

/// The offset of cell `(i, j)`'s feature point inside its cell, in `[0, 1)^2`, for the hash
/// key `key` and the period mask `mask` ([`Worley::hash_key`]): one hash, its two halves.
#[inline(always)]
pub(crate) fn cell_offset(key: u64, mask: i64, i: i64, j: i64) -> (f64, f64) {
    let h = mix64(((i & mask) as u64 | ((j & mask) as u64) << 32) ^ key);
    (unit_from_u32(h >> 32), unit_from_u32(h & 0xffff_ffff))
}

/// Tileable Worley noise with period `P` (a power of two) in both axes.
#[derive(Clone, Copy, Debug)]
pub struct Worley {
    seed: u64,
    key: u64,
    mask: i64,
}

/// The largest period: cell coordinates are hashed as two 32-bit words.
pub const MAX_PERIOD: u64 = 1 << 32;

impl Worley {
    /// Noise from `seed`, repeating every `period` cells in x and in y. `period` must be a power
    /// of two in `[1, 2^32]` (a mask, not a division, keeps the lookup fast).
    pub fn new(seed: u64, period: u64) -> Result<Self, LayerError> {
        if !period.is_power_of_two() || period > MAX_PERIOD {
            return Err(LayerError::Period(period));
        }
        Ok(Worley {
            seed,
            key: mix64(seed ^ 0x005e_ed0f_c0ff_ee00),
            mask: period as i64 - 1,
        })
    }

    pub fn seed(&self) -> u64 {
        self.seed
    }

    pub fn period(&self) -> u64 {
        self.mask as u64 + 1
    }

    /// The key and the period mask of [`Self::offset`]'s hash.
    pub fn hash_key(&self) -> (u64, i64) {
        (self.key, self.mask)
    }

    /// The offset of cell `(i, j)`'s feature point inside its cell, in `[0, 1)^2`.
    #[inline(always)]
    pub fn offset(&self, i: i64, j: i64) -> DVec2 {
        let (x, y) = cell_offset(self.key, self.mask, i, j);
        DVec2::new(x, y)
    }

    /// Cell `(i, j)`'s feature point.
    #[inline(always)]
    pub fn feature_point(&self, i: i64, j: i64) -> DVec2 {
        DVec2::new(i as f64, j as f64) + self.offset(i, j)
    }

    /// F1, F2, the nearest feature point and its cell at `q` (exact, Euclidean).
    pub fn eval(&self, q: DVec2) -> WorleySample {
        worley_search(q, |i, j| self.offset(i, j))
    }

    /// The feature point nearest to `q` (F1's, [`Self::eval`]'s `nearest`), visiting the cells
    /// ring by ring and only those that can hold a nearer one than the best so far: about half
    /// of the cells `eval` visits for F2 as well.
    pub fn nearest(&self, q: DVec2) -> DVec2 {
        let (i, j) = (floor_i64(q.x), floor_i64(q.y));
        let cell = DVec2::new(i as f64, j as f64);
        let f = q - cell;
        let mut best = (f64::INFINITY, DVec2::ZERO);
        for ring in 0..=2i64 {
            for dj in -ring..=ring {
                for di in -ring..=ring {
                    let (gx, gy) = (axis_gap(di, f.x), axis_gap(dj, f.y));
                    if di.abs().max(dj.abs()) != ring || gx * gx + gy * gy >= best.0 {
                        continue;
                    }
                    let p = DVec2::new(di as f64, dj as f64) + self.offset(i + di, j + dj);
                    let d = (p - f).length_squared();
                    if d < best.0 {
                        best = (d, p);
                    }
                }
            }
        }
        cell + best.1
    }

    /// Whether some feature point lies strictly closer than `r` to `q`, i.e. `F1(q) < r`
    /// (the scratch test of METHOD.md section 5).
    #[inline]
    pub fn any_within(&self, q: DVec2, r: f64) -> bool {
        self.feature_within(q, r).is_some()
    }

    /// A feature point strictly closer than `r` to `q` (noise space), if one is: the scratch
    /// covering `q`. Visits only the cells the disc of radius `r` touches (one to four for `r
    /// <= 1/2`), its own cell first.
    #[inline]
    pub fn feature_within(&self, q: DVec2, r: f64) -> Option<DVec2> {
        let (i, j) = (floor_i64(q.x), floor_i64(q.y));
        let cell = DVec2::new(i as f64, j as f64);
        let f = q - cell;
        let r2 = r * r;
        let hit = |di: i64, dj: i64| {
            let p = DVec2::new(di as f64, dj as f64) + self.offset(i + di, j + dj);
            ((p - f).length_squared() < r2).then_some(cell + p)
        };
        if r <= 0.5 {
            // The disc reaches at most one neighbour column and one neighbour row.
            if let Some(p) = hit(0, 0) {
                return Some(p);
            }
            let dx = if f.x < r {
                -1
            } else if f.x > 1.0 - r {
                1
            } else {
                0
            };
            let dy = if f.y < r {
                -1
            } else if f.y > 1.0 - r {
                1
            } else {
                0
            };
            let column = if dx != 0 { hit(dx, 0) } else { None };
            let row = || if dy != 0 { hit(0, dy) } else { None };
            let corner = || {
                if dx != 0 && dy != 0 {
                    hit(dx, dy)
                } else {
                    None
                }
            };
            column.or_else(row).or_else(corner)
        } else {
            let (i0, i1) = (floor_i64(f.x - r), floor_i64(f.x + r));
            let (j0, j1) = (floor_i64(f.y - r), floor_i64(f.y + r));
            (j0..=j1).find_map(|dj| (i0..=i1).find_map(|di| hit(di, dj)))
        }
    }
}

/// The gap along one axis between a point at `t` in `[0, 1)` within its cell and the cell `d`
/// steps away (0 for its own column or row).
#[inline(always)]
fn axis_gap(d: i64, t: f64) -> f64 {
    if d < 0 {
        t - (d + 1) as f64
    } else if d > 0 {
        d as f64 - t
    } else {
        0.0
    }
}

/// Exact F1/F2 search around `q` for any placement `offset(i, j)` in `[0, 1)^2` per cell.
/// Generic so that a test can feed it another implementation's feature points.
pub fn worley_search(q: DVec2, offset: impl Fn(i64, i64) -> DVec2) -> WorleySample {
    let (i, j) = (floor_i64(q.x), floor_i64(q.y));
    let (cx, cy) = (i as f64, j as f64);
    let f = q - DVec2::new(cx, cy);
    // (F1^2, F2^2, nearest cell offset and point relative to the query's cell)
    let mut st = (f64::INFINITY, f64::INFINITY, (0i64, 0i64, DVec2::ZERO));
    let visit = |st: &mut (f64, f64, (i64, i64, DVec2)), di: i64, dj: i64| {
        let p = DVec2::new(di as f64, dj as f64) + offset(i + di, j + dj);
        let d = (p - f).length_squared();
        if d < st.0 {
            st.1 = st.0;
            st.0 = d;
            st.2 = (di, dj, p);
        } else if d < st.1 {
            st.1 = d;
        }
    };
    for dj in -1..=1 {
        for di in -1..=1 {
            visit(&mut st, di, dj);
        }
    }
    // Ring at Chebyshev distance 2: visit a cell only if it can beat the current F2.
    for dj in -2i64..=2 {
        for di in -2i64..=2 {
            if di.abs() < 2 && dj.abs() < 2 {
                continue;
            }
            let (gx, gy) = (axis_gap(di, f.x), axis_gap(dj, f.y));
            if gx * gx + gy * gy < st.1 {
                visit(&mut st, di, dj);
            }
        }
    }
    let (d1, d2, best) = st;
    let (di, dj, p) = best;
    WorleySample {
        f1: d1.sqrt(),
        f2: d2.sqrt(),
        nearest: DVec2::new(cx, cy) + p,
        cell: [i + di, j + dj],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::chi2_discrete;
    use fastnoise_lite::{CellularDistanceFunction, CellularReturnType, FastNoiseLite, NoiseType};
    use rand::{Rng, SeedableRng};

    /// Brute force over a 9x9 block: the reference for the pruned search.
    fn brute(w: &Worley, q: DVec2) -> (f64, f64, [i64; 2]) {
        let (i, j) = (q.x.floor() as i64, q.y.floor() as i64);
        let mut d: Vec<(f64, [i64; 2])> = Vec::new();
        for dj in -4..=4 {
            for di in -4..=4 {
                let p = w.feature_point(i + di, j + dj);
                d.push(((p - q).length(), [i + di, j + dj]));
            }
        }
        d.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
        (d[0].0, d[1].0, d[0].1)
    }

    #[test]
    fn floor_pair_is_floor() {
        let mut x = 7;
        let hashed = (0..100_000).map(|k| {
            x = crate::hash::splitmix64(x);
            let unit = crate::hash::unit_from_u32(x >> 32) - 0.5;
            // Wide values, then values within an ulp of integers, then near zero.
            match k % 3 {
                0 => unit * 2f64.powi((x & 63) as i32 - 12),
                1 => ((x >> 8) % 2001) as f64 - 1000.0 + unit * 1e-12,
                _ => unit * 1e-300,
            }
        });
        let edges = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2f64.powi(51) - 0.5,
            -(2f64.powi(51) - 1.0),
        ];
        for v in edges.into_iter().chain(hashed) {
            let (f, i) = floor_pair(v);
            assert_eq!(i, floor_i64(v), "{v}");
            assert_eq!(f, v.floor(), "{v}");
        }
    }

    #[test]
    fn search_is_exact_against_brute_force() {
        let w = Worley::new(7, 1 << 16).unwrap();
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        for _ in 0..20_000 {
            let q = DVec2::new(
                rng.random_range(-300.0..300.0),
                rng.random_range(-300.0..300.0),
            );
            let s = w.eval(q);
            let (f1, f2, cell) = brute(&w, q);
            assert!(
                (s.f1 - f1).abs() < 1e-12 && (s.f2 - f2).abs() < 1e-12,
                "{q:?}"
            );
            assert_eq!(s.cell, cell);
            assert!((s.nearest - w.feature_point(cell[0], cell[1])).length() < 1e-12);
            assert!((w.nearest(q) - s.nearest).length() < 1e-12, "{q:?}");
            for r in [0.05, 0.1, 0.3, 0.5, 0.7, 1.0] {
                assert_eq!(w.any_within(q, r), f1 < r, "q {q:?} r {r}");
            }
        }
    }

    #[test]
    fn same_seed_same_noise_and_seeds_differ() {
        let (a, b, c) = (
            Worley::new(3, 256).unwrap(),
            Worley::new(3, 256).unwrap(),
            Worley::new(4, 256).unwrap(),
        );
        let mut differ = 0;
        for k in 0..1000 {
            let q = DVec2::new(k as f64 * 0.37, k as f64 * -0.91);
            assert_eq!(a.eval(q), b.eval(q));
            differ += (a.eval(q).f1 != c.eval(q).f1) as usize;
        }
        assert!(
            differ > 990,
            "another seed gives another noise ({differ}/1000 differ)"
        );
    }

    #[test]
    fn noise_tiles_with_its_period() {
        for period in [1u64, 4, 16] {
            let w = Worley::new(11, period).unwrap();
            let p = period as f64;
            let mut rng = rand_pcg::Pcg64::seed_from_u64(2);
            for _ in 0..2000 {
                // Dyadic coordinates keep q + k P exact in f64, so the comparison can be exact.
                let q = DVec2::new(
                    (rng.random_range(-4096i64..4096) as f64) / 256.0,
                    (rng.random_range(-4096i64..4096) as f64) / 256.0,
                );
                let s = w.eval(q);
                for (kx, ky) in [(1.0, 0.0), (0.0, 1.0), (-3.0, 2.0)] {
                    let t = w.eval(q + DVec2::new(kx * p, ky * p));
                    assert_eq!((s.f1, s.f2), (t.f1, t.f2));
                    assert_eq!(t.nearest - s.nearest, DVec2::new(kx * p, ky * p));
                }
            }
            // And a period is not a fake: a shift by half the period changes the noise.
            if period >= 4 {
                let q = DVec2::new(0.3, 0.6);
                let moved = (0..64).filter(|&k| {
                    let q = q + DVec2::new(k as f64 * 0.25, 0.0);
                    w.eval(q).f1 != w.eval(q + DVec2::new(p / 2.0, 0.0)).f1
                });
                assert!(moved.count() > 50);
            }
        }
        assert!(matches!(Worley::new(1, 3), Err(LayerError::Period(3))));
        assert!(Worley::new(1, 0).is_err());
    }

    /// The hashed offsets are uniform on the cell: chi-square over a 8x8 grid of sub-cells.
    #[test]
    fn feature_points_are_uniform_in_their_cells() {
        let w = Worley::new(99, 1 << 20).unwrap();
        let mut counts = vec![0u64; 64];
        let n = 64_000;
        for k in 0..n {
            let o = w.offset(k % 320 - 160, k / 320 - 100);
            counts[(o.x * 8.0) as usize + 8 * (o.y * 8.0) as usize] += 1;
        }
        let r = chi2_discrete(&counts, &vec![n as f64 / 64.0; 64]);
        assert!(r.p_value > 1e-3, "offsets not uniform: {r:?}");
    }

    /// Oracle: fastnoise-lite's cellular noise (Euclidean, F1 = `Distance`, F2 = `Distance2`,
    /// nearest = `CellValue`). Its feature points are not exposed, so we recover them: with
    /// jitter modifier 1 every point lies within 0.437 of its cell centre, hence querying
    /// fastnoise at the centre and at two nearby points (still nearest to the own point)
    /// trilaterates it. Feeding those points to our `worley_search` must then reproduce
    /// fastnoise's F1, F2 and nearest cell at random queries, up to fastnoise's f32 rounding.
    /// This checks our search (neighbourhood, pruning, F2 bookkeeping) against an independent
    /// implementation; the placement hash itself is checked by the uniformity test.
    #[test]
    fn matches_fastnoise_lite_with_its_feature_points() {
        let make = |ret| {
            let mut n = FastNoiseLite::with_seed(1234);
            n.set_noise_type(Some(NoiseType::Cellular));
            n.set_frequency(Some(1.0));
            n.set_cellular_distance_function(Some(CellularDistanceFunction::Euclidean));
            n.set_cellular_return_type(Some(ret));
            n.set_cellular_jitter(Some(1.0));
            n
        };
        let (d1, d2, cv) = (
            make(CellularReturnType::Distance),
            make(CellularReturnType::Distance2),
            make(CellularReturnType::CellValue),
        );
        // fastnoise's cell (xi, yi) is centred on the integer point; ours spans [i, i+1): our
        // query q corresponds to fastnoise's q - 1/2, and our offset is 1/2 + its jitter.
        const N: i64 = 24;
        let h = 0.05f64;
        let mut offs = std::collections::HashMap::new();
        let mut values = std::collections::HashMap::new();
        for j in -2..N + 2 {
            for i in -2..N + 2 {
                let f = |n: &FastNoiseLite, x: f64, y: f64| {
                    n.get_noise_2d(x as f32, y as f32) as f64 + 1.0
                };
                let r2 = f(&d1, i as f64, j as f64).powi(2);
                let a = (r2 - f(&d1, i as f64 + h, j as f64).powi(2) + h * h) / (2.0 * h);
                let b = (r2 - f(&d1, i as f64, j as f64 + h).powi(2) + h * h) / (2.0 * h);
                assert!(a.abs() < 0.44 && b.abs() < 0.44);
                offs.insert((i, j), DVec2::new(0.5 + a, 0.5 + b));
                values.insert(
                    (i, j),
                    cv.get_noise_2d((i as f64 + a) as f32, (j as f64 + b) as f32),
                );
            }
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let (mut worst1, mut worst2, mut same_cell) = (0.0f64, 0.0f64, 0);
        let n = 5000;
        for _ in 0..n {
            let q = DVec2::new(
                rng.random_range(1.0..N as f64 - 1.0),
                rng.random_range(1.0..N as f64 - 1.0),
            );
            let s = worley_search(q, |i, j| offs[&(i, j)]);
            let x = (q.x - 0.5) as f32;
            let y = (q.y - 0.5) as f32;
            worst1 = worst1.max((s.f1 - (d1.get_noise_2d(x, y) as f64 + 1.0)).abs());
            worst2 = worst2.max((s.f2 - (d2.get_noise_2d(x, y) as f64 + 1.0)).abs());
            same_cell += (values[&(s.cell[0], s.cell[1])] == cv.get_noise_2d(x, y)) as usize;
        }
        assert!(
            worst1 < 2e-4 && worst2 < 2e-4,
            "F1 off by {worst1}, F2 off by {worst2}"
        );
        // Ties within f32 rounding may pick the other point; they are vanishingly rare.
        assert!(
            same_cell >= n - 2,
            "nearest cell agrees at {same_cell}/{n} queries"
        );
    }
}
