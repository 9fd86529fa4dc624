//! Scratch layers from Worley cell noise (METHOD.md section 5, the seed's section 3.2 and Fig. 4).
//!
//! A scratch texture is tileable Worley noise ([`worley`]) seen through an affine map: texture
//! point `p` goes to noise point `q = S^-1 R(-alpha) (p - c)`, `S = diag(L, W)`, `c = (1/2, 1/2)`,
//! and `p` is scratched where `F1(q) < tau`. Every feature point thus becomes an ellipse of
//! half-axes `tau L` (along `d = (cos alpha, sin alpha)`) and `tau W`. A [`LayerSet`] holds `K`
//! such layers, each with its own `alpha_k` and noise seed drawn from one set seed.
//!
//! Two ways to use it:
//! * the renderer asks procedural questions, nothing rasterised: the point tests
//!   [`LayerSet::is_scratched`] and [`LayerSet::scratched_mask`], and the exact scratch
//!   coverage of a ray-differential footprint ([`footprint`]) for one layer
//!   ([`LayerSet::coverage`]), every layer ([`LayerSet::coverage_all`]) or the largest
//!   ([`LayerSet::coverage_max`]), each within a cell budget
//!   ([`LayerSet::coverage_query`]); a render worker's [`CoverageCache`] shares these between
//!   a pixel's samples and between nearby footprints ([`lattice`]);
//! * people get anti-aliased rasters with a mip chain ([`raster`]) and PNGs.
//!
//! Conventions. Texture space is `(u, v)` in `[0, 1]^2`; `alpha` is measured from the `u` axis
//! towards the `v` axis. Queries take `f32` texture coordinates (the renderer's) and work in
//! `f64` internally: with `W = 0.001` the noise coordinate reaches about 700, where `f32` would
//! keep only 1e-4 of a cell. Images map texel `(x, y)` (column `x`, row `y`, row 0 at the top)
//! of an `R x R` raster to `u in [x/R, (x+1)/R]`, `v in [1 - (y+1)/R, 1 - y/R]`: `u` runs right,
//! `v` runs up, so an angle `alpha` appears counter-clockwise from the right in the picture.
//! The layer is defined on the whole plane; `[0, 1]^2` is the part the rasters show (the noise
//! continues, it is not wrapped, outside it).

pub mod cache;
pub mod footprint;
pub mod lattice;
pub mod layer;
pub mod point_lanes;
pub mod random;
pub mod raster;
pub mod worley;

pub use cache::CoverageCache;
pub use layer::ScratchLayer;
pub use raster::CoverageRaster;
pub use worley::{Worley, WorleySample};

use crate::math::Vec2;
use serde::{Deserialize, Serialize};

/// Most layers a set may hold (a point query returns them as a 64-bit mask).
pub const MAX_LAYERS: usize = 64;
/// Smallest scratch length or width: below it the scratch is finer than `f32` texture
/// coordinates can place (their spacing near 1 is 6e-8).
pub const MIN_SIZE: f64 = 1e-6;
/// Largest scratch length or width: beyond it the whole texture `[0, 1]^2` lies within a
/// millionth of one noise cell, under one scratch or none whatever the seed.
pub const MAX_SIZE: f64 = 1e6;
/// The noise period of every layer (cells). With `MIN_SIZE` the texture spans at most 1.5e6
/// cells, so no layer repeats inside `[0, 1]^2`.
pub const LAYER_NOISE_PERIOD: u64 = 1 << 24;

/// Errors of the scratch-layer module: each names the parameter and the bad value.
#[derive(Debug, thiserror::Error)]
pub enum LayerError {
    #[error("scratch `length` must be a finite number in [{MIN_SIZE:e}, {MAX_SIZE:e}], got {0:?}")]
    Length(f64),
    #[error("scratch `width` must be a finite number in [{MIN_SIZE:e}, {MAX_SIZE:e}], got {0:?}")]
    Width(f64),
    #[error("scratch `threshold` (tau) must lie in (0, 1], got {0:?}")]
    Threshold(f64),
    #[error("number of `layers` must be between 1 and {MAX_LAYERS}, got {0}")]
    LayerCount(usize),
    #[error("unknown scratch `setting` {0}: the seed defines settings 1 and 2")]
    Setting(u32),
    #[error("noise `period` must be a power of two in [1, 2^32], got {0}")]
    Period(u64),
    #[error("raster `resolution` {res} is not allowed: {reason}")]
    Resolution { res: usize, reason: String },
    #[error("layer index {index} out of range: the set has {count} layers")]
    LayerIndex { index: usize, count: usize },
    #[error("could not encode {what} as PNG: {msg}")]
    Png { what: String, msg: String },
    /// A raster the allocator refused.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
}

