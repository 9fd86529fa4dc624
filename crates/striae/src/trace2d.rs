//! The 2D scratch BRDF by ray tracing inside the profile (METHOD.md section 3, eq. 1').
//!
//! For each of `M` incident angles `phi_i` (bin centres), `N` rays enter the groove through the
//! opening at stratified (jittered) points travelling along `-(sin phi_i, cos phi_i)`, bounce
//! off the profile's walls and are binned by their exit angle `phi_o` when they leave upward
//! through the opening. Walls are mirrors (`specular`, [Raymond16]'s metal scratches) or
//! Lambertian in 2D (`diffuse`, the seed's glass model, section 3.1). For diffuse walls the
//! seed's scheme is used: from each entry point `N_r` independent walks, each choosing one
//! random reflected direction per bounce (`sin a` uniform in `[-1, 1]` about the wall normal),
//! each weighted `1 / N_r`. A facet albedo scales each bounce; walks still inside after
//! `max_bounces` wall hits are dropped and their energy reported.
//!
//! With `FresnelMode::Walls` ([Raymond16], METHOD.md section 4) the same trace also carries,
//! for each theta slice, a weight multiplied at every wall hit by `F(cos theta * cos a)`, the
//! Fresnel factor at the true 3D incidence cosine (exact for mirror walls of an extruded groove).
//!
//! Geometry is `f64`. Work items are `(phi_i, block of entry points)`; the random stream of
//! each entry point is seeded from `(seed, phi_i index, entry index)` and the per-item
//! histograms are summed in item order, so the output is bit-identical for any thread count.

use crate::fresnel::FresnelLaw;
use crate::profile::Profile;
use rand::Rng;
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};

/// The theta slices of METHOD.md section 4, in table order: 0, pi/3, pi/2.
pub const THETA_SLICES: [f64; 3] = [0.0, PI / 3.0, FRAC_PI_2];
/// `cos` of [`THETA_SLICES`] (the last exactly 0).
pub const COS_THETA_SLICES: [f64; 3] = [1.0, 0.5, 0.0];

/// The micro-BRDF of the profile's walls (section 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Walls {
    /// Mirror reflection at every wall.
    Specular,
    /// 2D Lambertian reflection (`sin a` uniform), the seed's `N_r` scheme.
    Diffuse,
}

/// Where Fresnel is applied (section 4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FresnelMode {
    /// The seed's assumption: one factor `F(n, cos theta)` per slice, applied to `rho_m`.
    Seed,
    /// At every wall hit with the 3D incidence cosine `cos(theta) cos(a)`, per slice.
    Walls,
}

/// Settings of one trace (the table's parameters minus the profile).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TraceSettings {
    pub walls: Walls,
    /// Angle bins `M` (for both `phi_i` and `phi_o`).
    pub m: usize,
    /// Entry points per incident angle `N`.
    pub n: usize,
    /// Walks per entry point `N_r` (diffuse walls only; mirrors trace one path per entry).
    pub nr: usize,
    /// Facet albedo applied at every bounce, in `[0, 1]`.
    pub albedo: f64,
    /// Bounce cap (wall hits); energy of longer walks is dropped and reported.
    pub max_bounces: usize,
    pub seed: u64,
    pub fresnel_mode: FresnelMode,
    /// The law used by `FresnelMode::Walls` (and by the table for `Seed`).
    pub fresnel_law: FresnelLaw,
}

impl Default for TraceSettings {
    /// The seed's values: `N = 10000`, `M = 256`, `N_r = 100`; glass (Schlick, n = 1.5).
    fn default() -> Self {
        TraceSettings {
            walls: Walls::Diffuse,
            m: 256,
            n: 10_000,
            nr: 100,
            albedo: 1.0,
            max_bounces: 64,
            seed: 0,
            fresnel_mode: FresnelMode::Seed,
            fresnel_law: FresnelLaw::Schlick { n: 1.5 },
        }
    }
}

impl TraceSettings {
    /// Walks traced in total: `M N N_r` for diffuse walls, `M N` for mirrors.
    pub fn total_paths(&self) -> u64 {
        self.m as u64 * self.n as u64 * self.walks_per_entry() as u64
    }

