//! A renderable scene: camera, geometry (shapes in a BVH), materials, lights and render
//! settings, built from a TOML scene file ([`file`], documented key by key in
//! `docs/scenes.md`) with command-line overrides.
//!
//! Bad input is reported by [`SceneError`], which names the file, the key and the value: TOML
//! syntax and type errors and unknown keys come from `toml` with their line and column and a
//! caret under the offending key; semantic errors (an unknown material name, a missing mesh,
//! a degenerate camera) name the key path such as `shapes[2].path`.

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod explicit;
pub mod file;
pub mod gltf;
pub mod materials;
pub mod scratches;

use crate::math::Vec3;
use crate::render::camera::{CameraError, PerspectiveCamera};
use crate::render::envmap::EnvMap;
use crate::render::geometry::{Geometry, Shape, ShapeGeometry, TriangleMesh, TriangleTest};
use crate::render::lights::{Environment, Light};
use crate::render::material::Material;
use crate::render::sampler::SamplerKind;
use file::{EnvironmentType, LightType, SceneFile, ShapeSection, ShapeType};
use materials::{MaterialDesc, MaterialError};
use scratches::ExplicitSpec;
use std::path::{Path, PathBuf};

/// The built-in default scene (`striae render` with no argument): the glass teapot with the
/// seed's setting-1 scratches (Fig. 6 b), lit by a sun in a dark environment.
pub const DEFAULT_SCENE: &str = include_str!("../../../scenes/glass-teapot-setting1.toml");
/// The name the default scene is reported under in messages.
pub const DEFAULT_SCENE_NAME: &str = "<built-in glass-teapot-setting1.toml>";

/// Material index of a shape that has none (a pure emitter): it absorbs all light.
pub const NO_MATERIAL: u32 = u32::MAX;

/// Settings of one render.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    /// Longest path in segments (Mitsuba's convention); 0 = unlimited.
    pub max_depth: u32,
    /// Depth from which Russian roulette may end paths.
    pub rr_depth: u32,
    pub seed: u64,
    /// PNG preview exposure in stops.
    pub exposure: f32,
    /// The random numbers' kind.
    pub sampler: SamplerKind,
    /// The ray/triangle test (`render.watertight`; explicit scratch geometry is always
    /// watertight).
    pub triangles: TriangleTest,
    /// The lane render loop (`render.lanes`, `integrator::lanes`) instead of the one-path loop.
    pub lanes: bool,
}

/// Command-line values that replace the scene file's.
#[derive(Clone, Debug, Default)]
pub struct Overrides {
    pub spp: Option<u32>,
    pub resolution: Option<(u32, u32)>,
    pub seed: Option<u64>,
    pub max_depth: Option<u32>,
    pub sampler: Option<SamplerKind>,
    pub lanes: Option<bool>,
}

impl Overrides {
    /// The flags' values checked on their own, before any scene file is read: a bad value is
    /// blamed on its flag, not on the scene file.
    pub fn validate(&self) -> Result<(), SceneError> {
        let flag = |flag, value: String, reason: String| SceneError::Flag {
            flag,
            value,
            reason,
        };
        if let Some(spp) = self
            .spp
            .filter(|&n| n == 0 || n > crate::render::sampler::MAX_SPP)
        {
            let range = format!("must lie in 1..={}", crate::render::sampler::MAX_SPP);
            return Err(flag("--spp", spp.to_string(), range));
        }
        if let Some((w, h)) = self.resolution.filter(|&(w, h)| !resolution_in_range(w, h)) {
            let range = "each side must lie in 1..=32768".to_string();
            return Err(flag("--res", format!("{w}x{h}"), range));
        }
        Ok(())
    }
}

/// The longest side of an image the renderer makes, in pixels.
pub const MAX_RESOLUTION: u32 = 1 << 15;

/// Image sides from 1 to [`MAX_RESOLUTION`] pixels.
pub fn resolution_in_range(width: u32, height: u32) -> bool {
    (1..=MAX_RESOLUTION).contains(&width) && (1..=MAX_RESOLUTION).contains(&height)
}

