//! The scratched material at render time (METHOD.md sections 5-6, `docs/scratched.md`): a
//! smooth glass or metal base, a scratch layer set (section 5, evaluated procedurally) and a
//! shared scratch BRDF table (sections 3-4), combined at a hit as section 6 prescribes. Its
//! scene-file description and preparation are `scene::scratches`.
//!
//! At a hit ([`ScratchedMaterial::bsdf`]): every layer's coverage of the pixel footprint
//! (`uv` and `ShadingContext::footprint_uv`; exact, [`crate::layers`]); in `max` mode (section
//! 6) the layer with the largest coverage, one chosen by `ShadingContext::u_layer` among ties
//! (where several scratches cross); in `sum` mode ([Raymond16]) every layer with some coverage
//! (at most [`MAX_SCRATCH_LOBES`], the largest). The scratch frame's `t` is the layer's texture
//! direction `d` carried to 3D by `d.x dP/du + d.y dP/dv` and projected into the shading plane.
//! Where no layer covers the footprint the BSDF is the base itself, at no extra cost; glass seen
//! from inside skips the layer queries (its scratches are on the outer side, `bsdf::scratched`).
//! Curves (METHOD.md 9.1, [`crate::curves`]) and a painted map (9.5, [`crate::maps`]) add
//! candidate lobes beside the layers', which `layer_mix` combines alike ([`ScratchedMaterial::bsdf`]);
//! on glass with dielectric walls a curve's lobe at a footprint's hit sends its paths on from
//! the curve itself ([`curve_spawn`]).

use crate::curves::{CurveHits, CurveSet};
use crate::layers::cache::PixelKey;
use crate::layers::lattice::TileQuery;
use crate::layers::layer::MAX_FOOTPRINT_CELLS;
use crate::layers::{CoverageCache, LayerSet, Orientation, Scratch, MAX_LAYERS};
use crate::maps::{DirectionFrame, ScratchMap};
use crate::math::{Rgb, Vec3};
use crate::precompute::groove::totally_reflected;
use crate::render::bsdf::scratched::MAX_SCRATCH_LOBES;
use crate::render::bsdf::{
    Bsdf, Conductor, Dielectric, GlassWalls, GrooveBelow, GroovePlace, LobeShare, ScratchLobe,
    ScratchLobeTable, ScratchedBase, ScratchedBsdf, ScratchedGlassBsdf, ScratchedMetalBsdf,
    WallLobeTable,
};
use crate::render::shading::ShadingContext;
use lean::Along;
use serde::Deserialize;
use std::sync::Arc;

/// How the layers covering one footprint combine.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum LayerMix {
    /// The layer with the largest coverage (METHOD.md section 6, the seed).
    #[default]
    Max,
    /// `(1 - sum c_k) f_base + sum c_k f_scratch,k` over every layer ([Raymond16]).
    Sum,
    /// As `Sum`, with the coverages scaled to add up to the union's, `1 - prod(1 - c_k)`
    /// (exact for independent layers): `max` takes one layer's share of a footprint that holds
    /// scratches of several, `sum` counts their overlaps twice (`docs/fidelity.md`).
    Union,
    /// `union` in expectation at one lobe's cost: a single lobe a hit, of the union's coverage
    /// `1 - prod(1 - c_k)`, its layer (curve, map) drawn by `ShadingContext::u_layer` with
    /// probability `c_k / sum c_k` (stochastic layer selection; the default under
    /// `model = "default"`).
    Stochastic,
}

/// How a hit measures the layers' scratch coverage.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum CoverageMode {
    /// The exact share of the pixel footprint (the hit's `uv` and
    /// `ShadingContext::footprint_uv`) each layer's scratches cover (METHOD.md section 6,
    /// [Raymond16]): at hits reached from the camera by delta
    /// bounces only (the camera ray's first hit, surfaces seen through the glass or in a
    /// mirror), of the footprint centred on the pixel centre's ray, computed once per pixel and
    /// chain of bounces ([`LayerSet::coverage_of_pixel`]); at other hits, with the footprint
    /// snapped to the footprint-shaped tile that holds the hit and cached per tile
    /// ([`crate::layers::lattice`]).
    #[default]
    Footprint,
    /// The same exact coverage, of the footprint centred on each sample: no snapping, no
    /// reuse (several microseconds per hit where a pixel spans many scratches).
    Sample,
    /// The scratch test at the hit point only (`c` is 0 or 1 per layer). The camera ray's hit
    /// is uniformly distributed over the pixel's footprint, so averaging a pixel's samples
    /// estimates the same coverage without bias in `sum` mode (in `max` mode a footprint
    /// covered by several layers counts once per layer it picks, not the largest share).
    Point,
}

/// The scratch model and its shared table.
#[derive(Clone, Debug)]
pub enum ScratchModel {
    /// The seed's (METHOD.md sections 3-6): the scratch BRDF replaces the base's reflection.
    Seed(Arc<ScratchLobeTable>),
    /// Dielectric walls (METHOD.md 8.1-8.2, glass only): the groove's four lobes, reflected
    /// and transmitted from either side ([`ScratchedGlassBsdf`]).
    DielectricWalls(GlassWalls),
    /// Rough specular walls (METHOD.md 8.1, metal only): the seed's metal with its groove lobe
    /// read from a 4D table of GGX-rough conductor walls ([`ScratchedMetalBsdf`]).
    SpecularWalls(Arc<WallLobeTable>),
}

impl ScratchModel {
    /// The groove's cross-section.
    pub fn profile(&self) -> &crate::precompute::profile::Profile {
        match self {
            ScratchModel::Seed(t) => &t.table().params.profile,
            ScratchModel::DielectricWalls(w) => w.profile(),
            ScratchModel::SpecularWalls(t) => t.profile(),
        }
    }

    /// The table's parameter hash.
    pub fn hash(&self) -> &str {
        match self {
            ScratchModel::Seed(t) => t.hash(),
            ScratchModel::DielectricWalls(w) => w.hash(),
            ScratchModel::SpecularWalls(t) => t.hash(),
        }
    }
}

/// A prepared scratched material: the base, the shared table, the layer set.
#[derive(Clone)]
pub struct ScratchedMaterial {
    pub base: ScratchedBase,
    /// RGB factor on the scratch lobe (metal: the base's colour; glass: 1).
    pub tint: Rgb,
    pub model: ScratchModel,
    pub layers: LayerSet,
    /// Scratches as curves (METHOD.md 9.1, [`crate::curves`]), beside the layers or alone.
    pub curves: Option<Arc<CurveSet>>,
    /// A painted scratch map (METHOD.md 9.5, [`crate::maps`]) and its lobes' depth ratio, beside
    /// the layers and curves or alone ([`Self::with_map`]).
    pub map: Option<Arc<ScratchMap>>,
    map_depth: f32,
    /// The model at depth ratios below 1, ascending, for worn curves ([`Self::with_worn`]).
    worn: Vec<(f32, ScratchModel)>,
    /// Each layer's scratch direction `d_k` in texture space ([`LayerSet::direction`]), as `f32`,
    /// computed once here rather than with a `sin_cos` per hit.
    directions: Vec<[f32; 2]>,
    pub mix: LayerMix,
    pub coverage: CoverageMode,
    /// `lean = true`: twice the profile's cross-section area ([`Self::with_lean`]); 0 without.
    lean: f64,
    /// Crossing scratches traced through their union ([`Self::with_crossings`]).
    crossings: bool,
}

impl std::fmt::Debug for ScratchedMaterial {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScratchedMaterial")
            .field("base", &self.base)
            .field("table", &self.model.hash())
            .field("layers", &self.layers.len())
            .field("mix", &self.mix)
            .field("coverage", &self.coverage)
            .finish()
    }
}

impl ScratchedMaterial {
    pub fn new(
        base: ScratchedBase,
        tint: Rgb,
        table: Arc<ScratchLobeTable>,
        layers: LayerSet,
        mix: LayerMix,
        coverage: CoverageMode,
    ) -> ScratchedMaterial {
        Self::with_model(base, tint, ScratchModel::Seed(table), layers, mix, coverage)
    }

