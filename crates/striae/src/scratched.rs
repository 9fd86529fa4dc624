//! The scratched material (issue 5; `docs/METHOD.md` sections 5-7, `docs/scratched.md`): a
//! smooth glass or metal base, a scratch layer set (section 5, evaluated procedurally) and a
//! scratch BRDF table (sections 3-4), combined at a hit as section 6 prescribes.
//!
//! ```toml
//! [materials.glass]
//! type = "scratched"
//! base = "glass"                 # or "metal" (with preset = "gold", or eta and k)
//! ior = 1.5                      # glass only
//! [materials.glass.scratches]
//! profile = "v:angle=90"         # the syntax of `striae precompute --profile`
//! walls = "diffuse"              # "specular" = mirror walls, [Raymond16]'s delta lobe
//! fresnel = "seed"               # or "walls"
//! fresnel_law = "schlick"        # dielectric | conductor:ETA,K | none
//! m = 256                        # table size M, N, N_r (default: the seed's)
//! n = 10000
//! nr = 100
//! setting = 1                    # the seed's Table 1, or length / width / threshold
//! layers = 8
//! seed = 1
//! layer_mix = "max"              # or "sum" ([Raymond16])
//! # table = "my-table.npz"       # load a table instead of computing one
//! ```
//!
//! Tables. A computed table is cached on disk under its parameter hash
//! ([`TableParams::hash`]) in [`cache_dir`], written atomically; a cache file that cannot be
//! read (or holds other parameters) is recomputed with a warning on stderr. In memory, tables
//! are shared by hash between the materials of a scene (and between scenes alive at the same
//! time), so each distinct table is computed or loaded once ([`obtain_table`]).
//!
//! At a hit ([`ScratchedMaterial::bsdf`]): every layer's coverage of the pixel footprint
//! (`uv` and `ShadingContext::footprint_uv`; exact, [`crate::layers`]); in `max` mode (section 6) the layer
//! with the largest coverage, one chosen by `ShadingContext::u_layer` among ties (where several
//! scratches cross); in `sum` mode ([Raymond16]) every layer with some coverage (at most
//! [`MAX_SCRATCH_LOBES`], the largest). The scratch frame's `t` is the layer's texture direction
//! `d` carried to 3D by `d.x dP/du + d.y dP/dv` and projected into the shading plane. Where no
//! layer covers the footprint the BSDF is the base itself, at no extra cost; glass seen from
//! inside skips the layer queries (its scratches are on the outer side, `bsdf::scratched`).

use crate::bsdf::scratched::MAX_SCRATCH_LOBES;
use crate::bsdf::{
    Bsdf, Conductor, ConductorIor, Dielectric, ScratchLobe, ScratchLobeTable, ScratchedBase,
    ScratchedBsdf,
};
use crate::fresnel::FresnelLaw;
use crate::layers::lattice::{PixelKey, TileQuery};
use crate::layers::layer::MAX_FOOTPRINT_CELLS;
use crate::layers::{LayerError, LayerParams, LayerSet, MAX_LAYERS};
use crate::material::{Material, MaterialError};
use crate::math::{Rgb, Vec3};
use crate::profile::Profile;
use crate::shading::ShadingContext;
use crate::table::{ScratchTable, TableError, TableParams};
use crate::trace2d::{FresnelMode, TraceError, TraceSettings, Walls};
use serde::Deserialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock, Weak};

/// The smooth base under the scratches.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum BaseKind {
    /// A smooth dielectric (`ior`, default 1.5, the seed's glass).
    Glass,
    /// A smooth conductor (`preset`, or `eta` and `k`).
    Metal,
}

/// How the layers covering one footprint combine.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum LayerMix {
    /// The layer with the largest coverage (METHOD.md section 6, the seed).
    #[default]
    Max,
    /// `(1 - sum c_k) f_base + sum c_k f_scratch,k` over every layer ([Raymond16]).
    Sum,
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

