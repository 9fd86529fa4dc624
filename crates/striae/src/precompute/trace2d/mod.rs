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

/// Version of the tracer's random streams and estimators. The same seed and settings give the
/// same table only within one tracer version, so the on-disk table cache keys on it: bump it
/// whenever a change alters the numbers a given seed produces.
pub const TRACER_VERSION: u32 = 2;

use crate::hash::{mix64, GOLDEN};
use crate::optics::fresnel::FresnelLaw;
use crate::precompute::angle_bins::AngleBins;
use crate::precompute::cross_section::{CrossSection, Segment, T_EPS};
use crate::precompute::profile::Profile;
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

/// `sin(a) = k 2^-52 - 1` of the 53-bit integer `k` (exact).
#[inline(always)]
fn sin_of_int(k: u64) -> f64 {
    k as f64 * (1.0 / (1u64 << 52) as f64) - 1.0
}

/// The smallest 53-bit integer `k` with `sin_of_int(k) >= e` (`2^53` if none; `e` may be
/// infinite).
fn int_threshold(e: f64) -> u64 {
    first_int_where(|x| x >= e, e)
}

/// The smallest 53-bit integer `k` with `sin_of_int(k) > e` (`2^53` if none).
fn int_threshold_above(e: f64) -> u64 {
    first_int_where(|x| x > e, e)
}

/// The smallest `k` in `0..=2^53` where the monotone predicate `holds(sin_of_int(k))` is true
/// (`2^53` if none), starting near `e`.
fn first_int_where(holds: impl Fn(f64) -> bool, e: f64) -> u64 {
    const TOP: u64 = 1 << 53;
    if e.is_nan() || e > 1.0 {
        return TOP;
    }
    let mut k = (((e + 1.0) * (1u64 << 52) as f64).ceil().max(0.0) as u64).min(TOP);
    while k > 0 && holds(sin_of_int(k - 1)) {
        k -= 1;
    }
    while k < TOP && !holds(sin_of_int(k)) {
        k += 1;
    }
    k
}

/// Exit bins of a diffuse bounce off one wall, on the random integer itself.
///
/// The bounce's direction has `sin(a) = k 2^-52 - 1` ([`signed_unit`]) about the inner normal,
/// which makes the angle `alpha` with the vertical, so the exit angle is `phi_o = alpha + a`,
/// increasing in `k`: bin `j` is a range of `k` between integer thresholds of the edges
/// `sin(edge_j - alpha)` (clamped to `[-1, 1]` for edges the bounce cannot reach). An escaping
/// bounce is binned with neither its direction (no `sqrt`) nor a float comparison: a table on
/// the top bits of `k` and one threshold comparison.
struct WallBinner {
    m: usize,
    /// Thresholds of the `m + 1` edges, padded with `u64::MAX` to a power-of-two length.
    thresholds: Vec<u64>,
    threshold_mask: usize,
    /// Per cell of `k >> shift`: the bin of the cell's first `k`; `MULTI` flags a cell that
    /// spans more than one threshold (slow path).
    lut: Vec<u16>,
    lut_mask: usize,
    shift: u32,
}

impl WallBinner {
    const MULTI: u16 = 0x8000;

    fn new(m: usize, alpha: f64) -> Self {
        let mut thresholds: Vec<u64> = (0..=m)
            .map(|k| {
                let a = -FRAC_PI_2 + k as f64 * PI / m as f64 - alpha;
                int_threshold(a.clamp(-FRAC_PI_2, FRAC_PI_2).sin())
            })
            .collect();
        let slow_bin = |th: &[u64], k: u64| -> usize {
            th.partition_point(|&t| t <= k).saturating_sub(1).min(m - 1)
        };
        // ~16 cells per bin: cells spanning several thresholds are rare (|sin a| > 0.997).
        let bits = (16 * m).next_power_of_two().trailing_zeros().max(1);
        let shift = 53 - bits;
        let lut: Vec<u16> = (0..1u64 << bits)
            .map(|c| {
                let (first, last) = (c << shift, ((c + 1) << shift) - 1);
                let (j0, j1) = (slow_bin(&thresholds, first), slow_bin(&thresholds, last));
                let multi = if j1 > j0 + 1 { Self::MULTI } else { 0 };
                j0 as u16 | multi
            })
            .collect();
        thresholds.resize((m + 2).next_power_of_two(), u64::MAX);
        WallBinner {
            m,
            threshold_mask: thresholds.len() - 1,
            thresholds,
            lut_mask: lut.len() - 1,
            lut,
            shift,
        }
    }

    /// The bin of the bounce with random integer `k < 2^53`.
    #[inline(always)]
    fn bin(&self, k: u64) -> usize {
        let entry = self.lut[(k >> self.shift) as usize & self.lut_mask];
        if entry & Self::MULTI != 0 {
            return self.bin_slow(k);
        }
        let j = entry as usize;
        // `k` beyond the last edge (a direction past the horizon, never an escape) would
        // give `m`: clamped.
        (j + (k >= self.thresholds[(j + 1) & self.threshold_mask]) as usize).min(self.m - 1)
    }