/// What can be wrong with a scene.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("cannot read scene file {file}: {message}")]
    Read { file: PathBuf, message: String },
    /// Syntax, type, unknown-key and bad-value errors, with `toml`'s location and key.
    #[error("scene file {file}: {message}")]
    Parse { file: PathBuf, message: String },
    #[error("scene file {file}: key `{key}` = {value}: {reason}")]
    Invalid {
        file: PathBuf,
        key: String,
        value: String,
        reason: String,
    },
    /// A command-line flag overriding a scene key (`--spp`, `--res`) with a bad value.
    #[error("command-line flag `{flag}` = {value}: {reason}")]
    Flag {
        flag: &'static str,
        value: String,
        reason: String,
    },
    /// A problem with a key that is not one bad value (a missing file, a table that cannot be
    /// built, keys that do not go together).
    #[error("scene file {file}: key `{key}`: {message}")]
    Key {
        file: PathBuf,
        key: String,
        message: String,
    },
}

/// A scene ready to render.
#[derive(Debug)]
pub struct Scene {
    pub camera: PerspectiveCamera,
    pub geometry: Geometry,
    pub materials: Vec<Material>,
    /// Area lights first (in shape order), then the environment, then `[[lights]]`.
    pub lights: Vec<Light>,
    environment: Option<usize>,
    pub settings: RenderSettings,
    /// Whether a material absorbs ([`Material::absorption`]), worked out when the scene is
    /// built: without one the integrator skips the absorption test altogether.
    absorbing: bool,
}

impl Scene {
    /// Whether any material of the scene absorbs inside ([`Material::absorption`]), as the
    /// scene was built.
    #[inline(always)]
    pub fn has_absorption(&self) -> bool {
        self.absorbing
    }

    /// The environment light, if any.
    #[inline]
    pub fn environment(&self) -> Option<&Environment> {
        match self.environment.map(|i| &self.lights[i]) {
            Some(Light::Environment(e)) => Some(e),
            _ => None,
        }
    }

    /// Load a scene file; relative paths inside it are resolved against its folder.
    pub fn load(path: &Path, overrides: &Overrides) -> Result<Scene, SceneError> {
        Scene::load_with_text(path, overrides).map(|(scene, _)| scene)
    }

