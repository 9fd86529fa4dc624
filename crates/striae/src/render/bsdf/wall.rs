//! The wall of an explicit scratch groove (METHOD.md 8.1, 8.3): the BSDF the scratch table
//! assumes for opaque walls, applied at each wall hit. `Diffuse`: Lambertian times the Fresnel
//! law at the light's cosine, `f = tint F(cos theta_i) / pi` (the goniometer's walls, which
//! weight a path by `F` at the cosine of the light's arrival); `Specular`: a mirror of
//! reflectance `tint F(cos theta)`.

use super::{BsdfSample, Diffuse};
use crate::math::{Rgb, Vec2, Vec3, INV_PI};
use crate::optics::fresnel::FresnelLaw;

/// An opaque groove wall.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrooveWall {
    /// Mirror (`true`) or Lambertian (`false`).
    pub specular: bool,
    pub law: FresnelLaw,
    pub tint: Rgb,
}

impl GrooveWall {
    #[inline]
    fn fresnel(&self, cos: f32) -> Rgb {
        self.tint * self.law.reflectance(cos.clamp(0.0, 1.0) as f64) as f32
    }

    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if self.specular || wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        self.fresnel(wi.z) * INV_PI
    }

    /// The Lambertian lobe the diffuse wall samples (cosine-weighted, `Diffuse`'s).
    const LAMBERT: Diffuse = Diffuse {
        reflectance: Rgb::ONE,
    };

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.specular {
            return 0.0;
        }
        Self::LAMBERT.pdf(wo, wi)
    }

    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        if self.specular {
            return Some(BsdfSample {
                wi: Vec3::new(-wo.x, -wo.y, wo.z),
                weight: self.fresnel(wo.z),
                pdf: 1.0,
                delta: true,
                eta: 1.0,
                from: None,
            });
        }
        // Lambert's weight is 1, so f cos / pdf = tint F(cos_i).
        let s = Self::LAMBERT.sample(wo, u)?;
        Some(BsdfSample {
            weight: self.fresnel(s.wi.z),
            ..s
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::fresnel::schlick;
    use crate::testing::MeanEstimate;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// The directional albedo `2 int_0^1 F(mu) mu dmu` of a Lambertian wall times `F` at the
    /// light's cosine, by the midpoint rule.
    fn diffuse_albedo(f: impl Fn(f64) -> f64) -> f64 {
        let n = 100_000;
        (0..n)
            .map(|i| {
                let mu = (i as f64 + 0.5) / n as f64;
                2.0 * f(mu) * mu / n as f64
            })
            .sum()
    }

    #[test]
    fn diffuse_walls_reflect_their_fresnel_weighted_albedo() {
        let mut rng = Pcg64::seed_from_u64(11);
        for law in [FresnelLaw::None, FresnelLaw::Schlick { n: 1.5 }] {
            let wall = GrooveWall {
                specular: false,
                law,
                tint: Rgb::ONE,
            };
            let expected = diffuse_albedo(|mu| law.reflectance(mu));
            let wo = Vec3::new(0.3, -0.2, 0.93).normalize();
            let (mut sampled, mut uniform) = (MeanEstimate::default(), MeanEstimate::default());
            for _ in 0..200_000 {
                let u = Vec2::new(rng.random(), rng.random());
                let s = wall.sample(wo, u).expect("a sample above the wall");
                sampled.push(s.weight.x as f64);
                // The same integral from eval with uniform hemisphere directions.
                let z: f32 = rng.random();
                let phi = 2.0 * std::f32::consts::PI * rng.random::<f32>();
                let r = (1.0 - z * z).max(0.0).sqrt();
                let wi = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                let f = wall.eval(wo, wi).x as f64;
                uniform.push(f * z as f64 * 2.0 * std::f64::consts::PI);
                assert!((wall.pdf(wo, s.wi) - s.wi.z / std::f32::consts::PI).abs() < 1e-5);
            }
            assert!(
                sampled.agrees_with(expected, 4.0, 1e-4),
                "{law:?}: {} vs {expected}",
                sampled.mean()
            );
            assert!(
                uniform.agrees_with(expected, 4.0, 1e-4),
                "{law:?}: {} vs {expected}",
                uniform.mean()
            );
        }
        // Lossless walls reflect everything; Schlick's glass walls about 10 %.
        assert!((diffuse_albedo(|_| 1.0) - 1.0).abs() < 1e-9);
        let glass = diffuse_albedo(|mu| schlick(1.5, mu));
        assert!(glass > 0.05 && glass < 0.15, "{glass}");
    }

    #[test]
    fn specular_walls_mirror_with_their_fresnel_reflectance() {
        let gold = FresnelLaw::Conductor { eta: 0.2, k: 3.9 };
        let tint = Rgb::new(1.0, 0.8, 0.5);
        let wall = GrooveWall {
            specular: true,
            law: gold,
            tint,
        };
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let s = wall.sample(wo, Vec2::ZERO).unwrap();
        assert!(s.delta);
        assert_eq!(s.wi, Vec3::new(-0.6, 0.0, 0.8));
        let f = gold.reflectance(0.8) as f32;
        assert!((s.weight - tint * f).abs().max_element() < 1e-6);
        assert!(f < 1.0 && f > 0.8);
        assert_eq!(wall.eval(wo, s.wi), Rgb::ZERO);
        assert_eq!(wall.pdf(wo, s.wi), 0.0);
        assert!(wall.sample(-wo, Vec2::ZERO).is_none());
    }
}
