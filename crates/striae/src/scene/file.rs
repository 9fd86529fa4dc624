//! The TOML scene file, deserialised straight into tagged enums with `deny_unknown_fields`
//! (a misspelt key is an error that names it, like pbrt's "unused parameter"). Every key is
//! documented with an example in `docs/scenes.md`.

use crate::geometry::Transform;
use super::interim::Material;
use crate::math::{Rgb, Vec3};
use serde::Deserialize;
use std::collections::BTreeMap;

/// A colour: one number (grey) or `[r, g, b]`, linear.
#[derive(Clone, Copy, Debug, Deserialize, PartialEq)]
#[serde(untagged, expecting = "a number or an [r, g, b] array")]
pub enum Colour {
    Grey(f32),
    Rgb([f32; 3]),
}

impl Colour {
    pub fn rgb(self) -> Rgb {
        match self {
            Colour::Grey(g) => Rgb::splat(g),
            Colour::Rgb(c) => Rgb::from_array(c),
        }
    }
}

/// The whole file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default)]
    pub render: RenderSection,
    pub camera: CameraSection,
    #[serde(default)]
    pub materials: BTreeMap<String, Material>,
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
        }
    }
}

/// `[camera]`: a perspective camera placed by look-at; `fov` is vertical, in degrees.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSection {
    pub position: [f32; 3],
    pub look_at: [f32; 3],
    #[serde(default = "default_up")]
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

/// `[[shapes]]`: one shape; `type` picks the kind. Every kind takes `material` (a name from
/// `[materials]`; may be left out for a pure emitter, which then reflects nothing),
/// `emission` (makes it an area light) and `transform`.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum ShapeSection {
    /// A triangle mesh from an OBJ file, `path` relative to the scene file.
    Mesh {
        path: String,
        material: Option<String>,
        emission: Option<Colour>,
        #[serde(default)]
        transform: Transform,
    },
    /// The Utah teapot (Newell's Bezier patches), about 3.2 wide and 1.6 tall (Newell's units,
    /// lid up along `+y`... see `docs/scenes.md` for its extent after tessellation).
    Teapot {
        material: Option<String>,
        emission: Option<Colour>,
        #[serde(default)]
        transform: Transform,
        /// Segments per patch side in u and v.
        #[serde(default = "default_teapot_subdivisions")]
        subdivisions: u32,
    },
    /// The square `[-1, 1]^2` in the `xy` plane, normal `+z` (Mitsuba's `rectangle`).
    Rectangle {
        material: Option<String>,
        emission: Option<Colour>,
        #[serde(default)]
        transform: Transform,
    },
    /// The box `[-1, 1]^3` (Mitsuba's `cube`); a glass plate is a thin box.
    #[serde(rename = "box")]
    Cuboid {
        material: Option<String>,
        emission: Option<Colour>,
        #[serde(default)]
        transform: Transform,
    },
    /// An analytic sphere.
    Sphere {
        #[serde(default)]
        center: [f32; 3],
        #[serde(default = "one")]
        radius: f32,
        material: Option<String>,
        emission: Option<Colour>,
        #[serde(default)]
        transform: Transform,
    },
}

fn default_teapot_subdivisions() -> u32 {
    16
}
fn one() -> f32 {
    1.0
}

impl ShapeSection {
    pub fn kind(&self) -> &'static str {
        match self {
            ShapeSection::Mesh { .. } => "mesh",
            ShapeSection::Teapot { .. } => "teapot",
            ShapeSection::Rectangle { .. } => "rectangle",
            ShapeSection::Cuboid { .. } => "box",
            ShapeSection::Sphere { .. } => "sphere",
        }
    }

    /// `(material, emission, transform)`, common to every kind.
    pub fn common(&self) -> (Option<&str>, Option<Colour>, &Transform) {
        match self {
            ShapeSection::Mesh { material, emission, transform, .. }
            | ShapeSection::Teapot { material, emission, transform, .. }
            | ShapeSection::Rectangle { material, emission, transform }
            | ShapeSection::Cuboid { material, emission, transform }
            | ShapeSection::Sphere { material, emission, transform, .. } => (material.as_deref(), *emission, transform),
        }
    }
}

/// `[[lights]]`: lights that are not shapes.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum LightSection {
    /// A directional light. `direction` points from the scene **toward** the sun;
    /// `irradiance` is measured on a surface facing the sun.
    Sun { direction: [f32; 3], irradiance: Colour },
}

/// `[environment]`: light from infinitely far away.
#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum EnvironmentSection {
    /// The same radiance from every direction.
    Constant { radiance: Colour },
    /// An equirectangular OpenEXR map (`path` relative to the scene file), times `scale`.
    Map {
        path: String,
        #[serde(default = "one")]
        scale: f32,
        #[serde(default)]
        transform: Transform,
    },
}

pub fn vec3(a: [f32; 3]) -> Vec3 {
    Vec3::from_array(a)
}
