//! The curves' pixel cache of one render worker (held in `layers::CoverageCache`, which the
//! material gets): for hits reached from the camera by delta bounces only, the curves' exact
//! coverage of the whole pixel's footprint, computed at the pixel's first such hit and shared
//! by its later samples, as the layers' pixel footprints are (`layers::cache`). Each sample
//! then takes its direction from the segment holding its own hit point (the point test, a
//! few quads), so that over a pixel's samples each segment is chosen in proportion to its
//! share of the footprint; where the hit lies outside a covering curve, the direction drawn
//! when the footprint was computed.
//!
//! Determinism: the entry depends only on the pixel's own earlier samples (the render loop
//! starts every pixel with [`PixelCache::start_pixel`] and runs its samples in order).

use super::{CurveHits, CurveSet};
use crate::math::Vec2;

/// A sample shares the pixel's footprint when its own estimate of the pixel centre's texture
/// point lies within this fraction of the footprint's edges of the stored one (as the
/// layers' `PIXEL_TOLERANCE`).
pub const PIXEL_TOLERANCE: f32 = 0.25;

#[derive(Clone, Debug)]
struct Entry {
    /// Set id, shape, chain.
    key: [u64; 3],
    centre: Vec2,
    a: Vec2,
    b: Vec2,
    inv_det: f32,
    hits: CurveHits,
}

/// One pixel footprint's curve coverage (see the module notes).
#[derive(Clone, Debug, Default)]
pub struct PixelCache {
    entry: Option<Entry>,
}

impl PixelCache {
    /// Forget the previous pixel's footprint: call before each pixel's samples.
    #[inline]
    pub fn start_pixel(&mut self) {
        self.entry = None;
    }

    /// The curves covering the current pixel's footprint, for a hit at `uv` on `shape` along
    /// the chain of delta bounces `chain`, `offset` pixels from the pixel's centre, with the
    /// footprint `footprint() = (duvdx, duvdy)`; `u` draws the directions of a new footprint.
    /// The footprint centred on the pixel centre's texture point, `uv - offset.x duvdx -
    /// offset.y duvdy`, is computed once and shared by later samples on the same shape and
    /// chain whose own estimate of that centre lies within [`PIXEL_TOLERANCE`]; others query
    /// their own footprint, uncached.
    #[allow(clippy::too_many_arguments)]
    pub fn hits(
        &mut self,
        set: &CurveSet,
        uv: Vec2,
        footprint: impl FnOnce() -> (Vec2, Vec2),
        shape: u32,
        chain: u64,
        offset: Vec2,
        u: f64,
    ) -> CurveHits {
        let key = [set.id(), shape as u64, chain];
        if let Some(e) = &self.entry {
            if e.key == key {
                let d = uv - offset.x * e.a - offset.y * e.b - e.centre;
                let (s, t) = (d.perp_dot(e.b) * e.inv_det, e.a.perp_dot(d) * e.inv_det);
                if s.abs() <= PIXEL_TOLERANCE && t.abs() <= PIXEL_TOLERANCE {
                    return set.directed_at(e.hits.clone(), uv.as_dvec2());
                }
            }
        }
        let (a, b) = footprint();
        let centre = uv - offset.x * a - offset.y * b;
        let det = a.perp_dot(b);
        if !(det.abs() > 0.0 && det.is_finite() && centre.is_finite()) || self.entry.is_some() {
            // Degenerate, or a second footprint of the pixel: this sample's own.
            return set.footprint(uv.as_dvec2(), a.as_dvec2(), b.as_dvec2(), u);
        }
        let hits = set.footprint(centre.as_dvec2(), a.as_dvec2(), b.as_dvec2(), u);
        self.entry = Some(Entry {
            key,
            centre,
            a,
            b,
            inv_det: 1.0 / det,
            hits: hits.clone(),
        });
        set.directed_at(hits, uv.as_dvec2())
    }
}
