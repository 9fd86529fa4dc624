//! The scratched material as a scene file describes it (`type = "scratched"`, METHOD.md
//! sections 5-7, `docs/scratched.md`): its keys, their validation and defaults
//! ([`ScratchedDesc::resolve`]), and its preparation into the runtime
//! [`ScratchedMaterial`] (table obtained through [`crate::render::cache`], layers drawn).
//!
//! ```toml
//! [materials.glass]
//! type = "scratched"
//! base = "glass"                 # or "metal" (with preset = "gold", or eta and k)
//! ior = 1.5                      # glass only
//! [materials.glass.scratches]
//! model = "default"              # the defaults of the keys left out: "default" (striae's,
//!                                # docs/fidelity.md "The defaults") or "seed" (the seed's)
//! profile = "v:angle=90"         # the syntax of `striae precompute --profile`
//! walls = "diffuse"              # "specular" = mirror walls, [Raymond16]'s delta lobe;
//!                                # "dielectric" = glass walls, reflecting and transmitting
//!                                # from both sides (METHOD.md 8.1-8.2, glass only)
//! # roughness = 0.2              # GGX alpha of dielectric walls, or of a metal's specular
//!                                # walls (default 0: smooth)
//! # lobes = "table"              # smooth dielectric walls: read a precomputed table instead
//!                                # of tracing the exact groove at every sample (default
//!                                # "traced"; rough walls always read a table)
//! fresnel = "seed"               # or "walls" (default with groove_slices)
//! fresnel_law = "schlick"        # dielectric | conductor:ETA,K | none
//! m = 64                         # table size M, N, N_r (default with exact-groove slices
//! n = 50000                      # 64, 50000, 1; else, and under model = "seed", the
//! nr = 1                         # seed's 256, 10000, 100, `TraceSettings::default`)
//! groove_slices = 6              # exact-groove theta_i slices instead of eq. (3) (glass with
//!                                # diffuse walls and Fresnel: default 6; model = "seed": none)
//! setting = 1                    # the seed's Table 1, or length / width / threshold
//! layers = 8
//! seed = 1
//! layer_mix = "stochastic"       # or "union", "sum" ([Raymond16]), "max" (the seed's)
//! # table = "my-table.npz"       # load a table instead of computing one
//! # explicit = true              # real grooves on planar faces (METHOD.md 8.3)
//! # stations = 16                # stations along each explicit groove
//! # curves = "marks.svg"         # every stroked path a scratch (METHOD.md 9.1, `crate::curves`)
//! # pattern = { kind = "swirl", count = 300, radius = [0.05, 0.3], width = 4e-4 }
//! # polylines = [{ points = [[0.1, 0.2], [0.5, 0.3]], width = 4e-4 }]   # inline, in uv
//! # taper = 0.01                 # curves: taper length at each end (uv; SVG: canvas units)
//! # dashes = [0.004, 0.002]      # curves: on, off lengths (as stroke-dasharray)
//! # depth = 1.0                  # curves: depth ratio over the profile's, (0, 1]
//! # wear = 0.5                   # curves: the most of the depth wear takes, with
//! # wear_length = 0.02           # its correlation length along the scratch
//! # map = "wear.png"             # a painted scratch map: each texel the scratched fraction
//!                                # (METHOD.md 9.5, `crate::maps`)
//! # direction = "flow.png"       # its flow map (RG: direction = 2 rg - 1); default: the
//!                                # map's structure tensor
//! # map_scale = 1.0              # uv tiling of the map and its flow map
//! ```
//!
//! With `curves`, `pattern`, `polylines` or `map` and none of the layer keys (`setting`,
//! `length`, `width`, `threshold`, `layers`), the material has the curves and map only; with
//! both, both.

use super::materials::{conductor_ior, invalid, MaterialError};
use crate::curves::patterns::Pattern;
use crate::curves::stroke::StrokeStyle;
use crate::curves::{CurveError, CurveSet, Polyline};
use crate::layers::{LayerError, LayerParams, LayerSet, Orientation, MAX_LAYERS};
use crate::maps::{MapError, ScratchMap};
use crate::math::Rgb;
use crate::optics::fresnel::FresnelLaw;
use crate::precompute::profile::Profile;
use crate::precompute::table::{TableError, TableParams};
use crate::precompute::trace2d::{FresnelMode, TraceError, TraceSettings, Walls};
use crate::precompute::wall_table::{WallKind, WallTableParams};
use crate::render::bsdf::GrooveWall;
use crate::render::bsdf::{
    ConductorIor, DielectricCompensation, GlassWalls, ScratchedBase, TracedGroove,
};
use crate::render::geometry::carve::{DEFAULT_STATIONS, STATIONS_RANGE};
use crate::render::material::Material;
use crate::render::scratched::{CoverageMode, LayerMix, ScratchModel, ScratchedMaterial};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The smooth base under the scratches.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum BaseKind {
    /// A smooth dielectric (`ior`, default 1.5, the seed's glass).
    Glass,
    /// A smooth conductor (`preset`, or `eta` and `k`).
    Metal,
}

/// Default profile: a 90-degree V groove.
pub const DEFAULT_PROFILE: &str = "v:angle=90";
/// Default layer-set seed.
pub const DEFAULT_LAYER_SEED: u64 = 1;

/// Depth ratios of the worn tables a material with worn curves computes besides its own (1):
/// a lobe between two reads both, interpolated; below the first, the first (METHOD.md 9.2).
pub const WEAR_LEVELS: [f64; 3] = [0.25, 0.5, 0.75];

/// `model = "default"`: exact-groove slices of a table with diffuse walls and a Fresnel law
/// (docs/fidelity.md, "The defaults").
pub const DEFAULT_GROOVE_SLICES: usize = 6;
/// `model = "default"`: a table with exact-groove slices defaults to `M = 64`, `N = 50000`,
/// `N_r = 1` (50 000 goniometer paths per slice and `phi_i`, the sizes docs/fidelity.md
/// validates; the seed's sizes would trace 100 times as many, minutes on 2 cores).
pub const GROOVE_TABLE_SIZES: (usize, usize, usize) = (64, 50_000, 1);

/// `scratches.model`: which defaults fill the keys a scene leaves out. A key given explicitly
/// always wins.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ModelKey {
    /// striae's defaults: per key the most accurate validated choice that costs under about
    /// 10 % a sample (docs/fidelity.md, "The defaults"): glass with diffuse walls and a
    /// Fresnel law takes `groove_slices = 6` (with `fresnel = "walls"`) at
    /// [`GROOVE_TABLE_SIZES`]; layers combine by `layer_mix = "stochastic"` (curves or a map
    /// alone by `"union"`); every other key the seed's (`lean` and dielectric walls cost
    /// 1.2-1.7 x: they stay options).
    #[default]
    Default,
    /// The seed's choices (METHOD.md sections 3-6; a metal base [Raymond16]'s): no
    /// exact-groove slices (eq. (3)), glass `fresnel = "seed"`, the seed's `M`, `N`, `N_r`,
    /// `layer_mix = "max"`, and, as under `default`, `coverage = "footprint"`, `orientation =
    /// "layer"`, no `lean`.
    Seed,
}

