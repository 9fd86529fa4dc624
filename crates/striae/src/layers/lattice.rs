//! Footprint tiles: the renderer's coverage queries snapped to a lattice of footprint-shaped
//! tiles, and a per-thread cache of their exact coverage; and, for hits reached from the
//! camera by delta bounces only (a camera ray's first hit, a surface seen through glass or in
//! a mirror), the exact coverage of the whole pixel's footprint, computed once per pixel and
//! chain of bounces ([`LayerSet::coverage_of_pixel`]).
//!
//! A pixel's samples hit points spread over one pixel footprint, and each asks for the scratch
//! coverage of a footprint of that same shape (METHOD.md section 6). Computing it exactly at
//! every sample costs one noise-cell enumeration per cell the footprint spans, per layer:
//! several microseconds where a pixel spans many scratches (`BENCHMARKS.md`). Here the
//! footprint's edge vectors `a`, `b` are rounded to one of a discrete set of shapes
//! ([`quantize`]) and the hit point is snapped to the nearest point of the lattice
//! `{(i a + j b) / TILE_STEPS}`; the coverage is that of the footprint of the rounded shape
//! centred there, a function of `(i, j, a, b)` only, like a texel of an anisotropic mip level.
//! It is computed exactly once per thread and reused by every sample that snaps to it.
//!
//! This is a departure from a footprint centred on each sample: the footprint a sample sees is
//! displaced by at most `1 / (2 TILE_STEPS)` of its size along each edge, its edges are off by
//! at most about 1/14 and its area by at most 13 % (the rounding). The pixel's estimate
//! converges to a slightly different filter of the same coverage. Measured against the
//! per-sample footprint (`coverage = "sample"`) at 256 spp: the image means agree within
//! 0.1 %, and the difference (RMSE 0.0085 on the close-up, mean 0.118; 0.0031 on the teapot)
//! is a slight jaggedness of pixel-wide scratch lines (`BENCHMARKS.md`).
//!
//! Determinism: a tile's value depends only on its key, never on which sample or thread
//! computed it first, so images stay bit-identical for any thread count.

use super::layer::MAX_FOOTPRINT_CELLS;
use super::LayerSet;
use crate::math::Vec2;
use glam::DVec2;
use std::cell::RefCell;

/// Tiles whose noise-space bounding box spans more cells than this take the layers' expected
/// coverage (the prefiltered limit) instead of the exact one. Lower than the exact queries'
/// [`super::layer::MAX_FOOTPRINT_CELLS`]: such tiles come from grazing views and from rays that
/// went through curved glass, whose footprints change from sample to sample, so they are
/// rarely shared and cost most (the setting-1 teapot: 1.69x smooth glass per sample with 256,
/// 1.49x with 64; the images differ only along silhouettes, `BENCHMARKS.md`).
pub const TILE_MAX_CELLS: usize = 64;

/// Tile centres lie on the lattice of the footprint's edges divided by this: a footprint is
/// displaced by at most `1 / (2 TILE_STEPS)` of its size (with 1, pixel-wide scratch lines
/// visibly blur in the close-up, Fig. 8a: RMSE 0.027 against the per-sample footprint, 0.0085
/// with 2).
pub const TILE_STEPS: f64 = 2.0;

/// Layers a cached tile holds; larger sets are not cached.
pub const CACHED_LAYERS: usize = 16;
/// Entries of each thread's direct-mapped cache (a power of two). A 16 x 16 pixel tile of the
/// renderer touches a few hundred footprint tiles per surface.
const CACHE_ENTRIES: usize = 4096;

/// `x` rounded to 4 significant bits (relative error at most 1/16); `None` unless normal.
#[inline]
fn round_4_bits(x: f32) -> Option<f32> {
    if !x.is_normal() {
        return None;
    }
    const DROP: u32 = 20; // of the 23 stored mantissa bits: 3 stay, with the implicit one
    let r = f32::from_bits(x.to_bits().wrapping_add(1 << (DROP - 1)) & !((1 << DROP) - 1));
    r.is_finite().then_some(r)
}

