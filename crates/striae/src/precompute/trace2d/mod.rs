//! The 2D scratch BRDF by ray tracing inside the profile (METHOD.md section 3, eq. 1').
//!
//! For each of `M` incident angles `phi_i` (bin centres), `N` rays enter the groove through the
//! opening at stratified (jittered) points travelling along `-(sin phi_i, cos phi_i)`, bounce
//! off the profile's walls and are binned by their exit angle `phi_o` when they leave upward
//! through the opening. Walls are mirrors (`specular`, [Raymond16]'s metal scratches) or
//! Lambertian in 2D (`diffuse`, the seed's glass model, section 3.1). For diffuse use walls the
//! seed's scheme is used: from each entry point `N_r` independent walks, each choosing one
//! random reflected direction per bounce (`sin a` uniform in `[-1, 1]` about the wall normal),
//! each weighted `1 / N_r`. A facet albedo scales each bounce; walks still inside after
//! `max_bounces` wall hits are dropped and their energy reported.
//!
//! With `FresnelMode::Walls` ([Raymond16], METHOD.md section 4) the same trace also carries,
//! for each theta slice, a weight multiplied at every wall hit by `F(cos theta * cos a)`, the
//! Fresnel factor at the true 3D incidence cosine (exact for mirror walls of an extruded groove).
//!
//! Geometry is `f64`. Work items are `(phi_i, block of entry points)`; random numbers are
//! counter-based (SplitMix64 of `(seed, phi_i index, entry index)` and `(walk, bounce)`), and
//! the per-item histograms are summed in item order, so the output is bit-identical for any
//! thread count.
//!
//! Diffuse walls in a convex groove (V, round, trapezoid, flat) take a fast path that traces
//! the same walks with the same random numbers: the first hit is shared by an entry's `N_r`
//! walks, so their first bounce is classified (escape or not) by comparing the random integer
//! with the precomputed interval of the opening's corners and binned without building the
//! direction; walks that stay inside advance breadth-first. An optional kernel estimator
//! ([`Estimator::Kernel`], a departure from the seed documented in `docs/table-format.md`)
//! tabulates the exit distribution per wall position instead of walking from every entry.
//!
//! This file holds the settings, the entry points and the random streams the tracers share;
//! one tracer per file: `generic.rs` (the reference), `convex.rs` (the fast path) and
//! `kernel.rs` (the kernel estimator).

/// Version of the tracer's random streams and estimators. The same seed and settings give the
/// same table only within one tracer version, so the on-disk table cache keys on it: bump it
/// whenever a change alters the numbers a given seed produces.
pub const TRACER_VERSION: u32 = 2;

use crate::hash::{mix64, GOLDEN};
use crate::optics::fresnel::FresnelLaw;
use crate::precompute::angle_bins::AngleBins;
use crate::precompute::cross_section::{CrossSection, Segment};
use crate::precompute::profile::Profile;
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};

mod convex;
mod generic;
mod kernel;
#[cfg(test)]
mod tests;

use convex::ConvexDiffuse;
use generic::Generic;
use kernel::trace_kernel;

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

/// How diffuse walls are estimated (section 3.1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Estimator {
    /// The seed's `N_r` scheme: `N_r` independent random walks per entry point.
    #[default]
    Walks,
    /// Departure from the seed (an option, not the default): a kernel estimator. With
    /// diffuse walls the walk after the first wall hit depends only on the hit position, so
    /// the expected exit distribution from a wall point (the kernel) is tabulated once per
    /// wall at `KERNEL_NODES` positions by random walks, and each entry point adds the
    /// (linearly interpolated) kernel row of its first hit, weighted by that hit. Same
    /// expectation as the `N_r` scheme (up to the interpolation in position); lower variance
    /// per row, but the kernel's Monte Carlo error is shared by all rows. Exact only for
    /// diffuse walls with `FresnelMode::Seed` in a convex groove; other cases are refused.
    Kernel,
}

impl Estimator {
    fn is_walks(&self) -> bool {
        *self == Estimator::Walks
    }
}