/// `[materials.NAME.scratches]`. Every key is optional; the defaults depend on the base
/// (see [`ScratchedDesc::resolve`] and `docs/scratched.md`).
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScratchSpec {
    /// Which defaults fill the keys left out ([`ModelKey`]; default `default`).
    #[serde(default)]
    pub model: Option<ModelKey>,
    /// Profile spec, as `striae precompute --profile` (`file:` paths are relative to the scene).
    pub profile: Option<String>,
    /// Wall micro-BRDF: glass default `diffuse` (the seed), metal `specular` ([Raymond16]);
    /// `dielectric`: the groove's own glass (METHOD.md 8.1-8.2).
    #[serde(default)]
    pub walls: Option<WallsKey>,
    /// GGX `alpha` of dielectric walls, or of a metal's specular walls, in `[0, 1]` (default
    /// 0: smooth; the metal's mirror walls then keep the seed's 2D table).
    pub roughness: Option<f64>,
    /// Where Fresnel is applied: glass default `seed` (`walls` with exact-groove slices),
    /// metal `walls`.
    #[serde(default)]
    pub fresnel: Option<FresnelMode>,
    /// `schlick`, `dielectric`, `conductor:ETA,K` or `none`; glass default `schlick`, metal the
    /// base's complex IOR in its brightest channel (`none` for a perfect mirror base).
    pub fresnel_law: Option<String>,
    /// Index for `schlick` / `dielectric` (default: the glass base's `ior`, else 1.5).
    pub ior: Option<f64>,
    pub m: Option<usize>,
    pub n: Option<usize>,
    pub nr: Option<usize>,
    /// Facet albedo per bounce (default 1).
    pub albedo: Option<f64>,
    pub max_bounces: Option<usize>,
    /// Seed of the 2D trace (default 0).
    pub trace_seed: Option<u64>,
    /// Exact-groove `theta_i` slices (`crate::precompute::groove_slices`, 1 to 32) evaluated instead of
    /// eq. (3); diffuse walls, `fresnel` then defaults to (and must be) `walls`. Default
    /// [`DEFAULT_GROOVE_SLICES`] where they apply (glass, diffuse walls, a Fresnel law other
    /// than `none`, `fresnel` not `seed`, `albedo` 1), none under `model = "seed"`.
    pub groove_slices: Option<usize>,
    /// The seed's Table 1 (1 or 2); excludes `length`, `width`, `threshold`.
    pub setting: Option<u32>,
    pub length: Option<f64>,
    pub width: Option<f64>,
    pub threshold: Option<f64>,
    /// Number of layers `K` (default 8).
    pub layers: Option<usize>,
    /// Seed of the layer set (default 1).
    pub seed: Option<u64>,
    /// `layer` (default, the seed: a direction per layer) or `random` (a direction per scratch).
    #[serde(default)]
    pub orientation: Option<Orientation>,
    /// `stochastic` (default; curves or a map alone: `union`), `union`, `sum` or `max` (the
    /// seed's section 6, default under `model = "seed"`) ([`LayerMix`]).
    #[serde(default)]
    pub layer_mix: Option<LayerMix>,
    /// `footprint` (default, section 6) or `point` (see [`CoverageMode`]).
    #[serde(default)]
    pub coverage: Option<CoverageMode>,
    /// A table file (`.npz`, relative to the scene file) to load instead of computing one;
    /// excludes the table keys above.
    pub table: Option<PathBuf>,
    /// Smooth dielectric walls: `traced` (default: no table, each groove sample traces one
    /// path through the exact groove) or `table` (the precomputed lobes).
    #[serde(default)]
    pub lobes: Option<LobesKey>,
    /// Build the scratches as real grooves on the shape's planar faces instead of the
    /// SV-BRDF (METHOD.md 8.3; `scene::explicit`).
    pub explicit: Option<bool>,
    /// Lean the SV-BRDF's scratch frame along the scratch as the tapered groove's walls lean
    /// (default `false`, the seed's extruded groove; [`ScratchedMaterial::with_lean`]).
    /// Explicit grooves have the lean of their geometry whatever this says.
    pub lean: Option<bool>,
    /// Trace the union of two crossing grooves where two scratches cover a hit (traced glass
    /// walls under `layer_mix` `stochastic` or `union`; METHOD.md 8.3, "Ours": crossings).
    /// Default `true` under `model = "default"`, `false` under `"seed"`.
    pub crossings: Option<bool>,
    /// Stations along each explicit groove (default [`DEFAULT_STATIONS`]): its opening is the
    /// polygon through them (`geometry::carve`). The SV-BRDF does not read it.
    pub stations: Option<usize>,
    /// An SVG drawing (relative to the scene file) whose stroked paths are scratches
    /// (METHOD.md 9.1, [`crate::curves::svg`]).
    pub curves: Option<PathBuf>,
    /// Generated curves: swirls or concentric circles ([`Pattern`]).
    pub pattern: Option<Pattern>,
    /// Curves given inline, in uv: `[{ points = [[u, v], ...], width = W }]` (the stroke keys
    /// apply), or with `widths` (and `depths`) at each point (the stroke keys do not).
    pub polylines: Option<Vec<PolylineSpec>>,
    /// The curves' stroke ([`StrokeStyle`]): taper length at each end, dash pattern and
    /// offset, depth ratio, wear and its correlation length (drawing units: uv for a
    /// pattern, canvas units for an SVG).
    pub taper: Option<f64>,
    pub dashes: Option<Vec<f64>>,
    pub dash_offset: Option<f64>,
    pub depth: Option<f64>,
    pub wear: Option<f64>,
    pub wear_length: Option<f64>,
    /// A painted scratch map (METHOD.md 9.5, [`crate::maps`]; relative to the scene file): a
    /// PNG (8 or 16 bits, read linear, not sRGB-decoded) or EXR laid on uv as image textures
    /// are, each texel the scratched fraction in `[0, 1]` (an RGB file: the mean of R, G, B).
    pub map: Option<PathBuf>,
    /// The map's flow map (PNG or EXR of the map's size): `direction = 2 rg - 1` in the tangent
    /// frame (glTF `KHR_materials_anisotropy`); without it the map's structure gives the
    /// direction.
    pub direction: Option<PathBuf>,
    /// uv tiling of the map (default 1): it is read at `uv * map_scale`.
    pub map_scale: Option<f64>,
}

/// One inline curve (`scratches.polylines`), in uv: a constant `width` or a width at each
/// point (`widths`, with optional depth ratios `depths`).
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct PolylineSpec {
    pub points: Vec<[f64; 2]>,
    pub width: Option<f64>,
    pub widths: Option<Vec<f64>>,
    pub depths: Option<Vec<f64>>,
}

/// A material's painted scratch map (`scratches.map`, `direction`, `map_scale`), resolved.
#[derive(Clone, Debug, PartialEq)]
pub struct MapSource {
    pub map: PathBuf,
    pub direction: Option<PathBuf>,
    pub scale: f64,
    /// Its lobes' depth ratio (`scratches.depth`, default 1).
    pub depth: f64,
}

/// Where a material's curves come from (`scratches.curves`, `scratches.pattern` or
/// `scratches.polylines`).
#[derive(Clone, Debug, PartialEq)]
pub enum CurveSource {
    Svg(PathBuf),
    Pattern(Pattern),
    Polylines(Vec<PolylineSpec>),
}