/// The user's scratch parameters (METHOD.md section 5, the seed's Table 1). Deserializes from
/// `{ length, width, threshold, layers }` (unknown keys are errors); validate with
/// [`LayerParams::validate`] (done by [`LayerSet::new`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerParams {
    /// Scratch length scale `L` (texture units): scratches are `2 tau L` long.
    pub length: f64,
    /// Scratch width scale `W`: scratches are `2 tau W` wide.
    pub width: f64,
    /// Threshold `tau` on F1, in (0, 1]; coverage is about `pi tau^2`.
    pub threshold: f64,
    /// Number of layers `K`.
    #[serde(default = "default_layers")]
    pub layers: usize,
}

fn default_layers() -> usize {
    LayerParams::DEFAULT_LAYERS
}

impl LayerParams {
    /// Layers per set when not given (the seed does not say; 8 is what the benchmarks use).
    pub const DEFAULT_LAYERS: usize = 8;

    /// The seed's settings (Table 1): 1 = (L 0.3, W 0.001, tau 0.1), 2 = (L 0.6, W 0.010,
    /// tau 0.1), with [`Self::DEFAULT_LAYERS`] layers.
    pub fn setting(n: u32) -> Result<Self, LayerError> {
        let (length, width) = match n {
            1 => (0.3, 0.001),
            2 => (0.6, 0.010),
            _ => return Err(LayerError::Setting(n)),
        };
        Ok(LayerParams {
            length,
            width,
            threshold: 0.1,
            layers: Self::DEFAULT_LAYERS,
        })
    }

    pub fn validate(&self) -> Result<(), LayerError> {
        let size = |x: f64| (MIN_SIZE..=MAX_SIZE).contains(&x);
        if !size(self.length) {
            return Err(LayerError::Length(self.length));
        }
        if !size(self.width) {
            return Err(LayerError::Width(self.width));
        }
        if !(self.threshold > 0.0 && self.threshold <= 1.0) {
            return Err(LayerError::Threshold(self.threshold));
        }
        if !(1..=MAX_LAYERS).contains(&self.layers) {
            return Err(LayerError::LayerCount(self.layers));
        }
        Ok(())
    }
}

/// Which way a layer's scratches run.
#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Orientation {
    /// Every scratch of a layer along the layer's direction (METHOD.md section 5, the seed).
    #[default]
    Layer,
    /// Each scratch along its own uniform direction, hashed from its cell ([`random`]).
    Random,
}

/// One scratch of a layer in texture space: the ellipse of half-axes `half_length` along the
/// unit `direction` and `half_width` across it, about `centre` ([`LayerSet::scratches`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scratch {
    pub layer: usize,
    pub centre: glam::DVec2,
    pub direction: glam::DVec2,
    pub half_length: f64,
    pub half_width: f64,
}

impl Scratch {
    /// The half-length and half-width of the scratch's image under a linear map `A` from
    /// texture space to a surface, given `|A d|` (`along`, the image of its direction's length)
    /// and `|det A|` (`area`): `l |A d|` and `w |det A| / |A d|`, the thin ellipse of the same
    /// area along `A d` (exact for a similarity; `geometry::carve` builds its grooves so).
    pub fn mapped_half_axes(&self, along: f64, area: f64) -> (f64, f64) {
        (self.half_length * along, self.half_width * area / along)
    }
}

/// `K` scratch layers drawn from one seed (METHOD.md section 5). Layer `k`'s angle and noise
/// seed depend only on `(seed, k)`, so adding layers keeps the first ones unchanged.
#[derive(Clone, Debug)]
pub struct LayerSet {
    params: LayerParams,
    seed: u64,
    layers: Vec<ScratchLayer>,
    /// The layers' point test, lane by lane.
    point: point_lanes::PointLanes,
    orientation: Orientation,
    expected_coverage: f64,
    /// Names the set in per-thread caches ([`lattice`]); unique per process, from 1.
    id: u64,
}

/// Candidate discs [`LayerSet::coverage_max`] keeps from its first pass (bounds) for its
/// second (exact areas), for all layers together; a layer that does not fit is enumerated
/// again.
pub(crate) const CANDIDATE_POOL: usize = 2 * footprint::MAX_DISCS;

/// The next [`LayerSet`] id.
static NEXT_SET_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

