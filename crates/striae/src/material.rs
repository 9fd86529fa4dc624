//! Scene-level material descriptions (deserialised from the scene file's `[[material]]`
//! tables), validated, and turned into a [`Bsdf`] at a surface point's texture coordinates.
//!
//! ```toml
//! type = "diffuse"
//! reflectance = [0.8, 0.8, 0.8]          # or a grey number, or a texture table (see texture)
//!
//! type = "dielectric"
//! ior = 1.5                              # interior index (default 1.5)
//! ext_ior = 1.0                          # exterior index (default 1.0)
//! roughness = 0.0                        # GGX alpha; > 0 makes it a rough dielectric
//!
//! type = "conductor"
//! preset = "gold"                        # or eta = [r, g, b] and k = [r, g, b]
//! roughness = 0.0                        # GGX alpha; > 0 makes it a rough conductor
//!
//! type = "scratched"                     # issue 5: glass or metal with scratches, see
//! base = "glass"                         # `crate::scratched` and docs/scratched.md
//! ```
//!
//! `roughness` is the GGX `alpha` (Mitsuba's `alpha`, not squared). Mitsuba's dielectric
//! defaults differ from ours (`int_ior` 1.5046, `ext_ior` 1.000277): set both explicitly in
//! both renderers when comparing.
//!
//! Conductor presets and their sources are listed in [`CONDUCTOR_PRESETS`]. `preset = "none"`
//! is Mitsuba 3's perfect mirror (`eta = 0, k = 1`: `F = 1` at every angle) for furnace tests.
//!
//! The `scratched` variant holds its prepared table and layers; at a hit the scene asks it
//! for its BSDF with the whole shading context (`scene::material_bsdf`).

use crate::bsdf::{Bsdf, Conductor, Dielectric, Diffuse, RoughConductor, RoughDielectric};
use crate::math::{Rgb, Vec2, Vec3};
use crate::texture::{Texture, TextureError};
use serde::Deserialize;
use std::path::Path;

/// A material description that is out of range or refers to something unknown. The message
/// names the key and the value; the scene loader adds the file (and material index).
#[derive(Debug, thiserror::Error)]
pub enum MaterialError {
    #[error("invalid `{key}` = {value}: {reason}")]
    InvalidValue {
        key: &'static str,
        value: String,
        reason: String,
    },
    #[error("unknown conductor `preset` = \"{value}\"; known presets: {known}")]
    UnknownPreset { value: String, known: String },
    #[error("conductor needs either `preset` or both `eta` and `k` ({reason})")]
    ConductorIor { reason: &'static str },
    #[error("texture `{key}`: {source}")]
    Texture {
        key: &'static str,
        source: TextureError,
    },
    /// The scratched material's table could not be obtained (issue 5).
    #[error("`{key}`: {source}")]
    ScratchTable {
        key: &'static str,
        source: Box<crate::table::TableError>,
    },
}

/// A named complex IOR for a conductor: `(names, eta, k)` in linear RGB.
pub type ConductorPreset = (&'static [&'static str], [f32; 3], [f32; 3]);

