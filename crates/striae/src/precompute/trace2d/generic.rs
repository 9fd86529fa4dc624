//! The generic tracer (METHOD.md section 3): any profile, both wall models, walk by walk;
//! the reference the fast paths are tested against.

use super::{
    draw, entry_point, first_hit, hit_weights, incident_dir, signed_unit, walk_counter, Partial,
    TraceSettings, Walls,
};
use crate::precompute::angle_bins::AngleBins;
use crate::precompute::cross_section::{CrossSection, T_EPS};

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
pub(super) struct Generic<'a> {
    geo: &'a CrossSection,
    binner: AngleBins,
    s: &'a TraceSettings,
}

impl<'a> Generic<'a> {
    pub(super) fn new(geo: &'a CrossSection, s: &'a TraceSettings) -> Self {
        Generic {
            geo,
            binner: AngleBins::new(s.m),
            s,
        }
    }

    /// Trace the entries `entries` of incident bin `row`; weights are per walk (1 each, the
    /// `1 / N_r` is applied in the normalisation).
    pub(super) fn block(
        &self,
        channels: usize,
        row: usize,
        entries: std::ops::Range<usize>,
    ) -> Partial {
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