/// Kernel nodes per wall segment ([`Estimator::Kernel`]).
pub const KERNEL_NODES: usize = 256;

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
    /// The diffuse-wall estimator (absent from a table's parameters when `walks`, so older
    /// tables and their hashes are unchanged).
    #[serde(default, skip_serializing_if = "Estimator::is_walks")]
    pub estimator: Estimator,
    /// Exact-groove `theta_i` slices traced besides the 2D trace (`crate::precompute::groove_slices`;
    /// 0, the default: the seed's model only, absent from a table's parameters so that older
    /// tables and their hashes are unchanged).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub groove_slices: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
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
            estimator: Estimator::Walks,
            groove_slices: 0,
        }
    }
}

impl TraceSettings {
    /// Walks traced in total: `M N N_r` for diffuse walls, `M N` for mirrors.
    pub fn total_paths(&self) -> u64 {
        self.m as u64 * self.n as u64 * self.walks_per_entry() as u64
    }

    /// Goniometer paths of the exact-groove slices: `N N_r` per slice and `phi_i` bin, the
    /// 2D trace's walks per incident angle.
    pub fn groove_paths(&self) -> u64 {
        (self.groove_slices * self.m) as u64 * self.n as u64 * self.nr as u64
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
    BadParameter {
        key: &'static str,
        value: String,
        why: &'static str,
    },
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
            return bad(
                "max_bounces",
                self.max_bounces.to_string(),
                "must be in 1..=100000",
            );
        }
        // The walls are the scratched material seen from outside (air), so a dielectric
        // index below 1 is a mistake, as for a glass material's `ior`.
        match self.fresnel_law {
            FresnelLaw::Schlick { n } | FresnelLaw::Dielectric { n } => {
                if !(n.is_finite() && n >= 1.0) {
                    return bad(
                        "ior",
                        n.to_string(),
                        "an index of refraction must be finite and >= 1",
                    );
                }
            }
            FresnelLaw::Conductor { eta, k } => {
                if !(eta.is_finite() && k.is_finite() && eta > 0.0 && k >= 0.0) {
                    return bad(
                        "fresnel_law",
                        format!("{:?}", self.fresnel_law),
                        "a conductor needs finite eta > 0 and k >= 0",
                    );
                }
            }
            FresnelLaw::None => {}
        }
        self.validate_groove_slices()?;
        if self.estimator == Estimator::Kernel {
            if self.walls != Walls::Diffuse {
                return bad(
                    "estimator",
                    "kernel".into(),
                    "the kernel estimator needs diffuse walls (mirror walls are deterministic)",
                );
            }
            if self.fresnel_mode != FresnelMode::Seed {
                return bad(
                    "estimator",
                    "kernel".into(),
                    "the kernel estimator supports only --fresnel seed (with Fresnel at every \
                     wall the weights depend on each path's cosines)",
                );
            }
        }
        Ok(())
    }
}

impl TraceSettings {
    /// `groove_slices`: at most [`crate::precompute::groove_slices::MAX_SLICES`], and only where the exact
    /// groove is what the table stands for (diffuse walls, Fresnel at every wall hit, no facet
    /// albedo, which the groove tracer does not model).
    fn validate_groove_slices(&self) -> Result<(), TraceError> {
        let s = self.groove_slices;
        if s == 0 {
            return Ok(());
        }
        let bad = |key, value: String, why| Err(TraceError::BadParameter { key, value, why });
        if s > crate::precompute::groove_slices::MAX_SLICES {
            return bad("groove_slices", s.to_string(), "must be in 0..=32");
        }
        if self.walls != Walls::Diffuse {
            return bad(
                "groove_slices",
                s.to_string(),
                "exact-groove slices need diffuse walls (the mirror-wall lobe is a delta in \
                 theta, exact already with fresnel = walls)",
            );
        }
        if self.fresnel_mode != FresnelMode::Walls {
            return bad(
                "fresnel",
                "seed".into(),
                "exact-groove slices apply Fresnel at every wall hit: they need fresnel = walls",
            );
        }
        if self.albedo != 1.0 {
            return bad(
                "albedo",
                self.albedo.to_string(),
                "the exact groove has no facet albedo: with groove_slices it must be 1",
            );
        }
        if self.m > 1024 {
            return bad(
                "m",
                self.m.to_string(),
                "with groove_slices M must be in 1..=1024 (the goniometer bins M x M)",
            );
        }
        if self.n as u64 * self.nr as u64 > 1 << 40 {
            return bad(
                "nr",
                self.nr.to_string(),
                "with groove_slices N N_r (paths per slice and phi_i) must be at most 2^40",
            );
        }
        Ok(())
    }
}