impl PolylineSpec {
    /// Its scratches through `style` (a constant width) or as given (widths at its points);
    /// `i` names it in errors.
    fn polylines(&self, i: usize, style: &StrokeStyle) -> Result<Vec<Polyline>, MaterialError> {
        let bad = |why: String| invalid("scratches.polylines", i, why);
        let points: Vec<glam::DVec2> = self.points.iter().map(|&p| p.into()).collect();
        let line = match (self.width, &self.widths) {
            (Some(w), None) => {
                if self.depths.is_some() {
                    return Err(bad("`depths` go with `widths` (a constant `width` takes the stroke keys `depth` and `wear`)".into()));
                }
                if !(w.is_finite() && w > 0.0) {
                    return Err(bad(format!("width {w:?}: must be finite and > 0")));
                }
                if points.len() < 2 {
                    return Err(bad(format!(
                        "needs at least 2 points, has {}",
                        points.len()
                    )));
                }
                return Ok(style.apply(&points, 0.5 * w, i as u64));
            }
            (None, Some(ws)) => Polyline {
                half_widths: ws.iter().map(|w| 0.5 * w).collect(),
                depths: self
                    .depths
                    .clone()
                    .unwrap_or_else(|| vec![1.0; points.len()]),
                points,
            },
            _ => {
                return Err(bad(
                    "give `width` (constant) or `widths` (one a point)".into()
                ))
            }
        };
        line.validate(&format!("{i}"))
            .map_err(|e| bad(e.to_string()))?;
        Ok(line.deduplicated().into_iter().collect())
    }
}

/// A material's curves, flattened: polylines in drawing units and the map onto uv.
#[derive(Clone, Debug)]
pub struct CurveDrawing {
    pub polylines: Vec<Polyline>,
    pub to_uv: glam::DVec2,
}

/// `scratches.lobes`: how smooth dielectric walls' groove lobes are found (rough walls' are
/// always read from a table).
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum LobesKey {
    /// Read from the precomputed wall table (METHOD.md 8.1).
    Table,
    /// Sampled by tracing the exact groove at render time, one path a sample (the default).
    Traced,
}

/// `scratches.walls`: the 2D table's walls ([`Walls`]) or the groove's own glass.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum WallsKey {
    Diffuse,
    Specular,
    Dielectric,
}

/// Where a material's table comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum TableSource {
    Compute(TableParams),
    /// A wall table (METHOD.md 8.1; dielectric, or a metal's rough specular walls), computed
    /// or cached.
    Walls(WallTableParams),
    /// Smooth dielectric walls with no table, traced at render time (`lobes = "traced"`, the
    /// default for them).
    Traced(WallTableParams),
    /// A table file: the seed's or a wall table (`kind` says which).
    File(PathBuf),
}

/// Everything a scratched material resolves to before its table is built.
#[derive(Clone, Debug)]
pub struct Resolved {
    /// The defaults the keys left out took.
    pub model: ModelKey,
    pub base: ScratchedBase,
    pub tint: Rgb,
    pub table: TableSource,
    pub layers: LayerParams,
    pub layer_seed: u64,
    pub orientation: Orientation,
    pub mix: LayerMix,
    pub coverage: CoverageMode,
    /// Stations along each explicit groove.
    pub stations: usize,
    /// Whether the material has cell-noise layers (`false`: curves only).
    pub with_layers: bool,
    /// The curves and their stroke, where it has some.
    pub curves: Option<(CurveSource, StrokeStyle)>,
    /// The painted map, where it has one.
    pub map: Option<MapSource>,
}

/// The base's defaults for the scratch table.
struct BaseDefaults {
    base: ScratchedBase,
    tint: Rgb,
    law: FresnelLaw,
    walls: Walls,
    mode: FresnelMode,
}

/// `type = "scratched"` in a scene file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScratchedDesc {
    pub base: BaseKind,
    /// Glass: interior index (default 1.5; the exterior is 1).
    pub ior: Option<f32>,
    /// Metal: a conductor preset (see `bsdf::CONDUCTOR_PRESETS`) or `eta` and `k`.
    pub preset: Option<String>,
    #[serde(default, deserialize_with = "crate::strict_array::optional")]
    pub eta: Option<[f32; 3]>,
    #[serde(default, deserialize_with = "crate::strict_array::optional")]
    pub k: Option<[f32; 3]>,
    #[serde(default)]
    pub scratches: ScratchSpec,
    /// A flow map given as pixels (R, G as `direction`'s), read where `scratches.direction` is
    /// not set: the glTF importer's `KHR_materials_anisotropy` texture, in the tangent frame.
    #[serde(skip)]
    pub flow_image: Option<std::sync::Arc<crate::render::texture::RgbImage>>,
}

/// `scratches.KEY` for a trace parameter's name.
fn trace_key(key: &str) -> &'static str {
    match key {
        "m" => "scratches.m",
        "n" => "scratches.n",
        "nr" => "scratches.nr",
        "albedo" => "scratches.albedo",
        "max_bounces" => "scratches.max_bounces",
        "fresnel_law" => "scratches.fresnel_law",
        "ior" => "scratches.ior",
        "fresnel" => "scratches.fresnel",
        "groove_slices" => "scratches.groove_slices",
        _ => "scratches",
    }
}

/// A curve error as the scene key it comes from.
fn curve_error(e: CurveError) -> MaterialError {
    match e {
        CurveError::Param { key, value, why } => {
            let key = match key {
                "taper" => "scratches.taper",
                "dashes" => "scratches.dashes",
                "dash_offset" => "scratches.dash_offset",
                "depth" => "scratches.depth",
                "wear" => "scratches.wear",
                "wear_length" => "scratches.wear_length",
                k if k.starts_with("pattern.") => match k {
                    "pattern.radius" => "scratches.pattern.radius",
                    "pattern.arc" => "scratches.pattern.arc",
                    "pattern.centre" => "scratches.pattern.centre",
                    "pattern.jitter" => "scratches.pattern.jitter",
                    "pattern.count" => "scratches.pattern.count",
                    "pattern.width" => "scratches.pattern.width",
                    _ => "scratches.pattern",
                },
                _ => "scratches",
            };
            invalid(key, value, why)
        }
        e => invalid("scratches.curves", "", e.to_string()),
    }
}

fn layer_error(e: LayerError) -> MaterialError {
    let key = match e {
        LayerError::Length(_) => "scratches.length",
        LayerError::Width(_) => "scratches.width",
        LayerError::Threshold(_) => "scratches.threshold",
        LayerError::LayerCount(_) => "scratches.layers",
        LayerError::Setting(_) => "scratches.setting",
        _ => "scratches",
    };
    let value = match &e {
        // Debug: `1e308` as written, not 309 digits.
        LayerError::Length(v) | LayerError::Width(v) | LayerError::Threshold(v) => format!("{v:?}"),
        LayerError::LayerCount(v) => v.to_string(),
        LayerError::Setting(v) => v.to_string(),
        _ => String::new(),
    };
    invalid(key, value, e.to_string())
}

