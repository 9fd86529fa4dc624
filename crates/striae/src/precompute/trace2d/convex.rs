//! The convex-profile fast path (METHOD.md 3.1): diffuse walls in a convex groove, the same
//! walks as the generic tracer with the escape of the first bounce decided on the random
//! integer itself.

use super::{
    draw, entry_point, first_hit, hit_weights, incident_dir, lambert_dir, signed_unit,
    walk_counter, Partial, TraceSettings,
};
use crate::precompute::angle_bins::AngleBins;
use crate::precompute::cross_section::{CrossSection, T_EPS};
use std::f64::consts::{FRAC_PI_2, PI};

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

/// The fast path of [`Generic`](super::Generic) for diffuse walls in a convex groove: the same walks with
/// the same random numbers (up to round-off at bin edges and corners), cheaper per walk
/// (tested against [`Generic`](super::Generic) by `convex_fast_path_matches_generic_tracer`).
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
pub(super) struct ConvexDiffuse<'a> {
    pub(super) geo: &'a CrossSection,
    binner: AngleBins,
    wall_binners: Vec<WallBinner>,
    pub(super) s: &'a TraceSettings,
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
    pub(super) fn new(geo: &'a CrossSection, s: &'a TraceSettings) -> Self {
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

    /// Trace the entries `entries` of incident bin `row` (as [`Generic::block`](super::Generic::block)).
    pub(super) fn block<const WALLS_MODE: bool>(
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
    pub(super) fn kernel_walk(
        &self,
        key: u64,
        r: usize,
        mut pos: [f64; 2],
        mut seg: usize,
        row: &mut [f64],
    ) {
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

#[cfg(test)]
mod tests {
    use super::super::{bin_centre, bin_of, trace_with, unit, FresnelMode, TracePath};
    use super::*;
    use crate::precompute::profile::Profile;

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
        let w = Profile::w_groove();
        assert!(!CrossSection::new(&w).convex);
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
}
