//! Fresnel reflectance laws: Schlick's approximation (eq. 2 of the seed), the exact
//! dielectric equations and a conductor with a complex index of refraction.
//!
//! All are unpolarised. Cosines are measured from the surface normal; `eta` is the ratio
//! `n_transmitted / n_incident` for light arriving from the outside (1.5 for glass in air).

/// Eq. (2) of the seed, Schlick's approximation:
/// `F(n, c) = ((n - 1)^2 + 4 n (1 - c)^5) / (n + 1)^2`, i.e. `F0 + (1 - F0)(1 - c)^5` with
/// `F0 = ((n - 1)/(n + 1))^2`. `c` is clamped to `[0, 1]`.
#[inline]
pub fn schlick(n: f64, c: f64) -> f64 {
    let c = c.clamp(0.0, 1.0);
    ((n - 1.0).powi(2) + 4.0 * n * (1.0 - c).powi(5)) / (n + 1.0).powi(2)
}

/// The result of the exact dielectric Fresnel equations at one interface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DielectricFresnel {
    /// Reflectance in `[0, 1]` (1 under total internal reflection).
    pub r: f64,
    /// Cosine of the refracted direction, with the sign opposite to `cos_theta_i`
    /// (0 under total internal reflection).
    pub cos_theta_t: f64,
    /// Relative index `n_t / n_i` seen from the incident side.
    pub eta_it: f64,
}

/// Exact unpolarised Fresnel reflectance of a smooth dielectric interface (Mitsuba's
/// `fresnel()`). `cos_theta_i` is signed: positive when the incident direction is on the side
/// the normal points to (outside, index 1), negative from inside (index `eta`).
pub fn dielectric(cos_theta_i: f64, eta: f64) -> DielectricFresnel {
    let outside = cos_theta_i >= 0.0;
    let eta_it = if outside { eta } else { 1.0 / eta };
    let cos_i = cos_theta_i.abs().min(1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta_it * eta_it);
    if sin2_t >= 1.0 {
        return DielectricFresnel {
            r: 1.0,
            cos_theta_t: 0.0,
            eta_it,
        };
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t);
    let r_p = (eta_it * cos_i - cos_t) / (eta_it * cos_i + cos_t);
    let r = 0.5 * (r_s * r_s + r_p * r_p);
    DielectricFresnel {
        r,
        cos_theta_t: if outside { -cos_t } else { cos_t },
        eta_it,
    }
}

#[derive(Clone, Copy, Debug)]
struct Complex {
    re: f64,
    im: f64,
}

impl Complex {
    fn new(re: f64, im: f64) -> Self {
        Complex { re, im }
    }
    fn add(self, o: Complex) -> Complex {
        Complex::new(self.re + o.re, self.im + o.im)
    }
    fn sub(self, o: Complex) -> Complex {
        Complex::new(self.re - o.re, self.im - o.im)
    }
    fn mul(self, o: Complex) -> Complex {
        Complex::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
    fn scale(self, s: f64) -> Complex {
        Complex::new(self.re * s, self.im * s)
    }
    fn norm2(self) -> f64 {
        self.re * self.re + self.im * self.im
    }
    fn div(self, o: Complex) -> Complex {
        let d = o.norm2();
        Complex::new(
            (self.re * o.re + self.im * o.im) / d,
            (self.im * o.re - self.re * o.im) / d,
        )
    }
    fn sqrt(self) -> Complex {
        let r = self.norm2().sqrt();
        let re = (0.5 * (r + self.re)).max(0.0).sqrt();
        let im = (0.5 * (r - self.re)).max(0.0).sqrt().copysign(self.im);
        Complex::new(re, im)
    }
}

/// Exact unpolarised reflectance of a conductor with complex index `eta + i k` (relative to
/// the outside medium), for `cos_theta_i` in `[0, 1]` (pbrt-v4's `FrComplex`).
pub fn conductor(cos_theta_i: f64, eta: f64, k: f64) -> f64 {
    let cos_i = cos_theta_i.clamp(0.0, 1.0);
    let eta_c = Complex::new(eta, k);
    let sin2_i = 1.0 - cos_i * cos_i;
    let sin2_t = Complex::new(sin2_i, 0.0).div(eta_c.mul(eta_c));
    let cos_t = Complex::new(1.0, 0.0).sub(sin2_t).sqrt();
    let ci = Complex::new(cos_i, 0.0);
    let r_parl = eta_c
        .scale(cos_i)
        .sub(cos_t)
        .div(eta_c.scale(cos_i).add(cos_t));
    let r_perp = ci.sub(eta_c.mul(cos_t)).div(ci.add(eta_c.mul(cos_t)));
    0.5 * (r_parl.norm2() + r_perp.norm2())
}

/// A Fresnel law chosen at run time (the precompute's `--fresnel-law`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "law", rename_all = "lowercase")]
pub enum FresnelLaw {
    /// Eq. (2), Schlick, with index `n`.
    Schlick { n: f64 },
    /// The exact dielectric equations with relative index `n`.
    Dielectric { n: f64 },
    /// A conductor with complex index `eta + i k`.
    Conductor { eta: f64, k: f64 },
    /// No Fresnel attenuation: `F = 1` at every angle (the white-furnace tests of
    /// scratched metal; Mitsuba's perfect mirror).
    None,
}

impl FresnelLaw {
    /// Parse `schlick`, `dielectric` (both with index `ior`), `conductor:ETA,K` or `none` (the
    /// syntax of `striae precompute --fresnel-law` and of the scene files' `fresnel_law`).
    pub fn parse(s: &str, ior: f64) -> Result<FresnelLaw, String> {
        Ok(match s.trim() {
            "schlick" => FresnelLaw::Schlick { n: ior },
            "dielectric" => FresnelLaw::Dielectric { n: ior },
            "none" => FresnelLaw::None,
            t => {
                let Some(rest) = t.strip_prefix("conductor:") else {
                    return Err(format!("unknown Fresnel law `{s}` (expected schlick, dielectric, conductor:ETA,K or none)"));
                };
                let parts: Vec<&str> = rest.split(',').collect();
                let [eta, k] = parts[..] else {
                    return Err(format!("`{s}`: expected conductor:ETA,K"));
                };
                let eta: f64 = eta
                    .trim()
                    .parse()
                    .map_err(|_| format!("`{s}`: ETA `{eta}` is not a number"))?;
                let k: f64 = k
                    .trim()
                    .parse()
                    .map_err(|_| format!("`{s}`: K `{k}` is not a number"))?;
                FresnelLaw::Conductor { eta, k }
            }
        })
    }