impl ScratchedDesc {
    /// Check every key and work out the defaults (no table is computed).
    pub fn resolve(&self, base_dir: &Path) -> Result<Resolved, MaterialError> {
        let defaults = self.resolve_base()?;
        let table = self.resolve_table(&defaults, base_dir)?;
        let s = &self.scratches;
        if s.crossings == Some(true) && !matches!(table, TableSource::Traced(_)) {
            return Err(invalid(
                "scratches.crossings",
                "true",
                "applies to traced glass walls only (walls = \"dielectric\", smooth, lobes = \"traced\")",
            ));
        }
        let map = self.resolve_map(base_dir)?;
        let curves = self.resolve_curves(base_dir, map.is_some())?;
        let layer_keys = s.setting.is_some()
            || s.length.is_some()
            || s.width.is_some()
            || s.threshold.is_some()
            || s.layers.is_some();
        // Curves, a map or both, without layers: as curves alone.
        let curves_only = (curves.is_some() || map.is_some()) && !layer_keys;
        Ok(Resolved {
            with_layers: !curves_only,
            curves,
            map,
            model: self.model(),
            base: defaults.base,
            tint: defaults.tint,
            table,
            layers: self.resolve_layers()?,
            layer_seed: s.seed.unwrap_or(DEFAULT_LAYER_SEED),
            orientation: s.orientation.unwrap_or_default(),
            // Under `model = "default"`, layers: `stochastic`, `union` in expectation (within
            // 1.5 % of explicit grooves where the seed's `max` is 24-85 % off far away) at
            // 1.04-1.07 x `max`'s instructions a sample (`union`: 1.24-1.64 x; docs/fidelity.md,
            // "The defaults"). Curves alone: `union`, within 0.2 % of explicit grooves where
            // `max` is 1-1.7 % off, at `max`'s cost within noise (few cover a footprint;
            // docs/scratched.md, "Curves"); a map alone, or with curves, likewise.
            mix: s.layer_mix.unwrap_or(match self.model() {
                ModelKey::Seed => LayerMix::Max,
                ModelKey::Default if curves_only => LayerMix::Union,
                ModelKey::Default => LayerMix::Stochastic,
            }),
            coverage: s.coverage.unwrap_or_default(),
            stations: match s.stations {
                None => DEFAULT_STATIONS,
                Some(n) if !self.is_explicit() => {
                    return Err(invalid(
                        "scratches.stations",
                        n,
                        "applies to explicit grooves only (`scratches.explicit = true`); the SV-BRDF has no stations",
                    ))
                }
                Some(n) if STATIONS_RANGE.contains(&n) => n,
                Some(n) => {
                    return Err(invalid(
                        "scratches.stations",
                        n,
                        format!(
                            "between {} and {} stations along each explicit groove",
                            STATIONS_RANGE.start(),
                            STATIONS_RANGE.end()
                        ),
                    ))
                }
            },
        })
    }

    /// The painted map (`scratches.map`, with `direction`, `map_scale` and `depth`): `direction`
    /// or `map_scale` without a map are errors. The files are read by [`Self::scratch_map`].
    fn resolve_map(&self, base_dir: &Path) -> Result<Option<MapSource>, MaterialError> {
        let s = &self.scratches;
        let Some(map) = &s.map else {
            if let Some(d) = &s.direction {
                return Err(invalid(
                    "scratches.direction",
                    format!("{d:?}"),
                    "a flow map goes with a painted scratch map: give `scratches.map` too",
                ));
            }
            if let Some(x) = s.map_scale {
                return Err(invalid(
                    "scratches.map_scale",
                    format!("{x:?}"),
                    "applies to a painted scratch map (`scratches.map`) only",
                ));
            }
            return Ok(None);
        };
        let scale = s.map_scale.unwrap_or(1.0);
        if !(scale.is_finite() && scale > 0.0 && (scale as f32).is_normal()) {
            return Err(invalid(
                "scratches.map_scale",
                format!("{scale:?}"),
                "must be finite and > 0",
            ));
        }
        let depth = s.depth.unwrap_or(1.0);
        if !(depth > 0.0 && depth <= 1.0) {
            return Err(invalid(
                "scratches.depth",
                format!("{depth:?}"),
                "a depth ratio must lie in (0, 1]",
            ));
        }
        Ok(Some(MapSource {
            map: base_dir.join(map),
            direction: s.direction.as_ref().map(|d| base_dir.join(d)),
            scale,
            depth,
        }))
    }

