//! Multiple scattering on a rough GGX microsurface: the random walk of Heitz, Hanika, d'Eon and
//! Dachsbacher 2016, "Multiple-Scattering Microfacet BSDFs with the Smith Model" (METHOD.md
//! 9.7).
//!
//! A single-scattering microfacet BSDF ([`super::microfacet::Ggx`]) drops the light that meets a
//! second microfacet after the first. The Smith model's microsurface is a random medium of
//! heights and normals, independent of each other; a ray on it meets the next microfacet at a
//! height drawn from the height distribution and Smith's `Lambda` (Heitz16 sec. 5), scatters
//! off a normal drawn from the distribution of normals visible from its direction, and goes on
//! until it escapes. The walk is exact for the Smith model, stochastic and lossless where the
//! facets are (a dielectric; a conductor with `F = 1`). The height distribution is uniform on
//! `[-1, 1]`: the result does not depend on it (Heitz16 sec. 4.3).
//!
//! Frame: the macro-surface normal is `+z`. `wi` points from the surface towards where the
//! light comes from (`wi.z > 0`); the exit direction points away from the surface, up for
//! reflection and down for transmission. The walk's first event is the single-scattering BSDF
//! with height-correlated masking-shadowing `1 / (1 + Lambda(wi) + Lambda(wo))`.

use super::fresnel::dielectric;
use std::f64::consts::PI;

/// Scattering events after which a walk is dropped (energy lost). With `alpha <= 1` the mean
/// order is below 3 (tested), and none of the tests' 1.6 million lossless walks reaches it.
pub const MAX_ORDER: u32 = 64;

/// An isotropic GGX microsurface of roughness `alpha`, heights uniform on `[-1, 1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Microsurface {
    pub alpha: f64,
}

/// Where a walk left the microsurface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WalkExit {
    /// Unit exit direction: `z > 0` reflected, `z < 0` transmitted.
    pub w: [f64; 3],
    /// The product of the facets' reflectances (conductor; 1 for a dielectric).
    pub weight: f64,
    /// Scattering events (1: single scattering).
    pub order: u32,
}

impl Microsurface {
    /// Smallest `alpha` kept (as [`super::microfacet::Ggx::MIN_ALPHA`]).
    pub fn new(alpha: f64) -> Self {
        Microsurface {
            alpha: alpha.max(1e-4),
        }
    }

    /// Smith's `Lambda(w)` for GGX, for directions up (`>= 0`) and down (`Lambda(-w) = -1 -
    /// Lambda(w)`, `<= -1`).
    pub fn lambda(&self, w: [f64; 3]) -> f64 {
        let z = w[2];
        let xy2 = (w[0] * w[0] + w[1] * w[1]).max(0.0);
        if xy2 == 0.0 {
            return if z > 0.0 { 0.0 } else { -1.0 };
        }
        let up = 0.5 * (-1.0 + (1.0 + self.alpha * self.alpha * xy2 / (z * z)).sqrt());
        if z > 0.0 {
            up
        } else {
            -1.0 - up
        }
    }

    /// The next height of a ray travelling along `w` from height `h` (Heitz16 Algorithm 2's
    /// `sampleHeight`, uniform heights: `C1(h) = (h + 1) / 2`), or `None` if it escapes.
    fn next_height(&self, w: [f64; 3], h: f64, u: f64) -> Option<f64> {
        let c1 = |h: f64| (0.5 * (h + 1.0)).clamp(0.0, 1.0);
        let inv_c1 = |u: f64| (2.0 * u - 1.0).clamp(-1.0, 1.0);
        if w[2] > 0.9999 {
            return None;
        }
        if w[2] < -0.9999 {
            return Some(inv_c1(u * c1(h)));
        }
        if w[2].abs() < 1e-4 {
            return Some(h);
        }
        let lambda = self.lambda(w);
        // Probability of escaping from `h` upward (Smith's `G1(w, h) = C1(h)^Lambda`).
        let escape = if w[2] > 0.0 { c1(h).powf(lambda) } else { 0.0 };
        if u > 1.0 - escape {
            return None;
        }
        Some(inv_c1(c1(h) / (1.0 - u).powf(1.0 / lambda)))
    }