impl LayerSet {
    /// Validate `params` and draw the layers: `alpha_k` uniform in `[0, 2 pi)` (a direction, not
    /// just an axis: an asymmetric scratch profile tells `d` from `-d`) and a 64-bit noise seed.
    pub fn new(params: LayerParams, seed: u64) -> Result<Self, LayerError> {
        Self::with_orientation(params, seed, Orientation::Layer)
    }

    /// [`Self::new`] with the scratches' [`Orientation`]: `Random` keeps each layer's noise
    /// seed and gives every scratch its own direction ([`random`]).
    pub fn with_orientation(
        params: LayerParams,
        seed: u64,
        orientation: Orientation,
    ) -> Result<Self, LayerError> {
        params.validate()?;
        let layers = (0..params.layers)
            .map(|k| {
                // Bijective in k for a given seed, so no two layers of a set share their stream.
                let h = crate::hash::mix64(
                    crate::hash::mix64(seed ^ 0xa076_1d64_78bd_642f)
                        .wrapping_add((k as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15)),
                );
                let alpha = (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64) * std::f64::consts::TAU;
                let noise_seed = crate::hash::mix64(h ^ 0x9e37_79b9_7f4a_7c15);
                let layer = ScratchLayer::new(k, alpha, noise_seed, &params)?;
                match orientation {
                    Orientation::Layer => Ok(layer),
                    Orientation::Random => layer.into_random(noise_seed, &params),
                }
            })
            .collect::<Result<Vec<_>, _>>()?;
        let expected_coverage = match layers[0].random() {
            None => footprint::expected_coverage(params.threshold, 48),
            Some(r) => r.expected_coverage(),
        };
        Ok(LayerSet {
            params,
            seed,
            point: point_lanes::PointLanes::new(&layers),
            layers,
            orientation,
            expected_coverage,
            id: NEXT_SET_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        })
    }

    /// The set of no layers: a material whose scratches are curves only (`crate::curves`).
    /// Every query answers "not scratched"; `params()` holds no layers.
    pub fn none() -> Self {
        LayerSet {
            params: LayerParams {
                layers: 0,
                ..LayerParams::setting(1).expect("setting 1")
            },
            seed: 0,
            layers: Vec::new(),
            point: point_lanes::PointLanes::new(&[]),
            orientation: Orientation::Layer,
            expected_coverage: 0.0,
            id: NEXT_SET_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        }
    }

    /// A process-unique id (clones share it: they hold the same layers).
    pub fn id(&self) -> u64 {
        self.id
    }

    pub fn params(&self) -> &LayerParams {
        &self.params
    }

    pub fn seed(&self) -> u64 {
        self.seed
    }

    pub fn layers(&self) -> &[ScratchLayer] {
        &self.layers
    }

    pub fn len(&self) -> usize {
        self.layers.len()
    }

    pub fn is_empty(&self) -> bool {
        self.layers.is_empty()
    }

    /// Layer `k`, or an error naming the index.
    pub fn layer(&self, k: usize) -> Result<&ScratchLayer, LayerError> {
        self.layers.get(k).ok_or(LayerError::LayerIndex {
            index: k,
            count: self.layers.len(),
        })
    }

    pub fn orientation(&self) -> Orientation {
        self.orientation
    }

    /// The scratch direction of layer `k` at texture point `uv`: the layer's (`Layer`), or that
    /// of the scratch nearest to `uv` in its own metric (`Random`: the one covering `uv`, or the
    /// nearest where none does), as `(cos, sin)`.
    /// # Panics
    /// If `k >= len()`.
    pub fn direction_at(&self, k: usize, uv: Vec2) -> [f64; 2] {
        match self.layers[k]
            .random()
            .and_then(|r| r.nearest(uv.as_dvec2()))
        {
            Some((_, beta)) => [beta.cos(), beta.sin()],
            None => self.layers[k].direction(),
        }
    }

    /// The scratch of layer `k` at texture point `uv`: the one covering it (the nearest in its
    /// own metric, as [`Self::direction_at`]; for the seed's layers the nearest feature point
    /// of the stretched noise, whose ellipse is `F1 < tau`), or the nearest where none does;
    /// `None` where a random layer finds none within reach.
    /// # Panics
    /// If `k >= len()`.
    pub fn scratch_at(&self, k: usize, uv: glam::DVec2) -> Option<Scratch> {
        let layer = &self.layers[k];
        if let Some(r) = layer.random() {
            return r.nearest_scratch(uv, k);
        }
        Some(layer.scratch(layer.nearest_at(uv)))
    }