    /// The painted map read and prefiltered ([`ScratchMap::new`]), or `None`: errors name
    /// `scratches.map` (or `scratches.direction`), the file and the pixel.
    pub fn scratch_map(&self, r: &Resolved) -> Result<Option<ScratchMap>, MaterialError> {
        let Some(src) = &r.map else {
            return Ok(None);
        };
        let read = |key: &'static str, path: &Path| {
            crate::render::texture::RgbImage::load(path, Some(false))
                .map_err(|e| invalid(key, format!("{path:?}"), e.to_string()))
        };
        let map = read("scratches.map", &src.map)?;
        let coverage: Vec<f32> = map.pixels.iter().map(|p| (p.x + p.y + p.z) / 3.0).collect();
        use std::borrow::Cow;
        let flow = match (&src.direction, &self.flow_image) {
            (Some(path), _) => Some((
                Cow::Owned(read("scratches.direction", path)?),
                format!("{path:?}"),
            )),
            (None, Some(f)) => Some((Cow::Borrowed(&**f), "(the glTF's anisotropyTexture)".into())),
            (None, None) => None,
        };
        let flow = match flow {
            Some((f, name)) => {
                if (f.width, f.height) != (map.width, map.height) {
                    return Err(invalid(
                        "scratches.direction",
                        name,
                        format!(
                            "{} x {} pixels: a flow map must have the map's size, {} x {}",
                            f.width, f.height, map.width, map.height
                        ),
                    ));
                }
                Some(f.pixels.iter().map(|p| [p.x, p.y]).collect::<Vec<_>>())
            }
            None => None,
        };
        ScratchMap::new(map.width, map.height, &coverage, flow.as_deref(), src.scale)
            .map(Some)
            .map_err(|e| {
                let (key, path) = match &e {
                    MapError::Pixel {
                        image: "direction", ..
                    }
                    | MapError::Size {
                        image: "direction", ..
                    } => (
                        "scratches.direction",
                        src.direction.as_deref().unwrap_or(&src.map),
                    ),
                    MapError::Scale(_) => ("scratches.map_scale", src.map.as_path()),
                    _ => ("scratches.map", src.map.as_path()),
                };
                invalid(key, format!("{path:?}"), e.to_string())
            })
    }

    /// The curves (`scratches.curves` or `scratches.pattern`) and their stroke; the stroke
    /// keys without curves are errors (but `depth`, which a map's lobes take too, where there
    /// is a map).
    fn resolve_curves(
        &self,
        base_dir: &Path,
        with_map: bool,
    ) -> Result<Option<(CurveSource, StrokeStyle)>, MaterialError> {
        let s = &self.scratches;
        let d = StrokeStyle::default();
        let style = StrokeStyle {
            taper: s.taper.unwrap_or(d.taper),
            dashes: s.dashes.clone().unwrap_or_default(),
            dash_offset: s.dash_offset.unwrap_or(d.dash_offset),
            depth: s.depth.unwrap_or(d.depth),
            wear: s.wear.unwrap_or(d.wear),
            wear_length: s.wear_length.unwrap_or(d.wear_length),
            seed: s.seed.unwrap_or(DEFAULT_LAYER_SEED),
        };
        let given = [
            s.curves.is_some(),
            s.pattern.is_some(),
            s.polylines.is_some(),
        ];
        if given.iter().filter(|g| **g).count() > 1 {
            return Err(invalid(
                "scratches.curves",
                "(given)",
                "`scratches.curves` (an SVG), `scratches.pattern` and `scratches.polylines` exclude each other",
            ));
        }
        let source = match (&s.curves, &s.pattern, &s.polylines) {
            (Some(path), ..) => CurveSource::Svg(base_dir.join(path)),
            (_, Some(p), _) => {
                p.validate().map_err(curve_error)?;
                CurveSource::Pattern(p.clone())
            }
            (.., Some(lines)) => {
                if lines.is_empty() {
                    return Err(invalid("scratches.polylines", "[]", "holds no curve"));
                }
                let per_point = lines.iter().any(|l| l.widths.is_some());
                let style_keys = s.taper.is_some()
                    || s.dashes.is_some()
                    || s.wear.is_some()
                    || s.depth.is_some();
                if per_point && style_keys {
                    return Err(invalid(
                        "scratches.polylines",
                        "(widths)",
                        "curves with `widths` at their points take no stroke keys (`taper`, `dashes`, `depth`, `wear`)",
                    ));
                }
                CurveSource::Polylines(lines.clone())
            }
            (None, None, None) => {
                let stroke_keys = [
                    ("scratches.taper", s.taper.is_some()),
                    ("scratches.dashes", s.dashes.is_some()),
                    ("scratches.dash_offset", s.dash_offset.is_some()),
                    ("scratches.depth", s.depth.is_some() && !with_map),
                    ("scratches.wear", s.wear.is_some()),
                    ("scratches.wear_length", s.wear_length.is_some()),
                ];
                if let Some((key, _)) = stroke_keys.iter().find(|(_, given)| *given) {
                    return Err(invalid(
                        key,
                        "(given)",
                        "applies to curves only (`scratches.curves`, `scratches.pattern` or `scratches.polylines`; `depth` also to `scratches.map`)",
                    ));
                }
                return Ok(None);
            }
        };
        style.validate().map_err(curve_error)?;
        Ok(Some((source, style)))
    }

    /// The material's curves flattened (an SVG read, a pattern drawn), or `None`.
    pub fn curve_drawing(&self, r: &Resolved) -> Result<Option<CurveDrawing>, MaterialError> {
        let Some((source, style)) = &r.curves else {
            return Ok(None);
        };
        let drawing = match source {
            CurveSource::Svg(path) => {
                let d = crate::curves::svg::load(path, style)
                    .map_err(|e| invalid("scratches.curves", format!("{path:?}"), e.to_string()))?;
                CurveDrawing {
                    to_uv: d.to_uv(),
                    polylines: d.polylines,
                }
            }
            CurveSource::Pattern(p) => CurveDrawing {
                polylines: p.polylines(style).map_err(curve_error)?,
                to_uv: glam::DVec2::ONE,
            },
            CurveSource::Polylines(lines) => {
                let mut polylines = Vec::new();
                for (i, l) in lines.iter().enumerate() {
                    polylines.extend(l.polylines(i, style)?);
                }
                CurveDrawing {
                    polylines,
                    to_uv: glam::DVec2::ONE,
                }
            }
        };
        Ok(Some(drawing))
    }

    /// The defaults the keys left out take (`scratches.model`).
    pub fn model(&self) -> ModelKey {
        self.scratches.model.unwrap_or_default()
    }

    /// The base (`ior`, or a conductor's `preset` / `eta` and `k`) and the table defaults it
    /// implies: glass takes the seed's model (diffuse walls, Schlick, one Fresnel factor; the
    /// default model adds exact-groove slices, [`Self::default_groove_slices`]), metal
    /// [Raymond16]'s (mirror walls, Fresnel per wall hit).
    fn resolve_base(&self) -> Result<BaseDefaults, MaterialError> {
        match self.base {
            BaseKind::Glass => {
                for (key, given) in [
                    ("preset", self.preset.is_some()),
                    ("eta", self.eta.is_some()),
                    ("k", self.k.is_some()),
                ] {
                    if given {
                        return Err(invalid(key, "(given)", "applies to base = \"metal\" only"));
                    }
                }
                let ior = self.ior.unwrap_or(1.5);
                if !(ior.is_finite() && ior >= 1.0) {
                    return Err(invalid(
                        "ior",
                        ior,
                        "an index of refraction must be finite and >= 1",
                    ));
                }
                Ok(BaseDefaults {
                    base: ScratchedBase::Glass { eta: ior },
                    tint: Rgb::ONE,
                    law: FresnelLaw::Schlick {
                        n: self.scratches.ior.unwrap_or(ior as f64),
                    },
                    walls: Walls::Diffuse,
                    mode: FresnelMode::Seed,
                })
            }
            BaseKind::Metal => {
                if let Some(ior) = self.ior {
                    return Err(invalid(
                        "ior",
                        ior,
                        "applies to base = \"glass\" only (metal takes preset or eta and k)",
                    ));
                }
                let ior = conductor_ior(self.preset.as_deref(), self.eta, self.k)?;
                let (law, tint) = metal_law_and_tint(&ior);
                Ok(BaseDefaults {
                    base: ScratchedBase::Metal { ior },
                    tint,
                    law,
                    walls: Walls::Specular,
                    mode: FresnelMode::Walls,
                })
            }
        }
    }

    /// Where the table comes from: a file (`scratches.table`, excluding every table key) or
    /// the parameters of a computation.
    fn resolve_table(
        &self,
        defaults: &BaseDefaults,
        base_dir: &Path,
    ) -> Result<TableSource, MaterialError> {
        let s = &self.scratches;
        let table_keys = [
            ("scratches.profile", s.profile.is_some()),
            ("scratches.walls", s.walls.is_some()),
            ("scratches.roughness", s.roughness.is_some()),
            ("scratches.trace_seed", s.trace_seed.is_some()),
            ("scratches.lobes", s.lobes.is_some()),
        ];
        if let Some(path) = &s.table {
            let two_d = self.two_d_table_keys();
            if let Some((key, _)) = table_keys.iter().chain(&two_d).find(|(_, given)| *given) {
                return Err(invalid(key, "(given)", "`scratches.table` loads a precomputed table; its parameters cannot be given too"));
            }
            return Ok(TableSource::File(base_dir.join(path)));
        }
        let spec = s
            .profile
            .clone()
            .unwrap_or_else(|| DEFAULT_PROFILE.to_string());
        let profile = match spec.strip_prefix("file:") {
            Some(p) if Path::new(p).is_relative() => {
                Profile::parse(&format!("file:{}", base_dir.join(p).display()))
            }
            _ => Profile::parse(&spec),
        }
        .map_err(|e| invalid("scratches.profile", format!("{spec:?}"), e.to_string()))?;
        if s.walls == Some(WallsKey::Dielectric) {
            let params = self.resolve_walls(defaults, profile)?;
            let smooth = params.roughness == 0.0;
            return match s.lobes {
                Some(LobesKey::Traced) if !smooth => Err(invalid(
                    "scratches.lobes",
                    "\"traced\"",
                    "needs smooth walls: rough walls' lobes are light-sampled with MIS, which needs the table's density (leave out `roughness` or `lobes`)",
                )),
                Some(LobesKey::Traced) | None if smooth => Ok(TableSource::Traced(params)),
                _ => Ok(TableSource::Walls(params)),
            };
        }
        if let Some(lobes) = s.lobes {
            return Err(invalid(
                "scratches.lobes",
                format!("{lobes:?}").to_lowercase(),
                "applies to walls = \"dielectric\" only",
            ));
        }
        if let Some(r) = s.roughness {
            if let Some(params) = self.resolve_rough_specular(defaults, &profile, r)? {
                return Ok(TableSource::Walls(params));
            }
        }
        let law = self.resolve_law(defaults)?;
        let seed = TraceSettings::default();
        let walls = match s.walls {
            Some(WallsKey::Specular) => Walls::Specular,
            Some(WallsKey::Diffuse) => Walls::Diffuse,
            Some(WallsKey::Dielectric) | None => defaults.walls,
        };
        let groove_slices = match s.groove_slices {
            Some(0) => {
                return Err(invalid(
                    "scratches.groove_slices",
                    0,
                    "must be in 1..=32 (leave the key out for the default, or give model = \"seed\" for the seed's eq. (3))",
                ))
            }
            Some(n) => n,
            None => self.default_groove_slices(walls, law),
        };
        let mode = match groove_slices {
            0 => defaults.mode,
            _ => FresnelMode::Walls,
        };
        let (m, n, nr) = match (self.model(), groove_slices) {
            (ModelKey::Default, 1..) => GROOVE_TABLE_SIZES,
            _ => (seed.m, seed.n, seed.nr),
        };
        let trace = TraceSettings {
            walls,
            m: s.m.unwrap_or(m),
            n: s.n.unwrap_or(n),
            nr: s.nr.unwrap_or(nr),
            albedo: s.albedo.unwrap_or(seed.albedo),
            max_bounces: s.max_bounces.unwrap_or(seed.max_bounces),
            seed: s.trace_seed.unwrap_or(seed.seed),
            fresnel_mode: s.fresnel.unwrap_or(mode),
            fresnel_law: law,
            groove_slices,
            ..seed
        };
        trace.validate().map_err(|e| {
            let TraceError::BadParameter { key, value, why } = e;
            invalid(trace_key(key), value, why)
        })?;
        Ok(TableSource::Compute(TableParams::new(profile, trace)))
    }

    /// `groove_slices` left out: [`DEFAULT_GROOVE_SLICES`] under `model = "default"` on glass
    /// where the exact groove is what the table stands for and the slices add to it (diffuse
    /// walls, a Fresnel law other than `none`, which leaves the seed's table exact, `fresnel`
    /// not given as `seed`, `albedo` 1, `m` at most 1024, `N N_r` at most 2^40); else none. (A
    /// metal's Lambertian walls keep the seed's table: there the slices bring a near view of
    /// explicit grooves from 2.1 % to 0.3 % but a far one from 0.1 % to 0.9 %, where `max`'s
    /// coverage error no longer cancels the seed's Fresnel error; docs/fidelity.md.)
    fn default_groove_slices(&self, walls: Walls, law: FresnelLaw) -> usize {
        let s = &self.scratches;
        let (m, n, nr) = GROOVE_TABLE_SIZES;
        let applies = self.model() == ModelKey::Default
            && self.base == BaseKind::Glass
            && walls == Walls::Diffuse
            && law != FresnelLaw::None
            && s.fresnel != Some(FresnelMode::Seed)
            && s.albedo.is_none_or(|a| a == 1.0)
            && s.m.unwrap_or(m) <= 1024
            && (s.n.unwrap_or(n) as u64).saturating_mul(s.nr.unwrap_or(nr) as u64) <= 1 << 40;
        if applies {
            DEFAULT_GROOVE_SLICES
        } else {
            0
        }
    }

    /// `roughness` with other than dielectric walls: a metal's specular walls only, in
    /// `[0, 1]`. `Some` wall table for rough walls; `None` for 0, the seed's mirror walls (its
    /// 2D table, unchanged).
    fn resolve_rough_specular(
        &self,
        defaults: &BaseDefaults,
        profile: &Profile,
        roughness: f64,
    ) -> Result<Option<WallTableParams>, MaterialError> {
        let s = &self.scratches;
        let specular = match s.walls {
            Some(w) => w == WallsKey::Specular,
            None => defaults.walls == Walls::Specular,
        };
        if !(specular && matches!(defaults.base, ScratchedBase::Metal { .. })) {
            return Err(invalid(
                "scratches.roughness",
                roughness,
                "applies to walls = \"dielectric\" (glass) and to a metal's walls = \"specular\" only (the 2D table's Lambertian walls have no roughness)",
            ));
        }
        if !(roughness.is_finite() && (0.0..=1.0).contains(&roughness)) {
            return Err(invalid(
                "scratches.roughness",
                roughness,
                "must be in [0, 1] (GGX alpha; 0: mirror walls)",
            ));
        }
        if roughness == 0.0 {
            return Ok(None);
        }
        let law_keys = ["scratches.fresnel_law", "scratches.ior"];
        let two_d = self.two_d_table_keys();
        if let Some((key, _)) = two_d
            .iter()
            .find(|(key, given)| *given && !law_keys.contains(key))
        {
            return Err(invalid(
                key,
                "(given)",
                "applies to the 2D table; rough specular walls (`scratches.roughness` > 0) are traced exactly, with Fresnel at every wall hit",
            ));
        }
        let params = WallTableParams {
            seed: s.trace_seed.unwrap_or(0),
            ..WallTableParams::specular(profile.clone(), self.resolve_law(defaults)?, roughness)
        };
        params.validate().map_err(|e| {
            let key = match e.key {
                "roughness" => "scratches.roughness",
                "fresnel-law" => "scratches.fresnel_law",
                "ior" => "scratches.ior",
                _ => "scratches",
            };
            invalid(key, e.value, e.why)
        })?;
        Ok(Some(params))
    }

    /// The 2D table's (and rough specular walls') Fresnel law: `fresnel_law` with
    /// `scratches.ior`, else the base's.
    fn resolve_law(&self, defaults: &BaseDefaults) -> Result<FresnelLaw, MaterialError> {
        let s = &self.scratches;
        let law = match &s.fresnel_law {
            Some(text) => {
                let n = s.ior.unwrap_or(match defaults.base {
                    ScratchedBase::Glass { eta } => eta as f64,
                    ScratchedBase::Metal { .. } => 1.5,
                });
                FresnelLaw::parse(text, n)
                    .map_err(|e| invalid("scratches.fresnel_law", format!("{text:?}"), e))?
            }
            None => defaults.law,
        };
        if let (Some(n), Some(_)) = (
            s.ior,
            s.fresnel_law
                .as_deref()
                .filter(|l| l.starts_with("conductor") || *l == "none"),
        ) {
            return Err(invalid(
                "scratches.ior",
                n,
                "applies to the schlick and dielectric laws only",
            ));
        }
        Ok(law)
    }

    /// The keys of the 2D table alone, each with whether it is given.
    fn two_d_table_keys(&self) -> [(&'static str, bool); 9] {
        let s = &self.scratches;
        [
            ("scratches.fresnel", s.fresnel.is_some()),
            ("scratches.fresnel_law", s.fresnel_law.is_some()),
            ("scratches.ior", s.ior.is_some()),
            ("scratches.m", s.m.is_some()),
            ("scratches.n", s.n.is_some()),
            ("scratches.nr", s.nr.is_some()),
            ("scratches.albedo", s.albedo.is_some()),
            ("scratches.max_bounces", s.max_bounces.is_some()),
            ("scratches.groove_slices", s.groove_slices.is_some()),
        ]
    }

    /// `walls = "dielectric"`: glass only; the 2D table's keys do not apply; `roughness` in
    /// `[0, 1]`; `trace_seed` seeds the trace.
    fn resolve_walls(
        &self,
        defaults: &BaseDefaults,
        profile: Profile,
    ) -> Result<WallTableParams, MaterialError> {
        let s = &self.scratches;
        let ScratchedBase::Glass { eta } = defaults.base else {
            return Err(invalid(
                "scratches.walls",
                "\"dielectric\"",
                "dielectric walls are glass: they need base = \"glass\"",
            ));
        };
        if let Some((key, _)) = self.two_d_table_keys().iter().find(|(_, given)| *given) {
            return Err(invalid(
                key,
                "(given)",
                "applies to the 2D table (walls = \"diffuse\" or \"specular\"); dielectric walls take the glass's `ior` and `roughness`",
            ));
        }
        let roughness = s.roughness.unwrap_or(0.0);
        let params = WallTableParams {
            seed: s.trace_seed.unwrap_or(0),
            ..WallTableParams::new(profile, eta as f64, roughness)
        };
        params.validate().map_err(|e| {
            let key = match e.key {
                "roughness" => "scratches.roughness",
                "ior" => "ior",
                _ => "scratches",
            };
            invalid(key, e.value, e.why)
        })?;
        Ok(params)
    }

    /// The layer parameters: a `setting` of the seed's Table 1, or all of `length`, `width`
    /// and `threshold`; then `layers`.
    fn resolve_layers(&self) -> Result<LayerParams, MaterialError> {
        let s = &self.scratches;
        let mut layers = match (s.setting, s.length, s.width, s.threshold) {
            (Some(n), None, None, None) => LayerParams::setting(n).map_err(layer_error)?,
            (Some(_), ..) => {
                return Err(invalid(
                    "scratches.setting",
                    s.setting.unwrap_or(0),
                    "a setting excludes `length`, `width` and `threshold`",
                ));
            }
            (None, None, None, None) => LayerParams::setting(1).map_err(layer_error)?,
            (None, Some(length), Some(width), Some(threshold)) => LayerParams {
                length,
                width,
                threshold,
                layers: LayerParams::DEFAULT_LAYERS,
            },
            (None, ..) => {
                return Err(invalid(
                    "scratches.length",
                    format!("{:?}/{:?}/{:?}", s.length, s.width, s.threshold),
                    "give all of `length`, `width` and `threshold` (or a `setting`)",
                ));
            }
        };
        layers.layers = s.layers.unwrap_or(LayerParams::DEFAULT_LAYERS);
        if layers.layers > MAX_LAYERS {
            return Err(layer_error(LayerError::LayerCount(layers.layers)));
        }
        layers.validate().map_err(layer_error)?;
        Ok(layers)
    }

    /// Validate, then obtain the table (memory, disk cache, file or computation) and build the
    /// layer set.
    pub fn prepare(&self, base_dir: &Path) -> Result<ScratchedMaterial, MaterialError> {
        let r = self.resolve(base_dir)?;
        let model = self.model_of(&r, &r.table)?;
        let layers = if r.with_layers {
            LayerSet::with_orientation(r.layers, r.layer_seed, r.orientation)
                .map_err(layer_error)?
        } else {
            LayerSet::none()
        };
        let drawing = self.curve_drawing(&r)?;
        let map = self.scratch_map(&r)?;
        let worn_map = r.map.as_ref().is_some_and(|m| m.depth < 1.0);
        let worn = match &drawing {
            Some(d)
                if d.polylines
                    .iter()
                    .any(|l| l.depths.iter().any(|&x| x < 1.0)) =>
            {
                self.worn_models(&r)?
            }
            _ if worn_map => self.worn_models(&r)?,
            _ => Vec::new(),
        };
        if let Some(d) = &drawing {
            let (tight, min) = CurveSet::tight_turns(&d.polylines);
            if !tight.is_empty() {
                crate::log::warn(&format!(
                    "scratches.curves: {} of {} curves (the first: curve {}) turn tighter than {} times their width (down to {min:.2}); there the SV-BRDF's extruded groove is an approximation (docs/scratched.md, \"Curves\")",
                    tight.len(),
                    d.polylines.len(),
                    tight[0],
                    crate::curves::MIN_RADIUS_OVER_WIDTH
                ));
            }
        }
        let curves = match drawing {
            Some(d) => Some(std::sync::Arc::new(
                CurveSet::new(&d.polylines, d.to_uv)
                    .map_err(|e| invalid("scratches.curves", "", e.to_string()))?,
            )),
            None => None,
        };
        Ok(
            ScratchedMaterial::with_model(r.base, r.tint, model, layers, r.mix, r.coverage)
                .with_lean(self.scratches.lean == Some(true))
                .with_crossings(
                    self.scratches
                        .crossings
                        .unwrap_or(self.model() == ModelKey::Default),
                )
                .with_curves(curves)
                .with_map(
                    map.map(std::sync::Arc::new),
                    r.map.as_ref().map_or(1.0, |m| m.depth as f32),
                )
                .with_worn(worn),
        )
    }

    /// The scratch model of `table` (memory, disk cache, file or computation).
    fn model_of(&self, r: &Resolved, table: &TableSource) -> Result<ScratchModel, MaterialError> {
        let key = if self.scratches.table.is_some() {
            "scratches.table"
        } else {
            "scratches"
        };
        let table_error = |e: TableError| MaterialError::ScratchTable {
            key,
            source: Box::new(e),
        };
        Ok(match table {
            TableSource::Compute(params) => {
                ScratchModel::Seed(crate::render::cache::obtain_table(params).map_err(table_error)?)
            }
            TableSource::Walls(params) => {
                let table = crate::render::cache::obtain_wall_table(params).map_err(table_error)?;
                match params.walls {
                    WallKind::Dielectric => ScratchModel::DielectricWalls(GlassWalls::Table(table)),
                    WallKind::Specular { .. } => ScratchModel::SpecularWalls(table),
                }
            }
            TableSource::Traced(params) => ScratchModel::DielectricWalls(GlassWalls::Traced(
                std::sync::Arc::new(TracedGroove::new(params)),
            )),
            TableSource::File(path) => {
                let model = crate::render::cache::load_any_table_file(path).map_err(table_error)?;
                self.check_wall_table_base(&r.base, &model)?;
                model
            }
        })
    }

    /// The models of the profile worn to [`WEAR_LEVELS`], for worn curves (METHOD.md 9.2):
    /// each table computed (or found in the cache) from the worn profile with the material's
    /// other parameters. A table file cannot be worn: an error naming the key.
    fn worn_models(&self, r: &Resolved) -> Result<Vec<(f32, ScratchModel)>, MaterialError> {
        let mut out = Vec::new();
        for d in WEAR_LEVELS {
            let wear = |p: &Profile| {
                p.worn(d)
                    .map_err(|e| invalid("scratches.profile", d, e.to_string()))
            };
            let source = match &r.table {
                TableSource::Compute(p) => {
                    TableSource::Compute(TableParams::new(wear(&p.profile)?, p.trace.clone()))
                }
                TableSource::Walls(p) => TableSource::Walls(WallTableParams {
                    profile: wear(&p.profile)?,
                    ..p.clone()
                }),
                TableSource::Traced(p) => TableSource::Traced(WallTableParams {
                    profile: wear(&p.profile)?,
                    ..p.clone()
                }),
                TableSource::File(path) => {
                    return Err(invalid(
                        "scratches.table",
                        format!("{path:?}"),
                        "worn curves or a worn map (a depth ratio below 1: `depth`, `wear`, `depths` or an SVG's stroke-opacity) read tables of the worn profile, which a table file cannot give: give the table's parameters instead",
                    ))
                }
            };
            out.push((d as f32, self.model_of(r, &source)?));
        }
        Ok(out)
    }

    /// A dielectric-wall table file fits a glass base of its own index only, a specular-wall
    /// one a metal base.
    fn check_wall_table_base(
        &self,
        base: &ScratchedBase,
        model: &ScratchModel,
    ) -> Result<(), MaterialError> {
        let walls = match model {
            ScratchModel::Seed(_) => return Ok(()),
            ScratchModel::SpecularWalls(_) if matches!(base, ScratchedBase::Metal { .. }) => {
                return Ok(())
            }
            ScratchModel::SpecularWalls(_) => {
                return Err(invalid(
                    "scratches.table",
                    format!(
                        "{:?}",
                        self.scratches.table.as_deref().unwrap_or(Path::new(""))
                    ),
                    "a specular-wall table (rough metal walls) needs base = \"metal\"",
                ))
            }
            ScratchModel::DielectricWalls(walls) => walls,
        };
        match *base {
            ScratchedBase::Glass { eta } if (eta - walls.ior()).abs() <= 1e-6 * eta => Ok(()),
            ScratchedBase::Glass { eta } => Err(invalid(
                "scratches.table",
                format!(
                    "{:?}",
                    self.scratches.table.as_deref().unwrap_or(Path::new(""))
                ),
                format!(
                    "a dielectric-wall table traced for index {}, on glass of ior {eta}",
                    walls.ior()
                ),
            )),
            ScratchedBase::Metal { .. } => Err(invalid(
                "scratches.table",
                format!(
                    "{:?}",
                    self.scratches.table.as_deref().unwrap_or(Path::new(""))
                ),
                "a dielectric-wall table needs base = \"glass\"",
            )),
        }
    }
}