/// Round to nearest (ties to even) without a libm call (baseline x86-64 has no `roundss`):
/// exact for `|x| < 2^22`.
#[inline]
fn round_f32(x: f32) -> f32 {
    const M: f32 = 12_582_912.0; // 1.5 * 2^23
    (x + M) - M
}

/// [`round_f32`] for `f64`: exact for `|x| < 2^51`.
#[inline]
fn round_f64(x: f64) -> f64 {
    const M: f64 = 6_755_399_441_055_744.0; // 1.5 * 2^52
    (x + M) - M
}

/// Directions of `a` are rounded to the grid of `1/DIRECTION_STEPS` on each component.
const DIRECTION_STEPS: f32 = 64.0;

/// The footprint's edge vectors `a`, `b` rounded so that nearby footprints share one shape,
/// in `a`'s own frame, which keeps the area (thin, sheared footprints included): `a`'s
/// direction to the grid of 1/64 on each component (then normalised, about 0.5 degree), its
/// length and `b`'s component across it to 4 significant bits, and `b`'s component along it
/// to multiples of 1/8 of the leading power of two of the larger of the two. Each edge moves
/// by at most about 1/14 of its length and the area by at most 13 %. Coarser steps share more
/// tiles on the teapot, whose pixels see footprints that differ by several per cent from
/// sample to sample, but visibly blur pixel-wide scratches. Returns the rounded vectors and
/// the integers that name them; `None` for a degenerate or non-finite footprint.
pub fn quantize(a: Vec2, b: Vec2) -> Option<(Vec2, Vec2, [u64; 2])> {
    let la = a.length();
    let (cx, cy) = (
        round_f32(a.x / la * DIRECTION_STEPS),
        round_f32(a.y / la * DIRECTION_STEPS),
    );
    if !(cx.is_finite() && cy.is_finite()) {
        return None;
    }
    // b's components across and along a, in a's exact frame (so the area is la * across).
    let (across, along) = (a.perp_dot(b) / la, a.dot(b) / la);
    let dir = Vec2::new(cx, cy).normalize();
    let la = round_4_bits(la)?;
    let across = round_4_bits(across)?;
    // 2^e / 8, 2^e the leading power of two of the larger of |along| and |across|.
    let lead = across.abs().max(along.abs()).to_bits() & 0x7f80_0000;
    let step = f32::from_bits(lead.checked_sub(3 << 23)?);
    let along = round_f32(along / step); // |along / step| < 16
    if !along.is_finite() || along.abs() >= 1e6 {
        return None;
    }
    let (qa, qb) = (dir * la, dir * (along * step) + dir.perp() * across);
    let key = [
        ((cx as i32 as u32 as u64) << 32) | (cy as i32 as u32 as u64),
        ((la.to_bits() >> 20) as u64) << 40
            | ((across.to_bits() >> 20) as u64) << 28
            | (along as i32 as u32 as u64 & 0x0fff_ffff),
    ];
    Some((qa, qb, key))
}

/// The footprint tile containing a hit: its centre and edge vectors in texture space, and the
/// key that names it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FootprintTile {
    pub centre: DVec2,
    pub a: DVec2,
    pub b: DVec2,
    key: [u64; 4],
}

impl FootprintTile {
    /// The tile of `uv`: the footprint `duvdx`, `duvdy` rounded by [`quantize`], centred on the
    /// nearest point of the lattice of its edges over [`TILE_STEPS`]. `None` for a degenerate
    /// or non-finite footprint, or a hit too far from the origin for the tile index (those are
    /// queried unsnapped).
    pub fn containing(uv: Vec2, duvdx: Vec2, duvdy: Vec2) -> Option<FootprintTile> {
        let (qa, qb, shape) = quantize(duvdx, duvdy)?;
        let (a, b) = (qa.as_dvec2(), qb.as_dvec2());
        let det = a.x * b.y - a.y * b.x;
        let p = uv.as_dvec2();
        // Lattice coordinates in steps of a / STEPS, b / STEPS: p = (s a + t b) / STEPS.
        let s = (p.x * b.y - p.y * b.x) / det * TILE_STEPS;
        let t = (a.x * p.y - a.y * p.x) / det * TILE_STEPS;
        if !(det.abs() > 1e-30 && s.abs() < 1e15 && t.abs() < 1e15) {
            return None;
        }
        let (i, j) = (round_f64(s), round_f64(t));
        let key = [shape[0], shape[1], i as i64 as u64, j as i64 as u64];
        Some(FootprintTile {
            centre: (a * i + b * j) / TILE_STEPS,
            a,
            b,
            key,
        })
    }
}