/// Default table size: the seed's `M = 256, N = 10000, N_r = 100` (about 3 s on 2 cores for
/// diffuse walls with the precompute's fast path, then cached).
pub const DEFAULT_M: usize = 256;
pub const DEFAULT_N: usize = 10_000;
pub const DEFAULT_NR: usize = 100;
/// Default profile: a 90-degree V groove.
pub const DEFAULT_PROFILE: &str = "v:angle=90";
/// Default layer-set seed.
pub const DEFAULT_LAYER_SEED: u64 = 1;

/// `[materials.NAME.scratches]`. Every key is optional; the defaults depend on the base
/// (see [`ScratchedMaterial::resolve`] and `docs/scratched.md`).
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ScratchSpec {
    /// Profile spec, as `striae precompute --profile` (`file:` paths are relative to the scene).
    pub profile: Option<String>,
    /// Wall micro-BRDF: glass default `diffuse` (the seed), metal `specular` ([Raymond16]).
    #[serde(default, deserialize_with = "keyed::walls")]
    pub walls: Option<Walls>,
    /// Where Fresnel is applied: glass default `seed`, metal `walls`.
    #[serde(default, deserialize_with = "keyed::fresnel")]
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
    /// The seed's Table 1 (1 or 2); excludes `length`, `width`, `threshold`.
    pub setting: Option<u32>,
    pub length: Option<f64>,
    pub width: Option<f64>,
    pub threshold: Option<f64>,
    /// Number of layers `K` (default 8).
    pub layers: Option<usize>,
    /// Seed of the layer set (default 1).
    pub seed: Option<u64>,
    #[serde(default, deserialize_with = "keyed::layer_mix")]
    pub layer_mix: Option<LayerMix>,
    /// `footprint` (default, section 6) or `point` (see [`CoverageMode`]).
    #[serde(default, deserialize_with = "keyed::coverage")]
    pub coverage: Option<CoverageMode>,
    /// A table file (`.npz`, relative to the scene file) to load instead of computing one;
    /// excludes the table keys above.
    pub table: Option<PathBuf>,
}

/// Deserialisers of the scratched material's word-valued keys that put the key in the error.
/// A material is an internally tagged enum, which serde buffers, so `toml` can point only at the
/// material's table and its message would name the bad word but not the key.
mod keyed {
    use super::{BaseKind, CoverageMode, FresnelMode, LayerMix, Walls};
    use serde::de::{Deserialize, Deserializer, Error};

    fn named<'de, T: Deserialize<'de>, D: Deserializer<'de>>(
        d: D,
        key: &str,
    ) -> Result<T, D::Error> {
        T::deserialize(d).map_err(|e| D::Error::custom(format_args!("key `{key}`: {e}")))
    }

    pub fn base<'de, D: Deserializer<'de>>(d: D) -> Result<BaseKind, D::Error> {
        named(d, "base")
    }
    pub fn walls<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Walls>, D::Error> {
        named(d, "scratches.walls")
    }
    pub fn fresnel<'de, D: Deserializer<'de>>(d: D) -> Result<Option<FresnelMode>, D::Error> {
        named(d, "scratches.fresnel")
    }
    pub fn layer_mix<'de, D: Deserializer<'de>>(d: D) -> Result<Option<LayerMix>, D::Error> {
        named(d, "scratches.layer_mix")
    }
    pub fn coverage<'de, D: Deserializer<'de>>(d: D) -> Result<Option<CoverageMode>, D::Error> {
        named(d, "scratches.coverage")
    }
}

/// Where a material's table comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum TableSource {
    Compute(TableParams),
    File(PathBuf),
}

/// Everything a scratched material resolves to before its table is built.
#[derive(Clone, Debug)]
pub struct Resolved {
    pub base: ScratchedBase,
    pub tint: Rgb,
    pub table: TableSource,
    pub layers: LayerParams,
    pub layer_seed: u64,
    pub mix: LayerMix,
    pub coverage: CoverageMode,
}

/// What rendering needs: the base, the shared table, the layer set.
pub struct Prepared {
    pub base: ScratchedBase,
    pub tint: Rgb,
    pub table: Arc<ScratchLobeTable>,
    pub layers: LayerSet,
    /// Each layer's scratch direction `d_k` in texture space ([`LayerSet::direction`]), as `f32`,
    /// computed once here rather than with a `sin_cos` per hit.
    directions: Vec<[f32; 2]>,
    pub mix: LayerMix,
    pub coverage: CoverageMode,
}