/// What explicit scratch geometry (METHOD.md 8.3) takes from a scratched material: its layers
/// and profile, the material of the flat face (the smooth base) and of the groove walls (the
/// BSDF the table assumes: glass walls the glass, rough ones energy-compensated; metal walls
/// Lambertian or mirror times the table's Fresnel law and the lobe's tint).
#[derive(Clone, Debug)]
pub struct ExplicitSpec {
    /// The cell-noise layers (none where the material has curves only).
    pub layers: LayerSet,
    /// The curves, in drawing units, with their map onto uv.
    pub curves: Option<CurveDrawing>,
    pub profile: Profile,
    pub face: Material,
    pub wall: Material,
    /// Stations along each groove (`scratches.stations`).
    pub stations: usize,
}

impl ScratchedDesc {
    /// Whether `scratches.explicit = true`.
    pub fn is_explicit(&self) -> bool {
        self.scratches.explicit == Some(true)
    }

    /// The explicit geometry's ingredients (validated like [`ScratchedDesc::resolve`]).
    pub fn explicit(&self, base_dir: &Path) -> Result<ExplicitSpec, MaterialError> {
        let r = self.resolve(base_dir)?;
        if let Some(m) = &r.map {
            return Err(invalid(
                "scratches.map",
                format!("{:?}", m.map),
                "a painted map holds fractions, not grooves: it cannot be carved (`scratches.explicit = true`)",
            ));
        }
        if let TableSource::Walls(params) | TableSource::Traced(params) = &r.table {
            if let WallKind::Specular { .. } = params.walls {
                return Err(invalid(
                    "scratches.explicit",
                    true,
                    "explicit grooves have mirror or Lambertian metal walls: leave out `scratches.roughness` to carve them",
                ));
            }
            return self.explicit_glass(&r, params);
        }
        let TableSource::Compute(params) = r.table.clone() else {
            return Err(invalid(
                "scratches.explicit",
                true,
                "explicit grooves need the profile and walls: give them instead of `scratches.table`",
            ));
        };
        if let Some(n) = self.scratches.groove_slices {
            return Err(invalid(
                "scratches.groove_slices",
                n,
                "applies to the SV-BRDF's table; explicit grooves are traced exactly",
            ));
        }
        if r.orientation != Orientation::Layer {
            return Err(invalid(
                "scratches.explicit",
                true,
                "explicit grooves follow the layers' directions: they cannot be carved with `orientation = \"random\"`",
            ));
        }
        let (face, wall) = match r.base {
            ScratchedBase::Glass { eta } => {
                let glass = Material::Dielectric {
                    eta,
                    roughness: 0.0,
                };
                (glass.clone(), glass)
            }
            ScratchedBase::Metal { ior } => (
                Material::Conductor {
                    ior,
                    roughness: 0.0,
                },
                Material::GrooveWall(GrooveWall {
                    specular: params.trace.walls == Walls::Specular,
                    law: params.trace.fresnel_law,
                    tint: r.tint,
                }),
            ),
        };
        Ok(ExplicitSpec {
            layers: explicit_layers(&r)?,
            curves: self.curve_drawing(&r)?,
            profile: params.profile,
            face,
            wall,
            stations: r.stations,
        })
    }
}

