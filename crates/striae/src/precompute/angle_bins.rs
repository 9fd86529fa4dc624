//! Uniform angle bins on `[-pi/2, pi/2]` (METHOD.md sections 1 and 3), and a fast binner that
//! needs no `atan2`/`asin`.
//!
//! Bin `k` of `m` is `[-pi/2 + k pi/m, -pi/2 + (k + 1) pi/m)`, centre
//! `-pi/2 + (k + 1/2) pi/m` ([`bin_centre`]). An angle is usually known through its sine: the
//! 2D exit direction `(sin phi, cos phi)` of the precompute, `w.y = sin(theta)` of a 3D
//! direction, or `x / sqrt(x^2 + z^2) = sin(phi)` of its projection into the cross-section.
//! [`AngleBins`] bins the sine directly: a lookup table on a uniform grid in the sine gives a
//! starting bin, corrected against the exact edge sines, so it equals [`bin_of`] of the angle
//! except where `asin` itself rounds across an edge.
//!
//! `ScratchBrdf::phi_bin` in `table.rs` bins `phi = atan2(x, z)` of an unnormalised `(x, z)`
//! with `z > 0` by comparing `x / z` against the edges' tangents; [`AngleBins::bin_xz`] is the
//! same function of `(x, z)` (its edges are the same angles), through the sine instead.

use std::f64::consts::{FRAC_PI_2, PI};

/// The centre of angle bin `k` of `m`: `-pi/2 + (k + 1/2) pi / m`.
#[inline]
pub fn bin_centre(k: usize, m: usize) -> f64 {
    -FRAC_PI_2 + (k as f64 + 0.5) * PI / m as f64
}

/// The bin of angle `a` in `[-pi/2, pi/2]` (clamped to `0..m`).
#[inline]
pub fn bin_of(a: f64, m: usize) -> usize {
    (((a + FRAC_PI_2) * (m as f64 / PI)) as usize).min(m - 1)
}

/// Bins an angle in `[-pi/2, pi/2]` given by its sine, with `m` uniform bins.
#[derive(Clone, Debug)]
pub struct AngleBins {
    m: usize,
    /// The `m + 1` edges' sines, padded with `+inf` to a power-of-two length (index masks
    /// instead of bounds checks in the hot path).
    edge_sin: Vec<f64>,
    edge_mask: usize,
    /// Bin of each cell's lower end, padded to a power-of-two length.
    lut: Vec<u16>,
    lut_mask: usize,
    scale: f64,
}

impl AngleBins {
    /// `m` uniform bins over `[-pi/2, pi/2]`, `1 <= m <= 65536`.
    pub fn new(m: usize) -> Self {
        assert!((1..=1 << 16).contains(&m), "AngleBins: m = {m}");
        Self::from_edges(
            (0..=m)
                .map(|k| (-FRAC_PI_2 + k as f64 * PI / m as f64).sin())
                .collect(),
        )
    }

    /// From `m + 1` non-decreasing edge sines in `[-1, 1]`.
    fn from_edges(mut edge_sin: Vec<f64>) -> Self {
        let m = edge_sin.len() - 1;
        // 4 cells per bin on average; near the ends several bins share a cell (slow path).
        let cells = 4 * m;
        let scale = cells as f64 / 2.0;
        let mut lut: Vec<u16> = (0..=cells)
            .map(|q| {
                let x = -1.0 + q as f64 / scale;
                (edge_sin.partition_point(|&e| e <= x).saturating_sub(1)).min(m - 1) as u16
            })
            .collect();
        lut.resize((cells + 1).next_power_of_two(), (m - 1) as u16);
        edge_sin.resize((m + 2).next_power_of_two(), f64::INFINITY);
        AngleBins {
            m,
            edge_mask: edge_sin.len() - 1,
            edge_sin,
            lut_mask: lut.len() - 1,
            lut,
            scale,
        }
    }

    /// The number of bins.
    pub fn len(&self) -> usize {
        self.m
    }

