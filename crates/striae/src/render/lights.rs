//! Light sources and their sampling for next-event estimation (pbrt-v4 chapter 12, Mitsuba 3's
//! `area`, `constant`, `envmap`, `directional` emitters):
//!
//! * [`Light::Area`]: a shape that emits constant radiance from its front side (the side its
//!   geometric normal points to, one-sided as in Mitsuba); sampled uniformly by area
//!   (`Shape::sample_area`) and converted to solid angle, `pdf = pdf_A d^2 / |cos theta_l|`;
//!   a sphere seen from outside is sampled uniformly in the cone it subtends (pbrt-v4).
//! * [`Light::Environment`]: light from infinitely far away, either constant or an
//!   equirectangular map (importance-sampled by `envmap::EnvMap`). A constant environment
//!   gives next-event estimation no sample: BSDF sampling alone carries it, with MIS weight 1
//!   ([`Environment::light_pdf`]), as pbrt-v4 does with `allowIncompletePDF` (its
//!   `UniformInfiniteLight::SampleLi`). Against a constant radiance the BSDF's own sample is
//!   the better strategy (for a Lambertian surface it is exact but for visibility), so a
//!   uniform-sphere sample would add a shadow ray and almost no information: on the shipped
//!   scenes this gives the same noise or less in less time (setting-1 teapot 2-8 %, gold
//!   teapot 14 %; `BENCHMARKS.md`, "Design findings").
//! * [`Light::Sun`]: a directional (delta) light given by its irradiance on a surface facing it.
//! * [`Light::Point`] and [`Light::Spot`]: KHR_lights_punctual's point and spot lights, delta
//!   lights given by their radiant intensity `I` (W/sr): a surface facing the light at distance
//!   `d` receives the irradiance `I / d^2`. A spot's intensity falls off between its inner and
//!   outer cone as KHR_lights_punctual's reference implementation does (`t^2`, `t` linear in
//!   the cosine, [`spot_falloff`]).
//!
//! The integrator picks one light uniformly per shading point (probability `1 / n_lights`).

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::math::{Frame, Rgb, Vec2, Vec3, PI};
use crate::render::envmap::EnvMap;
use crate::render::geometry::{Shape, ShapeGeometry};

/// Light arriving from infinitely far away.
#[derive(Clone, Debug)]
pub enum Environment {
    /// The same radiance from every direction.
    Constant { radiance: Rgb },
    /// An equirectangular radiance map (its own orientation and scale applied inside).
    Map(Box<EnvMap>),
}

impl Environment {
    /// Radiance arriving along `-dir` (i.e. seen looking in world direction `dir`).
    #[inline]
    pub fn eval(&self, dir: Vec3) -> Rgb {
        match self {
            Environment::Constant { radiance } => *radiance,
            Environment::Map(m) => m.eval(dir),
        }
    }

    /// Solid-angle density with which next-event estimation ([`Light::sample_li`]) returns
    /// `dir`: the map's density (`EnvMap::pdf`), and 0 for a constant environment, which is left
    /// to BSDF sampling (the module notes). Enters the MIS weight of BSDF-sampled rays that
    /// escape the scene.
    #[inline]
    pub fn light_pdf(&self, dir: Vec3) -> f32 {
        match self {
            Environment::Constant { .. } => 0.0,
            Environment::Map(m) => m.pdf(dir),
        }
    }
}

/// A light source of the scene.
#[derive(Clone, Debug)]
pub enum Light {
    /// Shape `shape` emits `radiance` from its front side.
    Area {
        shape: u32,
        radiance: Rgb,
    },
    Environment(Environment),
    /// A directional light: `direction` points **toward** the sun (unit), `irradiance` is the
    /// irradiance on a surface facing it.
    Sun {
        direction: Vec3,
        irradiance: Rgb,
    },
    /// A point light at `position` of radiant intensity `intensity` (W/sr) in every direction.
    Point {
        position: Vec3,
        intensity: Rgb,
    },
    /// A spot light at `position` shining along `direction` (unit, the direction the light
    /// travels): radiant intensity `intensity` within the inner cone (`cos >= cos_inner`), 0
    /// outside the outer cone (`cos <= cos_outer`), [`spot_falloff`] between. Built by
    /// [`Light::spot`].
    Spot {
        position: Vec3,
        direction: Vec3,
        intensity: Rgb,
        cos_inner: f32,
        cos_outer: f32,
    },
}

/// KHR_lights_punctual's spot attenuation: `t = clamp((cos - cos_outer) / (cos_inner -
/// cos_outer), 0, 1)`, returned squared; `cos` is the cosine between the spot's direction and
/// the direction toward the lit point.
#[inline]
pub fn spot_falloff(cos: f32, cos_inner: f32, cos_outer: f32) -> f32 {
    let t = ((cos - cos_outer) / (cos_inner - cos_outer).max(1e-4)).clamp(0.0, 1.0);
    t * t
}