/// Conductor presets, `(names, eta, k)` per linear RGB channel.
///
/// Source for Ag, Al, Au, Cr, Cu: Tungsten's `ComplexIorData.hpp` (Bitterli), the spectral
/// data Mitsuba 3's `conductor` presets are built from (Mitsuba's `data/ior/*.spd`, from
/// Palik's handbook) integrated to linear sRGB. Fe: refractiveindex.info (Johnson and Christy
/// 1974) sampled at 650 / 550 / 450 nm; Mitsuba has no iron preset, so "steel" and "iron" are
/// not validated against it. `none`: Mitsuba's perfect mirror.
pub const CONDUCTOR_PRESETS: &[ConductorPreset] = &[
    (&["none", "mirror"], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
    (
        &["Au", "gold"],
        [0.143_118_96, 0.374_957_04, 1.442_478_6],
        [3.983_160_4, 2.385_720_7, 1.603_215_3],
    ),
    (
        &["Ag", "silver"],
        [0.155_264_65, 0.116_723_3, 0.138_380_7],
        [4.828_343_3, 3.122_245_8, 2.146_950_4],
    ),
    (
        &["Cu", "copper"],
        [0.200_437_7, 0.924_033_4, 1.102_212],
        [3.912_948_6, 2.452_847_7, 2.142_188],
    ),
    (
        &["Al", "aluminium", "aluminum"],
        [1.657_46, 0.880_368_96, 0.521_228_7],
        [9.223_869, 6.269_523_4, 4.837_001],
    ),
    (
        &["Cr", "chromium", "chrome"],
        [4.369_683, 2.916_702_5, 1.654_700_5],
        [5.206_434, 4.231_364_7, 3.754_946_7],
    ),
    (
        &["Fe", "iron", "steel"],
        [2.9114, 2.9497, 2.5845],
        [3.0893, 2.9318, 2.7670],
    ),
];

/// Look a conductor preset up by any of its names (case-insensitive).
pub fn conductor_preset(name: &str) -> Option<(Rgb, Rgb)> {
    CONDUCTOR_PRESETS
        .iter()
        .find(|(names, _, _)| names.iter().any(|n| n.eq_ignore_ascii_case(name)))
        .map(|(_, eta, k)| (Rgb::from(*eta), Rgb::from(*k)))
}

fn default_reflectance() -> Texture {
    Texture::Constant(Rgb::splat(0.5))
}
fn default_ior() -> f32 {
    1.5
}
fn one() -> f32 {
    1.0
}

/// A material as written in a scene file.
// One per material of a scene, read in place by the render loop: the size difference between
// the variants costs nothing, a box would add an indirection at every hit.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Material {
    /// Lambertian; `reflectance` in `[0, 1]` (default 0.5 grey).
    Diffuse {
        #[serde(default = "default_reflectance")]
        reflectance: Texture,
    },
    /// A dielectric interface with relative index `ior / ext_ior`; GGX `roughness` (alpha,
    /// default 0 = smooth).
    Dielectric {
        #[serde(default = "default_ior")]
        ior: f32,
        #[serde(default = "one")]
        ext_ior: f32,
        #[serde(default)]
        roughness: f32,
    },
    /// A conductor given by a `preset` name or by `eta` and `k`; GGX `roughness` (alpha,
    /// default 0 = smooth).
    Conductor {
        #[serde(default)]
        preset: Option<String>,
        #[serde(default)]
        eta: Option<[f32; 3]>,
        #[serde(default)]
        k: Option<[f32; 3]>,
        #[serde(default)]
        roughness: f32,
    },
    /// A smooth glass or metal base with scratches (issue 5, [`crate::scratched`]).
    Scratched(crate::scratched::ScratchedMaterial),
}

fn check_roughness(roughness: f32) -> Result<(), MaterialError> {
    if !(roughness.is_finite() && roughness >= 0.0) {
        return Err(MaterialError::InvalidValue {
            key: "roughness",
            value: roughness.to_string(),
            reason: "must be a finite GGX alpha >= 0 (0 = smooth)".into(),
        });
    }
    Ok(())
}

fn fmt3(v: [f32; 3]) -> String {
    format!("[{}, {}, {}]", v[0], v[1], v[2])
}

impl Material {
    /// Whether the material's BSDF transmits: [`Bsdf::has_transmission`] of the BSDF it gives at
    /// any hit, known before that BSDF is built (the integrator chooses the shading frame's
    /// side with it).
    #[inline]
    pub fn has_transmission(&self) -> bool {
        match self {
            Material::Dielectric { .. } => true,
            Material::Diffuse { .. } | Material::Conductor { .. } => false,
            Material::Scratched(m) => m.has_transmission(),
        }
    }

    /// Whether the material's BSDF reads the pixel footprint (`ShadingContext::duvdx`,
    /// `duvdy`): only the scratched material filters over it (not with `coverage = "point"`).
    /// When no material of a scene does, the integrator skips ray differentials altogether.
    pub fn reads_footprint(&self) -> bool {
        match self {
            Material::Scratched(m) => m.reads_footprint(),
            _ => false,
        }
    }

