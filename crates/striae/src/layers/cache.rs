//! The coverage caches of one worker of the render loop, owned by it and passed down to the
//! material ([`CoverageCache`]); the queries they answer are [`LayerSet`]'s pure ones.
//!
//! * **Pixel footprints** ([`CoverageCache::of_pixel`], [`CoverageCache::curves_of_pixel`]):
//!   for hits reached from the camera by
//!   delta bounces only (a camera ray's first hit, a surface seen through glass or in a mirror),
//!   the exact coverage of the whole pixel's footprint, computed once per pixel, shape and chain
//!   of bounces, and shared by the pixel's samples.
//! * **Footprint tiles** ([`CoverageCache::tiled`], [`CoverageCache::curves_tiled`]): at other
//!   hits, the coverage of the footprint snapped to its tile ([`FootprintTile`]), computed once
//!   per tile.
//!
//! Determinism: a tile's value depends only on its key, and a pixel's footprints only on the
//! pixel's own earlier samples (the render loop calls [`CoverageCache::start_pixel`] before each
//! pixel and runs its samples in order), never on which sample or thread came first, so images
//! are bit-identical for any thread count.

use super::lattice::{FootprintTile, TileQuery, CACHED_LAYERS, TILE_MAX_CELLS};
use super::layer::MAX_FOOTPRINT_CELLS;
use super::LayerSet;
use crate::curves::{CurveHits, CurveSet};
use crate::math::Vec2;

/// Entries of the direct-mapped tile cache (a power of two). A 16 x 16 pixel tile of the
/// renderer touches a few hundred footprint tiles per surface.
const TILE_ENTRIES: usize = 4096;

/// Pixel footprints kept for the current pixel: its first hit and the surfaces its samples see
/// through the glass or in mirrors, up to [`PIXEL_CLUSTERS`] per chain of delta bounces,
/// replaced oldest first.
const PIXEL_ENTRIES: usize = 16;

/// Footprints one pixel keeps per shape and chain: a sample whose estimate of the pixel
/// centre is not near any of them starts another, until there are this many (then it takes
/// its tile). Behind curved glass the estimates of a pixel's samples scatter (the footprint
/// changes across the pixel faster than the differentials' linear model): on the setting-1
/// teapot about 3 in 10 samples seen through the glass miss the first sample's footprint,
/// and the tiles they fell back to were shared by one sample in four.
pub const PIXEL_CLUSTERS: usize = 4;

/// A sample shares its pixel's footprint coverage when its own estimate of the pixel centre's
/// texture point lies within this fraction of the footprint's edges of the stored one.
pub const PIXEL_TOLERANCE: f32 = 0.25;

/// A footprint tile's coverage.
#[derive(Clone, Copy)]
struct TileEntry {
    /// Set id, query, tile key; all zero when empty (set ids start at 1).
    key: [u64; 6],
    values: [f32; CACHED_LAYERS],
}

/// A pixel's footprint: its centre's texture point and edges, and `1 / (a x b)`.
#[derive(Clone, Copy, Debug)]
struct PixelFootprint {
    centre: Vec2,
    a: Vec2,
    b: Vec2,
    inv_det: f32,
}

impl PixelFootprint {
    /// The footprint of edges `a`, `b` centred on the pixel centre's texture point as a hit at
    /// `uv`, `offset` pixels from the pixel's centre, estimates it, `uv - offset.x a - offset.y
    /// b`; `None` where it is degenerate or not finite.
    fn new(uv: Vec2, offset: Vec2, a: Vec2, b: Vec2) -> Option<Self> {
        let centre = uv - offset.x * a - offset.y * b;
        let det = a.perp_dot(b);
        (det.abs() > 0.0 && det.is_finite() && centre.is_finite()).then(|| PixelFootprint {
            centre,
            a,
            b,
            inv_det: 1.0 / det,
        })
    }

    /// Whether a hit at `uv`, `offset` pixels from the pixel's centre, estimates the centre
    /// within [`PIXEL_TOLERANCE`] of the edges from this footprint's.
    #[inline]
    fn holds(&self, uv: Vec2, offset: Vec2) -> bool {
        let d = uv - offset.x * self.a - offset.y * self.b - self.centre;
        let (s, t) = (
            d.perp_dot(self.b) * self.inv_det,
            self.a.perp_dot(d) * self.inv_det,
        );
        s.abs() <= PIXEL_TOLERANCE && t.abs() <= PIXEL_TOLERANCE
    }
}