    #[cold]
    fn bin_slow(&self, k: u64) -> usize {
        self.thresholds[..=self.m]
            .partition_point(|&t| t <= k)
            .saturating_sub(1)
            .min(self.m - 1)
    }
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

/// Walks interleaved per entry point (see [`Generic::block`]).
const LANES: usize = 4;

/// The state of one walk of the generic tracer.
#[derive(Clone, Copy)]
struct Lane {
    pos: [f64; 2],
    dir: [f64; 2],
    seg: usize,
    w: [f64; 4],
    bounces: usize,
    /// Index `r` of the walk among the entry's `N_r` (selects its random numbers).
    walk: usize,
    active: bool,
}

/// The reference tracer: any profile, both wall models, walk by walk.
struct Generic<'a> {
    geo: &'a CrossSection,
    binner: AngleBins,
    s: &'a TraceSettings,
}

impl<'a> Generic<'a> {
    fn new(geo: &'a CrossSection, s: &'a TraceSettings) -> Self {
        Generic {
            geo,
            binner: AngleBins::new(s.m),
            s,
        }
    }

    /// Trace the entries `entries` of incident bin `row`; weights are per walk (1 each, the
    /// `1 / N_r` is applied in the normalisation).
    fn block(&self, channels: usize, row: usize, entries: std::ops::Range<usize>) -> Partial {
        // Monomorphise the hot loop for the wall model and the Fresnel mode.
        match (self.s.walls, channels == 4) {
            (Walls::Diffuse, false) => self.block_impl::<true, false>(row, entries),
            (Walls::Diffuse, true) => self.block_impl::<true, true>(row, entries),
            (Walls::Specular, false) => self.block_impl::<false, false>(row, entries),
            (Walls::Specular, true) => self.block_impl::<false, true>(row, entries),
        }
    }

    fn block_impl<const DIFFUSE: bool, const WALLS_MODE: bool>(
        &self,
        row: usize,
        entries: std::ops::Range<usize>,
    ) -> Partial {
        let channels = if WALLS_MODE { 4 } else { 1 };
        let mut part = Partial::new(channels, self.s.m);
        let d0 = incident_dir(row, self.s.m);
        let walks = self.s.walks_per_entry();
        for k in entries {
            let (o, key) = entry_point(self.s, row, k);
            // The first segment is shared by the N_r walks of this entry point.
            let Some((seg0, hit0)) = first_hit(self.geo, o, d0) else {
                part.lost += walks as f64;
                continue;
            };
            let fresh = Lane {
                pos: hit0,
                dir: d0,
                seg: seg0,
                w: [1.0; 4],
                bounces: 0,
                walk: 0,
                active: true,
            };
            self.entry_walks::<DIFFUSE, WALLS_MODE>(key, fresh, &mut part);
        }
        part
    }

    /// The `N_r` walks of one entry, `LANES` at a time, interleaved: each bounce is a chain
    /// of dependent sqrt/div latencies, and independent walks side by side let the CPU
    /// overlap them. A finished lane restarts with the entry's next walk. Every walk still
    /// draws its own fresh uniforms (from the entry's stream, in a fixed order), so the
    /// estimator is exactly the seed's N_r scheme and the output is deterministic.
    fn entry_walks<const DIFFUSE: bool, const WALLS_MODE: bool>(
        &self,
        key: u64,
        fresh: Lane,
        part: &mut Partial,
    ) {
        let walks = self.s.walks_per_entry();
        let mut lanes = [Lane {
            active: false,
            ..fresh
        }; LANES];
        let mut started = 0;
        let mut active = 0;
        for lane in lanes.iter_mut() {
            if started < walks {
                *lane = Lane {
                    walk: started,
                    ..fresh
                };
                started += 1;
                active += 1;
            }
        }
        while active > 0 {
            for lane in lanes.iter_mut() {
                if !lane.active || !self.step::<DIFFUSE, WALLS_MODE>(key, lane, part) {
                    continue;
                }
                if started < walks {
                    *lane = Lane {
                        walk: started,
                        ..fresh
                    };
                    started += 1;
                } else {
                    lane.active = false;
                    active -= 1;
                }
            }
        }
    }

    /// One bounce of a walk at its wall hit: true when the walk ends (out, lost or dropped).
    #[inline(always)]
    fn step<const DIFFUSE: bool, const WALLS_MODE: bool>(
        &self,
        key: u64,
        lane: &mut Lane,
        part: &mut Partial,
    ) -> bool {
        let s = self.s;
        if lane.bounces == s.max_bounces {
            part.dropped += lane.w[0];
            return true;
        }
        let sg = &self.geo.segs[lane.seg];
        let mut n = sg.n;
        let dir = lane.dir;
        let mut cos_in = -(n[0] * dir[0] + n[1] * dir[1]);
        if cos_in < 0.0 {
            n = [-n[0], -n[1]];
            cos_in = -cos_in;
        }
        lane.bounces += 1;
        lane.w = hit_weights::<WALLS_MODE>(lane.w, cos_in, s.albedo, s.fresnel_law);
        let dir = if DIFFUSE {
            // sin(a) uniform in [-1, 1] about the wall normal (2D Lambert).
            let counter = walk_counter(lane.walk, lane.bounces - 1, s.max_bounces);
            let sa = signed_unit(draw(key, counter));
            let ca = (1.0 - sa * sa).max(0.0).sqrt();
            [ca * n[0] + sa * sg.t[0], ca * n[1] + sa * sg.t[1]]
        } else {
            let dn = 2.0 * cos_in;
            [dir[0] + dn * n[0], dir[1] + dn * n[1]]
        };
        lane.dir = dir;
        match self.geo.nearest(lane.pos, dir, lane.seg, T_EPS) {
            Some((k2, t)) => {
                lane.pos = [lane.pos[0] + t * dir[0], lane.pos[1] + t * dir[1]];
                lane.seg = k2;
                false
            }
            None => {
                let channels = if WALLS_MODE { 4 } else { 1 };
                part.leave(&self.binner, dir, &lane.w, channels);
                true
            }
        }
    }
}