    /// A material of any [`ScratchModel`] (dielectric walls: `base` must be glass; specular
    /// walls: metal).
    pub fn with_model(
        base: ScratchedBase,
        tint: Rgb,
        model: ScratchModel,
        layers: LayerSet,
        mix: LayerMix,
        coverage: CoverageMode,
    ) -> ScratchedMaterial {
        let directions = (0..layers.len())
            .map(|k| layers.direction(k).map(|x| x as f32))
            .collect();
        ScratchedMaterial {
            base,
            tint,
            model,
            layers,
            curves: None,
            map: None,
            map_depth: 1.0,
            worn: Vec::new(),
            directions,
            mix,
            coverage,
            lean: 0.0,
            crossings: false,
        }
    }

    /// The same material with `crossings` on or off (METHOD.md 8.3, "Ours": crossings): with
    /// traced glass walls (`lobes = "traced"`) and `layer_mix` `stochastic` or `union`, a hit
    /// that two scratches cover ([`crossing_partner`]) traces the union of their grooves
    /// ([`crate::precompute::crossing`]) instead of one groove alone. Other models have no
    /// crossings.
    pub fn with_crossings(mut self, on: bool) -> Self {
        let traced = matches!(
            self.model,
            ScratchModel::DielectricWalls(GlassWalls::Traced(_))
        );
        self.crossings = on && traced;
        self
    }

    /// The same material with the scratch curves `curves` beside its layers (METHOD.md 9.1):
    /// at a hit each curve that covers the footprint is one more candidate lobe, along the
    /// tangent of one of its segments there, and `layer_mix` combines curves and layers
    /// alike ([`Self::bsdf`]).
    pub fn with_curves(mut self, curves: Option<Arc<CurveSet>>) -> Self {
        self.curves = curves;
        self
    }

    /// The same material with the painted scratch map `map` beside its layers and curves
    /// (METHOD.md 9.5), its lobes of depth ratio `depth` (in `(0, 1]`; below 1 they read the worn
    /// tables, [`Self::with_worn`]): at a hit the map is one more candidate lobe, its coverage
    /// the map's filtered fraction over the footprint and its direction drawn from the filtered
    /// orientation ([`crate::maps::MapSample::draw_direction`]); `layer_mix` combines it with
    /// layers and curves alike ([`Self::bsdf`]). A map knows no crossings: one lobe at most.
    pub fn with_map(mut self, map: Option<Arc<ScratchMap>>, depth: f32) -> Self {
        self.map = map;
        self.map_depth = depth;
        self
    }

    /// The same material with the models of its profile worn to the depth ratios `worn`
    /// (`(d, model)`, `0 < d < 1`, any order): a curve's lobe of depth ratio `d` reads the
    /// tables around `d`, stochastically interpolated ([`Self::model_at_depth`], METHOD.md
    /// 9.2).
    pub fn with_worn(mut self, mut worn: Vec<(f32, ScratchModel)>) -> Self {
        worn.sort_by(|a, b| a.0.total_cmp(&b.0));
        self.worn = worn;
        self
    }

    /// Whether its lobes lean ([`Self::with_lean`]).
    pub fn has_lean(&self) -> bool {
        self.lean != 0.0
    }

    /// The same material with `lean = true` (an option of ours beside METHOD.md 8.3's
    /// explicit grooves): the scratch frame at a hit tilted along the scratch as the walls of
    /// its tapered groove lean there. A groove whose width `W(s) = 2 w sqrt(1 - (s/l)^2)`
    /// shrinks toward its tips, its depth in proportion, leans its walls toward its middle by
    /// `tan alpha = 2 A |W'(s)|` (`A` the profile's [`crate::precompute::profile::Profile::area`]): exactly
    /// for a V, whose walls all lean alike, and on average over the opening for other
    /// profiles; traced glass walls lean each wall by its own lean instead, the frame
    /// unturned. The seed's extruded groove has no lean.
    pub fn with_lean(mut self, on: bool) -> Self {
        self.lean = if on {
            2.0 * self.model.profile().area()
        } else {
            0.0
        };
        self
    }

    /// Whether its BSDF transmits, at every hit: glass does (scratched or not, from either
    /// side), metal does not.
    #[inline]
    pub fn has_transmission(&self) -> bool {
        matches!(self.base, ScratchedBase::Glass { .. })
    }