/// A pixel's footprint coverage: set id, query, shape and chain; the footprint; the values.
#[derive(Clone, Copy)]
struct PixelEntry {
    key: [u64; 4],
    footprint: PixelFootprint,
    values: [f32; CACHED_LAYERS],
}

/// The curves covering a pixel's footprint: set id, shape and chain; the footprint; the hits.
#[derive(Clone, Debug)]
struct CurvePixelEntry {
    key: [u64; 3],
    footprint: PixelFootprint,
    hits: CurveHits,
}

/// Which surface of the current pixel a hit is on, and through which chain of delta bounces
/// (`shading::PixelHit`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelKey {
    pub shape: u32,
    /// 0 for the camera ray's first hit, else names the chain of delta bounces.
    pub chain: u64,
}

/// The coverage caches of one render worker (see the module notes).
pub struct CoverageCache {
    /// Direct-mapped by the hash of the key; allocated at the first query.
    tiles: Vec<TileEntry>,
    /// The current pixel's footprints, written round-robin: the newest `pixel_count` entries
    /// before `pixel_next`.
    pixel: Vec<PixelEntry>,
    pixel_next: usize,
    pixel_count: usize,
    /// The curves covering the current pixel's first footprint ([`Self::curves_of_pixel`]).
    curve_pixel: Option<CurvePixelEntry>,
    /// The curves' footprint tiles ([`Self::curves_tiled`]), direct-mapped; allocated at the
    /// first query.
    curve_tiles: Vec<CurveTileEntry>,
    /// The current pixel's footprint edges for a painted map ([`Self::map_footprint`]): shape
    /// and chain, the edges.
    map_pixel: Option<([u64; 2], Vec2, Vec2)>,
}

/// Entries of the curves' direct-mapped tile cache (a power of two).
const CURVE_TILE_ENTRIES: usize = 1024;

/// A footprint tile's curves: set id and tile key (all zero when empty), and the hits.
#[derive(Clone)]
struct CurveTileEntry {
    key: [u64; 5],
    hits: CurveHits,
}

impl Default for CoverageCache {
    fn default() -> Self {
        Self::new()
    }
}

impl CoverageCache {
    /// An empty cache (allocates nothing until a scratched surface is queried).
    pub fn new() -> Self {
        CoverageCache {
            tiles: Vec::new(),
            pixel: Vec::new(),
            pixel_next: 0,
            pixel_count: 0,
            curve_pixel: None,
            curve_tiles: Vec::new(),
            map_pixel: None,
        }
    }

    /// Forget the previous pixel's footprints: call before each pixel's samples.
    #[inline]
    pub fn start_pixel(&mut self) {
        self.pixel_count = 0;
        self.curve_pixel = None;
        self.map_pixel = None;
    }

    /// The footprint edges `(duvdx, duvdy)` a painted map (METHOD.md 9.5) filters over at a
    /// hit reached from the camera by delta bounces (on `key`'s shape, along its chain): the
    /// first such sample's of the pixel, `footprint()`, kept for the pixel's later samples on
    /// the same shape and chain (which filter over edges of the same size around their own
    /// hits, without working out their ray differentials).
    #[inline]
    pub fn map_footprint(
        &mut self,
        key: PixelKey,
        footprint: impl FnOnce() -> (Vec2, Vec2),
    ) -> (Vec2, Vec2) {
        let key = [key.shape as u64, key.chain];
        match self.map_pixel {
            Some((k, a, b)) if k == key => (a, b),
            _ => {
                let (a, b) = footprint();
                self.map_pixel = Some((key, a, b));
                (a, b)
            }
        }
    }