    /// [`Scene::load`], with the text it was read from (which names the render of a part,
    /// `parts::RenderId`).
    pub fn load_with_text(
        path: &Path,
        overrides: &Overrides,
    ) -> Result<(Scene, String), SceneError> {
        if gltf::is_gltf_path(path) {
            // Named by its bytes: a `.glb` is not text.
            let bytes =
                crate::io::read_bounded(path, crate::io::MAX_BINARY_BYTES).map_err(|e| {
                    SceneError::Read {
                        file: path.to_path_buf(),
                        message: e.to_string(),
                    }
                })?;
            use sha2::Digest;
            let digest = sha2::Sha256::digest(&bytes);
            let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
            let name = path.file_name().unwrap_or_default().to_string_lossy();
            let id = format!("glTF {name}\nsha256 {hex}\n");
            return Ok((Scene::from_gltf(path, overrides)?, id));
        }
        let text = crate::io::read_text(path).map_err(|e| SceneError::Read {
            file: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok((Scene::parse(&text, path, &base, overrides)?, text))
    }

    /// A glTF file (`.gltf` or `.glb`) on its own, as a TOML scene holding only
    /// `[[shapes]] type = "gltf"` would render with the glTF's camera (an error without one):
    /// the default `[render]` settings with `overrides`, and no environment (black).
    pub fn from_gltf(path: &Path, overrides: &Overrides) -> Result<Scene, SceneError> {
        let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let name = path.file_name().map(PathBuf::from).unwrap_or_default();
        let f = SceneFile {
            render: Default::default(),
            camera: None,
            materials: Default::default(),
            shapes: vec![ShapeSection {
                kind: ShapeType::Gltf,
                material: None,
                emission: None,
                transform: Default::default(),
                path: Some(name.to_string_lossy().into_owned()),
                subdivisions: None,
                center: None,
                radius: None,
            }],
            lights: Vec::new(),
            environment: None,
        };
        build(f, path, &base, overrides)
    }

    /// The built-in default scene.
    pub fn default_scene(overrides: &Overrides) -> Result<Scene, SceneError> {
        Scene::parse(
            DEFAULT_SCENE,
            Path::new(DEFAULT_SCENE_NAME),
            Path::new("."),
            overrides,
        )
    }

    /// Parse scene text. `file` names it in messages, `base` resolves relative paths.
    pub fn parse(
        text: &str,
        file: &Path,
        base: &Path,
        overrides: &Overrides,
    ) -> Result<Scene, SceneError> {
        let parse_error = |e: toml::de::Error| SceneError::Parse {
            file: file.to_path_buf(),
            message: e.to_string(),
        };
        // Parsed twice: as a plain table, to find numbers an `f32` field would turn into
        // infinity (serde casts silently), then into `SceneFile`, straight from the text so
        // that errors keep `toml`'s line and caret.
        let table: toml::Table = toml::from_str(text).map_err(parse_error)?;
        if let Some((key, value)) = beyond_f32(&toml::Value::Table(table), String::new()) {
            return Err(invalid(
                file,
                key,
                format_args!("{value:e}"),
                "is beyond the range of a 32-bit float (about 3.4e38)",
            ));
        }
        let parsed: SceneFile = toml::from_str(text).map_err(parse_error)?;
        build(parsed, file, base, overrides)
    }
}

/// The first finite number of the file that a 32-bit float cannot hold (`1e39` would become
/// infinity and be reported as `inf`), with its key: `shapes[2].radius`, `camera.position`.
fn beyond_f32(value: &toml::Value, key: String) -> Option<(String, f64)> {
    let join = |k: &str| match key.is_empty() {
        true => k.to_string(),
        false => format!("{key}.{k}"),
    };
    match value {
        toml::Value::Float(v) if v.is_finite() && v.abs() > f32::MAX as f64 => Some((key, *v)),
        toml::Value::Table(t) => t.iter().find_map(|(k, v)| beyond_f32(v, join(k))),
        toml::Value::Array(items) => items.iter().enumerate().find_map(|(i, v)| match v {
            toml::Value::Table(_) => beyond_f32(v, format!("{key}[{i}]")),
            _ => beyond_f32(v, key.clone()),
        }),
        _ => None,
    }
}

fn invalid(
    file: &Path,
    key: impl Into<String>,
    value: impl std::fmt::Debug,
    reason: impl std::fmt::Display,
) -> SceneError {
    SceneError::Invalid {
        file: file.to_path_buf(),
        key: key.into(),
        value: format!("{value:?}"),
        reason: reason.to_string(),
    }
}

pub use crate::render::geometry::MAX_COORDINATE;

/// A point or vector key checked on its own: finite and within [`MAX_COORDINATE`].
fn coordinates(file: &Path, key: impl Into<String>, v: [f32; 3]) -> Result<Vec3, SceneError> {
    if v.iter().all(|x| x.abs() <= MAX_COORDINATE) {
        Ok(Vec3::from_array(v))
    } else {
        Err(invalid(
            file,
            key,
            v,
            format!("each component must be finite and within +-{MAX_COORDINATE:e}"),
        ))
    }
}

/// A camera error as the key it is about (`camera.fov`, `camera.look_at`, ...).
fn camera_error(
    file: &Path,
    c: &file::CameraSection,
    (width, height): (u32, u32),
    e: CameraError,
) -> SceneError {
    let bad_look_at = || {
        invalid(
            file,
            "camera.look_at",
            c.look_at,
            "must be finite and differ from camera.position",
        )
    };
    match e {
        CameraError::BadFov(fov) => {
            invalid(file, "camera.fov", fov, "must lie in (0, 180) degrees")
        }
        CameraError::DegenerateView => bad_look_at(),
        CameraError::DegenerateUp => invalid(
            file,
            "camera.up",
            c.up,
            "must be finite and not parallel to the view direction (look_at - position)",
        ),
        CameraError::BadLens(radius, _) if !(radius >= 0.0) => {
            invalid(file, "camera.aperture_radius", radius, "must be >= 0")
        }
        // Without `focus_distance` the focus is the look-at distance, zero when they coincide.
        CameraError::BadLens(..) if c.focus_distance.is_none() => bad_look_at(),
        CameraError::BadLens(_, focus) => invalid(
            file,
            "camera.focus_distance",
            focus,
            "must be finite and > 0",
        ),
        CameraError::BadResolution(..) => invalid(
            file,
            "render.width, render.height",
            [width, height],
            "must be at least 1 x 1",
        ),
    }
}

/// A material's error under its full key, `materials.NAME.KEY` (the material's own message
/// names `KEY` relative to the material).
fn material_error(file: &Path, name: &str, e: MaterialError) -> SceneError {
    let key = |k: &str| format!("materials.{name}.{k}");
    match e {
        MaterialError::InvalidValue {
            key: k,
            value,
            reason,
        } => SceneError::Invalid {
            file: file.to_path_buf(),
            key: key(k),
            value,
            reason,
        },
        MaterialError::UnknownPreset { value, known } => invalid(
            file,
            key("preset"),
            value,
            format!("unknown preset; known presets: {known}"),
        ),
        MaterialError::Texture { key: k, source } => SceneError::Key {
            file: file.to_path_buf(),
            key: key(k),
            message: with_causes(&source),
        },
        MaterialError::ScratchTable { key: k, source } => SceneError::Key {
            file: file.to_path_buf(),
            key: key(k),
            message: with_causes(&*source),
        },
        e @ MaterialError::ConductorIor { .. } => SceneError::Key {
            file: file.to_path_buf(),
            key: format!("materials.{name}"),
            message: e.to_string(),
        },
    }
}

/// `e` followed by its chain of causes (`cannot read or write table t.npz: No such file or
/// directory`), each cause left out where the text before already quotes it.
fn with_causes(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let t = c.to_string();
        if !text.contains(&t) {
            text = format!("{text}: {t}");
        }
        cause = c.source();
    }
    text
}

fn build(f: SceneFile, file: &Path, base: &Path, o: &Overrides) -> Result<Scene, SceneError> {
    let settings = render_settings(&f, file, o)?;
    let gltfs = import_gltfs(&f, file, base)?;
    let camera = camera(&f, &gltfs, file, &settings)?;
    let m = materials(&f, &gltfs, file, base)?;
    let (names, mut materials, explicit) = (m.names, m.materials, m.explicit);
    // Area lights first (in shape order), then the environment, then `[[lights]]`, then the
    // glTFs' punctual lights.
    let (plain, mut shapes, mut lights) = shapes(&f, file, base, &names)?;
    gltf_shapes(&gltfs, &m.gltf_slots, file, &mut shapes, &mut lights)?;
    let name_refs: Vec<&String> = names.iter().collect();
    let carve = explicit::carve(
        &plain,
        file,
        &name_refs,
        &explicit,
        &mut materials,
        &mut shapes,
    )?;
    let mut environment = None;
    if let Some(env) = self::environment(&f, file, base)? {
        lights.push(env);
        environment = Some(lights.len() - 1);
    }
    lights.extend(punctual_lights(&f, file)?);
    for (_, g) in &gltfs {
        lights.extend(g.lights.iter().cloned());
    }
    Ok(Scene {
        camera,
        geometry: match carve {
            Some(carve) => {
                let start = std::time::Instant::now();
                let g = Geometry::with_carve(shapes, carve);
                crate::log::info(&format!(
                    "BVH over {} primitives built in {:.2} s",
                    g.primitive_count(),
                    start.elapsed().as_secs_f64()
                ));
                g
            }
            None => Geometry::with_triangles(shapes, settings.triangles),
        },
        absorbing: materials.iter().any(|m| m.absorption().is_some()),
        materials,
        lights,
        environment,
        settings,
    })
}

/// Every `[[shapes]] type = "gltf"` imported, with its index among the shapes.
fn import_gltfs(
    f: &SceneFile,
    file: &Path,
    base: &Path,
) -> Result<Vec<(usize, gltf::GltfScene)>, SceneError> {
    let mut out = Vec::new();
    for (i, s) in f.shapes.iter().enumerate() {
        if s.kind != ShapeType::Gltf {
            continue;
        }
        let key = format!("shapes[{i}].path");
        let Some(path) = &s.path else {
            return Err(invalid(
                file,
                key,
                "(missing)",
                "a gltf shape needs the path of a .gltf or .glb file",
            ));
        };
        let full = base.join(path);
        let scene = gltf::import(&full, &s.transform).map_err(|e| {
            if gltf::is_gltf_path(file) {
                // The glTF is the scene file itself: its own element is the key.
                SceneError::Key {
                    file: file.to_path_buf(),
                    key: e.element.clone().unwrap_or_else(|| "(file)".into()),
                    message: e.message,
                }
            } else {
                invalid(file, key, path, e)
            }
        })?;
        out.push((i, scene));
    }
    Ok(out)
}

/// The glTFs' meshes as shapes (after the TOML's), an area light for each emissive one.
fn gltf_shapes(
    gltfs: &[(usize, gltf::GltfScene)],
    slots: &[Vec<Option<u32>>],
    file: &Path,
    shapes: &mut Vec<Shape>,
    lights: &mut Vec<Light>,
) -> Result<(), SceneError> {
    for ((i, g), slots) in gltfs.iter().zip(slots) {
        for m in &g.meshes {
            let material = slots[m.material].expect("a used material has a slot");
            let area_light = match g.materials[m.material].emission {
                Some(radiance) if m.mesh.area() > 0.0 => {
                    lights.push(Light::Area {
                        shape: shapes.len() as u32,
                        radiance,
                    });
                    Some(lights.len() as u32 - 1)
                }
                Some(_) => {
                    crate::log::warn(&format!(
                        "scene file {}: shapes[{i}]: {}: an emissive mesh of zero area emits nothing",
                        file.display(),
                        m.element
                    ));
                    None
                }
                None => None,
            };
            shapes.push(Shape {
                geometry: ShapeGeometry::Mesh(m.mesh.clone()),
                material,
                area_light,
            });
        }
    }
    Ok(())
}

/// The render settings: the file's `[render]` table with the command line's overrides.
fn render_settings(
    f: &SceneFile,
    file: &Path,
    o: &Overrides,
) -> Result<RenderSettings, SceneError> {
    o.validate()?;
    let r = &f.render;
    let (width, height) = o.resolution.unwrap_or((r.width, r.height));
    let sampler = match o.sampler {
        Some(kind) => kind,
        None => SamplerKind::from_name(&r.sampler).ok_or_else(|| {
            invalid(
                file,
                "render.sampler",
                &r.sampler,
                format!("must be {}", SamplerKind::allowed_names()),
            )
        })?,
    };
    let settings = RenderSettings {
        width,
        height,
        spp: o.spp.unwrap_or(r.spp),
        max_depth: o.max_depth.unwrap_or(r.max_depth),
        rr_depth: r.rr_depth,
        seed: o.seed.unwrap_or(r.seed),
        exposure: r.exposure,
        sampler,
        triangles: if r.watertight {
            TriangleTest::Watertight
        } else {
            TriangleTest::Fast
        },
        lanes: o.lanes.unwrap_or(r.lanes),
    };
    if settings.spp == 0 || settings.spp > crate::render::sampler::MAX_SPP {
        return Err(invalid(
            file,
            "render.spp",
            settings.spp,
            format!("must lie in 1..={}", crate::render::sampler::MAX_SPP),
        ));
    }
    if !resolution_in_range(width, height) {
        return Err(invalid(
            file,
            "render.width/height",
            (width, height),
            "each must lie in 1..=32768",
        ));
    }
    if !crate::render::film::exposure_in_range(r.exposure) {
        return Err(invalid(
            file,
            "render.exposure",
            r.exposure,
            format!(
                "must lie within +-{} stops",
                crate::render::film::MAX_EXPOSURE
            ),
        ));
    }
    Ok(settings)
}

/// The camera (`[camera]`, else the first glTF shape's camera) at the render's resolution.
fn camera(
    f: &SceneFile,
    gltfs: &[(usize, gltf::GltfScene)],
    file: &Path,
    settings: &RenderSettings,
) -> Result<PerspectiveCamera, SceneError> {
    let (width, height) = (settings.width, settings.height);
    let Some(c) = &f.camera else {
        let Some((i, g, cam)) = gltfs.iter().find_map(|(i, g)| g.camera.map(|c| (i, g, c))) else {
            let reason = match gltf::is_gltf_path(file) {
                true => "the glTF file has no camera (a node with a perspective camera)",
                false => "a scene needs [camera] unless a glTF shape brings one",
            };
            return Err(invalid(file, "camera", "(missing)", reason));
        };
        return PerspectiveCamera::new(
            cam.position,
            cam.position + cam.forward,
            cam.up,
            cam.fov_deg,
            width,
            height,
            0.0,
            1.0,
        )
        .map_err(|e| {
            invalid(
                file,
                format!("shapes[{i}].path"),
                g.file.display().to_string(),
                format!("its camera: {e}"),
            )
        });
    };
    let position = coordinates(file, "camera.position", c.position)?;
    let look_at = coordinates(file, "camera.look_at", c.look_at)?;
    coordinates(file, "camera.up", c.up)?;
    let focus = c.focus_distance.unwrap_or((look_at - position).length());
    PerspectiveCamera::new(
        position,
        look_at,
        Vec3::from_array(c.up),
        c.fov,
        width,
        height,
        c.aperture_radius,
        focus,
    )
    .map_err(|e| camera_error(file, c, (width, height), e))
}

/// The scene's materials, prepared: the TOML's in the order of their names (sorted: the
/// file's table is a `BTreeMap`), then the glTFs' that meshes use and no TOML material of the
/// same name overrides. `explicit`: per material what explicit scratch geometry needs of it
/// (for a scratched material with `scratches.explicit = true`, whose prepared material is
/// then its smooth base: the grooves replace the SV-BRDF). `gltf_slots[g][m]`: the scene's
/// material for glTF `g`'s material `m`.
struct Materials {
    names: Vec<String>,
    materials: Vec<Material>,
    explicit: Vec<Option<ExplicitSpec>>,
    gltf_slots: Vec<Vec<Option<u32>>>,
}

fn materials(
    f: &SceneFile,
    gltfs: &[(usize, gltf::GltfScene)],
    file: &Path,
    base: &Path,
) -> Result<Materials, SceneError> {
    let mut names: Vec<String> = f.materials.keys().cloned().collect();
    let mut materials: Vec<Material> = Vec::with_capacity(names.len());
    let mut explicit = Vec::with_capacity(names.len());
    for (name, m) in &f.materials {
        let error = |e| material_error(file, name, e);
        match m {
            MaterialDesc::Scratched(d) if d.is_explicit() => {
                let spec = d.explicit(base).map_err(error)?;
                materials.push(spec.face.clone());
                explicit.push(Some(spec));
            }
            _ => {
                materials.push(m.prepare(base).map_err(error)?);
                explicit.push(None);
            }
        }
    }
    // glTF materials: names unique across the scene (`name#2` for a second glTF's `name`).
    let mut taken: std::collections::HashSet<String> = std::collections::HashSet::new();
    let mut gltf_slots = Vec::with_capacity(gltfs.len());
    for (_, g) in gltfs {
        let gltf_base = g.file.parent().map(Path::to_path_buf).unwrap_or_default();
        let mut slots = Vec::with_capacity(g.materials.len());
        for m in &g.materials {
            let mut name = m.name.clone();
            let mut k = 1;
            while taken.contains(&name) {
                k += 1;
                name = format!("{}#{k}", m.name);
            }
            taken.insert(name.clone());
            if let Some(at) = f.materials.keys().position(|n| *n == name) {
                slots.push(Some(at as u32));
                continue;
            }
            let desc = m.to_desc(&g.file).map_err(|e| SceneError::Key {
                file: e.file.clone(),
                key: e.element.clone().unwrap_or_default(),
                message: e.message,
            })?;
            let material = desc
                .prepare(&gltf_base)
                .map_err(|e| material_error(&g.file, &name, e))?;
            names.push(name);
            materials.push(material);
            explicit.push(None);
            slots.push(Some(materials.len() as u32 - 1));
        }
        gltf_slots.push(slots);
    }
    Ok(Materials {
        names,
        materials,
        explicit,
        gltf_slots,
    })
}

/// The shapes (`[[shapes]]`), and an area light for each that emits.
/// `plain[k]` is the TOML shape (and its index in the file) that made `shapes[k]`; `gltf`
/// shapes make none here ([`gltf_shapes`]).
type Shapes<'a> = (Vec<(usize, &'a ShapeSection)>, Vec<Shape>, Vec<Light>);
fn shapes<'a>(
    f: &'a SceneFile,
    file: &Path,
    base: &Path,
    names: &[String],
) -> Result<Shapes<'a>, SceneError> {
    let mut shapes = Vec::with_capacity(f.shapes.len());
    let mut plain = Vec::with_capacity(f.shapes.len());
    let mut lights = Vec::new();
    for (i, s) in f.shapes.iter().enumerate() {
        if let Some(key) = s.foreign_keys().first() {
            return Err(invalid(
                file,
                format!("shapes[{i}].{key}"),
                s.kind,
                format!("`{key}` does not apply to this type of shape"),
            ));
        }
        if s.kind == ShapeType::Gltf {
            continue;
        }
        let material = match &s.material {
            Some(name) => names.iter().position(|n| n == name).ok_or_else(|| {
                invalid(
                    file,
                    format!("shapes[{i}].material"),
                    name,
                    format!("no such material (defined: {names:?})"),
                )
            })? as u32,
            None if s.emission.is_some() => NO_MATERIAL,
            None => {
                return Err(invalid(
                    file,
                    format!("shapes[{i}].material"),
                    "(missing)",
                    "a shape needs a material unless it has an emission",
                ))
            }
        };
        let geometry = shape_geometry(s, i, file, base)?;
        let geometry = if s.transform.is_identity() {
            geometry
        } else {
            geometry
                .transformed(&s.transform)
                .map_err(|e| invalid(file, format!("shapes[{i}].transform"), s.transform, e))?
        };
        let area_light = match s.emission {
            Some(e) => {
                let radiance = e.rgb();
                if !(radiance.is_finite() && radiance.min_element() >= 0.0) {
                    return Err(invalid(
                        file,
                        format!("shapes[{i}].emission"),
                        e,
                        "radiance must be finite and >= 0",
                    ));
                }
                lights.push(Light::Area {
                    shape: shapes.len() as u32,
                    radiance,
                });
                Some(lights.len() as u32 - 1)
            }
            None => None,
        };
        let shape = Shape {
            geometry,
            material,
            area_light,
        };
        if shape.area_light.is_some() && !(shape.area() > 0.0) {
            return Err(invalid(
                file,
                format!("shapes[{i}]"),
                s.kind,
                "an emitting shape must have a positive area",
            ));
        }
        shapes.push(shape);
        plain.push((i, s));
    }
    Ok((plain, shapes, lights))
}

