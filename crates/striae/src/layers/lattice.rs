//! Footprint tiles: the renderer's coverage queries at hits not reached from the camera by
//! delta bounces, snapped to a lattice of footprint-shaped tiles whose exact coverage is cached
//! (`layers::cache::CoverageCache::tiled`).
//!
//! A pixel's samples hit points spread over one pixel footprint, and each asks for the scratch
//! coverage of a footprint of that same shape (METHOD.md section 6). Computing it exactly at
//! every sample costs one noise-cell enumeration per cell the footprint spans, per layer:
//! 1-4 us for 8 layers where a pixel spans many scratches (`BENCHMARKS.md`, "Design findings"). Here the
//! footprint's edge vectors `a`, `b` are rounded to one of a discrete set of shapes
//! ([`quantize`]) and the hit point is snapped to the nearest point of the lattice
//! `{(i a + j b) / TILE_STEPS}`; the coverage is that of the footprint of the rounded shape
//! centred there, a function of `(i, j, a, b)` only, like a texel of an anisotropic mip level.
//! It is computed exactly once per render worker and reused by every sample that snaps to it.
//!
//! This is a departure from a footprint centred on each sample: the footprint a sample sees is
//! displaced by at most `1 / (2 TILE_STEPS)` of its size along each edge, its edges are off by
//! at most about 1/14 and its area by at most 13 % (the rounding). The pixel's estimate
//! converges to a slightly different filter of the same coverage. Measured against the
//! per-sample footprint (`coverage = "sample"`) at 256 spp: the image means agree within
//! 0.1 %, and the difference (RMSE 0.0085 on the close-up, mean 0.118; 0.0031 on the teapot)
//! is a slight jaggedness of pixel-wide scratch lines (`BENCHMARKS.md`, "Design findings").
//!
//! Determinism: a tile's value depends only on its key, never on which sample or thread
//! computed it first, so images stay bit-identical for any thread count.

use super::LayerSet;
use crate::math::Vec2;
use glam::DVec2;

/// Tiles whose noise-space bounding box spans more cells than this take the layers' expected
/// coverage (the prefiltered limit) instead of the exact one. Lower than the exact queries'
/// [`super::layer::MAX_FOOTPRINT_CELLS`]: such tiles come from grazing views and from rays that
/// went through curved glass, whose footprints change from sample to sample, so they are
/// rarely shared and cost most (the setting-1 teapot: 1.69x smooth glass per sample with 256,
/// 1.49x with 64; the images differ only along silhouettes).
pub const TILE_MAX_CELLS: usize = 64;

/// Tile centres lie on the lattice of the footprint's edges divided by this: a footprint is
/// displaced by at most `1 / (2 TILE_STEPS)` of its size (with 1, pixel-wide scratch lines
/// visibly blur in the close-up, Fig. 8a: RMSE 0.027 against the per-sample footprint, 0.0085
/// with 2).
pub const TILE_STEPS: f64 = 2.0;

/// Layers a cached tile holds; larger sets are not cached.
pub const CACHED_LAYERS: usize = 16;

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
    pub(crate) key: [u64; 4],
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
}