    /// The per-layer coverage of the current pixel's whole footprint, for a hit at texture
    /// point `uv` reached from the camera by delta bounces only (on `key`'s shape, along its
    /// chain), `offset` (pixels) from the pixel's centre, with the footprint `footprint() =
    /// (duvdx, duvdy)`: the exact coverage ([`LayerSet::coverage_max`] or
    /// [`LayerSet::coverage_all`] per `query`, up to [`TILE_MAX_CELLS`]) of that footprint
    /// centred on the texture point of the pixel centre's ray along the same chain,
    /// `uv - offset.x duvdx - offset.y duvdy`. It is computed at the pixel's first such hit and
    /// kept ([`PIXEL_ENTRIES`] of them); the pixel's later samples on the same shape along the
    /// same chain reuse it when their own estimate of the centre, `uv - offset.x a - offset.y b`
    /// with the stored footprint's edges `a`, `b`, lies within [`PIXEL_TOLERANCE`] of those
    /// edges from the stored centre. Those samples never call `footprint`: most samples of a
    /// pixel need no ray differentials worked out. A sample near none of the pixel's footprints
    /// for the hit (at silhouettes, texture seams, and behind curved glass, where the estimates
    /// scatter) adds its own, centred on its own estimate, up to [`PIXEL_CLUSTERS`]; after that
    /// it takes its tile ([`Self::tiled`]).
    ///
    /// So every sample of a pixel sees the coverage of the pixel's own footprint, exactly, as
    /// METHOD.md section 6 asks, for one exact query per pixel and chain (a few behind curved
    /// glass) instead of one per tile.
    /// # Panics
    /// If `out.len() < set.len()`.
    #[allow(clippy::too_many_arguments)]
    pub fn of_pixel(
        &mut self,
        set: &LayerSet,
        uv: Vec2,
        footprint: impl FnOnce() -> (Vec2, Vec2),
        key: PixelKey,
        offset: Vec2,
        query: TileQuery,
        out: &mut [f32],
    ) {
        let n = set.len();
        if n > CACHED_LAYERS {
            let (duvdx, duvdy) = footprint();
            self.tiled(set, uv, duvdx, duvdy, query, out);
            return;
        }
        let key = [set.id(), query as u64, key.shape as u64, key.chain];
        // Whether this sample shares one of the pixel's footprints for this hit, and if not,
        // how many the pixel has for it: look back from the newest entry.
        let mut same = 0;
        let mut slot = self.pixel_next;
        for _ in 0..self.pixel_count {
            slot = slot.checked_sub(1).unwrap_or(PIXEL_ENTRIES - 1);
            let e = &self.pixel[slot];
            if e.key != key {
                continue; // another shape or chain (or set, or query)
            }
            if e.footprint.holds(uv, offset) {
                out[..n].copy_from_slice(&e.values[..n]);
                return;
            }
            same += 1;
        }
        let (duvdx, duvdy) = footprint();
        // A new footprint of the pixel, centred on this sample's estimate of the pixel centre
        // (up to `PIXEL_CLUSTERS`; then, and where it is degenerate, the tile).
        let new = PixelFootprint::new(uv, offset, duvdx, duvdy);
        if let Some(footprint) = new.filter(|_| same < PIXEL_CLUSTERS) {
            let mut values = [0.0f32; CACHED_LAYERS];
            let c = footprint.centre;
            set.coverage_query(query, c, duvdx, duvdy, TILE_MAX_CELLS, &mut values);
            out[..n].copy_from_slice(&values[..n]);
            let entry = PixelEntry {
                key,
                footprint,
                values,
            };
            if self.pixel.len() < PIXEL_ENTRIES {
                self.pixel.resize(PIXEL_ENTRIES, entry);
            }
            self.pixel[self.pixel_next] = entry;
            self.pixel_next = (self.pixel_next + 1) % PIXEL_ENTRIES;
            self.pixel_count = (self.pixel_count + 1).min(PIXEL_ENTRIES);
            return;
        }
        self.tiled(set, uv, duvdx, duvdy, query, out);
    }

    /// The curves covering the current pixel's footprint (METHOD.md 9.1), for a hit at `uv`
    /// reached from the camera by delta bounces (on `key`'s shape, along its chain), `offset`
    /// pixels from the pixel's centre, with the footprint `footprint() = (duvdx, duvdy)`, as
    /// [`Self::of_pixel`] does for layers: the exact coverage of the footprint centred on the
    /// pixel centre's texture point, computed at the pixel's first such hit (its directions
    /// drawn by `u`) and shared by its later samples on the same shape and chain whose estimate
    /// of the centre lies within [`PIXEL_TOLERANCE`]; other samples query their own footprint,
    /// uncached. Each sample then takes the direction of the segment under its own hit
    /// ([`CurveSet::directed_at`]), so that over a pixel's samples each segment is chosen in
    /// proportion to its share of the footprint.
    pub fn curves_of_pixel(
        &mut self,
        set: &CurveSet,
        uv: Vec2,
        footprint: impl FnOnce() -> (Vec2, Vec2),
        key: PixelKey,
        offset: Vec2,
        u: f64,
    ) -> CurveHits {
        let key = [set.id(), key.shape as u64, key.chain];
        if let Some(e) = &self.curve_pixel {
            if e.key == key && e.footprint.holds(uv, offset) {
                return set.directed_at(e.hits.clone(), uv.as_dvec2());
            }
        }
        let (a, b) = footprint();
        let new = PixelFootprint::new(uv, offset, a, b);
        let Some(footprint) = new.filter(|_| self.curve_pixel.is_none()) else {
            // Degenerate, or a second footprint of the pixel: this sample's own.
            return set.footprint(uv.as_dvec2(), a.as_dvec2(), b.as_dvec2(), u);
        };
        let c = footprint.centre.as_dvec2();
        let hits = set.footprint(c, a.as_dvec2(), b.as_dvec2(), u);
        self.curve_pixel = Some(CurvePixelEntry {
            key,
            footprint,
            hits: hits.clone(),
        });
        set.directed_at(hits, uv.as_dvec2())
    }