/// The environment light (`[environment]`), if any.
fn environment(f: &SceneFile, file: &Path, base: &Path) -> Result<Option<Light>, SceneError> {
    let Some(env) = &f.environment else {
        return Ok(None);
    };
    let e = match env.kind {
        EnvironmentType::Constant => {
            let foreign = [
                ("path", env.path.as_ref().map(|p| format!("{p:?}"))),
                ("scale", env.scale.map(|s| format!("{s:?}"))),
                (
                    "transform",
                    (!env.transform.is_identity()).then(|| format!("{:?}", env.transform)),
                ),
            ];
            if let Some((key, Some(value))) = foreign.into_iter().find(|(_, v)| v.is_some()) {
                return Err(SceneError::Invalid {
                    file: file.to_path_buf(),
                    key: format!("environment.{key}"),
                    value,
                    reason: format!(
                        "`{key}` does not apply to a constant environment (it takes only `radiance`)"
                    ),
                });
            }
            let radiance = env.radiance.ok_or_else(|| {
                invalid(
                    file,
                    "environment.radiance",
                    "(missing)",
                    "a constant environment needs `radiance`",
                )
            })?;
            let rgb = radiance.rgb();
            if !(rgb.is_finite() && rgb.min_element() >= 0.0) {
                return Err(invalid(
                    file,
                    "environment.radiance",
                    radiance,
                    "radiance must be finite and >= 0",
                ));
            }
            Environment::Constant { radiance: rgb }
        }
        EnvironmentType::Map => {
            if env.radiance.is_some() {
                return Err(invalid(
                    file,
                    "environment.radiance",
                    env.radiance,
                    "a map environment takes `path`, `scale` and `transform`",
                ));
            }
            let path = env.path.as_ref().ok_or_else(|| {
                invalid(
                    file,
                    "environment.path",
                    "(missing)",
                    "a map environment needs `path`",
                )
            })?;
            let scale = env.scale.unwrap_or(1.0);
            if !(scale.is_finite() && scale >= 0.0) {
                return Err(invalid(
                    file,
                    "environment.scale",
                    scale,
                    "must be finite and >= 0",
                ));
            }
            let map = load_envmap(&base.join(path), scale, &env.transform)
                .map_err(|e| invalid(file, "environment.path", path, e))?;
            Environment::Map(Box::new(map))
        }
    };
    Ok(Some(Light::Environment(e)))
}