pub use crate::precompute::angle_bins::{bin_centre, bin_of};

/// The key of an entry point's random streams, from `(seed, phi_i index, entry index)`
/// (distinct for every `(row, entry)` as `row < 2^13`, `entry < 2^32`).
#[inline]
fn entry_key(seed: u64, row: usize, entry: usize) -> u64 {
    mix64(mix64(seed.wrapping_add(GOLDEN)) ^ (((row as u64) << 32) | entry as u64))
}

/// Counter-based random numbers (SplitMix64 of `key + counter * golden`): draw `counter` of
/// an entry's stream is computed directly, so walks are independent of the order (or the
/// interleaving) in which they are traced. Counter 0 is the entry's jitter; walk `r` uses
/// counters `1 + r * max_bounces + k` for its bounces `k = 0..max_bounces`.
#[inline(always)]
fn draw(key: u64, counter: u64) -> u64 {
    mix64(key.wrapping_add(counter.wrapping_mul(GOLDEN)))
}

/// Uniform in `[0, 1)` from the top 53 bits.
#[inline(always)]
fn unit(x: u64) -> f64 {
    (x >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// `sin(a)` of the 2D Lambert law: uniform in `[-1, 1)` from the top 53 bits (`2 u - 1`).
#[inline(always)]
fn signed_unit(x: u64) -> f64 {
    (x >> 11) as f64 * (1.0 / (1u64 << 52) as f64) - 1.0
}

/// The counter of bounce `k` of walk `r` (see [`draw`]).
#[inline(always)]
fn walk_counter(r: usize, k: usize, max_bounces: usize) -> u64 {
    1 + r as u64 * max_bounces as u64 + k as u64
}

/// Accumulators of one work item.
struct Partial {
    /// `channels x M`: channel 0 is `rho_m`, channels 1..=3 the `walls` slices.
    hist: Vec<f64>,
    dropped: f64,
    lost: f64,
}

impl Partial {
    fn new(channels: usize, m: usize) -> Self {
        Partial {
            hist: vec![0.0; channels * m],
            dropped: 0.0,
            lost: 0.0,
        }
    }

    /// A walk with no wall ahead: out through the opening if it heads up (binned by `d.x`),
    /// else lost to round-off.
    #[inline]
    fn leave(&mut self, binner: &AngleBins, dir: [f64; 2], w: &[f64; 4], channels: usize) {
        if dir[1] > 0.0 {
            let m = binner.len();
            let j = binner.bin_sin(dir[0]);
            for (c, wc) in w.iter().enumerate().take(channels) {
                self.hist[c * m + j] += wc;
            }
        } else {
            self.lost += w[0];
        }
    }
}

/// Entry points per work item.
const BLOCK: usize = 256;

/// Weights after a wall hit with 2D incidence cosine `cos_in`: the facet albedo, and with
/// `WALLS_MODE` the Fresnel factor of each theta slice at the 3D cosine `cos theta cos_in`.
#[inline(always)]
fn hit_weights<const WALLS_MODE: bool>(
    mut w: [f64; 4],
    cos_in: f64,
    albedo: f64,
    law: FresnelLaw,
) -> [f64; 4] {
    w[0] *= albedo;
    if WALLS_MODE {
        for (w, cos_theta) in w[1..].iter_mut().zip(COS_THETA_SLICES) {
            *w *= albedo * law.reflectance(cos_theta * cos_in);
        }
    }
    w
}

/// The 2D Lambert bounce off segment `sg` with `sin(a) = sa` about its inner normal.
#[inline(always)]
fn lambert_dir(sg: &Segment, sa: f64) -> [f64; 2] {
    let ca = (1.0 - sa * sa).max(0.0).sqrt();
    [ca * sg.n[0] + sa * sg.t[0], ca * sg.n[1] + sa * sg.t[1]]
}

/// The entry point of entry `k` of incident row `row` (stratified, jittered) and the key of
/// its random streams.
#[inline]
fn entry_point(s: &TraceSettings, row: usize, k: usize) -> ([f64; 2], u64) {
    let key = entry_key(s.seed, row, k);
    let x = -0.5 + (k as f64 + unit(draw(key, 0))) / s.n as f64;
    ([x, 0.0], key)
}

/// The first wall hit of a ray entering at `o` along `d0` (`None`: a numerical miss).
#[inline]
fn first_hit(geo: &CrossSection, o: [f64; 2], d0: [f64; 2]) -> Option<(usize, [f64; 2])> {
    let (seg0, t0) = geo.nearest(o, d0, usize::MAX, -1e-12)?;
    Some((
        seg0,
        [o[0] + t0.max(0.0) * d0[0], o[1] + t0.max(0.0) * d0[1]],
    ))
}

/// The incident travel direction of row `row`: `-(sin phi_i, cos phi_i)`.
#[inline]
fn incident_dir(row: usize, m: usize) -> [f64; 2] {
    let phi_i = bin_centre(row, m);
    [-phi_i.sin(), -phi_i.cos()]
}

/// Trace the profile (section 3). `progress` is called from worker threads with the number of
/// walks just finished. Runs on the current rayon pool.
pub fn trace(
    profile: &Profile,
    s: &TraceSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<TraceOutput, TraceError> {
    trace_with(profile, s, progress, TracePath::Auto)
}

/// Which implementation [`trace_with`] uses (the generic one exists to test the fast one).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TracePath {
    /// The convex fast path where it applies, else the generic tracer.
    Auto,
    /// Always the generic tracer.
    #[cfg_attr(not(test), allow(dead_code))]
    Generic,
}

fn trace_with(
    profile: &Profile,
    s: &TraceSettings,
    progress: &(dyn Fn(u64) + Sync),
    path: TracePath,
) -> Result<TraceOutput, TraceError> {
    s.validate()?;
    let geo = CrossSection::new(profile);
    if s.estimator == Estimator::Kernel {
        return trace_kernel(&geo, s, progress);
    }
    let m = s.m;
    let channels = match s.fresnel_mode {
        FresnelMode::Seed => 1,
        FresnelMode::Walls => 4,
    };
    let generic = Generic::new(&geo, s);
    // The fast path for diffuse walls in convex grooves (same random numbers, same walks).
    let convex = (geo.convex && s.walls == Walls::Diffuse && path == TracePath::Auto)
        .then(|| ConvexDiffuse::new(&geo, s));
    let blocks = s.n.div_ceil(BLOCK);
    let items: Vec<(usize, usize)> = (0..m)
        .flat_map(|i| (0..blocks).map(move |b| (i, b)))
        .collect();
    let partials: Vec<Partial> = items
        .par_iter()
        .map(|&(row, block)| {
            let entries = block * BLOCK..((block + 1) * BLOCK).min(s.n);
            let walks = (entries.len() * s.walks_per_entry()) as u64;
            let p = match &convex {
                Some(c) if channels == 4 => c.block::<true>(row, entries),
                Some(c) => c.block::<false>(row, entries),
                None => generic.block(channels, row, entries),
            };
            progress(walks);
            p
        })
        .collect();
    Ok(sum_rows(s, channels, blocks, &partials))
}

/// Sum the work items of each row in order (deterministic), then normalise by eq. (1').
fn sum_rows(
    s: &TraceSettings,
    channels: usize,
    blocks: usize,
    partials: &[Partial],
) -> TraceOutput {
    let m = s.m;
    let walks = s.walks_per_entry() as f64;
    let mut out = vec![0.0; channels * m * m];
    let mut dropped = vec![0.0; m];
    let mut lost = vec![0.0; m];
    let norm: Vec<f64> = (0..m)
        .map(|j| m as f64 / (PI * s.n as f64 * walks * bin_centre(j, m).cos()))
        .collect();
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
    TraceOutput {
        m,
        rho_m,
        rho_walls,
        dropped,
        lost,
    }
}
