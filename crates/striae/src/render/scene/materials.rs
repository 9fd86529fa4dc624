//! Materials as a scene file describes them (`[materials.NAME]` tables): plain data, validated
//! once and prepared into the immutable runtime [`Material`] (presets resolved, textures
//! loaded, scratch tables and layers attached).
//!
//! ```toml
//! type = "diffuse"
//! reflectance = [0.8, 0.8, 0.8]          # or a grey number, or a texture table (see texture)
//!
//! type = "dielectric"
//! ior = 1.5                              # interior index (default 1.5)
//! ext_ior = 1.0                          # exterior index (default 1.0)
//! roughness = 0.0                        # GGX alpha; > 0 makes it a rough dielectric
//! multiscatter = false                   # restore the energy single scattering loses
//!
//! type = "conductor"
//! preset = "gold"                        # or eta = [r, g, b] and k = [r, g, b]
//! roughness = 0.0                        # GGX alpha; > 0 makes it a rough conductor
//! multiscatter = false                   # restore the energy single scattering loses
//!
//! type = "scratched"                     # glass or metal with scratches: see
//! base = "glass"                         # `scene::scratches` and docs/scratched.md
//!
//! type = "pbr"                           # glTF 2.0 metallic-roughness (PbrDesc); defaults glTF's
//! base_color = [0.8, 0.8, 0.8]           # [0, 1], a texture as reflectance (default 1)
//! metallic = 0.0                         # [0, 1] (default 1)
//! roughness = 0.5                        # perceptual, [0, 1]: alpha = roughness^2 (default 1)
//! metallic_roughness = { type = "image", path = "mr.png", srgb = false } # G: roughness, B: metallic
//! normal_map = { type = "image", path = "n.png", srgb = false }          # tangent space, +y green
//! normal_scale = 1.0                     # (default 1)
//! ior = 1.5                              # >= 1 (default 1.5)
//! transmission = 0.0                     # [0, 1] (default 0)
//! attenuation_color = [1, 1, 1]          # (0, 1] per channel (default white)
//! attenuation_distance = 1.0             # > 0; left out: no absorption (the default)
//! anisotropy = 0.0                       # KHR_materials_anisotropy strength, [0, 1] (default 0)
//! anisotropy_rotation = 0.0              # degrees from dP/du (default 0)
//! ```
//!
//! `type = "pbr"` is glTF 2.0's material (section 3.9.2, Appendix B) with the transmission,
//! IOR, volume and anisotropy extensions ([`PbrDesc`]; the BSDF and its departures from
//! Appendix B in [`crate::render::bsdf::pbr`]). Its `roughness` is glTF's perceptual roughness
//! (GGX `alpha = roughness^2`), unlike the other materials' `roughness`, which is `alpha`.
//! `attenuation_distance` makes the object's inside absorb, `sigma_a =
//! -ln(attenuation_color) / attenuation_distance` (KHR_materials_volume), applied by the
//! integrator to path segments that end on the back side of the surface
//! ([`Material::absorption`]). Image textures the glTF importer has already decoded
//! (`Texture::Image` with `image: Some(..)`) are kept as they are by
//! [`PbrDesc::prepare`].
//!
//! `roughness` is the GGX `alpha` (Mitsuba's `alpha`, not squared). Mitsuba's dielectric
//! defaults differ from ours (`int_ior` 1.5046, `ext_ior` 1.000277): set both explicitly in
//! both renderers when comparing. Conductor presets and their sources are listed in
//! [`crate::render::bsdf::CONDUCTOR_PRESETS`].
//!
//! `multiscatter = true` adds to a rough dielectric or conductor the light its single
//! scattering loses to shadowing and masking (module [`crate::render::bsdf::multiscatter`]):
//! a white furnace then renders 1. It departs from Mitsuba 3 (whose `roughdielectric` and
//! `roughconductor` scatter once), so the default is `false`. With `roughness = 0` it is
//! accepted and changes nothing: a smooth interface loses no energy.

use super::scratches::ScratchedDesc;
use crate::math::Rgb;
use crate::render::bsdf::{ConductorCompensation, ConductorIor, DielectricCompensation};
use crate::render::material::{Material, PbrMaterial};
use crate::render::texture::{Texture, TextureError};
use serde::Deserialize;
use std::path::Path;

/// A material description that is out of range or refers to something unknown. The message
/// names the key and the value; the scene loader adds the file (and material name).
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
    /// The scratched material's table could not be obtained.
    #[error("`{key}`: {source}")]
    ScratchTable {
        key: &'static str,
        source: Box<crate::precompute::table::TableError>,
    },
}

