//! Sampling building blocks shared by the renderer and the precompute: warps from the unit
//! square (pbrt-v4 `util/sampling.h`) and piecewise-constant 1D/2D distributions.

use crate::math::{Vec2, Vec3, INV_PI, PI};

/// Cosine-weighted hemisphere around `+z` (Malley's method, concentric disk). pdf = cos/pi.
pub fn square_to_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = square_to_concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

pub fn cosine_hemisphere_pdf(w: Vec3) -> f32 {
    w.z.max(0.0) * INV_PI
}

/// Shirley-Chiu concentric map from `[0,1)^2` to the unit disk.
pub fn square_to_concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, PI / 4.0 * (o.y / o.x))
    } else {
        (o.y, PI / 2.0 - PI / 4.0 * (o.x / o.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// Uniform direction on the unit sphere. pdf = 1/(4 pi).
pub fn square_to_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

pub const UNIFORM_SPHERE_PDF: f32 = 1.0 / (4.0 * PI);

/// Uniform direction in the cone of half-angle `acos(cos_max)` around `+z`.
/// pdf = 1 / (2 pi (1 - cos_max)).
pub fn square_to_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_t = 1.0 - u.x * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// Uniform barycentrics `(b0, b1)` on a triangle (pbrt-v4's low-distortion map).
pub fn square_to_uniform_triangle(u: Vec2) -> Vec2 {
    if u.x < u.y {
        let b0 = u.x / 2.0;
        Vec2::new(b0, u.y - b0)
    } else {
        let b1 = u.y / 2.0;
        Vec2::new(u.x - b1, b1)
    }
}

/// Veach's power heuristic with beta = 2 for one sample from each of two strategies.
#[inline]
pub fn power_heuristic(pdf_a: f32, pdf_b: f32) -> f32 {
    let a2 = pdf_a * pdf_a;
    let b2 = pdf_b * pdf_b;
    if a2.is_infinite() {
        return 1.0;
    }
    if a2 + b2 == 0.0 {
        return 0.0;
    }
    a2 / (a2 + b2)
}

/// A piecewise-constant density on `[0, 1)` over `n` equal cells, from non-negative weights.
/// Sampling inverts the CDF; an all-zero function samples uniformly (pbrt's convention).
#[derive(Clone, Debug)]
pub struct Distribution1D {
    func: Vec<f64>,
    cdf: Vec<f64>,
    integral: f64,
}

impl Distribution1D {
    /// # Panics
    /// If `weights` is empty or holds a negative or non-finite value (a programming error:
    /// callers validate user data first).
    pub fn new(weights: &[f64]) -> Self {
        assert!(
            !weights.is_empty(),
            "Distribution1D needs at least one cell"
        );
        assert!(
            weights.iter().all(|w| w.is_finite() && *w >= 0.0),
            "weights must be finite and >= 0"
        );
        let n = weights.len();
        let mut cdf = Vec::with_capacity(n + 1);
        cdf.push(0.0);
        for (i, w) in weights.iter().enumerate() {
            cdf.push(cdf[i] + w / n as f64);
        }
        let integral = cdf[n];
        if integral > 0.0 {
            for c in cdf.iter_mut() {
                *c /= integral;
            }
        } else {
            for (i, c) in cdf.iter_mut().enumerate() {
                *c = i as f64 / n as f64;
            }
        }
        cdf[n] = 1.0;
        Distribution1D {
            func: weights.to_vec(),
            cdf,
            integral,
        }
    }

    pub fn len(&self) -> usize {
        self.func.len()
    }

    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// The integral of the function over `[0, 1)` (the mean weight).
    pub fn integral(&self) -> f64 {
        self.integral
    }

    pub fn func(&self) -> &[f64] {
        &self.func
    }

    /// Probability of choosing cell `i` by [`Distribution1D::sample_discrete`].
    pub fn pmf(&self, i: usize) -> f64 {
        self.cdf[i + 1] - self.cdf[i]
    }

    /// Density on `[0, 1)` of the continuous sample at `x`.
    pub fn pdf(&self, x: f64) -> f64 {
        let n = self.len();
        let i = ((x * n as f64) as usize).min(n - 1);
        self.pmf(i) * n as f64
    }

    /// Cell index `i` with probability `pmf(i)`, and `u` remapped to `[0, 1)` within the cell.
    pub fn sample_discrete(&self, u: f64) -> (usize, f64) {
        let n = self.len();
        // Largest i with cdf[i] <= u, skipping zero-width cells.
        let i = match self.cdf.partition_point(|&c| c <= u) {
            0 => 0,
            k => (k - 1).min(n - 1),
        };
        let w = self.cdf[i + 1] - self.cdf[i];
        let du = if w > 0.0 {
            ((u - self.cdf[i]) / w).clamp(0.0, 1.0 - f64::EPSILON)
        } else {
            0.5
        };
        (i, du)
    }

    /// A continuous sample `x` in `[0, 1)`, its density and cell.
    pub fn sample_continuous(&self, u: f64) -> (f64, f64, usize) {
        let (i, du) = self.sample_discrete(u);
        let n = self.len() as f64;
        let x = ((i as f64 + du) / n).min(1.0 - f64::EPSILON);
        (x, self.pmf(i) * n, i)
    }
}

/// A piecewise-constant density on `[0, 1)^2` (rows along `y`), sampled by the marginal in
/// `y` then the conditional row in `x` (pbrt's `PiecewiseConstant2D`).
#[derive(Clone, Debug)]
pub struct Distribution2D {
    rows: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// `weights` is row-major, `height` rows of `width` cells.
    pub fn new(weights: &[f64], width: usize, height: usize) -> Self {
        assert_eq!(weights.len(), width * height);
        let rows: Vec<_> = weights.chunks(width).map(Distribution1D::new).collect();
        let marginal = Distribution1D::new(&rows.iter().map(|r| r.integral()).collect::<Vec<_>>());
        Distribution2D { rows, marginal }
    }

    pub fn integral(&self) -> f64 {
        self.marginal.integral()
    }

    /// A point in `[0, 1)^2` and its density.
    pub fn sample(&self, u: [f64; 2]) -> ([f64; 2], f64) {
        let (y, pdf_y, row) = self.marginal.sample_continuous(u[1]);
        let (x, pdf_x, _) = self.rows[row].sample_continuous(u[0]);
        ([x, y], pdf_x * pdf_y)
    }

    pub fn pdf(&self, p: [f64; 2]) -> f64 {
        let h = self.rows.len();
        let row = ((p[1] * h as f64) as usize).min(h - 1);
        self.marginal.pdf(p[1]) * self.rows[row].pdf(p[0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{chi2_discrete, chi2_sphere, SphereGrid};
    use rand::{Rng, SeedableRng};

    #[test]
    fn distribution1d_discrete_chi2() {
        let w = [0.0, 1.0, 3.0, 0.5, 0.0, 2.0, 0.25];
        let d = Distribution1D::new(&w);
        let total: f64 = w.iter().sum();
        for (i, wi) in w.iter().enumerate() {
            assert!((d.pmf(i) - wi / total).abs() < 1e-12);
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(1);
        let n = 200_000;
        let mut counts = vec![0u64; w.len()];
        for _ in 0..n {
            let (i, _) = d.sample_discrete(rng.random());
            counts[i] += 1;
        }
        let expected: Vec<f64> = (0..w.len()).map(|i| d.pmf(i) * n as f64).collect();
        let r = chi2_discrete(&counts, &expected);
        assert!(r.p_value > 0.01, "{r:?}");
        assert_eq!(counts[0] + counts[4], 0, "zero cells are never sampled");
    }

    #[test]
    fn cosine_hemisphere_chi2() {
        let grid = SphereGrid::new(20, 40);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(2);
        let r = chi2_sphere(
            &grid,
            200_000,
            || {
                Some(square_to_cosine_hemisphere(Vec2::new(
                    rng.random(),
                    rng.random(),
                )))
            },
            |w| cosine_hemisphere_pdf(w) as f64,
        );
        assert!(r.p_value > 0.01, "{r:?}");
    }

    #[test]
    fn uniform_cone_chi2() {
        let grid = SphereGrid::new(40, 20);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let cos_max = 0.8f32;
        let r = chi2_sphere(
            &grid,
            100_000,
            || {
                Some(square_to_uniform_cone(
                    Vec2::new(rng.random(), rng.random()),
                    cos_max,
                ))
            },
            |w| {
                if w.z >= cos_max {
                    uniform_cone_pdf(cos_max) as f64
                } else {
                    0.0
                }
            },
        );
        assert!(r.p_value > 0.01, "{r:?}");
    }

    #[test]
    fn distribution2d_pdf_matches_sampling() {
        let (w, h) = (8, 5);
        let weights: Vec<f64> = (0..w * h).map(|i| ((i * 7919) % 13) as f64).collect();
        let d = Distribution2D::new(&weights, w, h);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(4);
        let n = 200_000;
        let mut counts = vec![0u64; w * h];
        for _ in 0..n {
            let (p, pdf) = d.sample([rng.random(), rng.random()]);
            assert!((pdf - d.pdf(p)).abs() < 1e-9 * pdf.max(1.0));
            let cx = (p[0] * w as f64) as usize;
            let cy = (p[1] * h as f64) as usize;
            counts[cy * w + cx] += 1;
        }
        let total: f64 = weights.iter().sum();
        let expected: Vec<f64> = weights.iter().map(|x| x / total * n as f64).collect();
        let r = chi2_discrete(&counts, &expected);
        assert!(r.p_value > 0.01, "{r:?}");
    }
}