    /// The smooth base's BSDF.
    #[inline]
    pub fn base_bsdf(&self) -> Bsdf<'static> {
        match self.base {
            ScratchedBase::Glass { eta } => Bsdf::Dielectric(Dielectric::new(eta)),
            ScratchedBase::Metal { ior } => Bsdf::Conductor(Conductor { ior }),
        }
    }

    /// Whether [`Self::bsdf`] reads the pixel footprint: every coverage mode but `point`.
    pub fn reads_footprint(&self) -> bool {
        self.coverage != CoverageMode::Point
    }

    /// Whether [`Self::bsdf`] reads the hit's footprint and `u_layer` for `wo` (world, toward
    /// the viewer) and the geometric normal `ng`: not for glass seen from inside (its smooth
    /// base).
    #[inline]
    pub fn reads_hit_context(&self, wo: Vec3, ng: Vec3) -> bool {
        !self.seen_from_inside(wo, ng)
    }

    /// Whether [`Self::bsdf`] reads the hit's footprint (and its pixel) for `wo` and `ng` as
    /// [`Self::reads_hit_context`]: where it reads the context at all, except glass with
    /// dielectric walls seen from inside, whose hits take the point test
    /// ([`Self::ridge_lobe`]) and read only `u_layer`.
    #[inline]
    pub fn reads_footprint_at(&self, wo: Vec3, ng: Vec3) -> bool {
        let inside_walls = matches!(self.model, ScratchModel::DielectricWalls(_))
            && matches!(self.base, ScratchedBase::Glass { .. })
            && wo.dot(ng) <= 0.0;
        self.reads_footprint() && !inside_walls
    }

    /// Whether lobes seen from inside carry the hit's place across their groove
    /// ([`ScratchLobe::place`]): traced glass walls, whose paths enter there and surface
    /// beside the opening ([`crate::precompute::groove::GroovePaths::trace`]).
    #[inline(always)]
    fn places_lobes(&self) -> bool {
        matches!(
            (&self.model, self.base),
            (
                ScratchModel::DielectricWalls(GlassWalls::Traced(_)),
                ScratchedBase::Glass { .. }
            )
        )
    }

    /// Whether a curve's lobe at this hit sends its paths on from the covering curve
    /// ([`curve_spawn`]): glass with dielectric walls seen from outside, its coverage a
    /// footprint's share (`coverage` other than `"point"`), where the hit mostly lies beside the
    /// scratch. Light a groove sends into the glass is not independent of that groove (trapped
    /// light running along a line meets it again from inside), so it goes on from where the
    /// point test's hit would lie: with it, footprint coverage renders the oblique line pairs
    /// as the point test does (docs/fidelity.md, "Crossings").
    #[inline]
    fn spawns_on_curves(&self, ctx: &ShadingContext) -> bool {
        self.coverage != CoverageMode::Point
            && matches!(
                (&self.model, self.base),
                (
                    ScratchModel::DielectricWalls(_),
                    ScratchedBase::Glass { .. }
                )
            )
            && ctx.wo.dot(ctx.ng) > 0.0
    }

    /// Glass seen from inside under the seed's model, which has no scratches there
    /// (`bsdf::scratched`); dielectric walls scatter from both sides.
    #[inline]
    fn seen_from_inside(&self, wo: Vec3, ng: Vec3) -> bool {
        matches!(self.base, ScratchedBase::Glass { .. })
            && matches!(self.model, ScratchModel::Seed(_))
            && wo.dot(ng) <= 0.0
    }

    /// The BSDF at a hit (see the module notes), with the render worker's coverage caches.
    #[inline(always)]
    pub fn bsdf(&self, ctx: &ShadingContext, cache: &mut CoverageCache) -> Bsdf<'_> {
        if self.seen_from_inside(ctx.wo, ctx.ng) {
            return self.base_bsdf();
        }
        let k = self.layers.len();
        let mut cov = [0.0f32; MAX_LAYERS];
        let inside = ctx.wo.dot(ctx.ng) <= 0.0;
        // Dielectric walls seen from inside: the point tests, then the ridges (METHOD.md 8.1).
        let walls_inside = match (&self.model, self.base) {
            (ScratchModel::DielectricWalls(walls), ScratchedBase::Glass { .. }) if inside => {
                Some(walls)
            }
            _ => None,
        };
        let covered = match walls_inside {
            _ if k == 0 => false,
            Some(_) => self.point_coverage(ctx.uv, &mut cov[..k]),
            None => self.layer_coverage(ctx, cache, &mut cov[..k]),
        };
        let curves = match &self.curves {
            Some(c) => self.curve_hits(c, ctx, cache, inside),
            None => CurveHits::new(),
        };
        let map = match &self.map {
            Some(m) => self.map_hit(m, ctx, cache, inside),
            None => None,
        };
        if !covered && curves.is_empty() && map.is_none() {
            if let Some((lobe, depth)) = walls_inside.and_then(|w| self.ridge_lobe(ctx, w)) {
                let model = self.model_at_depth(depth, ctx.u_layer);
                return self.with_lobes_at(ctx, model, &[lobe], LobeShare::default());
            }
            return self.base_bsdf();
        }
        let mut lobes = [ScratchLobe::default(); MAX_SCRATCH_LOBES];
        let (count, depth, share) = self.choose_lobes(ctx, &cov[..k], &curves, map, &mut lobes);
        if count == 0 {
            return self.base_bsdf();
        }
        self.with_lobes_at(
            ctx,
            self.model_at_depth(depth, ctx.u_layer),
            &lobes[..count],
            share,
        )
    }

    /// The curves at the hit (METHOD.md 9.1): the point test from inside dielectric-walled
    /// glass and under `coverage = "point"`; else the exact coverage of the pixel's footprint
    /// where the hit is reached from the camera by delta bounces (`coverage = "footprint"`,
    /// shared by the pixel's samples, [`CoverageCache::curves_of_pixel`]), of the footprint's tile at
    /// other hits (cached per tile, [`CoverageCache::curves_tiled`]), of the sample's own
    /// footprint under `coverage = "sample"` ([`CurveSet::footprint`]).
    #[inline(always)]
    fn curve_hits(
        &self,
        curves: &CurveSet,
        ctx: &ShadingContext,
        cache: &mut CoverageCache,
        inside: bool,
    ) -> CurveHits {
        let uv = ctx.uv.as_dvec2();
        if inside || self.coverage == CoverageMode::Point {
            return curves.at_point(uv);
        }
        let u = ctx.u_layer as f64;
        match ctx.pixel {
            Some(hit) if self.coverage == CoverageMode::Footprint => cache.curves_of_pixel(
                curves,
                ctx.uv,
                || ctx.footprint_uv(),
                PixelKey {
                    shape: hit.shape,
                    chain: hit.chain,
                },
                hit.offset,
                u,
            ),
            _ => {
                let (a, b) = ctx.footprint_uv();
                if self.coverage == CoverageMode::Footprint {
                    cache.curves_tiled(curves, ctx.uv, a, b, u)
                } else {
                    curves.footprint(uv, a.as_dvec2(), b.as_dvec2(), u)
                }
            }
        }
    }

    /// The painted map at the hit (METHOD.md 9.5): its prefiltered value over the sample's own
    /// footprint centred on the hit, trilinear ([`ScratchMap::filtered`]), its edges the
    /// pixel's first sample's at hits reached from the camera by delta bounces under
    /// `coverage = "footprint"` ([`CoverageCache::map_footprint`]), else the sample's own
    /// (`ShadingContext::footprint_uv`); at the hit point (the finest level) from inside
    /// dielectric-walled glass and under `coverage = "point"`; `None` where the map holds no
    /// scratch there. Not the pixel centre's footprint, as the layers' and curves' exact
    /// coverage is: the samples' hits spread over the pixel, so a pixel averages the map's
    /// filter over its footprint, and the pixels' sum keeps the map's integral whatever the
    /// filter's width against the pixel spacing (the filter sampled at the pixel centres
    /// alone aliases by up to 10 %). Its direction is drawn by a hash of `u_layer`
    /// ([`crate::maps::MapSample::draw_direction`]) and given in texture space.
    #[inline(always)]
    fn map_hit(
        &self,
        map: &ScratchMap,
        ctx: &ShadingContext,
        cache: &mut CoverageCache,
        inside: bool,
    ) -> Option<MapHit> {
        let s = if inside || self.coverage == CoverageMode::Point {
            map.at_point(ctx.uv)
        } else {
            let (a, b) = match ctx.pixel {
                Some(hit) if self.coverage == CoverageMode::Footprint => cache.map_footprint(
                    PixelKey {
                        shape: hit.shape,
                        chain: hit.chain,
                    },
                    || ctx.footprint_uv(),
                ),
                _ => ctx.footprint_uv(),
            };
            map.filtered(ctx.uv, a, b)
        };
        // (`MapSample::coverage` is never NaN.)
        if s.coverage <= 0.0 {
            return None;
        }
        // A second uniform from `u_layer`, independent of the layers' pick.
        let v = rehashed(ctx.u_layer, 0x6d61_7073);
        let d = s.draw_direction(v);
        let d = match map.frame() {
            DirectionFrame::Uv => d,
            // The flow map's unit tangents in texture space: `dP/du / |dP/du|` is `u / |dP/du|`.
            DirectionFrame::Tangent => {
                let (lu, lv) = (ctx.dpdu.length(), ctx.dpdv.length());
                if lu > 0.0 && lv > 0.0 && (lu * lv).is_finite() {
                    crate::math::Vec2::new(d.x / lu, d.y / lv)
                } else {
                    d
                }
            }
        };
        Some(MapHit {
            coverage: s.coverage,
            direction: [d.x, d.y],
        })
    }

    /// The lobes of a hit, from the layers' coverages `cov`, the curves `curves` and the map's
    /// lobe `map` covering it, which `layer_mix` treats alike (METHOD.md sections 6, 9.1, 9.5): `max` takes the largest
    /// coverage, one of the ties chosen by `ctx.u_layer` (several scratches crossing the
    /// footprint equally); `sum` ([Raymond16]) a lobe for each, the [`MAX_SCRATCH_LOBES`]
    /// largest where more cover the hit; `union` the same, scaled to the union's coverage
    /// ([`union_scale`]); `stochastic` one of them drawn in proportion to its coverage, with the
    /// union's. Returns the lobes' count (0 where nothing covers the hit), the depth ratio
    /// their BSDF reads (METHOD.md 9.2: the chosen curve's (or the map's) in `max` and
    /// `stochastic`, the largest covering curve's (else the map's) in `sum` and `union`, 1 for
    /// layers) and where `stochastic`'s pick lies within `ctx.u_layer` ([`LobeShare`]).
    #[inline(always)]
    fn choose_lobes(
        &self,
        ctx: &ShadingContext,
        cov: &[f32],
        curves: &CurveHits,
        map: Option<MapHit>,
        lobes: &mut [ScratchLobe; MAX_SCRATCH_LOBES],
    ) -> (usize, f32, LobeShare) {
        let whole = LobeShare::default();
        let placed = inside_placed(self, ctx);
        let spawns = self.spawns_on_curves(ctx);
        let curve_lobe = |i: usize, c: f32| match curves[i].axis.filter(|_| placed) {
            Some(a) => {
                let d = (a.end - a.start).as_vec2();
                let place = TangentMap::new(ctx).segment_place(&a, ctx.uv.as_dvec2());
                lobe_along(ctx, [d.x, d.y], c).at_place(place)
            }
            None => {
                let d = curves[i].direction;
                let lobe = lobe_along(ctx, [d.x as f32, d.y as f32], c);
                match self.curves.as_ref().filter(|_| spawns) {
                    Some(set) => lobe.spawned_at(curve_spawn(set, curves[i].curve, ctx)),
                    None => lobe,
                }
            }
        };
        if self.mix == LayerMix::Max {
            // (`curves` come largest first.)
            let first = curves.first().map_or(0.0, |h| h.coverage as f32);
            let mut best = cov.iter().copied().fold(first, f32::max);
            if let Some(m) = map {
                best = best.max(m.coverage);
            }
            if best <= 0.0 {
                // (`best` is never NaN: `f32::max` drops NaN.)
                return (0, 1.0, whole);
            }
            // `c > 0`: with a tiny best (a disc grazing the footprint) an uncovered layer must
            // not count as a tie. The layers' ties as a bit mask (one pass, no branch per
            // layer), the pick as its `pick`-th set bit.
            const _: () = assert!(MAX_LAYERS <= 64);
            let tie = |c: f32| (c > 0.0) & (c >= best - 1e-6);
            let layer_ties = cov
                .iter()
                .enumerate()
                .fold(0u64, |m, (i, &c)| m | (tie(c) as u64) << i);
            let nl = layer_ties.count_ones();
            let nc = curves.iter().take_while(|h| tie(h.coverage as f32)).count() as u32;
            let nm = map.is_some_and(|m| tie(m.coverage)) as u32;
            let n = nl + nc + nm;
            let pick = ((ctx.u_layer * n as f32) as u32).min(n - 1);
            // `u_layer`'s place within the pick's share, for the lean.
            let u = (ctx.u_layer * n as f32 - pick as f32).clamp(0.0, 1.0);
            if pick < nl {
                let mut rest = layer_ties;
                for _ in 0..pick {
                    rest &= rest - 1;
                }
                let layer = rest.trailing_zeros() as usize;
                lobes[0] = lobe(self, ctx, layer, cov[layer], u);
                return (1, 1.0, whole);
            }
            if let Some(m) = map.filter(|_| pick == nl + nc) {
                lobes[0] = lobe_along(ctx, m.direction, m.coverage);
                return (1, self.map_depth, whole);
            }
            let i = (pick - nl) as usize;
            lobes[0] = curve_lobe(i, curves[i].coverage as f32);
            return (1, curves[i].depth, whole);
        }
        // Sum, union and stochastic: every covering layer and curve (a curve as
        // `MAX_LAYERS + i`) and the map (as `MAP_SLOT`).
        const MAP_SLOT: usize = MAX_LAYERS + crate::curves::MAX_CURVE_HITS;
        const ALL: usize = MAP_SLOT + 1;
        let mut all = arrayvec::ArrayVec::<(f32, usize), ALL>::new();
        all.extend(
            cov.iter()
                .enumerate()
                .filter(|(_, &c)| c > 0.0)
                .map(|(i, &c)| (c, i)),
        );
        all.extend(
            curves
                .iter()
                .enumerate()
                .map(|(i, h)| (h.coverage as f32, MAX_LAYERS + i)),
        );
        if let Some(m) = map {
            all.push((m.coverage, MAP_SLOT));
        }
        // The lobe of slot `i` with coverage `c` (`u` places a layer's lean).
        let slot_lobe = |i: usize, c: f32, u: f32| {
            if i < MAX_LAYERS {
                lobe(self, ctx, i, c, u)
            } else if i == MAP_SLOT {
                lobe_along(ctx, map.map_or([1.0, 0.0], |m| m.direction), c)
            } else {
                curve_lobe(i - MAX_LAYERS, c)
            }
        };
        let scale = if self.mix == LayerMix::Sum {
            1.0
        } else {
            let c: arrayvec::ArrayVec<f32, ALL> = all.iter().map(|x| x.0).collect();
            union_scale(&c)
        };
        if self.mix == LayerMix::Stochastic {
            // One candidate drawn in proportion to its coverage, with the union's coverage:
            // the expected BSDF is `union`'s (`sum_k (c_k / sum) (scale sum) f_k`).
            let sum: f32 = all.iter().map(|x| x.0).sum();
            if all.is_empty() || sum.is_nan() || sum <= 0.0 {
                return (0, 1.0, whole);
            }
            let target = ctx.u_layer * sum;
            let mut below = 0.0;
            let mut chosen = all[all.len() - 1];
            for &(c, i) in &all[..all.len() - 1] {
                if target < below + c {
                    chosen = (c, i);
                    break;
                }
                below += c;
            }
            let (c, i) = chosen;
            let share = LobeShare::new(below / sum, c / sum);
            // The lean's place along the scratch: another uniform from `u_layer`, since the
            // BSDF's sampling reads the place within the share.
            lobes[0] = slot_lobe(i, scale * sum, rehashed(ctx.u_layer, 0x6c65_616e));
            if self.crossings {
                if let Some((cj, j)) = crossing_partner(&all, i, ctx.u_layer) {
                    lobes[0] = lobes[0].crossed_by(&slot_lobe(j, cj, ctx.u_layer));
                }
            }
            let depth = if i < MAX_LAYERS {
                1.0
            } else if i == MAP_SLOT {
                self.map_depth
            } else {
                curves[i - MAX_LAYERS].depth
            };
            return (1, depth, share);
        }
        if all.len() > MAX_SCRATCH_LOBES {
            all.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        }
        let n = all.len().min(MAX_SCRATCH_LOBES);
        for (l, &(c, i)) in lobes.iter_mut().zip(&all[..n]) {
            *l = slot_lobe(i, c * scale, ctx.u_layer);
        }
        let odds = (self.crossings && self.mix == LayerMix::Union)
            .then(|| crossing_odds(&all[..n]))
            .flatten();
        if let Some(odds) = odds {
            // Each lobe's partner among the others, by a uniform of its own.
            let built = *lobes;
            for (k, &(_, i)) in all[..n].iter().enumerate() {
                let u = rehashed(ctx.u_layer, k as u64);
                if let Some((_, j)) = partner_given(&all[..n], i, odds, u) {
                    let other = all[..n].iter().position(|x| x.1 == j).unwrap_or(k);
                    lobes[k] = built[k].crossed_by(&built[other]);
                }
            }
        }
        let depth = all[..n]
            .iter()
            .find(|x| x.1 >= MAX_LAYERS && x.1 != MAP_SLOT)
            .map(|x| curves[x.1 - MAX_LAYERS].depth)
            .or_else(|| {
                all[..n]
                    .iter()
                    .any(|x| x.1 == MAP_SLOT)
                    .then_some(self.map_depth)
            })
            .unwrap_or(1.0);
        (n, depth, whole)
    }

    /// The model a lobe of depth ratio `depth` reads (METHOD.md 9.2, wear): between the two
    /// tables of depth ratios around it ([`Self::with_worn`]), the deeper with probability
    /// in proportion to how close `depth` lies to it (so that over samples the lobe is the
    /// linear interpolation of the two), drawn by a hash of `u`'s bits; below the shallowest
    /// table, that table.
    #[inline(always)]
    fn model_at_depth(&self, depth: f32, u: f32) -> &ScratchModel {
        if depth >= 1.0 || self.worn.is_empty() {
            return &self.model;
        }
        let level = |i: usize| match self.worn.get(i) {
            Some((d, m)) => (*d, m),
            None => (1.0, &self.model),
        };
        let i = self.worn.iter().take_while(|(d, _)| *d <= depth).count();
        if i == 0 {
            return &self.worn[0].1;
        }
        let ((d0, m0), (d1, m1)) = (level(i - 1), level(i));
        // A second uniform from `u`, independent of what `u` stratifies.
        let v = rehashed(u, 0);
        if v * (d1 - d0) < depth - d0 {
            m1
        } else {
            m0
        }
    }

    /// The scratched BSDF of `model` (the material's, or a worn one) with `lobes` at the hit
    /// `ctx`.
    #[inline(always)]
    fn with_lobes_at<'a>(
        &'a self,
        ctx: &ShadingContext,
        model: &'a ScratchModel,
        lobes: &[ScratchLobe],
        share: LobeShare,
    ) -> Bsdf<'a> {
        let table = match model {
            ScratchModel::Seed(table) => table,
            ScratchModel::DielectricWalls(walls) => {
                let ScratchedBase::Glass { eta } = self.base else {
                    return self.base_bsdf();
                };
                return Bsdf::ScratchedGlass(
                    ScratchedGlassBsdf::new(eta, walls, lobes).in_share(share),
                );
            }
            ScratchModel::SpecularWalls(walls) => {
                let ScratchedBase::Metal { ior } = self.base else {
                    return self.base_bsdf();
                };
                let b = ScratchedMetalBsdf::new(ior, self.tint, walls, lobes).in_share(share);
                return Bsdf::ScratchedMetal(b);
            }
        };
        // The integrator evaluates and samples it with `wo` in this frame: precompute the
        // first lobe's `wo` terms once (`ScratchedBsdf::at_wo`; the same results bit for bit).
        Bsdf::Scratched(
            ScratchedBsdf::new(self.base, table, self.tint, lobes)
                .in_share(share)
                .at_wo(ctx.frame.to_local(ctx.wo)),
        )
    }

    /// A hit from inside dielectric-walled glass (METHOD.md 8.1) that no opening holds: the
    /// groove whose ridge the light met on its way, as a lobe of coverage 1 and the depth ratio
    /// of its model. Inside hits take the point test ([`CoverageMode::Point`] for layers,
    /// [`CurveSet::at_point`], the map's finest level), whatever the material's mode: they lie
    /// behind a refraction, where the camera's footprint says little and the seed's model has
    /// no scratches at all, and a path through a plate makes many of them; the point test
    /// estimates the same pixel average without bias (`sum`/`union`) at a fraction of the
    /// footprint's cost (BENCHMARKS.md, "Dielectric walls over the seed's model"). Seen from
    /// inside, a groove is a ridge of air below the surface, and light arriving at a grazing
    /// angle meets it beside its opening (the table's inside lobes are per unit of that
    /// intercepted light, [`crate::precompute::wall_table`]). The ray back along `wo` passes
    /// under the surface within the grooves' depth over the horizontal reach `R = D tan theta`
    /// (the deepest groove's `D`), and under total internal reflection the ray on from the
    /// hit, mirrored, over as much again past it ([`RidgeReach::reflected`]). Over that
    /// segment, one capsule test ([`LayerSet::capsule_mask`]) finds the layers whose scratches
    /// come within reach (most hits none) and the curves' grid the thick segments whose bounds
    /// it meets ([`CurveSet::for_segments_along`]); each is met against the groove's
    /// cross-section, the profile scaled to the local width ([`RidgeReach::meets_ridge`],
    /// [`RidgeReach::meets_segment`]), first on the way to the hit, then on the way back. The
    /// first groove met scatters with coverage 1, as the point test's covered hits do.
    /// Randomly oriented layers are searched by point tests along the segment, spaced half the
    /// narrowest groove's width: a ridge where a scratch tapers narrower is missed (about 2 %
    /// of them at 85 degrees). A painted map has no grooves to meet beside their openings.
    #[inline(always)]
    fn ridge_lobe(&self, ctx: &ShadingContext, walls: &GlassWalls) -> Option<(ScratchLobe, f32)> {
        if self.layers.is_empty() && self.curves.is_none() {
            return None;
        }
        let wo = ctx.frame.to_local(ctx.wo).as_dvec3();
        let r = RidgeReach::new(self, ctx, walls, wo, 0.0, ctx.origin_depth as f64)?;
        let uv = ctx.uv.as_dvec2();
        let profile = walls.profile();
        // Under total internal reflection the ray's reach continues past the hit, mirrored.
        let reflected =
            totally_reflected(r.wo.to_array(), walls.ior() as f64).then(|| r.reflected());
        let maybe = match reflected {
            _ if self.layers.is_empty() => 0,
            Some(_) => self.layers.capsule_mask(uv - r.reach_uv, 2.0 * r.reach_uv),
            None => self.layers.capsule_mask(uv, r.reach_uv),
        };
        let placed = self.places_lobes();
        let met = |reach: &RidgeReach| self.groove_met(ctx, reach, uv, maybe, placed, profile);
        met(&r).or_else(|| reflected.and_then(|m| met(&m)))
    }

    /// The first groove that the line from texture point `uv` over the reach `r` meets beside
    /// its opening, the layers' in `maybe` ([`Self::ridge_met`]) before the curves'
    /// ([`RidgeReach::meets_segment`]): its lobe with coverage 1 (`placed`: at its place where
    /// the line crosses the surface) and its depth ratio.
    #[inline(always)]
    fn groove_met(
        &self,
        ctx: &ShadingContext,
        r: &RidgeReach,
        uv: glam::DVec2,
        maybe: u64,
        placed: bool,
        profile: &crate::precompute::profile::Profile,
    ) -> Option<(ScratchLobe, f32)> {
        let layer = || {
            let sc = self.ridge_met(r, uv, maybe, profile)?;
            let lobe = scratch_lobe(self, ctx, &sc, 1.0, Along::Hit);
            let place = placed.then(|| r.map.scratch_place(&sc, uv)).flatten();
            Some((lobe.at_place(place), 1.0))
        };
        let curve = || {
            let mut met = None;
            self.curves
                .as_ref()?
                .for_segments_along(uv, uv + r.reach_uv, |axis| {
                    let hit = r.meets_segment(axis, uv, profile);
                    if hit {
                        met = Some(*axis);
                    }
                    hit
                });
            met.map(|a| {
                let d = (a.end - a.start).as_vec2();
                let place = placed.then(|| r.map.segment_place(&a, uv)).flatten();
                (lobe_along(ctx, [d.x, d.y], 1.0).at_place(place), a.depth)
            })
        };
        layer().or_else(curve)
    }

    /// The groove that light a traced groove seen from inside sends down into the glass meets
    /// next (METHOD.md 8.1, "Ours": light between grooves): it left the wall at `from` below the surface
    /// (shading frame, relative to the hit `ctx`) along `wi` (shading frame, `wi.z < 0`), and at
    /// a grazing angle it runs under the surface within the grooves' depth for a while, where
    /// another groove's walls may lie across its way. The search is the ridge search of a hit
    /// from inside ([`Self::ridge_lobe`]) over the line's stretch deeper than `from`, from where
    /// the line crosses the surface; the groove met is traced from `from` on
    /// ([`GrooveBelow::sample`]). `u` draws a curve's worn table ([`Self::model_at_depth`]).
    /// `None` where the line meets no groove, or the material's walls are not traced.
    #[inline]
    pub fn groove_below(
        &self,
        ctx: &ShadingContext,
        from: Vec3,
        wi: Vec3,
        u: f32,
    ) -> Option<GrooveBelow<'_>> {
        let ScratchModel::DielectricWalls(walls @ GlassWalls::Traced(_)) = &self.model else {
            return None;
        };
        if !(from.z < 0.0 && wi.z < 0.0) || (self.layers.is_empty() && self.curves.is_none()) {
            return None;
        }
        // Not the wall the light left: only the line's stretch a little deeper than it.
        let depth = -from.z as f64 * (1.0 + DEPARTURE_MARGIN);
        let r = RidgeReach::new(self, ctx, walls, wi.as_dvec3(), depth, f64::INFINITY)?;
        // Where the line crosses the surface, up its ray behind `from`.
        let surface = from - wi * (from.z / wi.z);
        let uv = ctx.uv.as_dvec2()
            + r.map
                .unmap(glam::DVec2::new(surface.x as f64, surface.y as f64));
        let maybe = if self.layers.is_empty() {
            0
        } else {
            self.layers.capsule_mask(uv, r.reach_uv)
        };
        let (lobe, depth_ratio) = self.groove_met(ctx, &r, uv, maybe, true, walls.profile())?;
        let ScratchModel::DielectricWalls(GlassWalls::Traced(groove)) =
            self.model_at_depth(depth_ratio, u)
        else {
            return None;
        };
        lobe.place.map(|_| GrooveBelow {
            groove,
            lobe,
            depth: -from.z,
            surface,
        })
    }

    /// The first scratch of the layers in `maybe` whose groove the reach `r` from `uv` meets
    /// beside its opening ([`RidgeReach::meets_ridge`]).
    #[inline(always)]
    fn ridge_met(
        &self,
        r: &RidgeReach,
        uv: glam::DVec2,
        maybe: u64,
        profile: &crate::precompute::profile::Profile,
    ) -> Option<Scratch> {
        if maybe == 0 {
            return None;
        }
        let mut met = None;
        if self.layers.orientation() == Orientation::Random {
            for j in 1..=r.tests {
                let q = uv + r.reach_uv * (j as f64 / r.tests as f64);
                let mask = self.layers.scratched_mask(q.as_vec2());
                for k in (0..self.layers.len()).filter(|k| mask >> k & 1 == 1) {
                    if let Some(sc) = self.layers.scratch_at(k, q) {
                        if r.meets_ridge(&sc, uv, profile) {
                            return Some(sc);
                        }
                    }
                }
            }
        } else {
            for k in (0..self.layers.len()).filter(|k| maybe >> k & 1 == 1) {
                let found = self
                    .layers
                    .find_scratch_near_segment(k, uv, r.reach_uv, |sc| {
                        let hit = r.meets_ridge(sc, uv, profile);
                        if hit {
                            met = Some(*sc);
                        }
                        hit
                    });
                if found {
                    break;
                }
            }
        }
        met
    }

    /// Each layer's coverage at the hit into `cov`, as the material's [`CoverageMode`] asks;
    /// `false` where the point test finds no scratch.
    #[inline(always)]
    fn layer_coverage(
        &self,
        ctx: &ShadingContext,
        cache: &mut CoverageCache,
        cov: &mut [f32],
    ) -> bool {
        let query = match self.mix {
            LayerMix::Max => TileQuery::Max,
            LayerMix::Sum | LayerMix::Union | LayerMix::Stochastic => TileQuery::All,
        };
        match self.coverage {
            CoverageMode::Footprint => match ctx.pixel {
                Some(hit) => cache.of_pixel(
                    &self.layers,
                    ctx.uv,
                    || ctx.footprint_uv(),
                    PixelKey {
                        shape: hit.shape,
                        chain: hit.chain,
                    },
                    hit.offset,
                    query,
                    cov,
                ),
                None => {
                    let (duvdx, duvdy) = ctx.footprint_uv();
                    cache.tiled(&self.layers, ctx.uv, duvdx, duvdy, query, cov)
                }
            },
            CoverageMode::Sample => {
                let (duvdx, duvdy) = ctx.footprint_uv();
                self.layers
                    .coverage_query(query, ctx.uv, duvdx, duvdy, MAX_FOOTPRINT_CELLS, cov)
            }
            CoverageMode::Point => return self.point_coverage(ctx.uv, cov),
        }
        true
    }

    /// [`CoverageMode::Point`]: 1 in `cov` for each layer scratched at `uv`, 0 for the others;
    /// `false`, `cov` untouched, where none is.
    #[inline(always)]
    fn point_coverage(&self, uv: crate::math::Vec2, cov: &mut [f32]) -> bool {
        let mask = self.layers.scratched_mask(uv);
        if mask == 0 {
            return false;
        }
        for (i, c) in cov.iter_mut().enumerate() {
            *c = ((mask >> i) & 1) as f32;
        }
        true
    }
}

