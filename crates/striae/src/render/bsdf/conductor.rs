//! Conductors: a smooth mirror and a rough GGX reflector (Walter et al. 2007 eq. 20; visible
//! normal sampling, Heitz 2018), with the exact Fresnel reflectance of a complex index of
//! refraction `eta + i k` per RGB channel (`fresnel::conductor`).
//!
//! Presets live in `material` (Mitsuba 3's `conductor` list); `eta = 0, k = 1` is Mitsuba's
//! `none`, a perfect mirror with `F = 1` at every angle.

use super::BsdfSample;
use crate::math::{reflect, reflect_z, Rgb, Vec2, Vec3};
use crate::optics::fresnel_f32;
use crate::optics::microfacet::{visible_azimuth, Ggx};

/// The complex index of refraction of a conductor, per RGB channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConductorIor {
    pub eta: Rgb,
    pub k: Rgb,
}

impl ConductorIor {
    /// Unpolarised reflectance per channel at `cos_theta` in `[0, 1]`.
    #[inline(always)]
    pub fn fresnel(&self, cos_theta: f32) -> Rgb {
        fresnel_f32::conductor(cos_theta, self.eta, self.k)
    }
}

/// A named complex IOR for a conductor: `(names, eta, k)` in linear RGB.
pub type ConductorPreset = (&'static [&'static str], [f32; 3], [f32; 3]);