/// The lights of `[[lights]]`, in file order: suns, point and spot lights (all delta lights).
fn punctual_lights(f: &SceneFile, file: &Path) -> Result<Vec<Light>, SceneError> {
    let mut lights = Vec::new();
    for (i, l) in f.lights.iter().enumerate() {
        if let Some(key) = l.foreign_keys().first() {
            return Err(invalid(
                file,
                format!("lights[{i}].{key}"),
                l.kind,
                format!("`{key}` does not apply to this type of light"),
            ));
        }
        let missing = |key: &str| SceneError::Key {
            file: file.to_path_buf(),
            key: format!("lights[{i}].{key}"),
            message: format!("missing: a {:?} light needs `{key}`", l.kind).to_lowercase(),
        };
        let direction = || -> Result<Vec3, SceneError> {
            let v = l.direction.ok_or_else(|| missing("direction"))?;
            let d = Vec3::from_array(v);
            let n = d.normalize();
            if n.is_finite() && n.length_squared() > 0.5 {
                return Ok(n);
            }
            // Scaled by its largest component first, so that no length overflows.
            let d = d / d.abs().max_element();
            if !(d.is_finite() && d.length_squared() > 0.0) {
                return Err(invalid(
                    file,
                    format!("lights[{i}].direction"),
                    v,
                    "must be a finite non-zero vector",
                ));
            }
            Ok(d.normalize())
        };
        let colour = |key: &str, c: Option<file::Colour>| -> Result<crate::math::Rgb, SceneError> {
            let c = c.ok_or_else(|| missing(key))?;
            let e = c.rgb();
            if !(e.is_finite() && e.min_element() >= 0.0) {
                return Err(invalid(
                    file,
                    format!("lights[{i}].{key}"),
                    c,
                    "must be finite and >= 0",
                ));
            }
            Ok(e)
        };
        let position = || -> Result<Vec3, SceneError> {
            let p = l.position.ok_or_else(|| missing("position"))?;
            coordinates(file, format!("lights[{i}].position"), p)
        };
        lights.push(match l.kind {
            LightType::Sun => Light::Sun {
                direction: direction()?,
                irradiance: colour("irradiance", l.irradiance)?,
            },
            LightType::Point => Light::Point {
                position: position()?,
                intensity: colour("intensity", l.intensity)?,
            },
            LightType::Spot => {
                let inner = l.inner_angle.unwrap_or(0.0);
                let outer = l.outer_angle.unwrap_or(45.0);
                if !(inner.is_finite() && (0.0..90.0).contains(&inner)) {
                    return Err(invalid(
                        file,
                        format!("lights[{i}].inner_angle"),
                        inner,
                        "must be a half-angle in degrees, 0 <= inner_angle < 90",
                    ));
                }
                if !(outer.is_finite() && outer > inner && outer <= 90.0) {
                    return Err(invalid(
                        file,
                        format!("lights[{i}].outer_angle"),
                        outer,
                        format!(
                            "must be a half-angle in degrees, inner_angle ({inner}) < outer_angle <= 90"
                        ),
                    ));
                }
                Light::spot(
                    position()?,
                    direction()?,
                    colour("intensity", l.intensity)?,
                    inner.to_radians(),
                    outer.to_radians(),
                )
            }
        });
    }
    Ok(lights)
}