/// [`MaterialError::InvalidValue`].
pub(crate) fn invalid(
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

fn default_reflectance() -> Texture {
    Texture::Constant(Rgb::splat(0.5))
}
fn default_ior() -> f32 {
    1.5
}
fn one() -> f32 {
    1.0
}

/// A material as written in a scene file: a table whose `type` picks the variant
/// ([`MaterialDesc::from_table`]).
// Read once, at load time: the size difference between the variants does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Deserialize)]
// `remote = "Self"`: the derive makes the inherent `MaterialDesc::deserialize` of the
// externally tagged form (`{ scratched = { ... } }`), which `from_table` calls; the trait impl
// below reads the scene's form.
#[serde(remote = "Self", rename_all = "snake_case", deny_unknown_fields)]
pub enum MaterialDesc {
    /// Lambertian; `reflectance` in `[0, 1]` (default 0.5 grey).
    Diffuse {
        #[serde(default = "default_reflectance")]
        reflectance: Texture,
    },
    /// A dielectric interface with relative index `ior / ext_ior`; GGX `roughness` (alpha,
    /// default 0 = smooth); `multiscatter` energy compensation (default false).
    Dielectric {
        #[serde(default = "default_ior")]
        ior: f32,
        #[serde(default = "one")]
        ext_ior: f32,
        #[serde(default)]
        roughness: f32,
        #[serde(default)]
        multiscatter: bool,
    },
    /// A conductor given by a `preset` name or by `eta` and `k`; GGX `roughness` (alpha,
    /// default 0 = smooth); `multiscatter` energy compensation (default false).
    Conductor {
        #[serde(default)]
        preset: Option<String>,
        #[serde(default, deserialize_with = "crate::strict_array::optional")]
        eta: Option<[f32; 3]>,
        #[serde(default, deserialize_with = "crate::strict_array::optional")]
        k: Option<[f32; 3]>,
        #[serde(default)]
        roughness: f32,
        #[serde(default)]
        multiscatter: bool,
    },
    /// A smooth glass or metal base with scratches ([`ScratchedDesc`]).
    Scratched(ScratchedDesc),
    /// glTF 2.0's metallic-roughness material with its transmission, IOR, volume and
    /// anisotropy extensions ([`PbrDesc`]).
    Pbr(PbrDesc),
}

fn white() -> Texture {
    Texture::Constant(Rgb::ONE)
}
fn one_rgb() -> [f32; 3] {
    [1.0, 1.0, 1.0]
}

/// `type = "pbr"`: glTF 2.0's metallic-roughness material (glTF 2.0 section 3.9.2 and
/// Appendix B) with KHR_materials_transmission, KHR_materials_ior, KHR_materials_volume's
/// absorption and KHR_materials_anisotropy. Every default is glTF's. The BSDF is
/// [`crate::render::bsdf::Pbr`]; the prepared material [`crate::render::material::PbrMaterial`].
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PbrDesc {
    /// `baseColorFactor` times `baseColorTexture` (images decoded sRGB to linear), in `[0, 1]`
    /// (default white).
    #[serde(default = "white")]
    pub base_color: Texture,
    /// `metallicFactor` in `[0, 1]` (default 1).
    #[serde(default = "one")]
    pub metallic: f32,
    /// `roughnessFactor`, glTF's perceptual roughness in `[0, 1]` (default 1); GGX
    /// `alpha = roughness^2`.
    #[serde(default = "one")]
    pub roughness: f32,
    /// `metallicRoughnessTexture`: its green channel multiplies `roughness`, its blue channel
    /// `metallic`. An image without `srgb` is read as linear data.
    #[serde(default)]
    pub metallic_roughness: Option<Texture>,
    /// `normalTexture` (tangent space, glTF's convention: red along `dP/du`, green toward
    /// decreasing `v`, the image's up). An image without `srgb` is read as linear data.
    #[serde(default)]
    pub normal_map: Option<Texture>,
    /// `normalTexture.scale` (default 1): scales the map's tangent components.
    #[serde(default = "one")]
    pub normal_scale: f32,
    /// KHR_materials_ior's `ior` (default 1.5, >= 1); the outside is taken as vacuum.
    #[serde(default = "default_ior")]
    pub ior: f32,
    /// KHR_materials_transmission's `transmissionFactor` in `[0, 1]` (default 0).
    #[serde(default)]
    pub transmission: f32,
    /// KHR_materials_volume's `attenuationColor`, each channel in `(0, 1]` (default white).
    #[serde(default = "one_rgb", deserialize_with = "crate::strict_array::exact")]
    pub attenuation_color: [f32; 3],
    /// KHR_materials_volume's `attenuationDistance` (> 0; default none: no absorption).
    #[serde(default)]
    pub attenuation_distance: Option<f32>,
    /// KHR_materials_anisotropy's `anisotropyStrength` in `[0, 1]` (default 0).
    #[serde(default)]
    pub anisotropy: f32,
    /// KHR_materials_anisotropy's `anisotropyRotation`, in degrees here (default 0):
    /// the anisotropy direction turned from `dP/du` toward the bitangent.
    #[serde(default)]
    pub anisotropy_rotation: f32,
}

impl Default for PbrDesc {
    /// glTF's default material (white, metallic 1, roughness 1).
    fn default() -> Self {
        PbrDesc {
            base_color: white(),
            metallic: 1.0,
            roughness: 1.0,
            metallic_roughness: None,
            normal_map: None,
            normal_scale: 1.0,
            ior: 1.5,
            transmission: 0.0,
            attenuation_color: one_rgb(),
            attenuation_distance: None,
            anisotropy: 0.0,
            anisotropy_rotation: 0.0,
        }
    }
}

/// The scale check and the `[0, 1]` range check of a texture (images only once loaded).
fn check_unit_texture(
    key: &'static str,
    scale_key: &'static str,
    texture: &Texture,
) -> Result<(), MaterialError> {
    if let Texture::Checkerboard { scale, .. } | Texture::Image { scale, .. } = texture {
        if !(scale.is_finite() && *scale != 0.0) {
            return Err(invalid(scale_key, scale, "must be finite and non-zero"));
        }
    }
    if let Some((lo, hi)) = texture.range() {
        if !(lo >= 0.0 && hi <= 1.0) {
            let value = match texture {
                Texture::Constant(c) => fmt3(c.to_array()),
                Texture::Checkerboard { color0, color1, .. } => {
                    format!("{} / {}", fmt3(color0.to_array()), fmt3(color1.to_array()))
                }
                Texture::Image { path, .. } => {
                    format!("image `{}` (values {lo} .. {hi})", path.display())
                }
            };
            return Err(invalid(key, value, "must lie in [0, 1]"));
        }
    }
    Ok(())
}

impl PbrDesc {
    /// Every key's range (textures' values once loaded): factors in `[0, 1]`, `ior >= 1`,
    /// `attenuation_color` in `(0, 1]`, `attenuation_distance > 0`, `normal_scale` finite.
    pub fn validate(&self) -> Result<(), MaterialError> {
        check_unit_texture("base_color", "base_color.scale", &self.base_color)?;
        if let Some(t) = &self.metallic_roughness {
            check_unit_texture("metallic_roughness", "metallic_roughness.scale", t)?;
        }
        if let Some(t) = &self.normal_map {
            check_unit_texture("normal_map", "normal_map.scale", t)?;
        }
        for (key, v) in [
            ("metallic", self.metallic),
            ("roughness", self.roughness),
            ("transmission", self.transmission),
            ("anisotropy", self.anisotropy),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(invalid(key, v, "must lie in [0, 1]"));
            }
        }
        if !(self.ior.is_finite() && self.ior >= 1.0) {
            return Err(invalid(
                "ior",
                self.ior,
                "an index of refraction must be finite and >= 1",
            ));
        }
        if !self.normal_scale.is_finite() {
            return Err(invalid("normal_scale", self.normal_scale, "must be finite"));
        }
        if !self.anisotropy_rotation.is_finite() {
            return Err(invalid(
                "anisotropy_rotation",
                self.anisotropy_rotation,
                "must be a finite angle in degrees",
            ));
        }
        let c = self.attenuation_color;
        if !c.iter().all(|&x| x > 0.0 && x <= 1.0) {
            return Err(invalid(
                "attenuation_color",
                fmt3(c),
                "each channel must lie in (0, 1]",
            ));
        }
        if let Some(d) = self.attenuation_distance {
            if !(d.is_finite() && d > 0.0) {
                return Err(invalid(
                    "attenuation_distance",
                    d,
                    "must be finite and > 0 (leave it out for no absorption)",
                ));
            }
        }
        Ok(())
    }

    /// The absorption coefficient KHR_materials_volume defines, `sigma_a = -ln(attenuation_color)
    /// / attenuation_distance` per unit length of the scene; `None` without a distance.
    pub fn sigma_a(&self) -> Option<Rgb> {
        let d = self.attenuation_distance?;
        Some(Rgb::from(self.attenuation_color.map(|c| -c.ln() / d)))
    }

    /// Validate, load the image textures not yet loaded (already loaded ones, as the glTF
    /// importer gives them, are kept) and build the runtime material.
    pub fn prepare(&self, base_dir: &Path) -> Result<PbrMaterial, MaterialError> {
        self.validate()?;
        // `linear`: data, not colour (glTF's metallic-roughness and normal textures): an image
        // whose `srgb` is not given is read without the sRGB decoding.
        let load = |key: &'static str, t: &Texture, linear: bool| {
            let mut t = t.clone();
            if let Texture::Image { srgb, image, .. } = &mut t {
                if linear && srgb.is_none() && image.is_none() {
                    *srgb = Some(false);
                }
            }
            t.load_images(base_dir)
                .map_err(|source| MaterialError::Texture { key, source })?;
            Ok::<Texture, MaterialError>(t)
        };
        let base_color = load("base_color", &self.base_color, false)?;
        let metallic_roughness = match &self.metallic_roughness {
            Some(t) => Some(load("metallic_roughness", t, true)?),
            None => None,
        };
        let normal_map = match &self.normal_map {
            Some(t) => Some(load("normal_map", t, true)?),
            None => None,
        };
        let loaded = PbrDesc {
            base_color,
            metallic_roughness,
            normal_map,
            ..self.clone()
        };
        loaded.validate()?;
        let angle = loaded.anisotropy_rotation.to_radians();
        Ok(PbrMaterial {
            sigma_a: loaded.sigma_a(),
            base_color: loaded.base_color,
            metallic: loaded.metallic,
            roughness: loaded.roughness,
            metallic_roughness: loaded.metallic_roughness,
            normal_map: loaded.normal_map,
            normal_scale: loaded.normal_scale,
            ior: loaded.ior,
            transmission: loaded.transmission,
            anisotropy: loaded.anisotropy,
            anisotropy_direction: (angle.cos(), angle.sin()),
            layer: crate::render::bsdf::LayerAlbedo::shared(loaded.ior),
        })
    }
}