impl ScratchedDesc {
    /// Explicit grooves with dielectric walls: smooth glass faces, walls of the glass with the
    /// walls' roughness.
    fn explicit_glass(
        &self,
        r: &Resolved,
        params: &WallTableParams,
    ) -> Result<ExplicitSpec, MaterialError> {
        if r.orientation != Orientation::Layer {
            return Err(invalid(
                "scratches.explicit",
                true,
                "explicit grooves follow the layers' directions: they cannot be carved with `orientation = \"random\"`",
            ));
        }
        let eta = params.ior as f32;
        Ok(ExplicitSpec {
            layers: explicit_layers(r)?,
            curves: self.curve_drawing(r)?,
            profile: params.profile.clone(),
            face: Material::Dielectric {
                eta,
                roughness: 0.0,
            },
            // Rough walls as lossless as the tables' microsurface walk (METHOD.md 9.7): the
            // energy-compensated rough dielectric (its lobe shape is single scattering's).
            wall: if params.roughness > 0.0 {
                Material::CompensatedDielectric(Box::new(DielectricCompensation::new(
                    eta,
                    params.roughness as f32,
                )))
            } else {
                Material::Dielectric {
                    eta,
                    roughness: 0.0,
                }
            },
            stations: r.stations,
        })
    }
}