impl Light {
    /// A spot light from its cone half-angles in radians (`0 <= inner < outer <= pi/2`, checked
    /// by the scene loader) and a `direction` of any non-zero length (normalised here).
    pub fn spot(position: Vec3, direction: Vec3, intensity: Rgb, inner: f32, outer: f32) -> Self {
        Light::Spot {
            position,
            direction: direction.normalize(),
            intensity,
            cos_inner: inner.cos(),
            cos_outer: outer.cos(),
        }
    }
}

/// A light sample seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the shading point toward the light.
    pub wi: Vec3,
    /// Distance to the sampled point (`f32::INFINITY` for environment and sun).
    pub dist: f32,
    /// Radiance arriving (for delta lights: the irradiance on a surface facing the light).
    pub radiance: Rgb,
    /// Solid-angle density (1 for the delta lights: sun, point, spot).
    pub pdf: f32,
    pub delta: bool,
}

impl Light {
    /// Sample light arriving at `p` with the random pair `u`. `None` when the sample carries
    /// nothing (back side of an area light, zero density), and always for a constant
    /// environment ([`Environment::light_pdf`]).
    #[inline(always)]
    pub fn sample_li(&self, p: Vec3, u: Vec2, shapes: &[Shape]) -> Option<LightSample> {
        match self {
            Light::Area { shape, radiance } => {
                let shape = &shapes[*shape as usize];
                if let ShapeGeometry::Sphere { centre, radius } = shape.geometry {
                    if let Some(cone) = SphereCone::new(p, centre, radius) {
                        let (wi, dist) = cone.sample(p, centre, radius, u);
                        return Some(LightSample {
                            wi,
                            dist,
                            radiance: *radiance,
                            pdf: cone.pdf(),
                            delta: false,
                        });
                    }
                }
                let (q, n, pdf_area) = shape.sample_area(u);
                let d = q - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0) {
                    return None;
                }
                let dist = dist2.sqrt();
                let wi = d / dist;
                let cos_l = -wi.dot(n);
                if cos_l <= 0.0 {
                    return None;
                }
                let pdf = pdf_area * dist2 / cos_l;
                if !(pdf > 0.0 && pdf.is_finite()) {
                    return None;
                }
                Some(LightSample {
                    wi,
                    dist,
                    radiance: *radiance,
                    pdf,
                    delta: false,
                })
            }
            // Left to BSDF sampling ([`Environment::light_pdf`]).
            Light::Environment(Environment::Constant { .. }) => None,
            Light::Environment(Environment::Map(map)) => {
                let (wi, radiance, pdf) = map.sample(u);
                if !(pdf > 0.0) {
                    return None;
                }
                Some(LightSample {
                    wi,
                    dist: f32::INFINITY,
                    radiance,
                    pdf,
                    delta: false,
                })
            }
            Light::Sun {
                direction,
                irradiance,
            } => Some(LightSample {
                wi: *direction,
                dist: f32::INFINITY,
                radiance: *irradiance,
                pdf: 1.0,
                delta: true,
            }),
            Light::Point {
                position,
                intensity,
            } => point_sample(p, *position, *intensity),
            Light::Spot {
                position,
                direction,
                intensity,
                cos_inner,
                cos_outer,
            } => {
                let mut ls = point_sample(p, *position, *intensity)?;
                let falloff = spot_falloff(-ls.wi.dot(*direction), *cos_inner, *cos_outer);
                if !(falloff > 0.0) {
                    return None;
                }
                ls.radiance *= falloff;
                Some(ls)
            }
        }
    }

    /// Radiance an area light emits toward `wo` (world, pointing away from the light) at a
    /// point with geometric normal `ng`: its radiance on the front side, 0 behind.
    #[inline]
    pub fn emitted(&self, ng: Vec3, wo: Vec3) -> Rgb {
        match self {
            Light::Area { radiance, .. } if ng.dot(wo) > 0.0 => *radiance,
            _ => Rgb::ZERO,
        }
    }

    /// Solid-angle density with which [`Light::sample_li`], called at `origin`, returns the
    /// point hit at distance `dist` along unit `dir` on this area light (geometric normal `ng`).
    #[inline]
    pub fn area_pdf(&self, shapes: &[Shape], origin: Vec3, dist: f32, dir: Vec3, ng: Vec3) -> f32 {
        match self {
            Light::Area { shape, .. } => {
                let shape = &shapes[*shape as usize];
                if let ShapeGeometry::Sphere { centre, radius } = shape.geometry {
                    if let Some(cone) = SphereCone::new(origin, centre, radius) {
                        return cone.pdf();
                    }
                }
                let cos_l = dir.dot(ng).abs();
                if cos_l <= 0.0 {
                    return 0.0;
                }
                dist * dist / (cos_l * shape.area())
            }
            _ => 0.0,
        }
    }
}

/// The sample of a point light of intensity `intensity` at `position` seen from `p`: the
/// irradiance `intensity / d^2` from the direction toward it. `None` at the light itself.
#[inline(always)]
fn point_sample(p: Vec3, position: Vec3, intensity: Rgb) -> Option<LightSample> {
    let d = position - p;
    let dist2 = d.length_squared();
    if !(dist2 > 0.0 && dist2.is_finite()) {
        return None;
    }
    let dist = dist2.sqrt();
    Some(LightSample {
        wi: d / dist,
        dist,
        radiance: intensity / dist2,
        pdf: 1.0,
        delta: true,
    })
}