    /// The scratch of layer `k` covering texture point `uv`, if one does
    /// ([`layer::ScratchLayer::scratch_covering`]; cheaper than [`Self::scratch_at`] where one does).
    /// # Panics
    /// If `k >= len()`.
    pub fn scratch_covering(&self, k: usize, uv: glam::DVec2) -> Option<Scratch> {
        self.layers[k].scratch_covering(uv)
    }

    /// Calls `f` with each scratch of layer `k` (one of the seed's layers: not randomly
    /// oriented) whose ellipse comes within reach of the texture segment from `uv` to `uv + v`
    /// (a feature point within `tau` of it in noise space, as [`Self::capsule_mask`]), until
    /// `f` returns `true`; whether one did. Without allocating: the cells of the segment's
    /// noise-space box, grown by `tau`.
    /// # Panics
    /// If `k >= len()`.
    pub fn find_scratch_near_segment(
        &self,
        k: usize,
        uv: glam::DVec2,
        v: glam::DVec2,
        mut f: impl FnMut(&Scratch) -> bool,
    ) -> bool {
        let layer = &self.layers[k];
        let (q0, q1) = (layer.to_noise(uv), layer.to_noise(uv + v));
        let tau = layer.threshold();
        let (lo, hi) = (q0.min(q1) - tau, q0.max(q1) + tau);
        let d = q1 - q0;
        let inv = if d.length_squared() > 0.0 {
            1.0 / d.length_squared()
        } else {
            0.0
        };
        // (Half-open ranges: an inclusive one checks its end twice a step.)
        let (i0, i1) = (worley::floor_i64(lo.x), worley::floor_i64(hi.x) + 1);
        let (j0, j1) = (worley::floor_i64(lo.y), worley::floor_i64(hi.y) + 1);
        for j in j0..j1 {
            for i in i0..i1 {
                let p = layer.noise().feature_point(i, j);
                let t = ((p - q0).dot(d) * inv).clamp(0.0, 1.0);
                if (q0 + d * t - p).length_squared() >= tau * tau {
                    continue;
                }
                if f(&layer.scratch(p)) {
                    return true;
                }
            }
        }
        false
    }

    /// Layer `k`'s scratch direction `d_k = (cos alpha_k, sin alpha_k)` in texture space.
    /// # Panics
    /// If `k >= len()`.
    pub fn direction(&self, k: usize) -> [f64; 2] {
        self.layers[k].direction()
    }

    /// The mean scratch coverage of one layer over the noise (exact for the hash's uniform
    /// placement; about `pi tau^2`): see [`footprint::expected_coverage`].
    pub fn expected_coverage(&self) -> f64 {
        self.expected_coverage
    }

    /// Whether texture point `uv` is scratched in layer `k` (`F1(q) < tau`).
    /// # Panics
    /// If `k >= len()`.
    #[inline]
    pub fn is_scratched(&self, k: usize, uv: Vec2) -> bool {
        self.layers[k].is_scratched(uv)
    }

    /// Bit `k` set where a scratch of layer `k` may reach the texture segment from `uv` to
    /// `uv + v` (exact for the seed's layers of `tau <= 1/2`, a feature point within `tau` of
    /// it in noise space; always for the others): [`point_lanes`]' capsule test.
    #[inline(always)]
    pub fn capsule_mask(&self, uv: glam::DVec2, v: glam::DVec2) -> u64 {
        self.point.capsule_mask(uv, v)
    }

    /// Bit `k` set iff layer `k` is scratched at `uv`: the point query over all layers
    /// ([`point_lanes`]).
    #[inline(always)]
    pub fn scratched_mask(&self, uv: Vec2) -> u64 {
        self.point.mask(uv.as_dvec2(), &self.layers)
    }

    /// Fraction of the footprint `{uv + s duvdx + t duvdy : s, t in [-1/2, 1/2]}` (one pixel's
    /// parallelogram from ray differentials) that layer `k`'s scratches cover, in `[0, 1]`.
    /// See [`ScratchLayer::coverage`]. # Panics: if `k >= len()`.
    #[inline]
    pub fn coverage(&self, k: usize, uv: Vec2, duvdx: Vec2, duvdy: Vec2) -> f32 {
        self.layers[k].coverage(uv, duvdx, duvdy, self.expected_coverage)
    }