/// The first bounces of an entry's `walks` walks (the hot loop of [`ConvexDiffuse::block`],
/// kept apart so that its few live values stay in registers): a walk escapes iff its random
/// integer `k` lies in `lo_k .. lo_k + span`; escapes are counted per exit bin, the others
/// are written to `pending`, whose length is returned. Branch-free: every walk is binned and
/// adds 0 or 1 (the escape outcome is unpredictable).
#[inline(never)]
fn first_bounces(
    key: u64,
    walks: usize,
    max_bounces: usize,
    (lo_k, span): (u64, u64),
    wb: &WallBinner,
    counts: &mut [u32],
    pending: &mut [u32],
) -> usize {
    let mut n_pending = 0;
    let pending = &mut pending[..walks];
    for r in 0..walks {
        let k = draw(key, walk_counter(r, 0, max_bounces)) >> 11;
        let escapes = k.wrapping_sub(lo_k) < span;
        counts[wb.bin(k)] += escapes as u32;
        pending[n_pending.min(walks - 1)] = r as u32;
        n_pending += (!escapes) as usize;
    }
    n_pending
}

/// A walk of the convex fast path, queued after a bounce that stays inside.
#[derive(Clone, Copy)]
struct Walk {
    /// The key of its entry's random streams.
    key: u64,
    /// Index among the entry's `N_r` walks (selects its random numbers).
    r: u32,
    seg: u32,
    /// The last wall hit and the direction leaving it.
    pos: [f64; 2],
    dir: [f64; 2],
    w: [f64; 4],
}

/// The fast path of [`Generic`] for diffuse walls in a convex groove: the same walks with
/// the same random numbers (up to round-off at bin edges and corners), cheaper per walk
/// (tested against [`Generic`] by `convex_fast_path_matches_generic_tracer`).
///
/// * The entry's first wall hit is shared by its `N_r` walks, so the escape test of their
///   first bounce is precomputed: a bounce from a point `p` of a convex groove escapes iff its
///   direction lies between those of the opening's corners, i.e. iff `sin(a)` lies between the
///   corners' `sin(a)` (`phi_o = alpha + a` is increasing in `sin a`).
/// * An escaping bounce is binned by `sin(a)` directly (a per-wall [`WallBinner`]):
///   no `sqrt`, no intersection. Only the walks that stay inside build their direction.
/// * Later bounces test escape by two cross products with the corner directions
///   ([`CrossSection::escapes_convex`]); in a V the next wall is found in closed form
///   ([`CrossSection::other_wall_hit`]).
struct ConvexDiffuse<'a> {
    geo: &'a CrossSection,
    binner: AngleBins,
    wall_binners: Vec<WallBinner>,
    s: &'a TraceSettings,
    two_walls: bool,
}

/// Per-block scratch space of [`ConvexDiffuse::block`].
struct ConvexScratch {
    /// Walks whose first bounce stays inside (walk indices).
    pending: Vec<u32>,
    queue: Vec<Walk>,
    /// First-bounce escapes per (wall, exit bin).
    first_counts: Vec<u32>,
    /// Exit histogram, `channels x (M + 1)`: the last bin of each channel is scratch.
    hist: Vec<f64>,
}

impl<'a> ConvexDiffuse<'a> {
    fn new(geo: &'a CrossSection, s: &'a TraceSettings) -> Self {
        let wall_binners = (0..geo.segs.len())
            .map(|k| WallBinner::new(s.m, geo.normal_angle(k)))
            .collect();
        ConvexDiffuse {
            geo,
            binner: AngleBins::new(s.m),
            wall_binners,
            s,
            two_walls: geo.segs.len() == 2,
        }
    }

    /// The next wall hit of a walk leaving wall `seg` at `pos` along `dir`.
    #[inline(always)]
    fn next_wall(&self, pos: [f64; 2], dir: [f64; 2], seg: usize) -> Option<(usize, f64)> {
        if self.two_walls {
            self.geo.other_wall_hit(pos, dir, seg)
        } else {
            self.geo.nearest(pos, dir, seg, T_EPS)
        }
    }

    /// A diffuse bounce off wall `seg` at `pos` with the random integer `k`: the direction,
    /// whether it leaves through the opening, and its exit bin if it does.
    #[inline(always)]
    fn bounce(&self, seg: usize, pos: [f64; 2], k: u64) -> ([f64; 2], bool, usize) {
        let dir = lambert_dir(&self.geo.segs[seg], sin_of_int(k));
        let escapes = CrossSection::escapes_convex(pos, dir);
        (dir, escapes, self.wall_binners[seg].bin(k))
    }