/// Load an environment map and orient it: `transform` must be a rotation (directions only).
fn load_envmap(
    path: &Path,
    scale: f32,
    transform: &crate::render::geometry::Transform,
) -> Result<EnvMap, String> {
    let m = glam::Mat3::from_mat4(transform.matrix());
    let orthonormal =
        (m.transpose() * m).abs_diff_eq(glam::Mat3::IDENTITY, 1e-4) && m.determinant() > 0.0;
    if !orthonormal {
        return Err("the environment's transform must be a rotation".into());
    }
    let map = EnvMap::load(path).map_err(|e| e.to_string())?;
    let map = map.with_scale(scale).map_err(|e| e.to_string())?;
    Ok(map.with_rotation(m))
}

fn shape_geometry(
    s: &ShapeSection,
    i: usize,
    file: &Path,
    base: &Path,
) -> Result<ShapeGeometry, SceneError> {
    Ok(match s.kind {
        ShapeType::Mesh => {
            let path = s.path.as_ref().ok_or_else(|| {
                invalid(
                    file,
                    format!("shapes[{i}].path"),
                    "(missing)",
                    "a mesh needs the path of an OBJ file",
                )
            })?;
            let mesh = TriangleMesh::from_obj(base.join(path))
                .map_err(|e| invalid(file, format!("shapes[{i}].path"), path, e))?;
            ShapeGeometry::Mesh(mesh)
        }
        ShapeType::Teapot => {
            let n = s.subdivisions.unwrap_or(8);
            if !(1..=64).contains(&n) {
                return Err(invalid(
                    file,
                    format!("shapes[{i}].subdivisions"),
                    n,
                    "must lie in 1..=64",
                ));
            }
            // Newell's teapot is z-up with its base at z = 0; scenes are y-up.
            let z_up_to_y_up =
                crate::render::geometry::Transform::rotate(Vec3::X, -90.0).expect("valid rotation");
            ShapeGeometry::Mesh(
                TriangleMesh::teapot(n)
                    .transformed(&z_up_to_y_up)
                    .expect("a rotation keeps the built-in teapot finite"),
            )
        }
        ShapeType::Gltf => unreachable!("gltf shapes are imported by `import_gltfs`"),
        ShapeType::Rectangle => ShapeGeometry::Mesh(TriangleMesh::rectangle()),
        ShapeType::Box => ShapeGeometry::Mesh(TriangleMesh::cuboid()),
        ShapeType::Sphere => {
            let radius = s.radius.unwrap_or(1.0);
            let center = coordinates(
                file,
                format!("shapes[{i}].center"),
                s.center.unwrap_or([0.0; 3]),
            )?;
            ShapeGeometry::sphere(center, radius)
                .map_err(|e| invalid(file, format!("shapes[{i}].radius"), radius, e))?
        }
    })
}