    /// Per-layer coverage of one footprint into `out[0..len()]` (the renderer then picks the
    /// layer with the largest share, METHOD.md section 6).
    /// # Panics
    /// If `out.len() < len()`.
    pub fn coverage_all(&self, uv: Vec2, duvdx: Vec2, duvdy: Vec2, out: &mut [f32]) {
        self.coverage_all_within(uv, duvdx, duvdy, layer::MAX_FOOTPRINT_CELLS, out);
    }

    /// [`Self::coverage_all`], with footprints spanning more than `max_cells` noise cells
    /// given the expected coverage.
    pub fn coverage_all_within(
        &self,
        uv: Vec2,
        duvdx: Vec2,
        duvdy: Vec2,
        max_cells: usize,
        out: &mut [f32],
    ) {
        let (p, a, b) = (uv.as_dvec2(), duvdx.as_dvec2(), duvdy.as_dvec2());
        let mut centres = [glam::DVec2::ZERO; layer::CANDIDATE_ROOM];
        for (layer, o) in self.layers.iter().zip(&mut out[..self.layers.len()]) {
            *o = layer
                .footprint_coverage_in(p, a, b, max_cells, &mut centres)
                .unwrap_or(self.expected_coverage) as f32;
        }
    }

    /// The largest coverage of one footprint over the layers, with every layer that may tie
    /// with it (METHOD.md section 6, `max` mode): `out[k]` is layer `k`'s exact coverage (as
    /// [`Self::coverage_all`]) where it is within 2e-6 of the largest, and 0 where it is
    /// smaller (its value is then not computed). So the largest value and the set of layers
    /// within 1e-6 of it (the ties) are exactly those of [`Self::coverage_all`].
    ///
    /// Every layer first gathers its candidate discs (kept in a pool shared by the layers,
    /// [`CANDIDATE_POOL`]) and an upper bound on its coverage
    /// ([`layer::FootprintCandidates::coverage_bound`]); the exact areas are then computed in
    /// decreasing order of bound until the next bound falls below the best coverage so far,
    /// each layer given up part way once it cannot reach the best
    /// ([`layer::FootprintCandidates::coverage_reaching`]). Which layers are computed depends
    /// on the bounds; the values kept do not (a layer is skipped only where its exact coverage
    /// is below the best less the tie tolerance, where it is cleared anyway).
    /// # Panics
    /// If `out.len() < len()`.
    pub fn coverage_max(&self, uv: Vec2, duvdx: Vec2, duvdy: Vec2, out: &mut [f32]) {
        self.coverage_max_within(uv, duvdx, duvdy, layer::MAX_FOOTPRINT_CELLS, out);
    }