impl MaterialDesc {
    /// The material a scene file's table describes, `prefix` (`materials.NAME`, or empty)
    /// naming it in errors: a bad value's message names its full key,
    /// `materials.glass.scratches.explicit`.
    ///
    /// serde reads an internally tagged enum (`type = "..."` among the keys) by buffering the
    /// table in its own form, in which `toml` knows neither the keys nor the positions of the
    /// values, so its errors could point only at the material's header. Instead the table is
    /// read as a `toml::Table`, its `type` taken out as the variant of the externally tagged
    /// form, and that deserialised through `serde_path_to_error`, which tracks the key path
    /// of any nested value (tables, arrays, textures) with no per-key code.
    pub fn from_table(mut table: toml::Table, prefix: &str) -> Result<MaterialDesc, String> {
        let key = |path: &str| match (prefix.is_empty(), path.is_empty()) {
            (_, true) => prefix.to_string(),
            (true, false) => path.to_string(),
            (false, false) => format!("{prefix}.{path}"),
        };
        let kind = match table.remove("type") {
            Some(toml::Value::String(kind)) => kind,
            Some(v) => {
                return Err(format!(
                    "key `{}`: invalid type: {} `{v}`, expected a material type (a string)",
                    key("type"),
                    v.type_str()
                ))
            }
            None => return Err(format!("key `{}`: missing field `type`", key("type"))),
        };
        let tagged =
            toml::Value::Table(toml::Table::from_iter([(kind, toml::Value::Table(table))]));
        let mut track = serde_path_to_error::Track::new();
        let de = serde_path_to_error::Deserializer::new(tagged, &mut track);
        MaterialDesc::deserialize(de).map_err(|e| {
            let path = track.path();
            let mut segments = path.iter();
            // The first segment is the variant, `type`'s value; none: `type` itself is bad.
            let mut at = match segments.next() {
                Some(_) => String::new(),
                None => "type".to_string(),
            };
            for s in segments {
                match s {
                    serde_path_to_error::Segment::Seq { index } => at += &format!("[{index}]"),
                    serde_path_to_error::Segment::Map { key }
                    | serde_path_to_error::Segment::Enum { variant: key } => {
                        if !at.is_empty() {
                            at.push('.');
                        }
                        at += key;
                    }
                    serde_path_to_error::Segment::Unknown => at += ".?",
                }
            }
            format!("key `{}`: {}", key(&at), e.message())
        })
    }
}