    pub fn walks_per_entry(&self) -> usize {
        match self.walls {
            Walls::Diffuse => self.nr,
            Walls::Specular => 1,
        }
    }
}

/// The output of [`trace`]: 2D BRDFs normalised by eq. (1'), indexed `[phi_i bin][phi_o bin]`.
#[derive(Clone, Debug, PartialEq)]
pub struct TraceOutput {
    pub m: usize,
    /// `rho_m`, `M x M` row-major, no Fresnel (albedo only).
    pub rho_m: Vec<f64>,
    /// `FresnelMode::Walls` only: the three slices `3 x M x M` with Fresnel at every hit.
    pub rho_walls: Option<Vec<f64>>,
    /// Per `phi_i`: fraction of the incident energy dropped by the bounce cap (before Fresnel).
    pub dropped: Vec<f64>,
    /// Per `phi_i`: fraction lost to numerical escapes (a ray that finds no wall and is not
    /// going up); should be 0.
    pub lost: Vec<f64>,
}

/// Why a trace was refused.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TraceError {
    #[error("invalid trace parameter `{key}` = {value}: {why}")]
    BadParameter { key: &'static str, value: String, why: &'static str },
}

impl TraceSettings {
    /// Reject parameters the tracer cannot honour.
    pub fn validate(&self) -> Result<(), TraceError> {
        let bad = |key, value: String, why| Err(TraceError::BadParameter { key, value, why });
        if !(1..=8192).contains(&self.m) {
            return bad("m", self.m.to_string(), "must be in 1..=8192");
        }
        if self.n == 0 || self.n > 1 << 32 {
            return bad("n", self.n.to_string(), "must be in 1..=2^32");
        }
        if self.nr == 0 || self.nr > 1 << 20 {
            return bad("nr", self.nr.to_string(), "must be in 1..=2^20");
        }
        if !(self.albedo.is_finite() && (0.0..=1.0).contains(&self.albedo)) {
            return bad("albedo", self.albedo.to_string(), "must be in [0, 1]");
        }
        if !(1..=100_000).contains(&self.max_bounces) {
            return bad("max_bounces", self.max_bounces.to_string(), "must be in 1..=100000");
        }
        let law_ok = match self.fresnel_law {
            FresnelLaw::Schlick { n } | FresnelLaw::Dielectric { n } => n.is_finite() && n > 0.0,
            FresnelLaw::Conductor { eta, k } => eta.is_finite() && k.is_finite() && eta > 0.0 && k >= 0.0,
            FresnelLaw::None => true,
        };
        if !law_ok {
            return bad("fresnel_law", format!("{:?}", self.fresnel_law), "indices must be finite, n > 0, k >= 0");
        }
        Ok(())
    }
}

/// The centre of angle bin `k` of `m`: `-pi/2 + (k + 1/2) pi / m`.
#[inline]
pub fn bin_centre(k: usize, m: usize) -> f64 {
    -FRAC_PI_2 + (k as f64 + 0.5) * PI / m as f64
}

/// The bin of angle `phi` in `[-pi/2, pi/2]`.
#[inline]
pub fn bin_of(phi: f64, m: usize) -> usize {
    (((phi + FRAC_PI_2) * (m as f64 / PI)) as usize).min(m - 1)
}

#[derive(Clone, Copy, Debug)]
struct Segment {
    p: [f64; 2],
    e: [f64; 2],
    /// Unit normal, pointing to the left of `e` (up for a floor traversed left to right).
    n: [f64; 2],
    /// Unit tangent `e / |e|`.
    t: [f64; 2],
}

/// The profile as segments, with ray queries.
struct Walls2D {
    segs: Vec<Segment>,
}

const T_EPS: f64 = 1e-10;

impl Walls2D {
    fn new(profile: &Profile) -> Self {
        let segs = profile
            .points
            .windows(2)
            .map(|w| {
                let e = [w[1][0] - w[0][0], w[1][1] - w[0][1]];
                let l = e[0].hypot(e[1]);
                let t = [e[0] / l, e[1] / l];
                Segment { p: w[0], e, n: [-t[1], t[0]], t }
            })
            .collect();
        Walls2D { segs }
    }