/// At a hit in the scratch of slot `i` among the candidates `all` (`(coverage, slot)`), the
/// scratch that crosses it there, if one does (METHOD.md 8.3, "Ours": crossings): with the
/// chance that a covered point lies in two or more scratches, `1 - P_1 / C` (`C = 1 - prod(1 -
/// c_k)` the union's coverage, `P_1 = sum_k c_k prod_(j != k) (1 - c_j)` the chance of exactly
/// one, layers independent), one of the others drawn in proportion to its coverage; both draws
/// are uniforms hashed from `u`. At a point test's hit (`c` 0 or 1) it is exact: a partner
/// wherever two scratches cover the point. Returns the partner's coverage and slot.
#[inline]
fn crossing_partner(all: &[(f32, usize)], i: usize, u: f32) -> Option<(f32, usize)> {
    partner_given(all, i, crossing_odds(all)?, u)
}

/// `(C, P_1)` of the candidates `all` ([`crossing_partner`]); `None` where fewer than two
/// could cross or nothing covers.
#[inline]
fn crossing_odds(all: &[(f32, usize)]) -> Option<(f32, f32)> {
    if all.len() < 2 {
        return None;
    }
    // `prod(1 - c_j)` over the candidates not certain to cover, how many are, and `sum c_j /
    // (1 - c_j)` over the others: `P_1` in one pass.
    let (mut open, mut certain, mut odds) = (1.0f32, 0, 0.0f32);
    for x in all {
        let c = x.0.clamp(0.0, 1.0);
        if c >= 1.0 {
            certain += 1;
        } else {
            open *= 1.0 - c;
            odds += c / (1.0 - c);
        }
    }
    let (union, one) = match certain {
        0 => (1.0 - open, open * odds),
        1 => (1.0, open),
        _ => (1.0, 0.0),
    };
    (union > 0.0).then_some((union, one))
}