impl Prepared {
    fn new(
        base: ScratchedBase,
        tint: Rgb,
        table: Arc<ScratchLobeTable>,
        layers: LayerSet,
        mix: LayerMix,
        coverage: CoverageMode,
    ) -> Prepared {
        let directions = (0..layers.len())
            .map(|k| layers.direction(k).map(|x| x as f32))
            .collect();
        Prepared {
            base,
            tint,
            table,
            layers,
            directions,
            mix,
            coverage,
        }
    }
}

impl std::fmt::Debug for Prepared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Prepared")
            .field("base", &self.base)
            .field("table", &self.table.hash())
            .field("layers", &self.layers.len())
            .field("mix", &self.mix)
            .field("coverage", &self.coverage)
            .finish()
    }
}

/// `type = "scratched"` in a scene file.
#[derive(Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScratchedMaterial {
    #[serde(deserialize_with = "keyed::base")]
    pub base: BaseKind,
    /// Glass: interior index (default 1.5; the exterior is 1).
    pub ior: Option<f32>,
    /// Metal: a conductor preset (see `material::CONDUCTOR_PRESETS`) or `eta` and `k`.
    pub preset: Option<String>,
    pub eta: Option<[f32; 3]>,
    pub k: Option<[f32; 3]>,
    #[serde(default)]
    pub scratches: ScratchSpec,
    /// Built by [`ScratchedMaterial::prepare`].
    #[serde(skip)]
    prepared: Option<Arc<Prepared>>,
}

impl std::fmt::Debug for ScratchedMaterial {
    /// Short: the material as its scene file names it, without its prepared table and layers.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{{ type = \"scratched\", base = \"{}\", .. }}",
            format!("{:?}", self.base).to_lowercase()
        )
    }
}

impl PartialEq for ScratchedMaterial {
    /// Equal descriptions (the prepared table and layers follow from them).
    fn eq(&self, o: &Self) -> bool {
        self.base == o.base
            && self.ior == o.ior
            && self.preset == o.preset
            && self.eta == o.eta
            && self.k == o.k
            && self.scratches == o.scratches
    }
}

fn invalid(
    key: &'static str,
    value: impl std::fmt::Display,
    reason: impl Into<String>,
) -> MaterialError {
    MaterialError::InvalidValue {
        key,
        value: value.to_string(),
        reason: reason.into(),
    }
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
        _ => "scratches",
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
        LayerError::Length(v) | LayerError::Width(v) | LayerError::Threshold(v) => v.to_string(),
        LayerError::LayerCount(v) => v.to_string(),
        LayerError::Setting(v) => v.to_string(),
        _ => String::new(),
    };
    invalid(key, value, e.to_string())
}

impl ScratchedMaterial {
    /// Check every key and work out the defaults (no table is computed).
    pub fn resolve(&self, base_dir: &Path) -> Result<Resolved, MaterialError> {
        let s = &self.scratches;
        let (base, tint, default_law, default_walls, default_mode) = match self.base {
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
                let law = FresnelLaw::Schlick {
                    n: s.ior.unwrap_or(ior as f64),
                };
                (
                    ScratchedBase::Glass { eta: ior },
                    Rgb::ONE,
                    law,
                    Walls::Diffuse,
                    FresnelMode::Seed,
                )
            }
            BaseKind::Metal => {
                if self.ior.is_some() {
                    return Err(invalid(
                        "ior",
                        self.ior.unwrap_or_default(),
                        "applies to base = \"glass\" only (metal takes preset or eta and k)",
                    ));
                }
                let cond = Material::Conductor {
                    preset: self.preset.clone(),
                    eta: self.eta,
                    k: self.k,
                    roughness: 0.0,
                };
                cond.validate()?;
                let Bsdf::Conductor(Conductor { ior }) = cond.bsdf_at(crate::math::Vec2::ZERO)
                else {
                    unreachable!("a smooth conductor material gives a smooth conductor BSDF")
                };
                let (law, tint) = metal_law_and_tint(&ior);
                (
                    ScratchedBase::Metal { ior },
                    tint,
                    law,
                    Walls::Specular,
                    FresnelMode::Walls,
                )
            }
        };