    /// Nearest wall hit of the ray `o + t d` with `t > t_min`, skipping segment `skip`.
    ///
    /// The polyline closed by the opening is a counter-clockwise simple polygon (validated by
    /// `profile`), so a ray inside can only hit a wall from its left (inner) side, where
    /// `d x e > 0`: other segments are culled, and the comparisons are division-free.
    #[inline]
    fn nearest(&self, o: [f64; 2], d: [f64; 2], skip: usize, t_min: f64) -> Option<(usize, f64)> {
        let mut best = usize::MAX;
        // Best hit as the fraction num/den (den > 0), initially +infinity.
        let (mut best_num, mut best_den) = (1.0f64, 0.0f64);
        for (k, s) in self.segs.iter().enumerate() {
            let denom = d[0] * s.e[1] - d[1] * s.e[0];
            if denom <= 0.0 || k == skip {
                continue;
            }
            let w = [s.p[0] - o[0], s.p[1] - o[1]];
            let t_num = w[0] * s.e[1] - w[1] * s.e[0];
            let u_num = w[0] * d[1] - w[1] * d[0];
            let tol = 1e-12 * denom;
            if t_num > t_min * denom && t_num * best_den < best_num * denom && u_num >= -tol && u_num <= denom + tol {
                best = k;
                best_num = t_num;
                best_den = denom;
            }
        }
        (best != usize::MAX).then(|| (best, best_num / best_den))
    }
}

