//! The GGX (Trowbridge-Reitz) microfacet distribution (Walter, Marschner, Li, Torrance 2007,
//! "Microfacet models for refraction through rough surfaces"), sampled by its distribution of
//! visible normals (Heitz 2018, "Sampling the GGX distribution of visible normals").
//!
//! Shadowing-masking is the **separable** Smith form `G = G1(wo, m) G1(wi, m)` (Walter eq. 23),
//! as Mitsuba 3's `MicrofacetDistribution::G` uses it; the renderer is validated against
//! Mitsuba 3, so we match its choice (pbrt-v4 uses the height-correlated form instead, which
//! is slightly brighter at grazing angles).
//!
//! Its functions compute every branch and select (no early returns), inlined always: the lane
//! vertex runs them in SIMD lanes, where a call or a branch LLVM's cost model will not
//! predicate keeps the loop scalar.

use crate::math::{Vec2, Vec3, PI};

/// An (optionally anisotropic) GGX distribution with roughness `alpha = roughness^2`-style
/// parameters `alpha_x`, `alpha_y` along the local `x` and `y` axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ggx {
    pub alpha_x: f32,
    pub alpha_y: f32,
}

impl Ggx {
    /// Smallest alpha kept: below it the distribution is numerically a delta and
    /// `D` overflows `f32`.
    pub const MIN_ALPHA: f32 = 1e-4;

    pub fn isotropic(alpha: f32) -> Self {
        let a = alpha.max(Self::MIN_ALPHA);
        Ggx {
            alpha_x: a,
            alpha_y: a,
        }
    }

    /// The normal distribution `D(m)` (Walter eq. 33), a density per unit solid
    /// angle of `m`, normalised so that `integral D(m) m.z dm = 1`. 0 below the surface.
    #[inline(always)]
    pub fn d(&self, m: Vec3) -> f32 {
        let (ax, ay) = (self.alpha_x, self.alpha_y);
        let t = (m.x / ax).powi(2) + (m.y / ay).powi(2) + m.z * m.z;
        let d = 1.0 / (PI * ax * ay * t * t);
        if (m.z > 0.0) & d.is_finite() {
            d
        } else {
            0.0
        }
    }

    /// Smith's masking `G1(v, m)` for GGX (Walter eq. 34), 0 when `m` is back-facing to `v`
    /// relative to the side `v` is on (Walter's chi+ term).
    #[inline(always)]
    pub fn g1(&self, v: Vec3, m: Vec3) -> f32 {
        let xy2 = (self.alpha_x * v.x).powi(2) + (self.alpha_y * v.y).powi(2);
        let tan2 = xy2 / (v.z * v.z);
        let g1 = if xy2 <= 0.0 {
            1.0
        } else {
            2.0 / (1.0 + (1.0 + tan2).sqrt())
        };
        if v.dot(m) * v.z <= 0.0 {
            0.0
        } else {
            g1
        }
    }

    /// Separable shadowing-masking `G1(wo, m) G1(wi, m)` (Walter eq. 23; Mitsuba 3).
    #[inline(always)]
    pub fn g(&self, wo: Vec3, wi: Vec3, m: Vec3) -> f32 {
        self.g1(wo, m) * self.g1(wi, m)
    }

    /// Density of [`Ggx::sample_visible`]: `D_v(m) = G1(v, m) max(0, v.m) D(m) / v.z`
    /// (Heitz 2018 eq. 1) for `v.z > 0`.
    #[inline(always)]
    pub fn pdf_visible(&self, v: Vec3, m: Vec3) -> f32 {
        let vm = v.dot(m);
        let pdf = self.g1(v, m) * vm * self.d(m) / v.z;
        if v.z <= 0.0 || vm <= 0.0 {
            0.0
        } else {
            pdf
        }
    }

    /// A microfacet normal `m` (upper hemisphere) visible from `v` (`v.z > 0`), distributed
    /// as [`Ggx::pdf_visible`] (Heitz 2018, listing 1).
    #[inline]
    pub fn sample_visible(&self, v: Vec3, u: Vec2) -> Vec3 {
        self.sample_visible_at(v, u.x, visible_azimuth(u.y))
    }

    /// [`Ggx::sample_visible`] with the azimuth's `(cos, sin)` given ([`visible_azimuth`]):
    /// libm's cosine and sine are calls, which keep a loop from vectorising, so the lane
    /// vertex works them out before its SIMD loop, which runs this.
    #[inline(always)]
    pub fn sample_visible_at(&self, v: Vec3, u_x: f32, (cos_phi, sin_phi): (f32, f32)) -> Vec3 {
        // Stretch the view direction to the hemisphere configuration.
        let vh = Vec3::new(self.alpha_x * v.x, self.alpha_y * v.y, v.z).normalize();
        let lensq = vh.x * vh.x + vh.y * vh.y;
        let t1 = if lensq > 0.0 {
            Vec3::new(-vh.y, vh.x, 0.0) / lensq.sqrt()
        } else {
            Vec3::X
        };
        let t2 = vh.cross(t1);
        // A point on the projected area of the hemisphere.
        let r = u_x.sqrt();
        let p1 = r * cos_phi;
        let mut p2 = r * sin_phi;
        let s = 0.5 * (1.0 + vh.z);
        p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * p2;
        let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
        // Unstretch.
        Vec3::new(self.alpha_x * nh.x, self.alpha_y * nh.y, nh.z.max(1e-7)).normalize()
    }
}

/// `(cos, sin)` of the azimuth `2 pi u_y` at which [`Ggx::sample_visible`] samples.
#[inline(always)]
pub fn visible_azimuth(u_y: f32) -> (f32, f32) {
    let phi = 2.0 * PI * u_y;
    (phi.cos(), phi.sin())
}