        // The table.
        let table_keys = [
            ("scratches.profile", s.profile.is_some()),
            ("scratches.walls", s.walls.is_some()),
            ("scratches.fresnel", s.fresnel.is_some()),
            ("scratches.fresnel_law", s.fresnel_law.is_some()),
            ("scratches.ior", s.ior.is_some()),
            ("scratches.m", s.m.is_some()),
            ("scratches.n", s.n.is_some()),
            ("scratches.nr", s.nr.is_some()),
            ("scratches.albedo", s.albedo.is_some()),
            ("scratches.max_bounces", s.max_bounces.is_some()),
            ("scratches.trace_seed", s.trace_seed.is_some()),
        ];
        let table = match &s.table {
            Some(path) => {
                if let Some((key, _)) = table_keys.iter().find(|(_, given)| *given) {
                    return Err(invalid(key, "(given)", "`scratches.table` loads a precomputed table; its parameters cannot be given too"));
                }
                TableSource::File(base_dir.join(path))
            }
            None => {
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
                let law = match &s.fresnel_law {
                    Some(text) => {
                        let n = s.ior.unwrap_or(match base {
                            ScratchedBase::Glass { eta } => eta as f64,
                            ScratchedBase::Metal { .. } => 1.5,
                        });
                        FresnelLaw::parse(text, n)
                            .map_err(|e| invalid("scratches.fresnel_law", format!("{text:?}"), e))?
                    }
                    None => default_law,
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
                let trace = TraceSettings {
                    walls: s.walls.unwrap_or(default_walls),
                    m: s.m.unwrap_or(DEFAULT_M),
                    n: s.n.unwrap_or(DEFAULT_N),
                    nr: s.nr.unwrap_or(DEFAULT_NR),
                    albedo: s.albedo.unwrap_or(1.0),
                    max_bounces: s.max_bounces.unwrap_or(64),
                    seed: s.trace_seed.unwrap_or(0),
                    fresnel_mode: s.fresnel.unwrap_or(default_mode),
                    fresnel_law: law,
                    ..TraceSettings::default()
                };
                trace.validate().map_err(|e| {
                    let TraceError::BadParameter { key, value, why } = e;
                    invalid(trace_key(key), value, why)
                })?;
                TableSource::Compute(TableParams::new(profile, trace))
            }
        };

        // The layers.
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
        Ok(Resolved {
            base,
            tint,
            table,
            layers,
            layer_seed: s.seed.unwrap_or(DEFAULT_LAYER_SEED),
            mix: s.layer_mix.unwrap_or_default(),
            coverage: s.coverage.unwrap_or_default(),
        })
    }

    /// Validate (no table is computed).
    pub fn validate(&self) -> Result<(), MaterialError> {
        self.resolve(Path::new(".")).map(|_| ())
    }

    /// Validate, then obtain the table (memory, disk cache, file or computation) and build the
    /// layer set.
    pub fn prepare(&mut self, base_dir: &Path) -> Result<(), MaterialError> {
        let r = self.resolve(base_dir)?;
        let table = match &r.table {
            TableSource::Compute(params) => obtain_table(params),
            TableSource::File(path) => load_table_file(path),
        }
        .map_err(|e| MaterialError::ScratchTable {
            key: if self.scratches.table.is_some() {
                "scratches.table"
            } else {
                "scratches"
            },
            source: Box::new(e),
        })?;
        let layers = LayerSet::new(r.layers, r.layer_seed).map_err(layer_error)?;
        self.prepared = Some(Arc::new(Prepared::new(
            r.base, r.tint, table, layers, r.mix, r.coverage,
        )));
        Ok(())
    }