    /// Whether the BSDF at a hit seen from `wo` (world, toward the viewer) with geometric
    /// normal `ng` reads the footprint's `duvdx`, `duvdy` and `u_layer`: the scratched
    /// material's, except glass seen from inside (its smooth base). The integrator computes
    /// neither where it does not (the image does not change).
    #[inline]
    pub fn reads_hit_context(&self, wo: Vec3, ng: Vec3) -> bool {
        match self {
            Material::Scratched(m) => m.reads_hit_context(wo, ng),
            _ => false,
        }
    }

    /// Check every value's range (IOR >= 1, roughness >= 0, albedo in `[0, 1]`, a known
    /// preset or a complete `eta`/`k`). Image textures are checked once loaded.
    pub fn validate(&self) -> Result<(), MaterialError> {
        match self {
            Material::Diffuse { reflectance } => {
                if let Texture::Checkerboard { scale, .. } | Texture::Image { scale, .. } =
                    reflectance
                {
                    if !(scale.is_finite() && *scale != 0.0) {
                        return Err(MaterialError::InvalidValue {
                            key: "reflectance.scale",
                            value: scale.to_string(),
                            reason: "must be finite and non-zero".into(),
                        });
                    }
                }
                if let Some((lo, hi)) = reflectance.range() {
                    if !(lo >= 0.0 && hi <= 1.0) {
                        let value = match reflectance {
                            Texture::Constant(c) => fmt3(c.to_array()),
                            Texture::Checkerboard { color0, color1, .. } => {
                                format!("{} / {}", fmt3(color0.to_array()), fmt3(color1.to_array()))
                            }
                            Texture::Image { path, .. } => {
                                format!("image `{}` (values {lo} .. {hi})", path.display())
                            }
                        };
                        return Err(MaterialError::InvalidValue {
                            key: "reflectance",
                            value,
                            reason: "a diffuse albedo must lie in [0, 1]".into(),
                        });
                    }
                }
                Ok(())
            }
            Material::Dielectric {
                ior,
                ext_ior,
                roughness,
            } => {
                for (key, v) in [("ior", *ior), ("ext_ior", *ext_ior)] {
                    if !(v.is_finite() && v >= 1.0) {
                        return Err(MaterialError::InvalidValue {
                            key,
                            value: v.to_string(),
                            reason: "an index of refraction must be finite and >= 1".into(),
                        });
                    }
                }
                check_roughness(*roughness)
            }
            Material::Conductor { roughness, .. } => {
                self.conductor_ior()?;
                check_roughness(*roughness)
            }
            Material::Scratched(m) => m.validate(),
        }
    }

    /// Validate and load image textures (paths relative to `base_dir`, the scene file's folder).
    /// A scratched material also obtains its table (cache or computation) and layers here.
    pub fn prepare(&mut self, base_dir: &Path) -> Result<(), MaterialError> {
        if let Material::Scratched(m) = self {
            return m.prepare(base_dir);
        }
        if let Material::Diffuse { reflectance } = self {
            reflectance
                .load_images(base_dir)
                .map_err(|source| MaterialError::Texture {
                    key: "reflectance",
                    source,
                })?;
        }
        self.validate()
    }

    /// A conductor's complex IOR from its preset or explicit values.
    fn conductor_ior(&self) -> Result<(Rgb, Rgb), MaterialError> {
        let Material::Conductor { preset, eta, k, .. } = self else {
            unreachable!("conductor_ior on a non-conductor")
        };
        let (eta, k) = match (preset, eta, k) {
            (Some(name), None, None) => {
                conductor_preset(name).ok_or_else(|| MaterialError::UnknownPreset {
                    value: name.clone(),
                    known: CONDUCTOR_PRESETS
                        .iter()
                        .map(|(n, _, _)| n.join("|"))
                        .collect::<Vec<_>>()
                        .join(", "),
                })?
            }
            (None, Some(eta), Some(k)) => (Rgb::from(*eta), Rgb::from(*k)),
            (Some(_), _, _) => {
                return Err(MaterialError::ConductorIor {
                    reason: "`preset` excludes `eta` and `k`",
                })
            }
            (None, _, _) => {
                return Err(MaterialError::ConductorIor {
                    reason: "give both `eta` and `k`",
                })
            }
        };
        for (key, v) in [("eta", eta), ("k", k)] {
            if !(v.is_finite() && v.min_element() >= 0.0) {
                return Err(MaterialError::InvalidValue {
                    key,
                    value: fmt3(v.to_array()),
                    reason: "must be finite and >= 0".into(),
                });
            }
        }
        if (0..3).any(|c| eta[c] == 0.0 && k[c] == 0.0) {
            return Err(MaterialError::InvalidValue {
                key: "eta",
                value: fmt3(eta.to_array()),
                reason: "eta and k cannot both be 0 in a channel".into(),
            });
        }
        Ok((eta, k))
    }