/// Conductor presets, `(names, eta, k)` per linear RGB channel.
///
/// Source for Ag, Al, Au, Cr, Cu: Tungsten's `ComplexIorData.hpp` (Bitterli), the spectral
/// data Mitsuba 3's `conductor` presets are built from (Mitsuba's `data/ior/*.spd`, from
/// Palik's handbook) integrated to linear sRGB. Fe: refractiveindex.info (Johnson and Christy
/// 1974) sampled at 650 / 550 / 450 nm; Mitsuba has no iron preset, so "steel" and "iron" are
/// not validated against it. `none`: Mitsuba's perfect mirror (`eta = 0, k = 1`: `F = 1` at
/// every angle), for furnace tests.
pub const CONDUCTOR_PRESETS: &[ConductorPreset] = &[
    (&["none", "mirror"], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
    (
        &["Au", "gold"],
        [0.143_118_96, 0.374_957_04, 1.442_478_6],
        [3.983_160_4, 2.385_720_7, 1.603_215_3],
    ),
    (
        &["Ag", "silver"],
        [0.155_264_65, 0.116_723_3, 0.138_380_7],
        [4.828_343_3, 3.122_245_8, 2.146_950_4],
    ),
    (
        &["Cu", "copper"],
        [0.200_437_7, 0.924_033_4, 1.102_212],
        [3.912_948_6, 2.452_847_7, 2.142_188],
    ),
    (
        &["Al", "aluminium", "aluminum"],
        [1.657_46, 0.880_368_96, 0.521_228_7],
        [9.223_869, 6.269_523_4, 4.837_001],
    ),
    (
        &["Cr", "chromium", "chrome"],
        [4.369_683, 2.916_702_5, 1.654_700_5],
        [5.206_434, 4.231_364_7, 3.754_946_7],
    ),
    (
        &["Fe", "iron", "steel"],
        [2.9114, 2.9497, 2.5845],
        [3.0893, 2.9318, 2.7670],
    ),
];

impl ConductorIor {
    /// A conductor preset by any of its names (case-insensitive).
    pub fn preset(name: &str) -> Option<ConductorIor> {
        CONDUCTOR_PRESETS
            .iter()
            .find(|(names, _, _)| names.iter().any(|n| n.eq_ignore_ascii_case(name)))
            .map(|(_, eta, k)| ConductorIor {
                eta: Rgb::from(*eta),
                k: Rgb::from(*k),
            })
    }

    /// Every preset's names, `"none|mirror, Au|gold, ..."`, for error messages.
    pub fn preset_names() -> String {
        CONDUCTOR_PRESETS
            .iter()
            .map(|(n, _, _)| n.join("|"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// A smooth conductor: a single delta reflection lobe with weight `F(cos theta_o)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Conductor {
    pub ior: ConductorIor,
}

impl Conductor {
    pub fn new(eta: Rgb, k: Rgb) -> Self {
        Conductor {
            ior: ConductorIor { eta, k },
        }
    }

    #[inline]
    pub fn sample(&self, wo: Vec3) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        Some(BsdfSample {
            wi: reflect_z(wo),
            weight: self.ior.fresnel(wo.z),
            pdf: 1.0,
            delta: true,
            eta: 1.0,
            from: None,
        })
    }
}

/// A rough GGX conductor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RoughConductor {
    pub ior: ConductorIor,
    pub distribution: Ggx,
}

impl RoughConductor {
    pub fn new(eta: Rgb, k: Rgb, alpha: f32) -> Self {
        RoughConductor {
            ior: ConductorIor { eta, k },
            distribution: Ggx::isotropic(alpha),
        }
    }

    /// `F(wo.m) D(m) G(wo, wi, m) / (4 cos_o cos_i)`, `m` the half vector (Walter eq. 20).
    /// (Inlined always, as [`Self::pdf`] and [`Self::sample_at`]: the lane vertex's SIMD loop
    /// runs them, and a call keeps it scalar.)
    #[inline(always)]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        let m = (wo + wi).normalize();
        let dg = self.distribution.d(m) * self.distribution.g(wo, wi, m);
        let v = self.ior.fresnel(wo.dot(m)) * (dg / (4.0 * wo.z * wi.z));
        if wo.z <= 0.0 || wi.z <= 0.0 || dg <= 0.0 {
            Rgb::ZERO
        } else {
            v
        }
    }

    /// `D_wo(m) / (4 wo.m)` (visible-normal density times the reflection Jacobian, eq. 14).
    #[inline(always)]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let m = (wo + wi).normalize();
        let wo_m = wo.dot(m);
        let pdf = self.distribution.pdf_visible(wo, m) / (4.0 * wo_m);
        if wo.z <= 0.0 || wi.z <= 0.0 || wo_m <= 0.0 {
            0.0
        } else {
            pdf
        }
    }

    /// `(eval, pdf)` sharing the half vector, `D` and `G1(wo)`.
    #[inline(always)]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        let m = (wo + wi).normalize();
        let wo_m = wo.dot(m);
        let d = self.distribution.d(m);
        let g1_o = self.distribution.g1(wo, m);
        let g = g1_o * self.distribution.g1(wi, m);
        let pdf = g1_o * wo_m * d / wo.z / (4.0 * wo_m);
        let f = self.ior.fresnel(wo_m) * (d * g / (4.0 * wo.z * wi.z));
        let connects = !(wo.z <= 0.0) & !(wi.z <= 0.0) & !(wo_m <= 0.0);
        (
            if connects & !(d * g <= 0.0) {
                f
            } else {
                Rgb::ZERO
            },
            if connects { pdf } else { 0.0 },
        )
    }

    /// Reflect `wo` about a visible normal; weight `F(wo.m) G1(wi, m)`.
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        self.sample_at(wo, u.x, visible_azimuth(u.y))
    }

    /// [`Self::sample`] with the visible normal's azimuth given ([`Ggx::sample_visible_at`]).
    #[inline(always)]
    pub fn sample_at(&self, wo: Vec3, u_x: f32, azimuth: (f32, f32)) -> Option<BsdfSample> {
        let m = self.distribution.sample_visible_at(wo, u_x, azimuth);
        let wi = reflect(wo, m);
        let wo_m = wo.dot(m);
        let pdf = self.distribution.pdf_visible(wo, m) / (4.0 * wo_m);
        let g1 = self.distribution.g1(wi, m);
        let valid = !(wo.z <= 0.0) & !(wi.z <= 0.0) & (pdf > 0.0) & !(g1 <= 0.0);
        valid.then_some(BsdfSample {
            wi,
            weight: self.ior.fresnel(wo_m) * g1,
            pdf,
            delta: false,
            eta: 1.0,
            from: None,
        })
    }
}