    /// [`Self::coverage_max`], with footprints spanning more than `max_cells` noise cells
    /// given the expected coverage.
    pub fn coverage_max_within(
        &self,
        uv: Vec2,
        duvdx: Vec2,
        duvdy: Vec2,
        max_cells: usize,
        out: &mut [f32],
    ) {
        const TIE: f64 = 2e-6;
        const POOL: usize = CANDIDATE_POOL;
        let (p, a, b) = (uv.as_dvec2(), duvdx.as_dvec2(), duvdy.as_dvec2());
        let n = self.layers.len();
        let out = &mut out[..n];
        if self.orientation == Orientation::Random {
            // No bounds to prune with: every layer's exact coverage, then the ties kept.
            self.coverage_all_within(uv, duvdx, duvdy, max_cells, out);
            let best = out.iter().fold(0.0f32, |m, &c| m.max(c)) as f64;
            for c in out.iter_mut() {
                if (*c as f64) < best - TIE {
                    *c = 0.0;
                }
            }
            return;
        }
        // Pass 1: exact values that need no area work, bounds (and the candidate discs) for
        // the rest.
        let mut bound = [0.0f64; MAX_LAYERS];
        let mut bound_area = [0.0f64; MAX_LAYERS];
        let mut order = [0u8; MAX_LAYERS];
        // Layer k's discs are pool[kept[k].0..kept[k].1]; an empty range: not kept.
        let mut kept = [(0u16, 0u16); MAX_LAYERS];
        let mut pool = [glam::DVec2::ZERO; POOL];
        let mut used = 0;
        let mut pending = 0;
        let mut best = 0.0f64;
        for (k, layer) in self.layers.iter().enumerate() {
            out[k] = 0.0;
            // `Some(coverage)` where no area work is needed.
            let done = match layer.footprint_candidates(p, a, b, max_cells, &mut pool[used..]) {
                layer::Candidates::Done(c) => Some(c),
                layer::Candidates::Discs(f) => {
                    bound_area[k] = f.bound_area(&pool[used..used + f.n]);
                    bound[k] = f.coverage_bound_of_area(bound_area[k]);
                    kept[k] = (used as u16, (used + f.n) as u16);
                    used += f.n;
                    None
                }
                // The pool's rest was too small: ask again with a whole buffer, which may find
                // more than MAX_DISCS discs (then `Done(None)`: the expected coverage).
                layer::Candidates::Overflow => {
                    let mut centres = [glam::DVec2::ZERO; layer::CANDIDATE_ROOM];
                    match layer.footprint_candidates(p, a, b, max_cells, &mut centres) {
                        layer::Candidates::Done(c) => Some(c),
                        layer::Candidates::Discs(f) => {
                            bound[k] = f.coverage_bound(&centres[..f.n]);
                            None
                        }
                        layer::Candidates::Overflow => {
                            unreachable!("a buffer of CANDIDATE_ROOM never overflows")
                        }
                    }
                }
            };
            if let Some(c) = done {
                let c = c.unwrap_or(self.expected_coverage);
                out[k] = c as f32;
                best = best.max(c);
                continue;
            }
            order[pending] = k as u8;
            pending += 1;
        }
        // Pass 2: exact areas, largest bound first.
        let order = &mut order[..pending];
        order.sort_unstable_by(|&i, &j| bound[j as usize].total_cmp(&bound[i as usize]));
        for &k in order.iter() {
            let k = k as usize;
            if bound[k] < best - TIE {
                break;
            }
            let (start, end) = (kept[k].0 as usize, kept[k].1 as usize);
            let c = if end > start {
                match self.layers[k].coverage_reaching(
                    p,
                    a,
                    b,
                    &pool[start..end],
                    bound_area[k],
                    best - TIE,
                ) {
                    Some(c) => c,
                    None => continue, // below the best: not a tie
                }
            } else {
                let mut centres = [glam::DVec2::ZERO; layer::CANDIDATE_ROOM];
                self.layers[k]
                    .footprint_coverage_in(p, a, b, max_cells, &mut centres)
                    .unwrap_or(self.expected_coverage)
            };
            out[k] = c as f32;
            best = best.max(c);
        }
        // Values computed before `best` settled may lie below it: not ties, so cleared.
        for c in out.iter_mut() {
            if (*c as f64) < best - TIE {
                *c = 0.0;
            }
        }
    }

    /// Every scratch of every layer whose ellipse reaches the texture-space box `[lo, hi]`,
    /// layer by layer, each once: the one enumeration of the scratches as objects (explicit
    /// geometry, METHOD.md 8.3). A scratch is one feature point's ellipse `F1 < tau`
    /// (section 5; where two of a layer's ellipses overlap, the layer's scratch is their
    /// union, as `F1 < tau` is).
    pub fn scratches(&self, lo: glam::DVec2, hi: glam::DVec2) -> Vec<Scratch> {
        let mut out = Vec::new();
        for layer in &self.layers {
            let (a, b) = layer.half_axes();
            // Noise-space box of the texture box, grown by the ellipse's reach (tau cells).
            let corners = [
                lo,
                glam::DVec2::new(hi.x, lo.y),
                hi,
                glam::DVec2::new(lo.x, hi.y),
            ]
            .map(|p| layer.to_noise(p));
            let tau = layer.threshold();
            let qlo = corners.iter().fold(glam::DVec2::INFINITY, |m, &q| m.min(q)) - tau;
            let qhi = corners
                .iter()
                .fold(glam::DVec2::NEG_INFINITY, |m, &q| m.max(q))
                + tau;
            let d = glam::DVec2::from(layer.direction());
            // The ellipse's half extents along u and v.
            let reach = glam::DVec2::new((a * d.x).hypot(b * d.y), (a * d.y).hypot(b * d.x));
            for j in worley::floor_i64(qlo.y)..=worley::floor_i64(qhi.y) {
                for i in worley::floor_i64(qlo.x)..=worley::floor_i64(qhi.x) {
                    let s = layer.scratch(layer.noise().feature_point(i, j));
                    if (s.centre + reach).cmpge(lo).all() && (s.centre - reach).cmple(hi).all() {
                        out.push(s);
                    }
                }
            }
        }
        out
    }

    /// Rasterise layer `k` at `res x res` (see [`raster`]).
    pub fn rasterize(&self, k: usize, res: usize) -> Result<CoverageRaster, LayerError> {
        raster::rasterize(self.layer(k)?, res)
    }
}

#[cfg(test)]
mod tests;