/// [`crossing_partner`] with the candidates' `(C, P_1)` known.
#[inline]
fn partner_given(
    all: &[(f32, usize)],
    i: usize,
    (union, one): (f32, f32),
    u: f32,
) -> Option<(f32, usize)> {
    if rehashed(u, 0x6372_6f73) * union >= union - one {
        return None;
    }
    let c = |x: &(f32, usize)| x.0.clamp(0.0, 1.0);
    let others = all.iter().filter(|x| x.1 != i);
    let mut target = rehashed(u, 0x7061_7274) * others.clone().map(c).sum::<f32>();
    // (Round-off can leave `target` past the last: the last then.)
    for x in others {
        if target < c(x) {
            return Some(*x);
        }
        target -= c(x);
    }
    all.iter().rev().find(|x| x.1 != i).copied()
}

/// The factor that takes the coverages `cov` to add up to their union's coverage
/// `1 - prod(1 - c_k)` (layers independent), `<= 1`; 1 where nothing is covered.
pub fn union_scale(cov: &[f32]) -> f32 {
    let sum: f32 = cov.iter().sum();
    if sum <= 0.0 || sum.is_nan() {
        return 1.0;
    }
    let uncovered: f32 = cov.iter().map(|c| 1.0 - c.clamp(0.0, 1.0)).product();
    ((1.0 - uncovered) / sum).min(1.0)
}