    /// Trace the entries `entries` of incident bin `row` (as [`Generic::block`]).
    fn block<const WALLS_MODE: bool>(
        &self,
        row: usize,
        entries: std::ops::Range<usize>,
    ) -> Partial {
        let channels = if WALLS_MODE { 4 } else { 1 };
        let m = self.s.m;
        let mut part = Partial::new(channels, m);
        let d0 = incident_dir(row, m);
        let mut scratch = ConvexScratch {
            pending: vec![0; self.s.nr],
            queue: Vec::new(),
            first_counts: vec![0; self.geo.segs.len() * m],
            hist: vec![0.0; channels * (m + 1)],
        };
        for k in entries {
            let (o, key) = entry_point(self.s, row, k);
            match first_hit(self.geo, o, d0) {
                Some((seg0, hit0)) => {
                    self.first_bounces::<WALLS_MODE>(key, d0, seg0, hit0, &mut scratch)
                }
                None => part.lost += self.s.nr as f64,
            }
        }
        // The walks of the whole block still inside advance breadth-first.
        let mut bounces = 1;
        while !scratch.queue.is_empty() {
            self.advance::<WALLS_MODE>(bounces, &mut scratch, &mut part);
            bounces += 1;
        }
        self.fold_first_counts::<WALLS_MODE>(d0, &mut scratch);
        for c in 0..channels {
            part.hist[c * m..(c + 1) * m]
                .copy_from_slice(&scratch.hist[c * (m + 1)..c * (m + 1) + m]);
        }
        part
    }

    /// The first bounces of an entry's walks from its first hit `hit0` on wall `seg0`: the
    /// escapes are counted per exit bin, the walks that stay inside are queued.
    fn first_bounces<const WALLS_MODE: bool>(
        &self,
        key: u64,
        d0: [f64; 2],
        seg0: usize,
        hit0: [f64; 2],
        scratch: &mut ConvexScratch,
    ) {
        let s = self.s;
        let m = s.m;
        let sg = &self.geo.segs[seg0];
        let cos_in0 = -(sg.n[0] * d0[0] + sg.n[1] * d0[1]);
        let w0 = hit_weights::<WALLS_MODE>([1.0; 4], cos_in0.abs(), s.albedo, s.fresnel_law);
        // `sin a` of the directions to the opening's corners: the escape interval.
        let corner_sin = |cx: f64, fallback: f64| {
            let v = [cx - hit0[0], -hit0[1]];
            let len = v[0].hypot(v[1]);
            if len > 0.0 {
                ((v[0] * sg.t[0] + v[1] * sg.t[1]) / len).clamp(-1.0, 1.0)
            } else {
                fallback
            }
        };
        let lo = corner_sin(-0.5, -1.0);
        let hi = corner_sin(0.5, 1.0);
        // The escape interval on the random integer: `lo_k <= k < hi_k`.
        let lo_k = int_threshold(lo);
        let span = int_threshold_above(hi).saturating_sub(lo_k);
        let n_pending = first_bounces(
            key,
            s.nr,
            s.max_bounces,
            (lo_k, span),
            &self.wall_binners[seg0],
            &mut scratch.first_counts[seg0 * m..(seg0 + 1) * m],
            &mut scratch.pending,
        );
        // Queue the walks still inside (advanced after the block's first bounces).
        let max_bounces = s.max_bounces;
        scratch
            .queue
            .extend(scratch.pending[..n_pending].iter().map(|&r| {
                let sa = signed_unit(draw(key, walk_counter(r as usize, 0, max_bounces)));
                Walk {
                    key,
                    r,
                    seg: seg0 as u32,
                    pos: hit0,
                    dir: lambert_dir(sg, sa),
                    w: w0,
                }
            }));
    }

    /// One bounce of every queued walk (`bounces`: wall hits so far of each): their
    /// `sqrt`/division latencies overlap, and the queue is compacted without branching on
    /// the (unpredictable) escapes.
    fn advance<const WALLS_MODE: bool>(
        &self,
        bounces: usize,
        scratch: &mut ConvexScratch,
        part: &mut Partial,
    ) {
        let s = self.s;
        let (m, channels) = (s.m, if WALLS_MODE { 4 } else { 1 });
        let queue = &mut scratch.queue;
        let mut kept = 0;
        for q in 0..queue.len() {
            let Walk {
                key,
                r,
                seg,
                pos,
                dir,
                w,
            } = queue[q];
            let Some((next, t)) = self.next_wall(pos, dir, seg as usize) else {
                // Only at round-off of a corner: treat as the generic tracer does.
                part.leave(&self.binner, dir, &w, channels);
                continue;
            };
            if bounces == s.max_bounces {
                part.dropped += w[0];
                continue;
            }
            let pos = [pos[0] + t * dir[0], pos[1] + t * dir[1]];
            let sg = &self.geo.segs[next];
            let cos_in = -(sg.n[0] * dir[0] + sg.n[1] * dir[1]);
            let w = hit_weights::<WALLS_MODE>(w, cos_in.abs(), s.albedo, s.fresnel_law);
            let k = draw(key, walk_counter(r as usize, bounces, s.max_bounces)) >> 11;
            let (dir, escapes, j) = self.bounce(next, pos, k);
            let e = (escapes as u8) as f64;
            for (c, wc) in w.iter().enumerate().take(channels) {
                scratch.hist[c * (m + 1) + j] += e * wc;
            }
            queue[kept] = Walk {
                key,
                r,
                seg: next as u32,
                pos,
                dir,
                w,
            };
            kept += (!escapes) as usize;
        }
        queue.truncate(kept);
    }

    /// Add the first-bounce escape counts, weighted by each wall's first-hit weight.
    fn fold_first_counts<const WALLS_MODE: bool>(&self, d0: [f64; 2], scratch: &mut ConvexScratch) {
        let s = self.s;
        let (m, channels) = (s.m, if WALLS_MODE { 4 } else { 1 });
        for (seg, counts) in scratch.first_counts.chunks(m).enumerate() {
            let sg = &self.geo.segs[seg];
            let cos_in = (sg.n[0] * d0[0] + sg.n[1] * d0[1]).abs();
            let w0 = hit_weights::<WALLS_MODE>([1.0; 4], cos_in, s.albedo, s.fresnel_law);
            for (c, wc) in w0.iter().enumerate().take(channels) {
                for (h, &n) in scratch.hist[c * (m + 1)..].iter_mut().zip(counts) {
                    *h += n as f64 * wc;
                }
            }
        }
    }