    /// A normal `m` (upper hemisphere) from the distribution of normals visible from `v`,
    /// `max(0, v.m) D(m) / A(v)` for any `v` with `v.z > -1` (Heitz 2018, "Sampling the GGX
    /// distribution of visible normals", whose construction holds below the horizon too: the
    /// visible part of the stretched hemisphere projects to the disk minus the half-ellipse).
    pub fn sample_visible(&self, v: [f64; 3], u0: f64, u1: f64) -> [f64; 3] {
        let a = self.alpha;
        let vh = normalize([a * v[0], a * v[1], v[2]]);
        let lensq = vh[0] * vh[0] + vh[1] * vh[1];
        let t1 = if lensq > 0.0 {
            let l = lensq.sqrt();
            [-vh[1] / l, vh[0] / l, 0.0]
        } else {
            [1.0, 0.0, 0.0]
        };
        let t2 = cross(vh, t1);
        let r = u0.sqrt();
        let (sp, cp) = (2.0 * PI * u1).sin_cos();
        let p1 = r * cp;
        let s = 0.5 * (1.0 + vh[2]);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * sp;
        let pz = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        let nh = [
            p1 * t1[0] + p2 * t2[0] + pz * vh[0],
            p1 * t1[1] + p2 * t2[1] + pz * vh[1],
            p1 * t1[2] + p2 * t2[2] + pz * vh[2],
        ];
        normalize([a * nh[0], a * nh[1], nh[2].max(1e-12)])
    }

    /// The walk on a conductor whose facets reflect `fresnel(cos)` (Heitz16 sec. 6.2), from
    /// light arriving along `-wi`. `None` past [`MAX_ORDER`] events. `rng` gives uniform
    /// numbers in `[0, 1)`, three per event.
    pub fn walk_conductor(
        &self,
        wi: [f64; 3],
        fresnel: impl Fn(f64) -> f64,
        rng: &mut impl FnMut() -> f64,
    ) -> Option<WalkExit> {
        let mut w = neg(wi);
        let mut h = 1.0 + 0.998; // above every height, as Heitz16's `1 + invC1(0.999)`
        let mut weight = 1.0;
        for order in 0..=MAX_ORDER {
            let Some(next) = self.next_height(w, h, rng()) else {
                return Some(WalkExit { w, weight, order });
            };
            if order == MAX_ORDER {
                break;
            }
            h = next;
            let v = neg(w);
            let m = self.sample_visible(v, rng(), rng());
            let c = dot(v, m).max(0.0);
            weight *= fresnel(c);
            w = normalize(reflect(v, m, c));
        }
        None
    }

    /// The walk on a dielectric interface of relative index `eta = n_below / n_above` (Heitz16
    /// sec. 6.3): each event reflects with the exact Fresnel reflectance at the microfacet or
    /// refracts and crosses to the other side, where heights are mirrored. Lossless; `None`
    /// past [`MAX_ORDER`] events.
    pub fn walk_dielectric(
        &self,
        wi: [f64; 3],
        eta: f64,
        rng: &mut impl FnMut() -> f64,
    ) -> Option<WalkExit> {
        let mut w = neg(wi);
        let mut h = 1.0 + 0.998;
        let mut above = true;
        for order in 0..=MAX_ORDER {
            let u = rng();
            let next = if above {
                self.next_height(w, h, u)
            } else {
                self.next_height(neg(w), -h, u).map(|h| -h)
            };
            let Some(next) = next else {
                return Some(WalkExit {
                    w,
                    weight: 1.0,
                    order,
                });
            };
            if order == MAX_ORDER {
                break;
            }
            h = next;
            let v = neg(w);
            // The normal faces the side the ray is on.
            let m = if above {
                self.sample_visible(v, rng(), rng())
            } else {
                neg(self.sample_visible(neg(v), rng(), rng()))
            };
            let c = dot(v, m).max(0.0);
            let eta_ti = if above { eta } else { 1.0 / eta };
            let f = dielectric(c, eta_ti);
            w = if rng() < f.r {
                normalize(reflect(v, m, c))
            } else {
                above = !above;
                let e = 1.0 / eta_ti;
                let k = e * c + f.cos_theta_t; // e c - cos_t
                normalize([
                    k * m[0] - e * v[0],
                    k * m[1] - e * v[1],
                    k * m[2] - e * v[2],
                ])
            };
        }
        None
    }
}

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn neg(a: [f64; 3]) -> [f64; 3] {
    [-a[0], -a[1], -a[2]]
}

#[inline]
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
fn normalize(a: [f64; 3]) -> [f64; 3] {
    let l = dot(a, a).sqrt();
    [a[0] / l, a[1] / l, a[2] / l]
}

/// `v` mirrored about `m` (`c = v . m`).
#[inline]
fn reflect(v: [f64; 3], m: [f64; 3], c: f64) -> [f64; 3] {
    [
        2.0 * c * m[0] - v[0],
        2.0 * c * m[1] - v[1],
        2.0 * c * m[2] - v[2],
    ]
}

#[cfg(test)]
mod tests;
