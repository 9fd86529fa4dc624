//! The TOML scene file, deserialised straight into tagged enums with `deny_unknown_fields`
//! (a misspelt key is an error that names it, like pbrt's "unused parameter"). Every key is
//! documented with an example in `docs/scenes.md`.

use super::materials::MaterialDesc;
use crate::math::Vec3;
use crate::render::geometry::Transform;
use serde::Deserialize;
use std::collections::BTreeMap;

pub use crate::render::texture::Colour;

/// The whole file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default)]
    pub render: RenderSection,
    /// Required unless a `gltf` shape brings a camera (the TOML's wins over the glTF's).
    pub camera: Option<CameraSection>,
    #[serde(default, deserialize_with = "super::materials::by_name")]
    pub materials: BTreeMap<String, MaterialDesc>,
    #[serde(default)]
    pub shapes: Vec<ShapeSection>,
    #[serde(default)]
    pub lights: Vec<LightSection>,
    pub environment: Option<EnvironmentSection>,
}

/// `[render]`: image size, samples, depth, seed, preview exposure.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSection {
    #[serde(default = "default_width")]
    pub width: u32,
    #[serde(default = "default_height")]
    pub height: u32,
    #[serde(default = "default_spp")]
    pub spp: u32,
    #[serde(default = "default_max_depth")]
    pub max_depth: u32,
    #[serde(default = "default_rr_depth")]
    pub rr_depth: u32,
    #[serde(default)]
    pub seed: u64,
    #[serde(default)]
    pub exposure: f32,
    /// `"sobol"` (default) or `"independent"` (`sampler::SamplerKind`).
    #[serde(default = "default_sampler")]
    pub sampler: String,
    /// The watertight ray/triangle test instead of the fast one (`geometry::TriangleTest`).
    #[serde(default)]
    pub watertight: bool,
    /// The lane render loop instead of the one-path loop (`integrator::lanes`).
    #[serde(default)]
    pub lanes: bool,
}

fn default_width() -> u32 {
    512
}
fn default_height() -> u32 {
    384
}
fn default_spp() -> u32 {
    64
}
fn default_max_depth() -> u32 {
    16
}
fn default_rr_depth() -> u32 {
    5
}
fn default_sampler() -> String {
    crate::render::sampler::SamplerKind::default().name().into()
}

impl Default for RenderSection {
    fn default() -> Self {
        RenderSection {
            width: default_width(),
            height: default_height(),
            spp: default_spp(),
            max_depth: default_max_depth(),
            rr_depth: default_rr_depth(),
            seed: 0,
            exposure: 0.0,
            sampler: default_sampler(),
            watertight: false,
            lanes: false,
        }
    }
}

/// `[camera]`: a perspective camera placed by look-at; `fov` is vertical, in degrees.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSection {
    #[serde(deserialize_with = "crate::strict_array::exact")]
    pub position: [f32; 3],
    #[serde(deserialize_with = "crate::strict_array::exact")]
    pub look_at: [f32; 3],
    #[serde(
        default = "default_up",
        deserialize_with = "crate::strict_array::exact"
    )]
    pub up: [f32; 3],
    pub fov: f32,
    #[serde(default)]
    pub aperture_radius: f32,
    /// Defaults to the distance from `position` to `look_at`.
    pub focus_distance: Option<f32>,
}

fn default_up() -> [f32; 3] {
    [0.0, 1.0, 0.0]
}

/// The kinds of shape.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ShapeType {
    /// A triangle mesh from an OBJ file (`path`, relative to the scene file).
    Mesh,
    /// The Utah teapot, tessellated from Newell's Bezier patches (`subdivisions`).
    Teapot,
    /// The square `[-1, 1]^2` in the `xy` plane, normal `+z` (Mitsuba's `rectangle`).
    Rectangle,
    /// The box `[-1, 1]^3` (Mitsuba's `cube`); a glass plate is a thin box.
    Box,
    /// An analytic sphere (`center`, `radius`).
    Sphere,
    /// A glTF 2.0 file (`path`, `.gltf` or `.glb`): its meshes, materials, lights and camera
    /// (`scene::gltf`); `transform` applies to all of it.
    Gltf,
}

