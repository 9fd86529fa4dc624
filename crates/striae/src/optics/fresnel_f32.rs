//! `f32` versions of the Fresnel laws of `crate::optics::fresnel` for the renderer's inner loop (the
//! `f64` originals stay the reference: the tests below compare against them).

use crate::math::Vec3;

/// Exact dielectric Fresnel, as `fresnel::dielectric`: returns `(R, cos_theta_t, eta_it)`,
/// `cos_theta_t` signed opposite to `cos_theta_i` (0 under total internal reflection).
#[inline(always)]
pub fn dielectric(cos_theta_i: f32, eta: f32) -> (f32, f32, f32) {
    let outside = cos_theta_i >= 0.0;
    let eta_it = if outside { eta } else { 1.0 / eta };
    let cos_i = cos_theta_i.abs().min(1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta_it * eta_it);
    if sin2_t >= 1.0 {
        return (1.0, 0.0, eta_it);
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_s = (cos_i - eta_it * cos_t) / (cos_i + eta_it * cos_t);
    let r_p = (eta_it * cos_i - cos_t) / (eta_it * cos_i + cos_t);
    let r = 0.5 * (r_s * r_s + r_p * r_p);
    (r, if outside { -cos_t } else { cos_t }, eta_it)
}

#[inline]
fn sqrt3(v: Vec3) -> Vec3 {
    Vec3::new(v.x.sqrt(), v.y.sqrt(), v.z.sqrt())
}

/// Conductor Fresnel for a complex index `eta + i k` per RGB channel at `cos_theta_i` in
/// `[0, 1]`, in the real-arithmetic form Mitsuba 3 uses (`fresnel_conductor`, after Moeller,
/// "Optics", 1988); equal to `fresnel::conductor`.
#[inline(always)]
pub fn conductor(cos_theta_i: f32, eta: Vec3, k: Vec3) -> Vec3 {
    let c2 = (cos_theta_i * cos_theta_i).min(1.0);
    let s2 = 1.0 - c2;
    let s4 = s2 * s2;
    let t1 = eta * eta - k * k - Vec3::splat(s2);
    let a2pb2 = sqrt3((t1 * t1 + 4.0 * k * k * eta * eta).max(Vec3::ZERO));
    let a = sqrt3((0.5 * (a2pb2 + t1)).max(Vec3::ZERO));
    let term1 = a2pb2 + Vec3::splat(c2);
    let term2 = 2.0 * cos_theta_i.max(0.0) * a;
    let r_s = (term1 - term2) / (term1 + term2);
    let term3 = a2pb2 * c2 + Vec3::splat(s4);
    let term4 = term2 * s2;
    let r_p = r_s * (term3 - term4) / (term3 + term4);
    let r = 0.5 * (r_s + r_p);
    // 0/0 only at cos = 0 with eta = k = 0 in a channel (rejected by validation): treat as 1.
    Vec3::new(
        if r.x.is_finite() { r.x } else { 1.0 },
        if r.y.is_finite() { r.y } else { 1.0 },
        if r.z.is_finite() { r.z } else { 1.0 },
    )
}

#[cfg(test)]
mod tests {
    use crate::math::Vec3;
    use crate::optics::fresnel;

    #[test]
    fn f32_laws_match_the_f64_reference() {
        let mut n = 0;
        for i in 0..=200 {
            let c = i as f32 / 200.0;
            for eta in [1.0f32, 1.33, 1.5, 2.4] {
                for sign in [1.0f32, -1.0] {
                    let (r, ct, e) = super::dielectric(sign * c, eta);
                    let f = fresnel::dielectric((sign * c) as f64, eta as f64);
                    assert!(
                        (r as f64 - f.r).abs() < 1e-5,
                        "dielectric {c} {eta} {sign}: {r} vs {}",
                        f.r
                    );
                    assert!((ct as f64 - f.cos_theta_t).abs() < 1e-5);
                    assert!((e as f64 - f.eta_it).abs() < 1e-6);
                    n += 1;
                }
            }
            for (eta, k) in [
                (0.0f32, 1.0f32),
                (0.143, 3.98),
                (1.657, 9.22),
                (2.91, 3.09),
                (1.5, 0.0),
                (4.37, 5.2),
            ] {
                let r = super::conductor(c, Vec3::splat(eta), Vec3::splat(k));
                let f = fresnel::conductor(c as f64, eta as f64, k as f64);
                assert!(
                    (r.x as f64 - f).abs() < 2e-5,
                    "conductor {c} {eta} {k}: {} vs {f}",
                    r.x
                );
                n += 1;
            }
        }
        assert!(n > 2000);
    }
}