    /// Build directly from parts (tests, benchmarks).
    pub fn from_parts(
        base: ScratchedBase,
        tint: Rgb,
        table: Arc<ScratchLobeTable>,
        layers: LayerSet,
        mix: LayerMix,
        coverage: CoverageMode,
    ) -> Self {
        ScratchedMaterial {
            base: match base {
                ScratchedBase::Glass { .. } => BaseKind::Glass,
                ScratchedBase::Metal { .. } => BaseKind::Metal,
            },
            ior: None,
            preset: None,
            eta: None,
            k: None,
            scratches: ScratchSpec::default(),
            prepared: Some(Arc::new(Prepared::new(
                base, tint, table, layers, mix, coverage,
            ))),
        }
    }

    pub fn prepared(&self) -> Option<&Prepared> {
        self.prepared.as_deref()
    }

    /// Whether its BSDF transmits, at every hit: glass does (scratched or not, from either
    /// side), metal does not. Read from the scene's `base`, without building the BSDF.
    #[inline]
    pub fn has_transmission(&self) -> bool {
        self.base == BaseKind::Glass
    }

    /// The smooth base's BSDF (also what an unprepared material renders as).
    #[inline]
    pub fn base_bsdf(&self) -> Bsdf<'static> {
        let base = match &self.prepared {
            Some(p) => p.base,
            None => match self.base {
                BaseKind::Glass => ScratchedBase::Glass {
                    eta: self.ior.unwrap_or(1.5),
                },
                BaseKind::Metal => ScratchedBase::Metal {
                    ior: ConductorIor {
                        eta: Rgb::ZERO,
                        k: Rgb::ONE,
                    },
                },
            },
        };
        match base {
            ScratchedBase::Glass { eta } => Bsdf::Dielectric(Dielectric::new(eta)),
            ScratchedBase::Metal { ior } => Bsdf::Conductor(Conductor { ior }),
        }
    }

    /// Whether [`Self::bsdf`] reads the pixel footprint: every coverage mode but `point`.
    pub fn reads_footprint(&self) -> bool {
        let mode = match self.prepared() {
            Some(p) => p.coverage,
            None => self.scratches.coverage.unwrap_or_default(),
        };
        mode != CoverageMode::Point
    }

    /// Whether [`Self::bsdf`] reads the hit's footprint and `u_layer` for `wo` (world, toward
    /// the viewer) and the geometric normal `ng`: not for glass seen from inside (its smooth
    /// base), nor for an unprepared material.
    #[inline]
    pub fn reads_hit_context(&self, wo: Vec3, ng: Vec3) -> bool {
        match self.prepared.as_deref() {
            Some(p) => !Self::seen_from_inside(p, wo, ng),
            None => false,
        }
    }

    /// Glass seen from inside: the scratches are on the outer side only (`bsdf::scratched`).
    #[inline]
    fn seen_from_inside(p: &Prepared, wo: Vec3, ng: Vec3) -> bool {
        matches!(p.base, ScratchedBase::Glass { .. }) && wo.dot(ng) <= 0.0
    }

    /// The BSDF at a hit (see the module notes).
    #[inline(always)]
    pub fn bsdf(&self, ctx: &ShadingContext) -> Bsdf<'_> {
        let Some(p) = self.prepared.as_deref() else {
            return self.base_bsdf();
        };
        if Self::seen_from_inside(p, ctx.wo, ctx.ng) {
            return self.base_bsdf();
        }
        let k = p.layers.len();
        let mut cov = [0.0f32; MAX_LAYERS];
        let query = match p.mix {
            LayerMix::Max => TileQuery::Max,
            LayerMix::Sum => TileQuery::All,
        };
        match p.coverage {
            CoverageMode::Footprint => match ctx.pixel {
                Some(hit) => p.layers.coverage_of_pixel(
                    ctx.uv,
                    || ctx.footprint_uv(),
                    PixelKey {
                        render: hit.render,
                        pixel: hit.pixel,
                        shape: hit.shape,
                        chain: hit.chain,
                    },
                    hit.offset,
                    query,
                    &mut cov[..k],
                ),
                None => {
                    let (duvdx, duvdy) = ctx.footprint_uv();
                    p.layers
                        .coverage_tiled(ctx.uv, duvdx, duvdy, query, &mut cov[..k])
                }
            },
            CoverageMode::Sample => {
                let (duvdx, duvdy) = ctx.footprint_uv();
                p.layers.coverage_query(
                    query,
                    ctx.uv,
                    duvdx,
                    duvdy,
                    MAX_FOOTPRINT_CELLS,
                    &mut cov[..k],
                )
            }
            CoverageMode::Point => {
                let mask = p.layers.scratched_mask(ctx.uv);
                if mask == 0 {
                    return self.base_bsdf();
                }
                for (i, c) in cov[..k].iter_mut().enumerate() {
                    *c = ((mask >> i) & 1) as f32;
                }
            }
        }
        let mut lobes = [ScratchLobe::default(); MAX_SCRATCH_LOBES];
        let count = match p.mix {
            LayerMix::Max => {
                let best = cov[..k].iter().copied().fold(0.0f32, f32::max);
                if best <= 0.0 {
                    // (`best` is never NaN: `f32::max` drops NaN.)
                    return self.base_bsdf();
                }
                // Ties (several scratches crossing the footprint equally): one at random.
                // `c > 0`: with a tiny best (a disc grazing the footprint) an uncovered layer
                // must not count as a tie. The ties as a bit mask (one pass, no branch per
                // layer), the pick as its `pick`-th set bit.
                const _: () = assert!(MAX_LAYERS <= 64);
                let ties = cov[..k].iter().enumerate().fold(0u64, |mask, (i, &c)| {
                    mask | (((c > 0.0) & (c >= best - 1e-6)) as u64) << i
                });
                let count = ties.count_ones();
                let layer = if count == 1 {
                    ties.trailing_zeros() as usize
                } else {
                    let pick = ((ctx.u_layer * count as f32) as u32).min(count - 1);
                    let mut rest = ties;
                    for _ in 0..pick {
                        rest &= rest - 1;
                    }
                    rest.trailing_zeros() as usize
                };
                lobes[0] = lobe(p, ctx, layer, cov[layer]);
                1
            }
            LayerMix::Sum => {
                let mut order: [usize; MAX_LAYERS] = std::array::from_fn(|i| i);
                let covered = {
                    let mut n = 0;
                    for (i, &c) in cov[..k].iter().enumerate() {
                        if c > 0.0 {
                            order[n] = i;
                            n += 1;
                        }
                    }
                    n
                };
                if covered == 0 {
                    return self.base_bsdf();
                }
                if covered > MAX_SCRATCH_LOBES {
                    order[..covered].sort_by(|&a, &b| cov[b].total_cmp(&cov[a]).then(a.cmp(&b)));
                }
                let n = covered.min(MAX_SCRATCH_LOBES);
                for j in 0..n {
                    lobes[j] = lobe(p, ctx, order[j], cov[order[j]]);
                }
                n
            }
        };
        // The integrator evaluates and samples it with `wo` in this frame: precompute the
        // first lobe's `wo` terms once (`ScratchedBsdf::at_wo`; the same results bit for bit).
        Bsdf::Scratched(
            ScratchedBsdf::new(p.base, &p.table, p.tint, &lobes[..count])
                .at_wo(ctx.frame.to_local(ctx.wo)),
        )
    }
}