/// `[[shapes]]`: one shape. `type` picks the kind; every kind takes `material` (a name from
/// `[materials]`; may be left out for a pure emitter, which then reflects nothing), `emission`
/// (makes it an area light) and `transform`. The other keys belong to one kind each.
///
/// A flat struct rather than a tagged enum, so that a bad value keeps its position in the file
/// (serde buffers the fields of internally tagged enums and `toml` loses their spans).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShapeSection {
    #[serde(rename = "type")]
    pub kind: ShapeType,
    pub material: Option<String>,
    pub emission: Option<Colour>,
    #[serde(default)]
    pub transform: Transform,
    /// `mesh`: the OBJ file; `gltf`: the glTF file.
    pub path: Option<String>,
    /// `teapot`: segments per patch side (default 8).
    pub subdivisions: Option<u32>,
    /// `sphere`: centre (default the origin) and radius (default 1).
    #[serde(default, deserialize_with = "crate::strict_array::optional")]
    pub center: Option<[f32; 3]>,
    pub radius: Option<f32>,
}

impl ShapeSection {
    /// The keys given that do not belong to this kind of shape.
    pub fn foreign_keys(&self) -> Vec<&'static str> {
        let mut out = Vec::new();
        if self.path.is_some() && !matches!(self.kind, ShapeType::Mesh | ShapeType::Gltf) {
            out.push("path");
        }
        if self.kind == ShapeType::Gltf {
            // A glTF's materials and emission are its own (a TOML material overrides one by name).
            if self.material.is_some() {
                out.push("material");
            }
            if self.emission.is_some() {
                out.push("emission");
            }
        }
        if self.subdivisions.is_some() && self.kind != ShapeType::Teapot {
            out.push("subdivisions");
        }
        if self.center.is_some() && self.kind != ShapeType::Sphere {
            out.push("center");
        }
        if self.radius.is_some() && self.kind != ShapeType::Sphere {
            out.push("radius");
        }
        out
    }
}

/// The kinds of `[[lights]]` entry.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum LightType {
    /// A directional light (`direction`, `irradiance`).
    Sun,
    /// A point light (`position`, `intensity`; KHR_lights_punctual's `point`).
    Point,
    /// A spot light (`position`, `direction`, `intensity`, `inner_angle`, `outer_angle`;
    /// KHR_lights_punctual's `spot`).
    Spot,
}

/// `[[lights]]`: lights that are not shapes. `type` picks the kind; the other keys belong to
/// some kinds only ([`LightSection::foreign_keys`]).
///
/// * `sun`: `direction` points from the scene **toward** the sun; `irradiance` is measured on
///   a surface facing the sun.
/// * `point`: `position`, and `intensity`, the radiant intensity in W/sr (a surface facing the
///   light at distance `d` receives the irradiance `intensity / d^2`).
/// * `spot`: a point light that shines along `direction` (the direction the light travels),
///   full within `inner_angle` of it and fading to 0 at `outer_angle` (half-angles in degrees,
///   `0 <= inner_angle < outer_angle <= 90`; defaults 0 and 45, glTF's).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightSection {
    #[serde(rename = "type")]
    pub kind: LightType,
    #[serde(default, deserialize_with = "crate::strict_array::optional")]
    pub direction: Option<[f32; 3]>,
    pub irradiance: Option<Colour>,
    #[serde(default, deserialize_with = "crate::strict_array::optional")]
    pub position: Option<[f32; 3]>,
    pub intensity: Option<Colour>,
    pub inner_angle: Option<f32>,
    pub outer_angle: Option<f32>,
}

impl LightSection {
    /// The keys given that do not belong to this kind of light.
    pub fn foreign_keys(&self) -> Vec<&'static str> {
        let (sun, point, spot) = (
            self.kind == LightType::Sun,
            self.kind == LightType::Point,
            self.kind == LightType::Spot,
        );
        let mut out = Vec::new();
        if self.direction.is_some() && point {
            out.push("direction");
        }
        if self.irradiance.is_some() && !sun {
            out.push("irradiance");
        }
        if self.position.is_some() && sun {
            out.push("position");
        }
        if self.intensity.is_some() && sun {
            out.push("intensity");
        }
        if self.inner_angle.is_some() && !spot {
            out.push("inner_angle");
        }
        if self.outer_angle.is_some() && !spot {
            out.push("outer_angle");
        }
        out
    }
}

/// The kinds of environment.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum EnvironmentType {
    /// The same radiance from every direction (`radiance`).
    Constant,
    /// An equirectangular OpenEXR map (`path` relative to the scene file, `scale`, `transform`).
    Map,
}

/// `[environment]`: light from infinitely far away.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentSection {
    #[serde(rename = "type")]
    pub kind: EnvironmentType,
    /// `constant`: the radiance.
    pub radiance: Option<Colour>,
    /// `map`: the EXR file, a multiplier and an orientation.
    pub path: Option<String>,
    pub scale: Option<f32>,
    #[serde(default)]
    pub transform: Transform,
}

pub fn vec3(a: [f32; 3]) -> Vec3 {
    Vec3::from_array(a)
}