impl<'de> Deserialize<'de> for MaterialDesc {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<MaterialDesc, D::Error> {
        let table = toml::Table::deserialize(d)?;
        MaterialDesc::from_table(table, "").map_err(serde::de::Error::custom)
    }
}

/// `[materials]` (`#[serde(deserialize_with)]`): each material read by
/// [`MaterialDesc::from_table`] under its name, so that its errors name the full key, and
/// raised at the material's table, where `toml` points.
pub(crate) fn by_name<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> Result<std::collections::BTreeMap<String, MaterialDesc>, D::Error> {
    use serde::de::{DeserializeSeed, MapAccess, Visitor};
    struct Named<'a>(&'a str);
    impl<'de> DeserializeSeed<'de> for Named<'_> {
        type Value = MaterialDesc;
        fn deserialize<D: serde::Deserializer<'de>>(self, d: D) -> Result<MaterialDesc, D::Error> {
            let table = toml::Table::deserialize(d)?;
            MaterialDesc::from_table(table, &format!("materials.{}", self.0))
                .map_err(serde::de::Error::custom)
        }
    }
    struct Materials;
    impl<'de> Visitor<'de> for Materials {
        type Value = std::collections::BTreeMap<String, MaterialDesc>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a table of materials")
        }
        fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
            let mut out = std::collections::BTreeMap::new();
            while let Some(name) = map.next_key::<String>()? {
                let desc = map.next_value_seed(Named(&name))?;
                out.insert(name, desc);
            }
            Ok(out)
        }
    }
    d.deserialize_map(Materials)
}

fn check_roughness(roughness: f32) -> Result<(), MaterialError> {
    if !(roughness.is_finite() && roughness >= 0.0) {
        return Err(invalid(
            "roughness",
            roughness,
            "must be a finite GGX alpha >= 0 (0 = smooth)",
        ));
    }
    Ok(())
}

pub(crate) fn fmt3(v: [f32; 3]) -> String {
    format!("[{}, {}, {}]", v[0], v[1], v[2])
}