    /// Reflectance for light arriving from outside at cosine `c` in `[0, 1]`.
    pub fn reflectance(&self, c: f64) -> f64 {
        match *self {
            FresnelLaw::Schlick { n } => schlick(n, c),
            FresnelLaw::Dielectric { n } => dielectric(c.clamp(0.0, 1.0), n).r,
            FresnelLaw::Conductor { eta, k } => conductor(c, eta, k),
            FresnelLaw::None => 1.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schlick_limits() {
        // Normal incidence: ((n-1)/(n+1))^2; grazing: 1.
        assert!((schlick(1.5, 1.0) - 0.04).abs() < 1e-12);
        assert!((schlick(1.5, 0.0) - 1.0).abs() < 1e-12);
        // n = 1 reflects nothing at normal incidence.
        assert_eq!(schlick(1.0, 1.0), 0.0);
        // Monotone in the cosine.
        let mut prev = 2.0;
        for i in 0..=100 {
            let f = schlick(1.5, i as f64 / 100.0);
            assert!(f <= prev);
            prev = f;
        }
    }

    #[test]
    fn dielectric_matches_known_values() {
        let f = dielectric(1.0, 1.5);
        assert!((f.r - 0.04).abs() < 1e-12);
        assert!((f.cos_theta_t + 1.0).abs() < 1e-12);
        // Brewster angle: r_p = 0, so R = r_s^2 / 2.
        let tb = 1.5f64.atan();
        let f = dielectric(tb.cos(), 1.5);
        let ct = (1.0 - (tb.sin() / 1.5).powi(2)).sqrt();
        let rs = (tb.cos() - 1.5 * ct) / (tb.cos() + 1.5 * ct);
        assert!((f.r - 0.5 * rs * rs).abs() < 1e-12);
        // Total internal reflection from inside beyond the critical angle.
        let crit = (1.0f64 / 1.5).asin();
        assert_eq!(dielectric(-(crit + 0.01).cos(), 1.5).r, 1.0);
        assert!(dielectric(-(crit - 0.01).cos(), 1.5).r < 1.0);
        // Reciprocity of the interface: R(outside, theta_i) = R(inside, theta_t).
        let f = dielectric(0.6, 1.5);
        let g = dielectric(f.cos_theta_t, 1.5);
        assert!((f.r - g.r).abs() < 1e-12);
    }

    #[test]
    fn conductor_reduces_to_dielectric_for_zero_k() {
        for c in [1.0, 0.8, 0.3, 0.05] {
            assert!((conductor(c, 1.5, 0.0) - dielectric(c, 1.5).r).abs() < 1e-12);
        }
        // Gold-like: high reflectance, 1 at grazing.
        assert!(conductor(1.0, 0.18, 3.0) > 0.9);
        assert!((conductor(0.0, 0.18, 3.0) - 1.0).abs() < 1e-9);
    }
}