/// Scratch lobe of `layer` with coverage `c`: `t = d.x dP/du + d.y dP/dv` in the shading
/// plane, as `(cos beta, sin beta)` against the frame's `s` axis (METHOD.md section 1).
fn lobe(p: &Prepared, ctx: &ShadingContext, layer: usize, c: f32) -> ScratchLobe {
    let d = p.directions[layer];
    let t: Vec3 = ctx.dpdu * d[0] + ctx.dpdv * d[1];
    let (x, y) = (t.dot(ctx.frame.s), t.dot(ctx.frame.t));
    let len = (x * x + y * y).sqrt();
    let (cos, sin) = if len > 1e-20 && len.is_finite() {
        (x / len, y / len)
    } else {
        (1.0, 0.0)
    };
    ScratchLobe {
        coverage: c,
        cos,
        sin,
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

/// The on-disk table cache: `$STRIAE_CACHE`, else `$XDG_CACHE_HOME/striae`, else
/// `~/.cache/striae` (`None` if none can be named).
pub fn cache_dir() -> Option<PathBuf> {
    let var = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    var("STRIAE_CACHE")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("striae")))
        .or_else(|| var("HOME").map(|h| h.join(".cache").join("striae")))
}

/// The cache file of a table: `scratch-table-HASH.npz`.
pub fn cache_file(dir: &Path, hash: &str) -> PathBuf {
    dir.join(format!("scratch-table-{hash}.npz"))
}