    /// The curves covering the footprint tile that holds `uv` ([`FootprintTile`], as the
    /// layers' [`Self::tiled`]): the exact coverage of the tile's footprint, cached, with each
    /// curve's direction drawn once per tile by a number hashed from the tile's key (so a
    /// tile's value depends only on its key, whatever the thread count), then taken from the
    /// segment under `uv` where `uv` lies in that curve ([`CurveSet::directed_at`]). Without a
    /// tile, the footprint itself, uncached, its directions drawn by `u`.
    pub fn curves_tiled(
        &mut self,
        set: &CurveSet,
        uv: Vec2,
        duvdx: Vec2,
        duvdy: Vec2,
        u: f64,
    ) -> CurveHits {
        let (p, a, b) = (uv.as_dvec2(), duvdx.as_dvec2(), duvdy.as_dvec2());
        let Some(tile) = FootprintTile::containing(uv, duvdx, duvdy) else {
            return set.footprint(p, a, b, u);
        };
        let key = [set.id(), tile.key[0], tile.key[1], tile.key[2], tile.key[3]];
        let hash = key.iter().fold(0u64, |h, &k| crate::hash::mix64(h ^ k));
        if self.curve_tiles.is_empty() {
            self.curve_tiles.resize(
                CURVE_TILE_ENTRIES,
                CurveTileEntry {
                    key: [0; 5],
                    hits: Default::default(),
                },
            );
        }
        let entry = &mut self.curve_tiles[hash as usize & (CURVE_TILE_ENTRIES - 1)];
        if entry.key != key {
            let u_tile = (crate::hash::mix64(hash) >> 11) as f64 * (1.0 / (1u64 << 53) as f64);
            entry.hits = set.footprint(tile.centre, tile.a, tile.b, u_tile);
            entry.key = key;
        }
        set.directed_at(entry.hits.clone(), p)
    }

    /// The per-layer coverage of the footprint tile containing `uv` ([`FootprintTile`]), into
    /// `out[0..set.len()]`, as [`LayerSet::coverage_all`] or [`LayerSet::coverage_max`] of the
    /// tile (up to [`TILE_MAX_CELLS`]), cached. Where there is no tile
    /// ([`FootprintTile::containing`]) or the set has more than [`CACHED_LAYERS`] layers, the
    /// footprint itself is queried, uncached.
    /// # Panics
    /// If `out.len() < set.len()`.
    pub fn tiled(
        &mut self,
        set: &LayerSet,
        uv: Vec2,
        duvdx: Vec2,
        duvdy: Vec2,
        query: TileQuery,
        out: &mut [f32],
    ) {
        let n = set.len();
        let tile = FootprintTile::containing(uv, duvdx, duvdy).filter(|_| n <= CACHED_LAYERS);
        let Some(tile) = tile else {
            set.coverage_query(query, uv, duvdx, duvdy, MAX_FOOTPRINT_CELLS, out);
            return;
        };
        let key = [
            set.id(),
            query as u64,
            tile.key[0],
            tile.key[1],
            tile.key[2],
            tile.key[3],
        ];
        let h =
            key.iter().fold(0u64, |h, &k| crate::hash::mix64(h ^ k)) as usize & (TILE_ENTRIES - 1);
        if self.tiles.is_empty() {
            self.tiles.resize(
                TILE_ENTRIES,
                TileEntry {
                    key: [0; 6],
                    values: [0.0; CACHED_LAYERS],
                },
            );
        }
        let entry = &mut self.tiles[h];
        // (Compared field by field: `!=` on the array compiled to a `memcmp` call.)
        if !entry.key.iter().zip(&key).all(|(a, b)| a == b) {
            let (c, a, b) = (tile.centre.as_vec2(), tile.a.as_vec2(), tile.b.as_vec2());
            set.coverage_query(query, c, a, b, TILE_MAX_CELLS, &mut entry.values);
            entry.key = key;
        }
        out[..n].copy_from_slice(&entry.values[..n]);
    }
}