/// The painted map's candidate lobe at a hit ([`ScratchedMaterial::map_hit`]).
#[derive(Clone, Copy, Debug)]
struct MapHit {
    /// The filtered scratched fraction, in `(0, 1]`.
    coverage: f32,
    /// The direction in texture space (carried to 3D by [`lobe_along`]).
    direction: [f32; 2],
}

/// Where a ray's reach crosses a groove's axis ([`RidgeReach::axis_crossing`]), tangent-plane
/// units: how far along the axis from its given point, the axis vector's length there, the
/// hit's offset across it (the profile's `x`) and `wo`'s part across.
struct AxisCrossing {
    along: f64,
    axis_len: f64,
    offset: f64,
    dx: f64,
}

/// The share of its depth below the wall light left that the search for the groove it meets
/// next leaves out ([`ScratchedMaterial::groove_below`]): the wall it left lies there, its
/// width at the search's crossing a rounding away from the width it was traced at.
const DEPARTURE_MARGIN: f64 = 0.01;

/// The most points the search of randomly oriented layers tests along a ray's reach: enough
/// for a groove of depth 0.3 (in opening widths) up to 84 degrees from the normal.
const MAX_RIDGE_TESTS: usize = 16;

/// The face's texture-to-tangent-plane map `A = [a_u a_v]` at a hit (the shading frame's `s`
/// and `t` axes) and its determinant.
#[derive(Clone, Copy)]
struct TangentMap {
    au: glam::DVec2,
    av: glam::DVec2,
    det: f64,
}

/// Where a point lies against a groove's axis, tangent-plane units: how far along the axis
/// from the axis's given point, its offset across (the scratch frame's `x`, `b = t x n`,
/// METHOD.md section 1, the profile's), and the axis vector's length.
struct AxisPlace {
    along: f64,
    offset: f64,
    axis_len: f64,
}