/// Per-entry random stream from `(seed, phi_i index, entry index)` (SplitMix64 finaliser).
fn entry_rng(seed: u64, row: usize, entry: usize) -> rand_pcg::Pcg64Mcg {
    let mut z = seed ^ 0x9E37_79B9_7F4A_7C15u64.wrapping_mul(row as u64 + 1);
    let mut mix = |x: u64| {
        z = z.wrapping_add(x).wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut y = z;
        y = (y ^ (y >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        y = (y ^ (y >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        y ^ (y >> 31)
    };
    let a = mix(entry as u64);
    let b = mix(0x5851_F42D_4C95_7F2D);
    rand_pcg::Pcg64Mcg::new(((a as u128) << 64) | b as u128)
}

/// Bins an upward unit exit direction by `sin(phi_o) = d.x` (no `atan2`): a lookup table on
/// a uniform grid in `d.x` gives a starting bin, corrected against the exact edge sines.
struct ExitBinner {
    edge_sin: Vec<f64>,
    lut: Vec<u32>,
    scale: f64,
}

impl ExitBinner {
    fn new(m: usize) -> Self {
        let edge_sin: Vec<f64> = (0..=m).map(|k| (-FRAC_PI_2 + k as f64 * PI / m as f64).sin()).collect();
        let cells = 4 * m;
        let scale = cells as f64 / 2.0;
        let lut = (0..=cells)
            .map(|q| {
                let x = -1.0 + q as f64 / scale;
                (edge_sin.partition_point(|&e| e <= x).saturating_sub(1)).min(m - 1) as u32
            })
            .collect();
        ExitBinner { edge_sin, lut, scale }
    }

    #[inline]
    fn bin(&self, dx: f64) -> usize {
        let m = self.edge_sin.len() - 1;
        let dx = dx.clamp(-1.0, 1.0);
        let mut j = self.lut[((dx + 1.0) * self.scale) as usize] as usize;
        while j + 1 < m && dx >= self.edge_sin[j + 1] {
            j += 1;
        }
        while j > 0 && dx < self.edge_sin[j] {
            j -= 1;
        }
        j
    }
}

/// Walks interleaved per entry point (see `trace_block`).
const LANES: usize = 4;

/// The state of one walk.
#[derive(Clone, Copy)]
struct Lane {
    pos: [f64; 2],
    dir: [f64; 2],
    seg: usize,
    w: [f64; 4],
    bounces: usize,
    active: bool,
}

/// Accumulators of one work item.
struct Partial {
    /// `channels x M`: channel 0 is `rho_m`, channels 1..=3 the `walls` slices.
    hist: Vec<f64>,
    dropped: f64,
    lost: f64,
}

/// Entry points per work item.
const BLOCK: usize = 256;

/// Trace the profile (section 3). `progress` is called from worker threads with the number of
/// walks just finished. Runs on the current rayon pool.
pub fn trace(profile: &Profile, s: &TraceSettings, progress: &(dyn Fn(u64) + Sync)) -> Result<TraceOutput, TraceError> {
    s.validate()?;
    let geo = Walls2D::new(profile);
    let m = s.m;
    let channels = match s.fresnel_mode {
        FresnelMode::Seed => 1,
        FresnelMode::Walls => 4,
    };
    let blocks = s.n.div_ceil(BLOCK);
    let items: Vec<(usize, usize)> = (0..m).flat_map(|i| (0..blocks).map(move |b| (i, b))).collect();
    let partials: Vec<Partial> = items
        .par_iter()
        .map(|&(row, block)| {
            let lo = block * BLOCK;
            let hi = (lo + BLOCK).min(s.n);
            let p = trace_block(&geo, s, channels, row, lo..hi);
            progress(((hi - lo) * s.walks_per_entry()) as u64);
            p
        })
        .collect();

    // Sum the items of each row in order (deterministic), then normalise by eq. (1').
    let walks = s.walks_per_entry() as f64;
    let mut out = vec![0.0; channels * m * m];
    let mut dropped = vec![0.0; m];
    let mut lost = vec![0.0; m];
    let norm: Vec<f64> = (0..m).map(|j| m as f64 / (PI * s.n as f64 * walks * bin_centre(j, m).cos())).collect();
    for (row, chunk) in partials.chunks(blocks).enumerate() {
        let mut acc = vec![0.0; channels * m];
        for p in chunk {
            for (a, h) in acc.iter_mut().zip(&p.hist) {
                *a += h;
            }
            dropped[row] += p.dropped;
            lost[row] += p.lost;
        }
        dropped[row] /= s.n as f64 * walks;
        lost[row] /= s.n as f64 * walks;
        for c in 0..channels {
            for j in 0..m {
                out[(c * m + row) * m + j] = acc[c * m + j] * norm[j];
            }
        }
    }
    let rho_m = out[..m * m].to_vec();
    let rho_walls = (channels == 4).then(|| out[m * m..].to_vec());
    Ok(TraceOutput { m, rho_m, rho_walls, dropped, lost })
}

/// Trace the entries `entries` of incident bin `row`; weights are per walk (1 each, the
/// `1 / N_r` is applied in the normalisation).
fn trace_block(geo: &Walls2D, s: &TraceSettings, channels: usize, row: usize, entries: std::ops::Range<usize>) -> Partial {
    // Monomorphise the hot loop for the wall model and the Fresnel mode.
    match (s.walls, channels == 4) {
        (Walls::Diffuse, false) => trace_block_impl::<true, false>(geo, s, row, entries),
        (Walls::Diffuse, true) => trace_block_impl::<true, true>(geo, s, row, entries),
        (Walls::Specular, false) => trace_block_impl::<false, false>(geo, s, row, entries),
        (Walls::Specular, true) => trace_block_impl::<false, true>(geo, s, row, entries),
    }
}

fn trace_block_impl<const DIFFUSE: bool, const WALLS_MODE: bool>(
    geo: &Walls2D,
    s: &TraceSettings,
    row: usize,
    entries: std::ops::Range<usize>,
) -> Partial {
    let channels = if WALLS_MODE { 4 } else { 1 };
    let m = s.m;
    let mut part = Partial { hist: vec![0.0; channels * m], dropped: 0.0, lost: 0.0 };
    let phi_i = bin_centre(row, m);
    let d0 = [-phi_i.sin(), -phi_i.cos()];
    let walks = s.walks_per_entry();
    let law = s.fresnel_law;
    let binner = ExitBinner::new(m);
    let albedo = s.albedo;
    let max_bounces = s.max_bounces;
    for k in entries {
        let mut rng = entry_rng(s.seed, row, k);
        let x = -0.5 + (k as f64 + rng.random::<f64>()) / s.n as f64;
        let o = [x, 0.0];
        // The first segment is shared by the N_r walks of this entry point.
        let Some((seg0, t0)) = geo.nearest(o, d0, usize::MAX, -1e-12) else {
            part.lost += walks as f64;
            continue;
        };
        let hit0 = [o[0] + t0.max(0.0) * d0[0], o[1] + t0.max(0.0) * d0[1]];
        // The walks of this entry run LANES at a time, interleaved: each bounce is a chain of
        // dependent sqrt/div latencies, and independent walks side by side let the CPU overlap
        // them. A finished lane restarts with the entry's next walk. Every walk still draws
        // its own fresh uniforms (from the entry's stream, in a fixed order), so the estimator
        // is exactly the seed's N_r scheme and the output is deterministic.
        let fresh = Lane { pos: hit0, dir: d0, seg: seg0, w: [1.0; 4], bounces: 0, active: true };
        let mut lanes = [Lane { active: false, ..fresh }; LANES];
        let mut started = 0;
        let mut active = 0;
        for lane in lanes.iter_mut() {
            if started < walks {
                *lane = fresh;
                started += 1;
                active += 1;
            }
        }
        while active > 0 {
            for lane in lanes.iter_mut() {
                if !lane.active {
                    continue;
                }
                let done = if lane.bounces == max_bounces {
                    part.dropped += lane.w[0];
                    true
                } else {
                    let sg = &geo.segs[lane.seg];
                    let mut n = sg.n;
                    let dir = lane.dir;
                    let mut cos_in = -(n[0] * dir[0] + n[1] * dir[1]);
                    if cos_in < 0.0 {
                        n = [-n[0], -n[1]];
                        cos_in = -cos_in;
                    }
                    lane.bounces += 1;
                    lane.w[0] *= albedo;
                    if WALLS_MODE {
                        for c in 0..3 {
                            lane.w[c + 1] *= albedo * law.reflectance(COS_THETA_SLICES[c] * cos_in);
                        }
                    }
                    let dir = if DIFFUSE {
                        // sin(a) uniform in [-1, 1] about the wall normal (2D Lambert).
                        let sa = 2.0 * rng.random::<f64>() - 1.0;
                        let ca = (1.0 - sa * sa).max(0.0).sqrt();
                        [ca * n[0] + sa * sg.t[0], ca * n[1] + sa * sg.t[1]]
                    } else {
                        let dn = 2.0 * cos_in;
                        [dir[0] + dn * n[0], dir[1] + dn * n[1]]
                    };
                    lane.dir = dir;
                    match geo.nearest(lane.pos, dir, lane.seg, T_EPS) {
                        Some((k2, t)) => {
                            lane.pos = [lane.pos[0] + t * dir[0], lane.pos[1] + t * dir[1]];
                            lane.seg = k2;
                            false
                        }
                        None => {
                            if dir[1] > 0.0 {
                                let j = binner.bin(dir[0]);
                                for c in 0..channels {
                                    part.hist[c * m + j] += lane.w[c];
                                }
                            } else {
                                part.lost += lane.w[0];
                            }
                            true
                        }
                    }
                };
                if done {
                    if started < walks {
                        *lane = fresh;
                        started += 1;
                    } else {
                        lane.active = false;
                        active -= 1;
                    }
                }
            }
        }
    }
    part
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(walls: Walls) -> TraceSettings {
        TraceSettings { walls, m: 32, n: 2000, nr: 8, ..TraceSettings::default() }
    }

    /// Sum over `phi_o` of `rho_m cos(phi_o) pi/M`: the 2D albedo of row `i`.
    fn albedo_2d(rho: &[f64], m: usize, i: usize) -> f64 {
        (0..m).map(|j| rho[i * m + j] * bin_centre(j, m).cos() * PI / m as f64).sum()
    }

    #[test]
    fn lossless_profiles_conserve_energy() {
        for spec in ["v:angle=90", "round:depth=0.4", "trapezoid:depth=0.3,bottom=0.2", "v:depth=2"] {
            let p = Profile::parse(spec).unwrap();
            for walls in [Walls::Specular, Walls::Diffuse] {
                let out = trace(&p, &small(walls), &|_| {}).unwrap();
                for i in 0..out.m {
                    let a = albedo_2d(&out.rho_m, out.m, i);
                    let dropped = out.dropped[i];
                    assert!(out.lost[i] == 0.0, "{spec} {walls:?} row {i} lost {}", out.lost[i]);
                    assert!((a + dropped - 1.0).abs() < 1e-9, "{spec} {walls:?} row {i}: {a} + {dropped}");
                    assert!(dropped < 1e-3, "{spec} {walls:?} row {i}: dropped {dropped}");
                }
            }
        }
    }

    #[test]
    fn albedo_scales_energy() {
        // A flat profile: one bounce each, so the 2D albedo is exactly the facet albedo.
        let s = TraceSettings { albedo: 0.7, ..small(Walls::Diffuse) };
        let out = trace(&Profile::flat(), &s, &|_| {}).unwrap();
        for i in 0..out.m {
            assert!((albedo_2d(&out.rho_m, out.m, i) - 0.7).abs() < 1e-9);
        }
    }

    #[test]
    fn flat_diffuse_is_one_half() {
        // sin(a) uniform: P(phi_o in bin j) = (sin b_{j+1} - sin b_j)/2 ~ cos(phi_j) (pi/M)/2,
        // so eq. (1') gives 1/2 per bin. Compare with the exact bin integral, within MC error.
        let m = 16;
        let s = TraceSettings { walls: Walls::Diffuse, m, n: 4000, nr: 16, ..TraceSettings::default() };
        let out = trace(&Profile::flat(), &s, &|_| {}).unwrap();
        let walks = (s.n * s.nr) as f64;
        let mut max_z = 0.0f64;
        for i in 0..m {
            for j in 0..m {
                let lo = -FRAC_PI_2 + j as f64 * PI / m as f64;
                let hi = lo + PI / m as f64;
                let p = (hi.sin() - lo.sin()) / 2.0;
                let norm = m as f64 / (PI * bin_centre(j, m).cos());
                let expect = p * norm;
                let sigma = (p * (1.0 - p) / walks).sqrt() * norm;
                let z = (out.rho_m[i * m + j] - expect) / sigma;
                max_z = max_z.max(z.abs());
                // And the binning approximation is close to 1/2.
                assert!((expect - 0.5).abs() < 0.01, "{expect}");
            }
        }
        assert!(max_z < 5.0, "max |z| = {max_z}");
    }

    #[test]
    fn flat_mirror_reflects_into_mirror_bin() {
        let s = small(Walls::Specular);
        let out = trace(&Profile::flat(), &s, &|_| {}).unwrap();
        let m = s.m;
        for i in 0..m {
            for j in 0..m {
                let v = out.rho_m[i * m + j];
                if j == m - 1 - i {
                    assert!((v * bin_centre(j, m).cos() * PI / m as f64 - 1.0).abs() < 1e-12);
                } else {
                    assert_eq!(v, 0.0);
                }
            }
        }
    }

    /// A 90-degree mirror V-groove (depth 1/2): left wall L `z = -x - 1/2` (x <= 0), right
    /// wall R `z = x - 1/2`. Reflection off L maps `(dx, dz) -> (-dz, -dx)`, off R
    /// `(dx, dz) -> (dz, dx)`; two reflections (one off each wall) give `-d`: retroreflection,
    /// `phi_o = phi_i` exactly. Take `0 < phi < pi/4`, direction `d = -(sin phi, cos phi)`,
    /// entry `x0` uniform in [-1/2, 1/2].
    /// * The ray crosses `x = 0` at `z = -x0 cot phi`, above the bottom iff `x0 < tan(phi)/2`:
    ///   then it hits L first (case A), else R first (case B).
    /// * Case B: off R it travels `(-cos phi, -sin phi)`, must hit L, leaves as `(sin phi,
    ///   cos phi)`; along that direction `z - x` grows, so it never meets R again: retro.
    /// * Case A: L is hit at `s = (x0 + 1/2)/(sin phi + cos phi)`, `xh + 1/2 = (x0 + 1/2) cos
    ///   phi / (sin phi + cos phi)`; it then travels `(cos phi, sin phi)` and reaches z = 0 at
    ///   `x = xh + (xh + 1/2) cot phi`, which is `<= 1/2` (escape after one bounce, out at
    ///   `phi_o = pi/2 - phi`, another bin) iff `x0 + 1/2 <= tan phi`; otherwise it hits R and
    ///   leaves retroreflected (steep, moving away from both walls).
    /// Retroreflected fraction: `(1/2 - tan(phi)/2) + (tan(phi)/2 - (tan(phi) - 1/2)) =
    /// 1 - tan(phi)`; for `phi >= pi/4` both ranges are empty: 0. By symmetry, for any phi:
    /// `max(0, 1 - tan |phi|)`.
    #[test]
    fn mirror_v_groove_retroreflects_the_two_wall_fraction() {
        let m = 64;
        let s = TraceSettings { walls: Walls::Specular, m, n: 20_000, ..TraceSettings::default() };
        let out = trace(&Profile::parse("v:angle=90").unwrap(), &s, &|_| {}).unwrap();
        for i in 0..m {
            let phi = bin_centre(i, m);
            let retro = out.rho_m[i * m + i] * phi.cos() * PI / m as f64;
            let expect = (1.0 - phi.abs().tan()).max(0.0);
            // Stratified entries: error at most a couple of strata.
            assert!((retro - expect).abs() < 3.0 / s.n as f64, "phi {phi}: {retro} vs {expect}");
        }
    }

    #[test]
    fn deterministic_across_thread_counts() {
        let p = Profile::parse("round:depth=0.35").unwrap();
        let s = TraceSettings {
            m: 16,
            n: 600,
            nr: 4,
            fresnel_mode: FresnelMode::Walls,
            seed: 42,
            ..TraceSettings::default()
        };
        let run = |threads| {
            rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap().install(|| trace(&p, &s, &|_| {}).unwrap())
        };
        let a = run(1);
        let b = run(3);
        assert_eq!(a, b);
        // And a different seed changes the output.
        let c = trace(&p, &TraceSettings { seed: 43, ..s.clone() }, &|_| {}).unwrap();
        assert_ne!(a.rho_m, c.rho_m);
    }

    #[test]
    fn walls_fresnel_for_mirrors_at_grazing_slice_is_lossless() {
        // Slice theta = pi/2 has incidence cosine 0: Schlick gives F = 1, so the slice equals
        // rho_m; slice 0 of a flat mirror is exactly F(cos phi_i).
        let s = TraceSettings { fresnel_mode: FresnelMode::Walls, ..small(Walls::Specular) };
        let out = trace(&Profile::flat(), &s, &|_| {}).unwrap();
        let m = s.m;
        let w = out.rho_walls.unwrap();
        for i in 0..m {
            for j in 0..m {
                assert_eq!(w[2 * m * m + i * m + j], out.rho_m[i * m + j]);
                let f = crate::fresnel::schlick(1.5, bin_centre(i, m).cos());
                assert!((w[i * m + j] - f * out.rho_m[i * m + j]).abs() < 1e-9 * out.rho_m[i * m + j].max(1.0));
            }
        }
    }

    #[test]
    fn exit_binner_matches_atan2() {
        for m in [1, 7, 64, 256] {
            let b = ExitBinner::new(m);
            for k in 0..20_000 {
                let phi = -FRAC_PI_2 + (k as f64 + 0.37) * PI / 20_000.0;
                let (x, z) = (phi.sin(), phi.cos());
                let want = bin_of(x.atan2(z), m);
                let got = b.bin(x);
                // Equal except within rounding of an edge.
                if got != want {
                    let edge = -FRAC_PI_2 + got.max(want) as f64 * PI / m as f64;
                    assert!((phi - edge).abs() < 1e-12, "m {m} phi {phi}: {got} vs {want}");
                }
            }
        }
    }

    #[test]
    fn invalid_settings_rejected() {
        let p = Profile::flat();
        let base = small(Walls::Diffuse);
        for s in [
            TraceSettings { m: 0, ..base.clone() },
            TraceSettings { n: 0, ..base.clone() },
            TraceSettings { nr: 0, ..base.clone() },
            TraceSettings { albedo: 1.5, ..base.clone() },
            TraceSettings { albedo: f64::NAN, ..base.clone() },
            TraceSettings { max_bounces: 0, ..base.clone() },
            TraceSettings { fresnel_law: FresnelLaw::Schlick { n: -1.0 }, ..base.clone() },
            TraceSettings { fresnel_law: FresnelLaw::Conductor { eta: 0.2, k: f64::INFINITY }, ..base.clone() },
        ] {
            assert!(trace(&p, &s, &|_| {}).is_err(), "{s:?}");
        }
    }
}