    /// One kernel walk `r` from wall `seg` at `pos`, its first hit (bounce 1) already counted:
    /// adds its exit weight to `row[bin]`, or to `row[m]` (dropped by the cap) or `row[m + 1]`
    /// (lost). The same bounce rules as [`ConvexDiffuse::advance`].
    fn kernel_walk(&self, key: u64, r: usize, mut pos: [f64; 2], mut seg: usize, row: &mut [f64]) {
        let s = self.s;
        let m = s.m;
        let mut w = 1.0;
        let mut bounces = 1;
        loop {
            let k = draw(key, walk_counter(r, bounces - 1, s.max_bounces)) >> 11;
            let (dir, escapes, j) = self.bounce(seg, pos, k);
            if escapes {
                row[j] += w;
                return;
            }
            let Some((next, t)) = self.next_wall(pos, dir, seg) else {
                if dir[1] > 0.0 {
                    row[self.binner.bin_sin(dir[0])] += w;
                } else {
                    row[m + 1] += w;
                }
                return;
            };
            if bounces == s.max_bounces {
                row[m] += w;
                return;
            }
            pos = [pos[0] + t * dir[0], pos[1] + t * dir[1]];
            seg = next;
            bounces += 1;
            w *= s.albedo;
        }
    }
}

/// Salt of the kernel walks' random streams (distinct from the entry streams).
const KERNEL_SALT: u64 = 0x4B45_524E_454C_0001;