impl TangentMap {
    #[inline(always)]
    fn new(ctx: &ShadingContext) -> Self {
        let (s, t) = (ctx.frame.s, ctx.frame.t);
        let tangent = |v: Vec3| glam::DVec2::new(v.dot(s) as f64, v.dot(t) as f64);
        let (au, av) = (tangent(ctx.dpdu), tangent(ctx.dpdv));
        TangentMap {
            au,
            av,
            det: au.perp_dot(av),
        }
    }

    #[inline(always)]
    fn map(&self, v: glam::DVec2) -> glam::DVec2 {
        self.au * v.x + self.av * v.y
    }

    /// The texture vector that [`Self::map`] takes to the tangent-plane vector `v`.
    #[inline(always)]
    fn unmap(&self, v: glam::DVec2) -> glam::DVec2 {
        glam::DVec2::new(v.perp_dot(self.av), self.au.perp_dot(v)) / self.det
    }

    /// An axis along texture vector `e`: its unit direction and across axis in the tangent
    /// plane and `|A e|`; `None` where `e` maps to nothing.
    #[inline(always)]
    fn axis(&self, e: glam::DVec2) -> Option<(glam::DVec2, glam::DVec2, f64)> {
        let d = self.map(e);
        let axis_len = d.length();
        if axis_len.is_nan() || axis_len <= 0.0 {
            return None;
        }
        let along = d / axis_len;
        Some((along, -along.perp(), axis_len))
    }

    /// Where texture point `uv` lies against the axis through `p` along `e`.
    #[inline(always)]
    fn place_of(&self, p: glam::DVec2, e: glam::DVec2, uv: glam::DVec2) -> Option<AxisPlace> {
        let (along, across, axis_len) = self.axis(e)?;
        let v = self.map(uv - p);
        Some(AxisPlace {
            along: v.dot(along),
            offset: v.dot(across),
            axis_len,
        })
    }

    /// Layer scratch `sc`'s groove at texture point `uv`: where it lies across the groove and
    /// the width there, as the explicit geometry carves it (tapered, METHOD.md 8.3).
    #[inline(always)]
    fn scratch_place(&self, sc: &Scratch, uv: glam::DVec2) -> Option<GroovePlace> {
        let a = self.place_of(sc.centre, sc.direction, uv)?;
        groove_place(a.offset, self.scratch_half_width(sc, a.along, a.axis_len))
    }

    /// A curve's thick segment `a` at texture point `uv` (its width linear between its ends).
    #[inline(always)]
    fn segment_place(
        &self,
        a: &crate::curves::SegmentAxis,
        uv: glam::DVec2,
    ) -> Option<GroovePlace> {
        let p = self.place_of(a.start, a.end - a.start, uv)?;
        let s = (p.along / p.axis_len).clamp(0.0, 1.0);
        groove_place(p.offset, self.segment_half_width(a, s, p.axis_len))
    }

    /// Layer scratch `sc`'s half-width (tangent-plane units) `along` its axis from its centre,
    /// the axis vector `axis_len` long there: tapered as the explicit geometry carves it
    /// (METHOD.md 8.3); NaN beyond its ends.
    #[inline(always)]
    fn scratch_half_width(&self, sc: &Scratch, along: f64, axis_len: f64) -> f64 {
        let s = along / (sc.half_length * axis_len);
        sc.mapped_half_axes(axis_len, self.det.abs()).1 * (1.0 - s * s).sqrt()
    }

    /// A curve's thick segment `a`'s half-width at `s` in `[0, 1]` along it (linear between
    /// its ends): a texture width `h` across the axis maps to `h |det A| |e| / |A e|` (`e` the
    /// axis, `|A e| = axis_len`).
    #[inline(always)]
    fn segment_half_width(&self, a: &crate::curves::SegmentAxis, s: f64, axis_len: f64) -> f64 {
        a.half_width_at(s) * self.det.abs() * (a.end - a.start).length() / axis_len
    }
}

/// The place `offset` across a groove of half-width `half_width` (tangent-plane units); `None`
/// for a degenerate width.
#[inline(always)]
fn groove_place(offset: f64, half_width: f64) -> Option<GroovePlace> {
    let width = 2.0 * half_width;
    (width > 0.0 && width.is_finite()).then(|| GroovePlace {
        at: (offset / width) as f32,
        width: width as f32,
    })
}

/// A line down from a point of the surface into the glass, in the face's tangent plane, over
/// the reach where it passes under the surface within the grooves' depth: the ray back from a
/// hit inside the glass (no deeper than where the ray began,
/// [`ShadingContext::origin_depth`]), or the light a groove sends down from below the surface
/// (no shallower than the wall it left, [`ScratchedMaterial::groove_below`]).
#[derive(Clone, Copy)]
struct RidgeReach {
    /// The line's direction in the shading frame (`z < 0`).
    wo: glam::DVec3,
    map: TangentMap,
    /// The reach as a texture vector, and how many point tests span it (random layers).
    reach_uv: glam::DVec2,
    tests: usize,
    /// The stretch of the line that light runs, as depths below the surface (world units).
    min_depth: f64,
    max_depth: f64,
}

impl RidgeReach {
    /// The line along `wo` (shading frame) over the depths `min_depth..max_depth`; `None`
    /// where no groove can be met beside its opening: light from outside, or steeper than the
    /// profile's rims let it reach a wall (`GlassWalls::ridge_tan`).
    #[inline(always)]
    fn new(
        m: &ScratchedMaterial,
        ctx: &ShadingContext,
        walls: &GlassWalls,
        wo: glam::DVec3,
        min_depth: f64,
        max_depth: f64,
    ) -> Option<Self> {
        use glam::DVec2;
        let h_len = (wo.x * wo.x + wo.y * wo.y).sqrt();
        let tan = h_len / -wo.z;
        let grazing = wo.z < 0.0 && tan > walls.ridge_tan();
        if !grazing {
            return None;
        }
        let map = TangentMap::new(ctx);
        let (au, av, det) = (map.au, map.av, map.det);
        // World half-widths lie within `w sigma_min .. w sigma_max` (`A`'s singular values).
        let (e, f, g) = (au.length_squared(), au.dot(av), av.length_squared());
        let spread = ((0.5 * (e - g)).powi(2) + f * f).sqrt();
        let sigma_max = (0.5 * (e + g) + spread).sqrt();
        if !(det.abs() > 1e-30 && sigma_max.is_finite()) {
            return None;
        }
        let sigma_min = det.abs() / sigma_max;
        // Every layer of a set has the same scratch width; the curves' widest sets their reach.
        let w_layers = m.layers.layers().first().map_or(0.0, |l| l.half_axes().1);
        let w_curves = m.curves.as_ref().map_or(0.0, |c| c.max_half_width());
        let w = w_layers.max(w_curves);
        let reach = walls.profile().depth() * 2.0 * w * sigma_max * tan;
        let v = DVec2::new(wo.x, wo.y) * (reach / h_len);
        let reach_uv = map.unmap(v);
        let narrowest = if w_layers > 0.0 { w_layers } else { w };
        let tests = ((reach / (narrowest * sigma_min)).ceil() as usize).clamp(1, MAX_RIDGE_TESTS);
        Some(RidgeReach {
            wo,
            map,
            reach_uv,
            tests,
            min_depth,
            max_depth,
        })
    }

    /// The same reach after the flat surface's mirror reflection at the hit: the ray on from
    /// the hit, `wo`'s tangent part reversed, as deep as the grooves.
    fn reflected(&self) -> Self {
        RidgeReach {
            wo: glam::DVec3::new(-self.wo.x, -self.wo.y, self.wo.z),
            reach_uv: -self.reach_uv,
            max_depth: f64::INFINITY,
            ..*self
        }
    }

    /// Whether the ray from texture point `uv` meets scratch `sc`'s groove beside its opening:
    /// in the tangent plane, the groove's cross-section where the ray's reach crosses the
    /// scratch's axis (the scratch's local width there, as the explicit geometry carves it,
    /// METHOD.md 8.3) met by the ray's projection across the scratch.
    #[inline(always)]
    fn meets_ridge(
        &self,
        sc: &Scratch,
        uv: glam::DVec2,
        profile: &crate::precompute::profile::Profile,
    ) -> bool {
        let Some(c) = self.axis_crossing(sc.centre, sc.direction, uv) else {
            return false;
        };
        let half_width = self.map.scratch_half_width(sc, c.along, c.axis_len);
        self.meets_section(c.offset, c.dx, half_width, 1.0, profile)
    }