/// Which per-layer values a cache entry holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TileQuery {
    /// [`LayerSet::coverage_all`].
    All,
    /// [`LayerSet::coverage_max`].
    Max,
}

#[derive(Clone, Copy)]
struct Entry {
    /// Set id, query, tile key; all zero when empty (set ids start at 1).
    key: [u64; 6],
    values: [f32; CACHED_LAYERS],
}

/// Pixel footprints ([`LayerSet::coverage_of_pixel`]) each thread keeps: the pixel's first
/// hit and the surfaces its samples see through the glass or in mirrors, up to
/// [`PIXEL_CLUSTERS`] per chain of delta bounces, replaced oldest first.
const PIXEL_ENTRIES: usize = 16;

/// Footprints one pixel keeps per shape and chain: a sample whose estimate of the pixel
/// centre is not near any of them starts another, until there are this many (then it takes
/// its tile). Behind curved glass the estimates of a pixel's samples scatter (the footprint
/// changes across the pixel faster than the differentials' linear model): on the setting-1
/// teapot about 3 in 10 samples seen through the glass miss the first sample's footprint,
/// and the tiles they fell back to were shared by one sample in four.
pub const PIXEL_CLUSTERS: usize = 4;

thread_local! {
    static CACHE: RefCell<Vec<Entry>> = const { RefCell::new(Vec::new()) };
    static PIXEL: RefCell<PixelCache> = const {
        RefCell::new(PixelCache {
            entries: [None; PIXEL_ENTRIES],
            next: 0,
        })
    };
}

/// The pixel footprints of one thread, written round-robin. A pixel's entries are replaced
/// only by the pixel's own later ones, oldest first, whatever the slot the pixel starts at, so
/// the values a sample sees depend only on its pixel's earlier samples (determinism). Its
/// entries are always the newest ones, so a lookup stops at the first entry of another pixel.
struct PixelCache {
    entries: [Option<PixelEntry>; PIXEL_ENTRIES],
    next: usize,
}

/// A pixel's footprint coverage ([`LayerSet::coverage_of_pixel`]): set id, query, render,
/// pixel, shape and chain; the footprint's centre and edges, and `1 / (a x b)`; the values.
#[derive(Clone, Copy)]
struct PixelEntry {
    key: [u64; 6],
    centre: Vec2,
    a: Vec2,
    b: Vec2,
    inv_det: f32,
    values: [f32; CACHED_LAYERS],
}

/// Which pixel of which render a hit belongs to, the chain of delta bounces that reached it
/// and the shape it is on ([`LayerSet::coverage_of_pixel`], `shading::PixelHit`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelKey {
    pub render: u64,
    pub pixel: u64,
    pub shape: u32,
    /// 0 for the camera ray's first hit, else names the chain of delta bounces.
    pub chain: u64,
}

/// A sample shares its pixel's footprint coverage when its own estimate of the pixel centre's
/// texture point lies within this fraction of the footprint's edges of the stored one.
pub const PIXEL_TOLERANCE: f32 = 0.25;

/// Empty the calling thread's tile cache (for benchmarks that render one scene repeatedly:
/// results never depend on it, only the time does).
pub fn clear_cache() {
    CACHE.with(|cache| cache.borrow_mut().clear());
    PIXEL.with(|cache| cache.borrow_mut().entries = [None; PIXEL_ENTRIES]);
}