fn registry() -> &'static Mutex<HashMap<String, Weak<ScratchLobeTable>>> {
    static REGISTRY: OnceLock<Mutex<HashMap<String, Weak<ScratchLobeTable>>>> = OnceLock::new();
    REGISTRY.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The table of `params`: shared in memory if a live one has the same hash, else read from the
/// disk cache, else computed (and cached, atomically). The registry lock is held meanwhile, so
/// two materials needing one table compute it once.
pub fn obtain_table(params: &TableParams) -> Result<Arc<ScratchLobeTable>, TableError> {
    let hash = params.hash();
    let mut reg = registry().lock().unwrap_or_else(|e| e.into_inner());
    if let Some(t) = reg.get(&hash).and_then(Weak::upgrade) {
        return Ok(t);
    }
    let table = load_or_compute(params, &hash, cache_dir().as_deref())?;
    let t = Arc::new(ScratchLobeTable::new(table));
    reg.retain(|_, w| w.strong_count() > 0);
    reg.insert(hash, Arc::downgrade(&t));
    Ok(t)
}

/// Read a table file (shared in memory by its parameter hash like computed ones).
pub fn load_table_file(path: &Path) -> Result<Arc<ScratchLobeTable>, TableError> {
    let table = ScratchTable::load(path)?;
    let hash = table.params.hash();
    let mut reg = registry().lock().unwrap_or_else(|e| e.into_inner());
    if let Some(t) = reg.get(&hash).and_then(Weak::upgrade) {
        return Ok(t);
    }
    let t = Arc::new(ScratchLobeTable::new(table));
    reg.insert(hash, Arc::downgrade(&t));
    Ok(t)
}

/// The disk-cache step of [`obtain_table`] with an explicit cache folder (`None`: no cache).
pub fn load_or_compute(
    params: &TableParams,
    hash: &str,
    dir: Option<&Path>,
) -> Result<ScratchTable, TableError> {
    if let Some(dir) = dir {
        let file = cache_file(dir, hash);
        if file.exists() {
            match ScratchTable::load(&file) {
                Ok(t) if t.params.hash() == hash => return Ok(t),
                Ok(_) => eprintln!(
                    "striae: warning: cached table {} holds other parameters; recomputing it",
                    file.display()
                ),
                Err(e) => {
                    eprintln!("striae: warning: cached table unreadable ({e}); recomputing it")
                }
            }
        }
    }
    let start = std::time::Instant::now();
    let t = &params.trace;
    eprintln!(
        "striae: computing scratch table {} ({}, {:?} walls, M {} N {} N_r {}) ...",
        &hash[..12],
        params.profile.spec,
        t.walls,
        t.m,
        t.n,
        t.nr
    );
    let table = ScratchTable::compute(params, &|_| {})?;
    eprintln!(
        "striae: scratch table {} computed in {:.2} s",
        &hash[..12],
        start.elapsed().as_secs_f64()
    );
    if let Some(dir) = dir {
        // A name unique to this process and call, then a rename: concurrent writers of the same
        // table (tests, two renders) never see a half-written file.
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let tmp = dir.join(format!(
            ".{hash}.{}-{}.npz",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let result = std::fs::create_dir_all(dir)
            .map_err(|e| TableError::Io {
                path: dir.to_path_buf(),
                source: e,
            })
            .and_then(|_| table.save(&tmp))
            .and_then(|_| {
                std::fs::rename(&tmp, cache_file(dir, hash)).map_err(|e| TableError::Io {
                    path: cache_file(dir, hash),
                    source: e,
                })
            });
        if let Err(e) = result {
            let _ = std::fs::remove_file(&tmp);
            eprintln!("striae: warning: could not cache the scratch table ({e})");
        }
    }
    Ok(table)
}

#[cfg(test)]
mod tests;