/// The cone of directions under which a sphere is seen from a point outside it; sampled
/// uniformly (pbrt-v4 `Sphere::Sample(ctx, u)`), which beats uniform area sampling because no
/// sample lands on the far side. `None` from inside the sphere (area sampling is used then).
#[derive(Clone, Copy, Debug)]
struct SphereCone {
    cos_max: f32,
    /// `1 - cos_max`, computed without cancellation for small cones.
    one_minus_cos_max: f32,
    frame: Frame,
}

impl SphereCone {
    fn new(p: Vec3, centre: Vec3, radius: f32) -> Option<SphereCone> {
        let to_centre = centre - p;
        let d2 = to_centre.length_squared();
        // Slightly outside is treated as inside: the cone degenerates at the surface.
        if !(d2 > radius * radius * 1.0001) {
            return None;
        }
        let sin2_max = radius * radius / d2;
        // 1 - sqrt(1 - x) = x / (1 + sqrt(1 - x)): no cancellation for small cones.
        let root = (1.0 - sin2_max).max(0.0).sqrt();
        let one_minus_cos_max = sin2_max / (1.0 + root);
        if !(one_minus_cos_max > 0.0) {
            return None;
        }
        Some(SphereCone {
            cos_max: root,
            one_minus_cos_max,
            frame: Frame::from_normal(to_centre / d2.sqrt()),
        })
    }

    fn pdf(&self) -> f32 {
        1.0 / (2.0 * PI * self.one_minus_cos_max)
    }

    /// A direction in the cone and the distance to the near side of the sphere along it.
    fn sample(&self, p: Vec3, centre: Vec3, radius: f32, u: Vec2) -> (Vec3, f32) {
        let cos_t = 1.0 - u.x * self.one_minus_cos_max;
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        let wi = self
            .frame
            .to_world(Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t))
            .normalize();
        // Nearest intersection of p + t wi with the sphere (tangent point at the cone's rim).
        let oc = p - centre;
        let b = oc.dot(wi);
        let disc = (b * b - (oc.length_squared() - radius * radius)).max(0.0);
        let dist = (-b - disc.sqrt()).max(0.0);
        debug_assert!(cos_t >= self.cos_max - 1e-6);
        (wi, dist)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Ray;
    use crate::render::geometry::{Geometry, Transform, TriangleMesh};
    use crate::testing::{chi2_sphere, SphereGrid};
    use rand::{Rng, SeedableRng};

    /// `sample_li` from `p` against `area_pdf` of the points rays in those directions hit:
    /// the density a light sample reports is the density MIS uses for BSDF hits.
    fn check_light(geometry: ShapeGeometry, p: Vec3) {
        let shapes = vec![Shape {
            geometry,
            material: 0,
            area_light: Some(0),
        }];
        let light = Light::Area {
            shape: 0,
            radiance: Rgb::ONE,
        };
        let scene = Geometry::new(shapes.clone());
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        // Fine quadrature: cells on the light's rim are only partly covered.
        let grid = SphereGrid {
            sub: 24,
            ..SphereGrid::new(48, 96)
        };
        let r = chi2_sphere(
            &grid,
            200_000,
            || {
                let ls = light.sample_li(p, Vec2::new(rng.random(), rng.random()), &shapes)?;
                // The sampled point is where a ray along wi hits the light.
                let hit = scene
                    .intersect(&Ray::new(p, ls.wi))
                    .expect("sampled direction hits the light");
                assert!(
                    (hit.t - ls.dist).abs() < 1e-3 * ls.dist.max(1.0),
                    "{} vs {}",
                    hit.t,
                    ls.dist
                );
                let pdf = light.area_pdf(&shapes, p, hit.t, ls.wi, hit.ng);
                assert!((pdf - ls.pdf).abs() < 1e-3 * ls.pdf, "{pdf} vs {}", ls.pdf);
                Some(ls.wi)
            },
            |w| match scene.intersect(&Ray::new(p, w)) {
                Some(h) if h.ng.dot(w) < 0.0 => light.area_pdf(&shapes, p, h.t, w, h.ng) as f64,
                _ => 0.0,
            },
        );
        assert!(r.p_value > 0.01, "{r:?}");
        assert!((r.pdf_mass - 1.0).abs() < 0.02, "{r:?}");
    }

    #[test]
    fn sphere_light_cone_sampling_matches_its_pdf() {
        check_light(
            ShapeGeometry::sphere(Vec3::new(0.3, 2.0, -0.5), 0.8).unwrap(),
            Vec3::ZERO,
        );
    }

    #[test]
    fn rectangle_light_area_sampling_matches_its_pdf() {
        let t = Transform::rotate(Vec3::X, 90.0)
            .unwrap()
            .then(&Transform::translate(Vec3::new(0.5, 1.5, 0.0)).unwrap());
        check_light(
            ShapeGeometry::Mesh(TriangleMesh::rectangle().transformed(&t).unwrap()),
            Vec3::ZERO,
        );
    }
}