impl LayerSet {
    /// [`Self::coverage_all_within`] or [`Self::coverage_max_within`], as `query` asks.
    /// # Panics
    /// If `out.len() < len()`.
    pub fn coverage_query(
        &self,
        query: TileQuery,
        uv: Vec2,
        duvdx: Vec2,
        duvdy: Vec2,
        max_cells: usize,
        out: &mut [f32],
    ) {
        match query {
            TileQuery::All => self.coverage_all_within(uv, duvdx, duvdy, max_cells, out),
            TileQuery::Max => self.coverage_max_within(uv, duvdx, duvdy, max_cells, out),
        }
    }

    /// The per-layer coverage of a whole pixel's footprint, for a hit at texture point `uv`
    /// reached from the camera through `pixel` by delta bounces only (on its shape, along its
    /// chain, in its render), `offset` (pixels) from the pixel's centre, with the footprint
    /// `footprint() = (duvdx, duvdy)`: the exact coverage ([`Self::coverage_max`] or
    /// [`Self::coverage_all`] per `query`, up to [`TILE_MAX_CELLS`]) of that footprint centred
    /// on the texture point of the pixel centre's ray along the same chain,
    /// `uv - offset.x duvdx - offset.y duvdy`. It is computed at the pixel's first such hit and
    /// kept per thread ([`PIXEL_ENTRIES`] of them); the pixel's later samples on the same
    /// shape along the same chain reuse it when their own estimate of the centre,
    /// `uv - offset.x a - offset.y b` with the stored footprint's edges `a`, `b`, lies within
    /// [`PIXEL_TOLERANCE`] of those edges from the stored centre. Those samples never call
    /// `footprint`: most samples of a pixel need no ray differentials worked out. A sample
    /// near none of the pixel's footprints for the hit (at silhouettes, texture seams, and
    /// behind curved glass, where the estimates scatter) adds its own, centred on its own
    /// estimate, up to [`PIXEL_CLUSTERS`]; after that it takes its tile
    /// ([`Self::coverage_tiled`]).
    ///
    /// So every sample of a pixel sees the coverage of the pixel's own footprint, exactly, as
    /// METHOD.md section 6 asks, for one exact query per pixel and chain (a few behind curved
    /// glass) instead of one per tile. Deterministic: a pixel's samples run in order on one
    /// thread, so which sample fills an entry depends only on the pixel ([`PixelCache`]).
    /// # Panics
    /// If `out.len() < len()`.
    pub fn coverage_of_pixel(
        &self,
        uv: Vec2,
        footprint: impl FnOnce() -> (Vec2, Vec2),
        pixel: PixelKey,
        offset: Vec2,
        query: TileQuery,
        out: &mut [f32],
    ) {
        let n = self.len();
        if n > CACHED_LAYERS {
            let (duvdx, duvdy) = footprint();
            self.coverage_tiled(uv, duvdx, duvdy, query, out);
            return;
        }
        let key = [
            self.id(),
            query as u64,
            pixel.render,
            pixel.pixel,
            pixel.shape as u64,
            pixel.chain,
        ];
        // Whether this sample shares one of the pixel's footprints for this hit, and if not,
        // how many the pixel has.
        enum Lookup {
            Shared,
            Far(usize),
        }
        let lookup = PIXEL.with(|cache| {
            let cache = cache.borrow();
            // The pixel's own entries are the newest ones (its samples run one after another
            // on this thread): look back from the newest, up to the first of another pixel.
            let mut same = 0;
            let mut slot = cache.next;
            for _ in 0..PIXEL_ENTRIES {
                slot = slot.checked_sub(1).unwrap_or(PIXEL_ENTRIES - 1);
                let Some(e) = &cache.entries[slot] else { break };
                if e.key[2] != key[2] || e.key[3] != key[3] {
                    break; // another pixel's (render, pixel)
                }
                if e.key[4] != key[4] || e.key[5] != key[5] || e.key[..2] != key[..2] {
                    continue; // another shape or chain (or set, or query)
                }
                // This sample's estimate of the centre in the stored footprint's edge
                // coordinates.
                let d = uv - offset.x * e.a - offset.y * e.b - e.centre;
                let (s, t) = (d.perp_dot(e.b) * e.inv_det, e.a.perp_dot(d) * e.inv_det);
                if s.abs() <= PIXEL_TOLERANCE && t.abs() <= PIXEL_TOLERANCE {
                    out[..n].copy_from_slice(&e.values[..n]);
                    return Lookup::Shared;
                }
                same += 1;
            }
            Lookup::Far(same)
        });
        let same = match lookup {
            Lookup::Shared => return,
            Lookup::Far(same) => same,
        };
        let (duvdx, duvdy) = footprint();
        // A new footprint of the pixel, centred on this sample's estimate of the pixel centre
        // (up to `PIXEL_CLUSTERS`; then, and where it is degenerate, the tile).
        let centre = uv - offset.x * duvdx - offset.y * duvdy;
        let det = duvdx.perp_dot(duvdy);
        if same < PIXEL_CLUSTERS && det.abs() > 0.0 && det.is_finite() && centre.is_finite() {
            let mut values = [0.0f32; CACHED_LAYERS];
            self.coverage_query(query, centre, duvdx, duvdy, TILE_MAX_CELLS, &mut values);
            out[..n].copy_from_slice(&values[..n]);
            PIXEL.with(|cache| {
                let mut cache = cache.borrow_mut();
                let slot = cache.next;
                cache.entries[slot] = Some(PixelEntry {
                    key,
                    centre,
                    a: duvdx,
                    b: duvdy,
                    inv_det: 1.0 / det,
                    values,
                });
                cache.next = (slot + 1) % PIXEL_ENTRIES;
            });
            return;
        }
        self.coverage_tiled(uv, duvdx, duvdy, query, out);
    }