    /// [`Self::meets_ridge`] for a curve's thick segment `a` (METHOD.md 9.1): its groove's
    /// cross-section where the reach crosses the segment's axis, of the half-width there
    /// (linear between its ends) and depth ratio `a.depth`; `false` where the crossing lies
    /// off the segment (its neighbours hold it).
    #[inline(always)]
    fn meets_segment(
        &self,
        a: &crate::curves::SegmentAxis,
        uv: glam::DVec2,
        profile: &crate::precompute::profile::Profile,
    ) -> bool {
        let Some(c) = self.axis_crossing(a.start, a.end - a.start, uv) else {
            return false;
        };
        let s = c.along / c.axis_len;
        if !(0.0..=1.0).contains(&s) {
            return false;
        }
        let half_width = self.map.segment_half_width(a, s, c.axis_len);
        self.meets_section(c.offset, c.dx, half_width, a.depth as f64, profile)
    }

    /// Where the reach from texture point `uv` crosses the axis through texture point `p`
    /// along texture vector `e`, in the tangent plane ([`AxisCrossing`]); `None` where the
    /// ray runs away from the axis (it cannot meet the groove: most of the grooves near the
    /// reach lie behind it) or `e` maps to nothing.
    #[inline(always)]
    fn axis_crossing(
        &self,
        p: glam::DVec2,
        e: glam::DVec2,
        uv: glam::DVec2,
    ) -> Option<AxisCrossing> {
        let (along, across, axis_len) = self.map.axis(e)?;
        let point = self.map.map(p - uv);
        let dx = glam::DVec2::new(self.wo.x, self.wo.y).dot(across);
        if point.dot(across) * dx <= 0.0 {
            return None;
        }
        let reach = self.map.map(self.reach_uv);
        let t = (point.dot(across) / reach.dot(across)).clamp(0.0, 1.0);
        let t = if t.is_finite() { t } else { 0.0 };
        Some(AxisCrossing {
            along: (reach * t - point).dot(along),
            axis_len,
            offset: -point.dot(across),
            dx,
        })
    }

    /// Whether the ray back along `wo` from a hit `offset` across a groove's axis (tangent
    /// plane units, `dx` its direction's part across), beside the opening of half-width
    /// `half_width` and depth ratio `depth` (the profile's depth scaled by it), meets its walls.
    #[inline(always)]
    fn meets_section(
        &self,
        offset: f64,
        dx: f64,
        half_width: f64,
        depth: f64,
        profile: &crate::precompute::profile::Profile,
    ) -> bool {
        if !(half_width > 0.0 && depth > 0.0) {
            return false;
        }
        let x = offset / (2.0 * half_width);
        // A groove `depth` times as deep meets the ray `wo.z / depth` steep in the profile's
        // units, and the ray's beginning lies that much shallower in them.
        let units = 2.0 * half_width * depth;
        let (min_depth, max_depth) = (self.min_depth / units, self.max_depth / units);
        x.abs() >= 0.5
            && profile.ray_meets_ridge_between(x, dx, self.wo.z / depth, min_depth, max_depth)
    }
}

/// Scratch lobe of `layer` with coverage `c` ([`lobe_along`] its direction at the hit; with
/// `lean`, [`scratch_lobe`] of the scratch at the hit, `u` uniform in `[0, 1)` placing it).
fn lobe(p: &ScratchedMaterial, ctx: &ShadingContext, layer: usize, c: f32, u: f32) -> ScratchLobe {
    let placed = inside_placed(p, ctx);
    if p.has_lean() || placed {
        let uv = ctx.uv.as_dvec2();
        // (A placed hit is the point test's: a scratch covers it.)
        let sc = placed
            .then(|| p.layers.scratch_covering(layer, uv))
            .flatten();
        if let Some(sc) = sc.or_else(|| p.layers.scratch_at(layer, uv)) {
            let along = if p.coverage == CoverageMode::Point || placed {
                Along::Hit
            } else {
                Along::Footprint(u)
            };
            let lobe = scratch_lobe(p, ctx, &sc, c, along);
            let place = placed.then(|| TangentMap::new(ctx).scratch_place(&sc, uv));
            return lobe.at_place(place.flatten());
        }
    }
    let d = if p.layers.orientation() == Orientation::Random {
        // The scratch at the hit point (or nearest to it): the hit is spread uniformly over the
        // footprint, so each scratch of the footprint is chosen in proportion to its share.
        p.layers.direction_at(layer, ctx.uv).map(|x| x as f32)
    } else {
        p.directions[layer]
    };
    lobe_along(ctx, d, c)
}

/// Whether the lobes at `ctx` carry the hit's place across their groove
/// ([`ScratchedMaterial::places_lobes`], seen from inside).
#[inline(always)]
fn inside_placed(p: &ScratchedMaterial, ctx: &ShadingContext) -> bool {
    p.places_lobes() && ctx.wo.dot(ctx.ng) <= 0.0
}

/// Where the lobe of curve `curve`, covering the footprint of the hit `ctx`, sends its paths on
/// from ([`ScratchLobe::spawn`]): the curve's point nearest to the hit within the footprint's
/// reach ([`CurveSet::nearest_point`]), moved across its opening by a uniform hashed from
/// `ctx.u_layer`, as an offset in the shading plane; zero (the hit) where no segment of the
/// curve comes within reach.
fn curve_spawn(set: &CurveSet, curve: u32, ctx: &ShadingContext) -> [f32; 2] {
    let (a, b) = ctx.footprint_uv();
    let reach = (a.abs() + b.abs()).as_dvec2();
    let uv = ctx.uv.as_dvec2();
    let across = 2.0 * rehashed(ctx.u_layer, 0x7370_6177) as f64 - 1.0;
    match set.nearest_point(curve, uv, reach, across) {
        Some(q) => {
            let offset = TangentMap::new(ctx).map(q - uv).as_vec2();
            if offset.is_finite() {
                offset.to_array()
            } else {
                [0.0; 2]
            }
        }
        None => [0.0; 2],
    }
}

/// Scratch `sc`'s lobe with coverage `c`: along its direction, and where the material asks it,
/// leaned as the tapered groove's walls lean where `along` places it ([`lean::leaned`]).
fn scratch_lobe(
    p: &ScratchedMaterial,
    ctx: &ShadingContext,
    sc: &Scratch,
    c: f32,
    along: Along,
) -> ScratchLobe {
    let d = sc.direction.as_vec2();
    let lobe = lobe_along(ctx, [d.x, d.y], c);
    if p.has_lean() {
        lean::leaned(lobe, p.lean, ctx, sc, along)
    } else {
        lobe
    }
}

/// Scratch lobe of texture direction `d` with coverage `c`: `t = d.x dP/du + d.y dP/dv` in the
/// shading plane, as `(cos beta, sin beta)` against the frame's `s` axis (METHOD.md section 1).
#[inline(always)]
fn lobe_along(ctx: &ShadingContext, d: [f32; 2], c: f32) -> ScratchLobe {
    let t: Vec3 = ctx.dpdu * d[0] + ctx.dpdv * d[1];
    let (x, y) = (t.dot(ctx.frame.s), t.dot(ctx.frame.t));
    let len = (x * x + y * y).sqrt();
    let (cos, sin) = if len > 1e-20 && len.is_finite() {
        (x / len, y / len)
    } else {
        (1.0, 0.0)
    };
    ScratchLobe::new(c, cos, sin)
}

/// A uniform in `[0, 1)` hashed from `u`'s bits and `salt`: a further number from one already
/// drawn, independent of what `u` itself decides.
#[inline(always)]
fn rehashed(u: f32, salt: u64) -> f32 {
    crate::hash::unit_f32(crate::hash::mix64(u.to_bits() as u64 ^ salt))
}

mod lean;

#[cfg(test)]
mod tests;