/// A conductor's complex IOR from a preset name or explicit `eta` and `k` (exactly one of the
/// two), checked: finite, `>= 0`, and not both 0 in a channel.
pub fn conductor_ior(
    preset: Option<&str>,
    eta: Option<[f32; 3]>,
    k: Option<[f32; 3]>,
) -> Result<ConductorIor, MaterialError> {
    let ior = match (preset, eta, k) {
        (Some(name), None, None) => {
            ConductorIor::preset(name).ok_or_else(|| MaterialError::UnknownPreset {
                value: name.to_string(),
                known: ConductorIor::preset_names(),
            })?
        }
        (None, Some(eta), Some(k)) => ConductorIor {
            eta: Rgb::from(eta),
            k: Rgb::from(k),
        },
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
    for (key, v) in [("eta", ior.eta), ("k", ior.k)] {
        if !(v.is_finite() && v.min_element() >= 0.0) {
            return Err(invalid(key, fmt3(v.to_array()), "must be finite and >= 0"));
        }
    }
    if (0..3).any(|c| ior.eta[c] == 0.0 && ior.k[c] == 0.0) {
        return Err(invalid(
            "eta",
            fmt3(ior.eta.to_array()),
            "eta and k cannot both be 0 in a channel",
        ));
    }
    Ok(ior)
}

/// The range check of a diffuse `reflectance` (image textures are checked once loaded).
fn check_reflectance(reflectance: &Texture) -> Result<(), MaterialError> {
    if let Texture::Checkerboard { scale, .. } | Texture::Image { scale, .. } = reflectance {
        if !(scale.is_finite() && *scale != 0.0) {
            return Err(invalid(
                "reflectance.scale",
                scale,
                "must be finite and non-zero",
            ));
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
            return Err(invalid(
                "reflectance",
                value,
                "a diffuse albedo must lie in [0, 1]",
            ));
        }
    }
    Ok(())
}

impl MaterialDesc {
    /// Check every value's range (IOR >= 1, roughness >= 0, albedo in `[0, 1]`, a known preset
    /// or a complete `eta`/`k`, every scratch key; a profile file, relative to `base_dir`, the
    /// scene file's folder, is read). No table is loaded or computed.
    pub fn validate(&self, base_dir: &Path) -> Result<(), MaterialError> {
        match self {
            MaterialDesc::Diffuse { reflectance } => check_reflectance(reflectance),
            MaterialDesc::Dielectric {
                ior,
                ext_ior,
                roughness,
                ..
            } => {
                for (key, v) in [("ior", *ior), ("ext_ior", *ext_ior)] {
                    if !(v.is_finite() && v >= 1.0) {
                        return Err(invalid(
                            key,
                            v,
                            "an index of refraction must be finite and >= 1",
                        ));
                    }
                }
                check_roughness(*roughness)
            }
            MaterialDesc::Conductor {
                preset,
                eta,
                k,
                roughness,
                ..
            } => {
                conductor_ior(preset.as_deref(), *eta, *k)?;
                check_roughness(*roughness)
            }
            MaterialDesc::Scratched(m) => m.resolve(base_dir).map(|_| ()),
            MaterialDesc::Pbr(m) => m.validate(),
        }
    }

    /// Validate, then build the runtime material: image textures loaded (paths relative to
    /// `base_dir`, the scene file's folder), presets resolved, a scratched material's table
    /// obtained (memory, disk cache, file or computation) and its layers drawn.
    pub fn prepare(&self, base_dir: &Path) -> Result<Material, MaterialError> {
        // A scratched material validates in its own `prepare`, which resolves it (its profile
        // file read) once.
        if !matches!(self, MaterialDesc::Scratched(_)) {
            self.validate(base_dir)?;
        }
        Ok(match self {
            MaterialDesc::Scratched(m) => Material::Scratched(Box::new(m.prepare(base_dir)?)),
            MaterialDesc::Pbr(m) => Material::Pbr(Box::new(m.prepare(base_dir)?)),
            MaterialDesc::Diffuse { reflectance } => {
                let mut reflectance = reflectance.clone();
                reflectance
                    .load_images(base_dir)
                    .map_err(|source| MaterialError::Texture {
                        key: "reflectance",
                        source,
                    })?;
                check_reflectance(&reflectance)?;
                Material::Diffuse { reflectance }
            }
            MaterialDesc::Dielectric {
                ior,
                ext_ior,
                roughness,
                multiscatter,
            } => {
                if *multiscatter && *roughness > 0.0 {
                    Material::CompensatedDielectric(Box::new(DielectricCompensation::new(
                        ior / ext_ior,
                        *roughness,
                    )))
                } else {
                    Material::Dielectric {
                        eta: ior / ext_ior,
                        roughness: *roughness,
                    }
                }
            }
            MaterialDesc::Conductor {
                preset,
                eta,
                k,
                roughness,
                multiscatter,
            } => {
                let ior = conductor_ior(preset.as_deref(), *eta, *k)?;
                if *multiscatter && *roughness > 0.0 {
                    Material::CompensatedConductor(Box::new(ConductorCompensation::new(
                        ior, *roughness,
                    )))
                } else {
                    Material::Conductor {
                        ior,
                        roughness: *roughness,
                    }
                }
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{Vec2, Vec3};
    use crate::render::bsdf::Bsdf;
    use crate::render::bsdf::CONDUCTOR_PRESETS;

    fn parse(s: &str) -> Result<MaterialDesc, String> {
        let m: MaterialDesc = toml::from_str(s).map_err(|e| e.to_string())?;
        m.validate(Path::new(".")).map_err(|e| e.to_string())?;
        Ok(m)
    }

    /// The runtime material a valid description prepares into.
    fn prepared(s: &str) -> Material {
        parse(s).unwrap().prepare(Path::new(".")).unwrap()
    }

    /// The BSDF of a material on a flat hit at `uv`, seen from above.
    fn bsdf_at(m: &Material, uv: Vec2) -> Bsdf<'_> {
        let hit = crate::render::geometry::SurfaceHit::flat(uv);
        let view = crate::render::material::HitView {
            wo: Vec3::Z,
            rd: None,
            u_layer: None,
            pixel: None,
            origin_depth: f32::INFINITY,
        };
        m.shade(&hit, view, &mut crate::layers::CoverageCache::new())
            .1
    }

    #[test]
    fn good_materials_parse_into_the_right_bsdf() {
        let uv = Vec2::new(0.3, 0.6);
        let m = prepared("type = \"dielectric\"\nior = 1.5");
        assert!(matches!(bsdf_at(&m, uv), Bsdf::Dielectric(d) if d.eta == 1.5));
        let m =
            prepared("type = \"dielectric\"\nior = 1.5046\next_ior = 1.000277\nroughness = 0.1");
        assert!(
            matches!(bsdf_at(&m, uv), Bsdf::RoughDielectric(d) if (d.eta - 1.5046 / 1.000277).abs() < 1e-6)
        );
        let m = prepared("type = \"conductor\"\npreset = \"gold\"");
        let Bsdf::Conductor(c) = bsdf_at(&m, uv) else {
            panic!()
        };
        assert_eq!(c.ior.eta, ConductorIor::preset("Au").unwrap().eta);
        let m = prepared(
            "type = \"conductor\"\neta = [0.2, 0.9, 1.1]\nk = [3.9, 2.4, 2.1]\nroughness = 0.3",
        );
        assert!(matches!(bsdf_at(&m, uv), Bsdf::RoughConductor(_)));
        let m = prepared("type = \"diffuse\"\nreflectance = [0.2, 0.4, 0.6]");
        assert!(
            matches!(bsdf_at(&m, uv), Bsdf::Diffuse(d) if d.reflectance == Rgb::new(0.2, 0.4, 0.6))
        );
        let m = prepared("type = \"diffuse\"\nreflectance = { type = \"checkerboard\", color0 = [1, 1, 1], color1 = [0, 0, 0] }");
        assert!(
            matches!(bsdf_at(&m, Vec2::new(0.1, 0.1)), Bsdf::Diffuse(d) if d.reflectance == Rgb::ONE)
        );
        assert!(
            matches!(bsdf_at(&m, Vec2::new(0.6, 0.1)), Bsdf::Diffuse(d) if d.reflectance == Rgb::ZERO)
        );
        // Every preset resolves, and none reflects more than all of the light.
        for (names, _, _) in CONDUCTOR_PRESETS {
            for n in *names {
                let m = prepared(&format!("type = \"conductor\"\npreset = \"{n}\""));
                let Bsdf::Conductor(c) = bsdf_at(&m, uv) else {
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
        let m = prepared("type = \"conductor\"\npreset = \"none\"");
        let Bsdf::Conductor(c) = bsdf_at(&m, uv) else {
            panic!()
        };
        for cos in [1.0, 0.7, 0.2, 0.01] {
            assert!((c.ior.fresnel(cos) - Rgb::ONE).abs().max_element() < 1e-6);
        }
    }

    /// `multiscatter = true` makes a rough dielectric or conductor compensated; it is off by
    /// default, ignored at roughness 0, and a non-boolean value is refused naming the key.
    #[test]
    fn multiscatter_key_picks_the_compensated_bsdf() {
        let uv = Vec2::new(0.3, 0.6);
        let d = "type = \"dielectric\"\nior = 1.5";
        let c = "type = \"conductor\"\npreset = \"gold\"";
        for (base, smooth_ok) in [(d, 0), (c, 1)] {
            let rough = prepared(&format!("{base}\nroughness = 0.3"));
            let rough_off = prepared(&format!("{base}\nroughness = 0.3\nmultiscatter = false"));
            let on = prepared(&format!("{base}\nroughness = 0.3\nmultiscatter = true"));
            let smooth_on = prepared(&format!("{base}\nmultiscatter = true"));
            match smooth_ok {
                0 => {
                    assert!(matches!(bsdf_at(&rough, uv), Bsdf::RoughDielectric(_)));
                    assert!(matches!(bsdf_at(&rough_off, uv), Bsdf::RoughDielectric(_)));
                    assert!(matches!(bsdf_at(&on, uv), Bsdf::CompensatedDielectric(b)
                        if b.ss.eta == 1.5 && b.ss.distribution.alpha_x == 0.3));
                    assert!(matches!(bsdf_at(&smooth_on, uv), Bsdf::Dielectric(_)));
                }
                _ => {
                    assert!(matches!(bsdf_at(&rough, uv), Bsdf::RoughConductor(_)));
                    assert!(matches!(bsdf_at(&rough_off, uv), Bsdf::RoughConductor(_)));
                    assert!(matches!(bsdf_at(&on, uv), Bsdf::CompensatedConductor(b)
                        if b.ss.ior == ConductorIor::preset("gold").unwrap()));
                    assert!(matches!(bsdf_at(&smooth_on, uv), Bsdf::Conductor(_)));
                }
            }
            let e = parse(&format!("{base}\nroughness = 0.3\nmultiscatter = 1")).unwrap_err();
            assert!(e.contains("multiscatter"), "{e}");
        }
        let e = parse("type = \"diffuse\"\nmultiscatter = true").unwrap_err();
        assert!(e.contains("multiscatter"), "{e}");
    }

    /// `scratches.lean = true` leans the scratch lobes' frames; without it they have none.
    #[test]
    fn scratched_lean_key_leans_the_lobes() {
        let text = |lean: &str| {
            format!(
                "type = \"scratched\"\nbase = \"metal\"\npreset = \"none\"\n[scratches]\nwalls = \"specular\"\nfresnel_law = \"none\"\nm = 8\nn = 50\nlength = 0.3\nwidth = 0.05\nthreshold = 1.0\nlayers = 1\ncoverage = \"point\"\n{lean}"
            )
        };
        for (lean, leaned) in [("", false), ("lean = false", false), ("lean = true", true)] {
            let m = prepared(&text(lean));
            let mut covered = 0;
            for i in 0..49 {
                let uv = Vec2::new((i % 7) as f32 + 0.5, (i / 7) as f32 + 0.5) / 7.0;
                let hit = crate::render::geometry::SurfaceHit::flat(uv);
                let view = crate::render::material::HitView {
                    wo: Vec3::Z,
                    rd: None,
                    u_layer: Some(0.3),
                    pixel: None,
                    origin_depth: f32::INFINITY,
                };
                let mut cache = crate::layers::CoverageCache::new();
                if let Bsdf::Scratched(b) = m.shade(&hit, view, &mut cache).1 {
                    assert_eq!(b.lobes()[0].lean != 0.0, leaned, "{lean} {uv:?}");
                    covered += 1;
                }
            }
            assert!(covered >= 10, "{lean}: {covered}");
        }
        let e = parse(&text("lean = \"yes\"")).unwrap_err();
        assert!(e.contains("lean") || e.contains("boolean"), "{e}");
    }

    /// `scratches.crossings`: on by default for traced glass walls, where two layers' scratches
    /// cover a hit (here every hit: the point test on scratches wider than the face) its lobe
    /// carries the other scratch's axis; `false` and `model = "seed"` leave it out; `true`
    /// where the walls are not traced glass, or not a boolean, is refused naming the key.
    #[test]
    fn scratched_crossings_key_crosses_the_lobes() {
        let text = |walls: &str, key: &str| {
            format!(
                "type = \"scratched\"\nbase = \"glass\"\nior = 1.5\n[scratches]\n{walls}\nlength = 2.0\nwidth = 2.0\nthreshold = 1.0\nlayers = 2\ncoverage = \"point\"\n{key}"
            )
        };
        let traced = "walls = \"dielectric\"\nprofile = \"v:angle=90\"";
        for (key, crossed) in [
            ("", true),
            ("crossings = true", true),
            ("crossings = false", false),
            ("model = \"seed\"", false),
        ] {
            let m = prepared(&text(traced, key));
            let mut seen = 0;
            for i in 0..16 {
                let uv = Vec2::new((i % 4) as f32 + 0.5, (i / 4) as f32 + 0.5) / 4.0;
                let hit = crate::render::geometry::SurfaceHit::flat(uv);
                let view = crate::render::material::HitView {
                    wo: Vec3::Z,
                    rd: None,
                    u_layer: Some((i as f32 + 0.5) / 16.0),
                    pixel: None,
                    origin_depth: f32::INFINITY,
                };
                let mut cache = crate::layers::CoverageCache::new();
                if let Bsdf::ScratchedGlass(b) = m.shade(&hit, view, &mut cache).1 {
                    assert_eq!(b.lobes()[0].cross != [0.0; 2], crossed, "{key} {uv:?}");
                    seen += 1;
                }
            }
            assert!(seen >= 8, "{key}: {seen}");
        }
        let e = parse(&text("walls = \"diffuse\"", "crossings = true")).unwrap_err();
        assert!(e.contains("scratches.crossings"), "{e}");
        let e = parse(&text(traced, "crossings = \"yes\"")).unwrap_err();
        assert!(e.contains("crossings") || e.contains("boolean"), "{e}");
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
        let m: MaterialDesc = toml::from_str(
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
        let m: MaterialDesc = toml::from_str(
            "type = \"diffuse\"\nreflectance = { type = \"image\", path = \"white.png\" }",
        )
        .unwrap();
        let m = m.prepare(&dir).unwrap();
        assert!(
            matches!(bsdf_at(&m, Vec2::splat(0.3)), Bsdf::Diffuse(d) if d.reflectance == Rgb::ONE)
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    /// `type = "pbr"`: glTF's defaults, every key read, and the BSDF at a hit.
    #[test]
    fn pbr_parses_with_gltf_defaults_and_keys() {
        let m: MaterialDesc = toml::from_str("type = \"pbr\"").unwrap();
        assert_eq!(m, MaterialDesc::Pbr(PbrDesc::default()));
        let m = prepared(
            "type = \"pbr\"\nbase_color = [0.5, 0.25, 1]\nmetallic = 0.25\nroughness = 0.5\nmetallic_roughness = [0, 0.5, 1]\nior = 1.33\ntransmission = 0.5\nattenuation_color = [0.5, 1, 1]\nattenuation_distance = 2\nanisotropy = 0.5\nanisotropy_rotation = 90\nnormal_scale = 0.5",
        );
        let sigma = m.absorption().unwrap();
        assert!((sigma.x - 2f32.ln() / 2.0).abs() < 1e-6 && sigma.y == 0.0 && sigma.z == 0.0);
        assert!(m.has_transmission());
        let Bsdf::Pbr(b) = bsdf_at(&m, Vec2::splat(0.5)) else {
            panic!()
        };
        assert_eq!(b.base_color, Rgb::new(0.5, 0.25, 1.0));
        assert_eq!((b.metallic, b.transmission, b.eta), (0.25, 0.5, 1.33));
        // Roughness 0.5 x 0.5 (green) = 0.25: alpha_b = 0.0625, alpha_t = mix(alpha, 1, 0.25).
        assert_eq!(b.distribution.alpha_y, 0.0625);
        assert!((b.distribution.alpha_x - (0.0625 + 0.9375 * 0.25)).abs() < 1e-6);
        // No attenuation distance: no absorption; metallic 1: opaque.
        let m = prepared("type = \"pbr\"\nattenuation_color = [0.5, 1, 1]");
        assert!(m.absorption().is_none() && !m.has_transmission());
    }

    /// The normal map tilts the shading normal as glTF says: red along `dP/du`, green toward
    /// decreasing `v`; a flat (0.5, 0.5, 1) map leaves the frame exactly as without a map;
    /// the anisotropy rotation turns the frame's `s` toward the bitangent.
    #[test]
    fn pbr_normal_map_and_anisotropy_turn_the_frame() {
        use crate::render::geometry::SurfaceHit;
        let hit = SurfaceHit::flat(Vec2::splat(0.5));
        let frame_of = |extra: &str| {
            let m = prepared(&format!("type = \"pbr\"\nroughness = 0.5\n{extra}"));
            let Material::Pbr(p) = &m else { panic!() };
            p.shade(&hit, Vec3::new(0.1, 0.2, 1.0).normalize()).0
        };
        let plain = frame_of("");
        let flat = frame_of("normal_map = [0.5, 0.5, 1.0]");
        assert_eq!((plain.s, plain.t, plain.n), (flat.s, flat.t, flat.n));
        let (s, c) = 0.3f32.sin_cos();
        let tilted = frame_of(&format!(
            "normal_map = [{}, 0.5, {}]",
            0.5 + 0.5 * s,
            0.5 + 0.5 * c
        ));
        assert!(
            (tilted.n - Vec3::new(s, 0.0, c)).length() < 1e-5,
            "{:?}",
            tilted.n
        );
        // SurfaceHit::flat has dP/dv = +y: the green channel points to -y.
        let green = frame_of(&format!(
            "normal_map = [0.5, {}, {}]",
            0.5 + 0.5 * s,
            0.5 + 0.5 * c
        ));
        assert!(
            (green.n - Vec3::new(0.0, -s, c)).length() < 1e-5,
            "{:?}",
            green.n
        );
        // normal_scale scales the tangent part before normalising.
        let scaled = frame_of(&format!(
            "normal_map = [{}, 0.5, {}]\nnormal_scale = 2",
            0.5 + 0.5 * s,
            0.5 + 0.5 * c
        ));
        assert!((scaled.n - Vec3::new(2.0 * s, 0.0, c).normalize()).length() < 1e-5);
        // Anisotropy rotated by 90 degrees: s along the bitangent (-y here).
        let aniso = frame_of("anisotropy = 0.5\nanisotropy_rotation = 90");
        assert!(
            (aniso.s - Vec3::new(0.0, -1.0, 0.0)).length() < 1e-5,
            "{:?}",
            aniso.s
        );
        assert!((aniso.t - aniso.n.cross(aniso.s)).length() < 1e-6);
    }
}