    /// The per-layer coverage of the footprint tile containing `uv` ([`FootprintTile`]), into
    /// `out[0..len()]`, as [`Self::coverage_all`] or [`Self::coverage_max`] of the tile (up to
    /// [`TILE_MAX_CELLS`]); cached per thread. Where there is no tile
    /// ([`FootprintTile::containing`]) or the set has more than [`CACHED_LAYERS`] layers, the
    /// footprint itself is queried, uncached.
    /// # Panics
    /// If `out.len() < len()`.
    pub fn coverage_tiled(
        &self,
        uv: Vec2,
        duvdx: Vec2,
        duvdy: Vec2,
        query: TileQuery,
        out: &mut [f32],
    ) {
        let n = self.len();
        let tile = FootprintTile::containing(uv, duvdx, duvdy).filter(|_| n <= CACHED_LAYERS);
        let Some(tile) = tile else {
            self.coverage_query(query, uv, duvdx, duvdy, MAX_FOOTPRINT_CELLS, out);
            return;
        };
        let key = [
            self.id(),
            query as u64,
            tile.key[0],
            tile.key[1],
            tile.key[2],
            tile.key[3],
        ];
        let h =
            key.iter().fold(0u64, |h, &k| crate::hash::mix64(h ^ k)) as usize & (CACHE_ENTRIES - 1);
        CACHE.with(|cache| {
            let mut cache = cache.borrow_mut();
            if cache.is_empty() {
                cache.resize(
                    CACHE_ENTRIES,
                    Entry {
                        key: [0; 6],
                        values: [0.0; CACHED_LAYERS],
                    },
                );
            }
            let entry = &mut cache[h];
            // (Compared field by field: `!=` on the array compiled to a `memcmp` call.)
            if !entry.key.iter().zip(&key).all(|(a, b)| a == b) {
                let (c, a, b) = (tile.centre.as_vec2(), tile.a.as_vec2(), tile.b.as_vec2());
                self.coverage_query(query, c, a, b, TILE_MAX_CELLS, &mut entry.values);
                entry.key = key;
            }
            out[..n].copy_from_slice(&entry.values[..n]);
        });
    }
}