/// The layers explicit grooves carve: none where the material has curves only.
fn explicit_layers(r: &Resolved) -> Result<LayerSet, MaterialError> {
    if r.with_layers {
        LayerSet::new(r.layers, r.layer_seed).map_err(layer_error)
    } else {
        Ok(LayerSet::none())
    }
}

/// Metal scratches: the table's Fresnel law is a scalar, so it takes the base's complex IOR in
/// the channel that reflects most at normal incidence (`none` when that channel is the perfect
/// mirror `eta = 0`), and the lobe is tinted by `F_rgb(1) / F_max(1) <= 1` (an approximation:
/// the colour of one reflection at normal incidence; documented in `docs/scratched.md`).
fn metal_law_and_tint(ior: &ConductorIor) -> (FresnelLaw, Rgb) {
    let f = ior.fresnel(1.0);
    let c = if f.x >= f.y && f.x >= f.z {
        0
    } else if f.y >= f.z {
        1
    } else {
        2
    };
    let (eta, k) = (ior.eta[c] as f64, ior.k[c] as f64);
    let law = if eta > 0.0 {
        FresnelLaw::Conductor { eta, k }
    } else {
        FresnelLaw::None
    };
    let fmax = f[c].max(1e-6);
    (law, (f / fmax).min(Rgb::ONE))
}

#[cfg(test)]
mod tests;