    /// The BSDF at texture coordinates `uv`. Call on a validated material (an invalid
    /// conductor falls back to the perfect mirror).
    /// A scratched material gives its smooth base here (its scratches need the whole
    /// shading context: `scene::material_bsdf`).
    #[inline(always)]
    pub fn bsdf_at(&self, uv: Vec2) -> Bsdf<'_> {
        match self {
            Material::Diffuse { reflectance } => Bsdf::Diffuse(Diffuse::new(reflectance.eval(uv))),
            Material::Dielectric {
                ior,
                ext_ior,
                roughness,
            } => {
                let eta = ior / ext_ior;
                if *roughness > 0.0 {
                    Bsdf::RoughDielectric(RoughDielectric::new(eta, *roughness))
                } else {
                    Bsdf::Dielectric(Dielectric::new(eta))
                }
            }
            Material::Conductor { roughness, .. } => {
                let (eta, k) = self.conductor_ior().unwrap_or((Rgb::ZERO, Rgb::ONE));
                if *roughness > 0.0 {
                    Bsdf::RoughConductor(RoughConductor::new(eta, k, *roughness))
                } else {
                    Bsdf::Conductor(Conductor::new(eta, k))
                }
            }
            Material::Scratched(m) => m.base_bsdf(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<Material, String> {
        let m: Material = toml::from_str(s).map_err(|e| e.to_string())?;
        m.validate().map_err(|e| e.to_string())?;
        Ok(m)
    }

    #[test]
    fn good_materials_parse_into_the_right_bsdf() {
        let uv = Vec2::new(0.3, 0.6);
        let m = parse("type = \"dielectric\"\nior = 1.5").unwrap();
        assert!(matches!(m.bsdf_at(uv), Bsdf::Dielectric(d) if d.eta == 1.5));
        let m = parse("type = \"dielectric\"\nior = 1.5046\next_ior = 1.000277\nroughness = 0.1")
            .unwrap();
        assert!(
            matches!(m.bsdf_at(uv), Bsdf::RoughDielectric(d) if (d.eta - 1.5046 / 1.000277).abs() < 1e-6)
        );
        let m = parse("type = \"conductor\"\npreset = \"gold\"").unwrap();
        let Bsdf::Conductor(c) = m.bsdf_at(uv) else {
            panic!()
        };
        assert_eq!(c.ior.eta, conductor_preset("Au").unwrap().0);
        let m = parse(
            "type = \"conductor\"\neta = [0.2, 0.9, 1.1]\nk = [3.9, 2.4, 2.1]\nroughness = 0.3",
        )
        .unwrap();
        assert!(matches!(m.bsdf_at(uv), Bsdf::RoughConductor(_)));
        let m = parse("type = \"diffuse\"\nreflectance = [0.2, 0.4, 0.6]").unwrap();
        assert!(
            matches!(m.bsdf_at(uv), Bsdf::Diffuse(d) if d.reflectance == Rgb::new(0.2, 0.4, 0.6))
        );
        let m = parse("type = \"diffuse\"\nreflectance = { type = \"checkerboard\", color0 = [1, 1, 1], color1 = [0, 0, 0] }").unwrap();
        assert!(
            matches!(m.bsdf_at(Vec2::new(0.1, 0.1)), Bsdf::Diffuse(d) if d.reflectance == Rgb::ONE)
        );
        assert!(
            matches!(m.bsdf_at(Vec2::new(0.6, 0.1)), Bsdf::Diffuse(d) if d.reflectance == Rgb::ZERO)
        );
        // Every preset resolves, and none reflects more than all of the light.
        for (names, _, _) in CONDUCTOR_PRESETS {
            for n in *names {
                let m = parse(&format!("type = \"conductor\"\npreset = \"{n}\"")).unwrap();
                let Bsdf::Conductor(c) = m.bsdf_at(uv) else {
                    panic!()
                };
                for cos in [1.0, 0.5, 0.1] {
                    let f = c.ior.fresnel(cos);
                    assert!(
                        f.min_element() > 0.3 && f.max_element() <= 1.0 + 1e-5,
                        "{n}: {f:?}"
                    );
                }
            }
        }
        // The "none" preset is a perfect mirror.
        let Bsdf::Conductor(c) = parse("type = \"conductor\"\npreset = \"none\"")
            .unwrap()
            .bsdf_at(uv)
        else {
            panic!()
        };
        for cos in [1.0, 0.7, 0.2, 0.01] {
            assert!((c.ior.fresnel(cos) - Rgb::ONE).abs().max_element() < 1e-6);
        }
    }

    #[test]
    fn bad_materials_are_rejected_with_key_and_value() {
        let cases = [
            ("type = \"dielectric\"\nior = 0.8", &["`ior`", "0.8", ">= 1"][..]),
            ("type = \"dielectric\"\next_ior = 0.5", &["`ext_ior`", "0.5"]),
            ("type = \"dielectric\"\nroughness = -0.1", &["`roughness`", "-0.1"]),
            ("type = \"conductor\"\npreset = \"gold\"\nroughness = -1", &["`roughness`", "-1"]),
            ("type = \"conductor\"\npreset = \"unobtainium\"", &["unobtainium", "preset", "gold"]),
            ("type = \"conductor\"\neta = [1, 1, 1]", &["`eta` and `k`"]),
            ("type = \"conductor\"\npreset = \"gold\"\neta = [1, 1, 1]", &["excludes"]),
            ("type = \"conductor\"\neta = [1, -1, 1]\nk = [1, 1, 1]", &["`eta`", "-1"]),
            ("type = \"diffuse\"\nreflectance = [0.5, 1.2, 0.5]", &["`reflectance`", "1.2", "[0, 1]"]),
            ("type = \"diffuse\"\nreflectance = -0.5", &["`reflectance`", "-0.5"]),
            (
                "type = \"diffuse\"\nreflectance = { type = \"checkerboard\", color0 = [2, 1, 1], color1 = [0, 0, 0] }",
                &["`reflectance`", "2"],
            ),
            ("type = \"diffuse\"\nalbedo = 0.5", &["albedo"]),
            ("type = \"dielectric\"\nior = 1.5\nroughnes = 0.1", &["roughnes"]),
            ("type = \"plastic\"", &["plastic"]),
            ("ior = 1.5", &["type"]),
        ];
        for (src, needles) in cases {
            let e = parse(src).expect_err(src);
            for n in needles {
                assert!(e.contains(n), "error for {src:?} should mention {n:?}: {e}");
            }
        }
    }

    #[test]
    fn prepare_loads_images_and_names_missing_files() {
        let dir = std::env::temp_dir().join(format!("striae-material-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut m: Material = toml::from_str(
            "type = \"diffuse\"\nreflectance = { type = \"image\", path = \"missing.png\" }",
        )
        .unwrap();
        let e = m.prepare(&dir).unwrap_err().to_string();
        assert!(
            e.contains("missing.png") && e.contains("reflectance"),
            "{e}"
        );
        image::RgbImage::from_pixel(1, 1, image::Rgb([255, 255, 255]))
            .save(dir.join("white.png"))
            .unwrap();
        let mut m: Material = toml::from_str(
            "type = \"diffuse\"\nreflectance = { type = \"image\", path = \"white.png\" }",
        )
        .unwrap();
        m.prepare(&dir).unwrap();
        assert!(
            matches!(m.bsdf_at(Vec2::splat(0.3)), Bsdf::Diffuse(d) if d.reflectance == Rgb::ONE)
        );
        std::fs::remove_dir_all(&dir).ok();
    }
}