    /// Never true (at least one bin).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The bin centres, radians.
    pub fn centres(&self) -> Vec<f64> {
        (0..self.m).map(|k| bin_centre(k, self.m)).collect()
    }

    /// The bin `j` with `sin(edge_j) <= s < sin(edge_{j+1})` (`s` clamped to `[-1, 1]`,
    /// `j < m`; NaN gives bin 0).
    #[inline(always)]
    pub fn bin_sin(&self, s: f64) -> usize {
        let (e, em) = (&self.edge_sin, self.edge_mask);
        let s = s.clamp(-1.0, 1.0);
        let mut j = self.lut[((s + 1.0) * self.scale) as i64 as usize & self.lut_mask] as usize;
        // One branch-free correction step; a (rare, predictable) slow path where a cell
        // spans several edges.
        j += (s >= e[(j + 1) & em]) as usize;
        if (s >= e[(j + 1) & em]) | (s < e[j & em]) {
            j = self.bin_slow(s, j);
        }
        j.min(self.m - 1)
    }

    /// The bin of `phi = atan2(x, z)` for `z >= 0` (the projection of a direction into the
    /// cross-section plane, METHOD.md section 1); `(0, 0)` gives the middle bin's sine 0.
    #[inline(always)]
    pub fn bin_xz(&self, x: f64, z: f64) -> usize {
        let r = (x * x + z * z).sqrt();
        self.bin_sin(if r > 0.0 { x / r } else { 0.0 })
    }

    #[cold]
    fn bin_slow(&self, s: f64, mut j: usize) -> usize {
        let m = self.m;
        while j + 1 < m && s >= self.edge_sin[j + 1] {
            j += 1;
        }
        while j > 0 && s < self.edge_sin[j.min(m)] {
            j -= 1;
        }
        j
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bin_sin_matches_asin() {
        for m in [1, 2, 7, 32, 64, 256, 4096] {
            let b = AngleBins::new(m);
            assert_eq!(b.len(), m);
            for k in 0..20_000 {
                let a = -FRAC_PI_2 + (k as f64 + 0.37) * PI / 20_000.0;
                let want = bin_of(a, m);
                let got = b.bin_sin(a.sin());
                // Equal except within rounding of an edge.
                if got != want {
                    let edge = -FRAC_PI_2 + got.max(want) as f64 * PI / m as f64;
                    assert!((a - edge).abs() < 1e-12, "m {m} a {a}: {got} vs {want}");
                }
            }
        }
    }

    #[test]
    fn edges_and_out_of_range() {
        let m = 64;
        let b = AngleBins::new(m);
        // Exactly on an edge: the upper bin (half-open bins).
        for k in 1..m {
            let s = (-FRAC_PI_2 + k as f64 * PI / m as f64).sin();
            assert_eq!(b.bin_sin(s), k, "edge {k}");
        }
        assert_eq!(b.bin_sin(-1.0), 0);
        assert_eq!(b.bin_sin(1.0), m - 1);
        assert_eq!(b.bin_sin(-7.0), 0);
        assert_eq!(b.bin_sin(3.0), m - 1);
        assert_eq!(b.bin_sin(f64::NAN), 0);
    }

    #[test]
    fn bin_xz_matches_atan2() {
        let m = 48;
        let b = AngleBins::new(m);
        for k in 0..5000 {
            let phi = -FRAC_PI_2 + (k as f64 + 0.5) * PI / 5000.0;
            let r = 0.1 + (k % 7) as f64;
            let (x, z) = (r * phi.sin(), r * phi.cos());
            let want = bin_of(x.atan2(z), m);
            let got = b.bin_xz(x, z);
            if got != want {
                let edge = -FRAC_PI_2 + got.max(want) as f64 * PI / m as f64;
                assert!((phi - edge).abs() < 1e-12, "phi {phi}: {got} vs {want}");
            }
        }
        assert_eq!(b.bin_xz(0.0, 0.0), m / 2);
        assert_eq!(b.centres()[0], bin_centre(0, m));
    }
}