/// [`Estimator::Kernel`]: tabulate the kernel of every wall, then give each entry point the
/// interpolated kernel row of its first hit. Fresnel mode `Seed` and diffuse walls (checked
/// by `validate`); the groove must be convex.
fn trace_kernel(
    geo: &CrossSection,
    s: &TraceSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<TraceOutput, TraceError> {
    if !geo.convex {
        return Err(TraceError::BadParameter {
            key: "estimator",
            value: "kernel".into(),
            why: "the kernel estimator needs a convex groove profile (V, round, trapezoid, \
                  flat or a convex polyline)",
        });
    }
    let m = s.m;
    let (nodes, nseg) = (KERNEL_NODES, geo.segs.len());
    let node_weights: Vec<Vec<f64>> = (0..m)
        .into_par_iter()
        .map(|row| kernel_node_weights(geo, s, row))
        .collect();
    // Walks per node: `W_n = N N_r max_i(w_in / N)`. Then each row's kernel variance,
    // `sum_n (w_in / N)^2 var_n / W_n <= sum_n (w_in / N) var / (N N_r)`, is at most what
    // the N_r scheme's walks give (grazing rows, whose first hits crowd into a few nodes
    // near a wall's top, get those nodes densely sampled). At least 64 walks per node.
    let paths = s.n as f64 * s.nr as f64;
    let walks_per_node: Vec<usize> = (0..nseg * nodes)
        .map(|id| {
            let max_w = node_weights.iter().map(|w| w[id]).fold(0.0f64, f64::max);
            ((paths * max_w / s.n as f64).ceil() as usize).clamp(64, s.n * s.nr)
        })
        .collect();
    let kernel = kernel_rows(&ConvexDiffuse::new(geo, s), &walks_per_node, progress);
    // Each row: its node weights times the kernel rows.
    let phi_rows: Vec<Vec<f64>> = node_weights
        .par_iter()
        .map(|node_w| {
            let mut acc = vec![0.0; m + 2];
            for (w, krow) in node_w.iter().zip(&kernel) {
                if *w != 0.0 {
                    for (a, kv) in acc.iter_mut().zip(krow) {
                        *a += w * kv;
                    }
                }
            }
            acc[m + 1] += node_w[nseg * nodes];
            acc
        })
        .collect();
    let norm: Vec<f64> = (0..m)
        .map(|j| m as f64 / (PI * s.n as f64 * bin_centre(j, m).cos()))
        .collect();
    let mut out = TraceOutput {
        m,
        rho_m: vec![0.0; m * m],
        rho_walls: None,
        dropped: vec![0.0; m],
        lost: vec![0.0; m],
    };
    for (row, acc) in phi_rows.iter().enumerate() {
        for j in 0..m {
            out.rho_m[row * m + j] = acc[j] * norm[j];
        }
        out.dropped[row] = acc[m] / s.n as f64;
        out.lost[row] = acc[m + 1] / s.n as f64;
    }
    Ok(out)
}

/// Row `row`'s entry weights per kernel node (first hits, linear interpolation in the position
/// along the wall), and its lost entries (last element).
fn kernel_node_weights(geo: &CrossSection, s: &TraceSettings, row: usize) -> Vec<f64> {
    let (nodes, nseg) = (KERNEL_NODES, geo.segs.len());
    let d0 = incident_dir(row, s.m);
    let mut node_w = vec![0.0; nseg * nodes + 1];
    for k in 0..s.n {
        let (o, _) = entry_point(s, row, k);
        let Some((seg0, hit0)) = first_hit(geo, o, d0) else {
            node_w[nseg * nodes] += 1.0;
            continue;
        };
        let sg = &geo.segs[seg0];
        let e2 = sg.e[0] * sg.e[0] + sg.e[1] * sg.e[1];
        let u = ((hit0[0] - sg.p[0]) * sg.e[0] + (hit0[1] - sg.p[1]) * sg.e[1]) / e2;
        let f = u * nodes as f64 - 0.5;
        let i0 = (f.floor().max(0.0) as usize).min(nodes - 2);
        let frac = (f - i0 as f64).clamp(0.0, 1.0);
        // The first hit's weight: the facet albedo (no Fresnel in `Seed` mode).
        node_w[seg0 * nodes + i0] += (1.0 - frac) * s.albedo;
        node_w[seg0 * nodes + i0 + 1] += frac * s.albedo;
    }
    node_w
}

/// The kernel row of node `i` of wall `seg` (index `seg * nodes + i`): the exit histogram per
/// walk started by a diffuse bounce there (its hit already counted), then the dropped and the
/// lost fractions.
fn kernel_rows(
    convex: &ConvexDiffuse,
    walks_per_node: &[usize],
    progress: &(dyn Fn(u64) + Sync),
) -> Vec<Vec<f64>> {
    let (s, geo, nodes) = (convex.s, convex.geo, KERNEL_NODES);
    let kernel_walks: u64 = walks_per_node.iter().map(|&w| w as u64).sum();
    (0..geo.segs.len() * nodes)
        .into_par_iter()
        .map(|id| {
            let (seg, node) = (id / nodes, id % nodes);
            let sg = &geo.segs[seg];
            let u = (node as f64 + 0.5) / nodes as f64;
            let pos = [sg.p[0] + u * sg.e[0], sg.p[1] + u * sg.e[1]];
            let key = mix64(mix64(s.seed ^ KERNEL_SALT) ^ (((seg as u64) << 32) | node as u64));
            let walks = walks_per_node[id];
            let mut row = vec![0.0; s.m + 2];
            for r in 0..walks {
                convex.kernel_walk(key, r, pos, seg, &mut row);
            }
            for v in row.iter_mut() {
                *v /= walks as f64;
            }
            progress((walks as u64 * s.total_paths()).div_ceil(kernel_walks.max(1)));
            row
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(walls: Walls) -> TraceSettings {
        TraceSettings {
            walls,
            m: 32,
            n: 2000,
            nr: 8,
            ..TraceSettings::default()
        }
    }

    /// Sum over `phi_o` of `rho_m cos(phi_o) pi/M`: the 2D albedo of row `i`.
    fn albedo_2d(rho: &[f64], m: usize, i: usize) -> f64 {
        (0..m)
            .map(|j| rho[i * m + j] * bin_centre(j, m).cos() * PI / m as f64)
            .sum()
    }

    #[test]
    fn lossless_profiles_conserve_energy() {
        for spec in [
            "v:angle=90",
            "round:depth=0.4",
            "trapezoid:depth=0.3,bottom=0.2",
            "v:depth=2",
        ] {
            let p = Profile::parse(spec).unwrap();
            for walls in [Walls::Specular, Walls::Diffuse] {
                let out = trace(&p, &small(walls), &|_| {}).unwrap();
                for i in 0..out.m {
                    let a = albedo_2d(&out.rho_m, out.m, i);
                    let dropped = out.dropped[i];
                    assert!(
                        out.lost[i] == 0.0,
                        "{spec} {walls:?} row {i} lost {}",
                        out.lost[i]
                    );
                    assert!(
                        (a + dropped - 1.0).abs() < 1e-9,
                        "{spec} {walls:?} row {i}: {a} + {dropped}"
                    );
                    assert!(
                        dropped < 1e-3,
                        "{spec} {walls:?} row {i}: dropped {dropped}"
                    );
                }
            }
        }
    }

    #[test]
    fn albedo_scales_energy() {
        // A flat profile: one bounce each, so the 2D albedo is exactly the facet albedo.
        let s = TraceSettings {
            albedo: 0.7,
            ..small(Walls::Diffuse)
        };
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
        let s = TraceSettings {
            walls: Walls::Diffuse,
            m,
            n: 4000,
            nr: 16,
            ..TraceSettings::default()
        };
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
    ///
    /// Retroreflected fraction: `(1/2 - tan(phi)/2) + (tan(phi)/2 - (tan(phi) - 1/2)) =
    /// 1 - tan(phi)`; for `phi >= pi/4` both ranges are empty: 0. By symmetry, for any phi:
    /// `max(0, 1 - tan |phi|)`.
    #[test]
    fn mirror_v_groove_retroreflects_the_two_wall_fraction() {
        let m = 64;
        let s = TraceSettings {
            walls: Walls::Specular,
            m,
            n: 20_000,
            ..TraceSettings::default()
        };
        let out = trace(&Profile::parse("v:angle=90").unwrap(), &s, &|_| {}).unwrap();
        for i in 0..m {
            let phi = bin_centre(i, m);
            let retro = out.rho_m[i * m + i] * phi.cos() * PI / m as f64;
            let expect = (1.0 - phi.abs().tan()).max(0.0);
            // Stratified entries: error at most a couple of strata.
            assert!(
                (retro - expect).abs() < 3.0 / s.n as f64,
                "phi {phi}: {retro} vs {expect}"
            );
        }
    }

    /// The convex fast path traces the same walks with the same random numbers as the generic
    /// tracer: the tables agree up to the rare walk that round-off at a bin edge or a corner
    /// sends elsewhere.
    #[test]
    fn convex_fast_path_matches_generic_tracer() {
        for (spec, mode, albedo) in [
            ("v:angle=90", FresnelMode::Seed, 1.0),
            ("v:depth=1.5", FresnelMode::Walls, 0.9),
            ("round:depth=0.4", FresnelMode::Seed, 0.8),
            ("trapezoid:depth=0.3,bottom=0.2", FresnelMode::Walls, 1.0),
        ] {
            let p = Profile::parse(spec).unwrap();
            assert!(CrossSection::new(&p).convex, "{spec}");
            let s = TraceSettings {
                m: 24,
                n: 500,
                nr: 12,
                albedo,
                fresnel_mode: mode,
                seed: 7,
                ..TraceSettings::default()
            };
            let fast = trace_with(&p, &s, &|_| {}, TracePath::Auto).unwrap();
            let slow = trace_with(&p, &s, &|_| {}, TracePath::Generic).unwrap();
            // One walk's weight in rho units is at most M / (pi N N_r cos(phi_o)).
            let one_walk = s.m as f64 / (PI * (s.n * s.nr) as f64 * bin_centre(0, s.m).cos());
            let mut walks_moved = 0.0;
            let pairs = [(&fast.rho_m, &slow.rho_m)]
                .into_iter()
                .chain(fast.rho_walls.iter().zip(slow.rho_walls.iter()));
            for (a, b) in pairs {
                assert_eq!(a.len(), b.len());
                for (x, y) in a.iter().zip(b) {
                    walks_moved += (x - y).abs() / one_walk;
                }
            }
            assert!(walks_moved < 4.0, "{spec}: ~{walks_moved} walks differ");
            for i in 0..s.m {
                assert!((fast.dropped[i] - slow.dropped[i]).abs() < 1e-12);
                assert_eq!(fast.lost[i], 0.0);
            }
        }
        // A non-convex profile takes the generic path.
        let w = Profile::from_points(
            "w",
            vec![
                [-0.5, 0.0],
                [-0.25, -0.5],
                [0.0, -0.1],
                [0.25, -0.5],
                [0.5, 0.0],
            ],
        )
        .unwrap();
        assert!(!CrossSection::new(&w).convex);
    }

    /// The kernel estimator has the expectation of the `N_r` scheme: per bin, the difference
    /// is within the two estimates' Monte Carlo error (binomial per walk); it conserves
    /// energy exactly (rows sum to the albedo of the walks); it is deterministic.
    #[test]
    fn kernel_estimator_agrees_with_walks() {
        for (spec, albedo) in [("v:angle=90", 1.0), ("round:depth=0.4", 0.8)] {
            let p = Profile::parse(spec).unwrap();
            let s = TraceSettings {
                m: 16,
                n: 1000,
                nr: 64,
                albedo,
                seed: 3,
                ..TraceSettings::default()
            };
            let k = TraceSettings {
                estimator: Estimator::Kernel,
                ..s.clone()
            };
            let walks = trace(&p, &s, &|_| {}).unwrap();
            let kernel = trace(&p, &k, &|_| {}).unwrap();
            let m = s.m;
            let paths = (s.n * s.nr) as f64;
            let (mut max_z, mut sum_z2, mut count) = (0.0f64, 0.0, 0);
            for i in 0..m {
                // Fraction of the incident energy in bin j.
                let frac =
                    |rho: &[f64], j: usize| rho[i * m + j] * bin_centre(j, m).cos() * PI / m as f64;
                for j in 0..m {
                    let (fw, fk) = (frac(&walks.rho_m, j), frac(&kernel.rho_m, j));
                    let f = 0.5 * (fw + fk);
                    if f <= 0.0 {
                        continue;
                    }
                    // Walk weights are at most 1: binomial variance bounds each estimate's.
                    let sigma = (2.0 * f * (1.0 - f).max(0.0) / paths).sqrt();
                    let z = (fw - fk) / sigma;
                    max_z = max_z.max(z.abs());
                    sum_z2 += z * z;
                    count += 1;
                }
                if albedo == 1.0 {
                    let total: f64 = (0..m).map(|j| frac(&kernel.rho_m, j)).sum();
                    assert!(
                        (total + kernel.dropped[i] - 1.0).abs() < 1e-9,
                        "{spec} row {i}: {total} + {}",
                        kernel.dropped[i]
                    );
                }
                assert_eq!(kernel.lost[i], 0.0);
            }
            let mean_z2 = sum_z2 / count as f64;
            assert!(max_z < 5.0, "{spec}: max |z| {max_z}");
            assert!(mean_z2 < 2.0, "{spec}: mean z^2 {mean_z2}");
            // And it is a different estimate, not a copy.
            assert_ne!(walks.rho_m, kernel.rho_m);
            let one = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap()
                .install(|| trace(&p, &k, &|_| {}).unwrap());
            assert_eq!(one, kernel, "{spec}: thread-count dependent");
        }
    }

    #[test]
    fn kernel_estimator_refuses_inexact_cases() {
        let k = TraceSettings {
            m: 8,
            n: 50,
            nr: 4,
            estimator: Estimator::Kernel,
            ..TraceSettings::default()
        };
        let v = Profile::parse("v:angle=90").unwrap();
        for s in [
            TraceSettings {
                walls: Walls::Specular,
                ..k.clone()
            },
            TraceSettings {
                fresnel_mode: FresnelMode::Walls,
                ..k.clone()
            },
        ] {
            let e = trace(&v, &s, &|_| {}).unwrap_err();
            assert!(e.to_string().contains("estimator"), "{e}");
        }
        let w = Profile::from_points(
            "w",
            vec![
                [-0.5, 0.0],
                [-0.25, -0.5],
                [0.0, -0.1],
                [0.25, -0.5],
                [0.5, 0.0],
            ],
        )
        .unwrap();
        let e = trace(&w, &k, &|_| {}).unwrap_err();
        assert!(e.to_string().contains("convex"), "{e}");
        assert!(trace(&v, &k, &|_| {}).is_ok());
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
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| trace(&p, &s, &|_| {}).unwrap())
        };
        let a = run(1);
        let b = run(3);
        assert_eq!(a, b);
        // And a different seed changes the output.
        let c = trace(
            &p,
            &TraceSettings {
                seed: 43,
                ..s.clone()
            },
            &|_| {},
        )
        .unwrap();
        assert_ne!(a.rho_m, c.rho_m);
    }

    #[test]
    fn walls_fresnel_for_mirrors_at_grazing_slice_is_lossless() {
        // Slice theta = pi/2 has incidence cosine 0: Schlick gives F = 1, so the slice equals
        // rho_m; slice 0 of a flat mirror is exactly F(cos phi_i).
        let s = TraceSettings {
            fresnel_mode: FresnelMode::Walls,
            ..small(Walls::Specular)
        };
        let out = trace(&Profile::flat(), &s, &|_| {}).unwrap();
        let m = s.m;
        let w = out.rho_walls.unwrap();
        for i in 0..m {
            for j in 0..m {
                assert_eq!(w[2 * m * m + i * m + j], out.rho_m[i * m + j]);
                let f = crate::optics::fresnel::schlick(1.5, bin_centre(i, m).cos());
                assert!(
                    (w[i * m + j] - f * out.rho_m[i * m + j]).abs()
                        < 1e-9 * out.rho_m[i * m + j].max(1.0)
                );
            }
        }
    }

    /// The fast per-wall binner on the random integer equals binning the bounce's exit angle
    /// `alpha + a` (`sin a` from the same integer) with the float binner, except within
    /// round-off of a bin edge.
    #[test]
    fn wall_binner_matches_float_binning() {
        for (m, alpha) in [(16usize, 0.0f64), (64, 0.785), (256, -1.2), (7, 0.3)] {
            let wb = WallBinner::new(m, alpha);
            let mut state = 12345u64;
            for _ in 0..50_000 {
                state = crate::hash::splitmix64(state);
                let k = state >> 11;
                let phi = alpha + sin_of_int(k).asin();
                if phi.abs() >= FRAC_PI_2 {
                    continue; // past the horizon: never an escape
                }
                let (got, want) = (wb.bin(k), bin_of(phi, m));
                if got != want {
                    let edge = -FRAC_PI_2 + got.max(want) as f64 * PI / m as f64;
                    assert!(
                        (phi - edge).abs() < 1e-9,
                        "m {m} alpha {alpha}: {got} vs {want}"
                    );
                }
            }
        }
    }

    /// The closed-form next wall of a V equals the general nearest-wall query.
    #[test]
    fn v_other_wall_matches_nearest() {
        for spec in ["v:angle=90", "v:depth=2", "v:angle=150"] {
            let geo = CrossSection::new(&Profile::parse(spec).unwrap());
            let mut state = 99u64;
            let mut hits = 0;
            for _ in 0..20_000 {
                let mut u = || {
                    state = crate::hash::splitmix64(state);
                    unit(state)
                };
                let seg = (u() * 2.0) as usize;
                let sg = &geo.segs[seg];
                let at = u();
                let pos = [sg.p[0] + at * sg.e[0], sg.p[1] + at * sg.e[1]];
                let dir = lambert_dir(sg, 2.0 * u() - 1.0);
                if CrossSection::escapes_convex(pos, dir) {
                    continue;
                }
                let fast = geo.other_wall_hit(pos, dir, seg);
                let slow = geo.nearest(pos, dir, seg, T_EPS);
                match (fast, slow) {
                    (Some((a, ta)), Some((b, tb))) => {
                        assert_eq!(a, b, "{spec}");
                        assert!((ta - tb).abs() <= 1e-12 * ta.abs().max(1.0), "{spec}");
                        hits += 1;
                    }
                    (f, s) => panic!("{spec}: {f:?} vs {s:?} from {pos:?} along {dir:?}"),
                }
            }
            assert!(hits > 300, "{spec}: {hits}");
        }
    }

    #[test]
    fn invalid_settings_rejected() {
        let p = Profile::flat();
        let base = small(Walls::Diffuse);
        for s in [
            TraceSettings {
                m: 0,
                ..base.clone()
            },
            TraceSettings {
                n: 0,
                ..base.clone()
            },
            TraceSettings {
                nr: 0,
                ..base.clone()
            },
            TraceSettings {
                albedo: 1.5,
                ..base.clone()
            },
            TraceSettings {
                albedo: f64::NAN,
                ..base.clone()
            },
            TraceSettings {
                max_bounces: 0,
                ..base.clone()
            },
            TraceSettings {
                fresnel_law: FresnelLaw::Schlick { n: -1.0 },
                ..base.clone()
            },
            TraceSettings {
                fresnel_law: FresnelLaw::Conductor {
                    eta: 0.2,
                    k: f64::INFINITY,
                },
                ..base.clone()
            },
        ] {
            assert!(trace(&p, &s, &|_| {}).is_err(), "{s:?}");
        }
    }
}
