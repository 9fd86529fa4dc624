//! The glTF 2.0 importer (`.gltf` with its buffers and images, or a binary `.glb`): the default
//! scene's triangle meshes in world space, its first camera, its `KHR_lights_punctual` lights
//! and its materials, as the scene description the TOML loader builds on (`docs/scenes.md`,
//! "glTF"; the vendor extension `STRIAE_materials_scratches` in
//! `docs/STRIAE_materials_scratches.md`).
//!
//! The `gltf` crate parses the JSON and the GLB container and checks that every index names an
//! existing object. It does not check that an accessor lies within its buffer view, nor a view
//! within its buffer, nor index values against the vertex count, nor float values: all of
//! that is checked here, against the bytes actually held, before anything is allocated, and
//! every error names the file and the element (`meshes[0].primitives[1].indices`).
//!
//! Units: glTF lengths are metres and striae's are unitless, taken as they are. Punctual light
//! intensities are photometric (candela for point and spot lights, lux for directional ones);
//! striae is radiometric: `I [W/sr] = cd / 683` and `E [W/m^2] = lux / 683`, 683 lm/W being the
//! luminous efficacy at 555 nm (the definition of the candela). One exception: Blender's
//! exporter writes a sun's W/m^2 as its "lux" (`docs/blender.md`), so a directional light in a
//! file whose `asset.generator` names that exporter is read as W/m^2, with a warning.

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::materials::{MaterialDesc, PbrDesc};
use super::scratches::{BaseKind, ScratchSpec, ScratchedDesc};
use crate::math::{Rgb, Vec2, Vec3};
use crate::render::geometry::{Transform, TriangleMesh};
use crate::render::lights::Light;
use crate::render::texture::{RgbImage, Texture};
use ::gltf::json;
use glam::{Mat4, Quat, Vec4};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Photometric to radiometric: lumens per watt at 555 nm.
pub const LUMENS_PER_WATT: f32 = 683.0;

/// The name of the vendor extension that puts scratches on a glTF material.
pub const SCRATCHES_EXTENSION: &str = "STRIAE_materials_scratches";

/// Extensions whose data the importer reads.
pub const SUPPORTED_EXTENSIONS: &[&str] = &[
    "KHR_lights_punctual",
    "KHR_materials_emissive_strength",
    "KHR_materials_ior",
    "KHR_materials_transmission",
    "KHR_materials_volume",
    "KHR_materials_anisotropy",
    SCRATCHES_EXTENSION,
];

/// Deepest node hierarchy followed.
const MAX_NODE_DEPTH: usize = 1024;

/// A glTF file that cannot be imported: the file, the element (`meshes[0].primitives[1].indices`)
/// where there is one, and why.
#[derive(Debug, thiserror::Error)]
#[error("glTF file {}: {}{message}", file.display(), element.as_ref().map(|e| format!("`{e}`: ")).unwrap_or_default())]
pub struct GltfError {
    pub file: PathBuf,
    pub element: Option<String>,
    pub message: String,
}

/// A camera as the glTF places it (world space, after the importer's transform).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GltfCamera {
    pub position: Vec3,
    /// Unit view direction: the node's local `-z`.
    pub forward: Vec3,
    /// The node's local `+y`.
    pub up: Vec3,
    /// Vertical field of view in degrees (glTF's `yfov`, in radians there).
    pub fov_deg: f32,
}

/// A glTF material as imported, before it is mapped onto a striae material
/// ([`ImportedMaterial::to_desc`]). Factors and textures keep glTF's meaning, except that the
/// base colour factor is multiplied into the base colour texture's pixels.
#[derive(Clone, Debug)]
pub struct ImportedMaterial {
    /// The glTF's `materials[i]` (`None`: glTF's default material).
    pub index: Option<usize>,
    /// Unique within the scene (`name`, `name#2`, ...; an unnamed material is `material<i>`).
    pub name: String,
    /// The metallic-roughness description, glTF's factors and textures field for field:
    /// `base_color` is `baseColorFactor` (rgb) times `baseColorTexture` (sRGB decoded), not
    /// yet clamped; `metallic_roughness` is linear (green: roughness, blue: metallic, times the
    /// factors); `ior` is `KHR_materials_ior`, `transmission` `KHR_materials_transmission`,
    /// the attenuation `KHR_materials_volume`'s (its thickness is not needed: meshes are
    /// closed); `anisotropy_rotation` is in degrees, counter-clockwise from the tangent.
    pub pbr: PbrDesc,
    /// `emissiveFactor * KHR_materials_emissive_strength`, where not black.
    pub emission: Option<Rgb>,
    /// `STRIAE_materials_scratches`, read as `[materials.NAME.scratches]` is.
    pub scratches: Option<ScratchSpec>,
    /// `KHR_materials_anisotropy`'s direction texture (its rotation applied) as the flow map of
    /// the scratches' painted map ([`anisotropy_flow`]), where they have a `map` and no
    /// `direction`.
    pub scratch_flow: Option<Arc<RgbImage>>,
}

/// One triangle primitive instanced by one node, in world space.
#[derive(Clone, Debug)]
pub struct GltfMesh {
    /// `meshes[m].primitives[p]` and the instancing node, for messages.
    pub element: String,
    pub mesh: TriangleMesh,
    /// Index into [`GltfScene::materials`].
    pub material: usize,
}

/// Everything imported from one glTF file.
#[derive(Clone, Debug)]
pub struct GltfScene {
    pub file: PathBuf,
    pub meshes: Vec<GltfMesh>,
    pub materials: Vec<ImportedMaterial>,
    pub camera: Option<GltfCamera>,
    /// `KHR_lights_punctual`'s lights in striae's radiometric units, world space: suns, point
    /// and spot lights.
    pub lights: Vec<Light>,
}

/// Whether `path` names a glTF file by its extension (`.gltf` or `.glb`, any case).
pub fn is_gltf_path(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("gltf") || e.eq_ignore_ascii_case("glb"))
}

/// Read and import a glTF file; `transform` is applied to the whole scene.
pub fn import(path: &Path, transform: &Transform) -> Result<GltfScene, GltfError> {
    let bytes =
        crate::io::read_bounded(path, crate::io::MAX_BINARY_BYTES).map_err(|e| GltfError {
            file: path.to_path_buf(),
            element: None,
            message: format!("cannot read it: {e}"),
        })?;
    import_bytes(&bytes, path, transform)
}

/// Import a glTF held in `bytes`, read from `path` (which names it in messages and whose
/// folder resolves relative `uri`s).
pub fn import_bytes(
    bytes: &[u8],
    path: &Path,
    transform: &Transform,
) -> Result<GltfScene, GltfError> {
    let mut importer = Importer::parse(bytes, path)?;
    importer.load_buffers()?;
    importer.walk(transform)
}

fn warn(file: &Path, message: &str) {
    crate::log::warn(&format!("glTF file {}: {message}", file.display()));
}

struct Importer {
    file: PathBuf,
    base: PathBuf,
    root: json::Root,
    blob: Option<Vec<u8>>,
    buffers: Vec<Vec<u8>>,
    images: HashMap<(usize, bool), Arc<RgbImage>>,
}

impl Importer {
    fn error(
        &self,
        element: impl Into<Option<String>>,
        message: impl std::fmt::Display,
    ) -> GltfError {
        GltfError {
            file: self.file.clone(),
            element: element.into(),
            message: message.to_string(),
        }
    }

    /// The JSON (and GLB container) parsed and validated by the `gltf` crate; the extensions
    /// checked here (the crate would refuse required extensions it has no types for).
    fn parse(bytes: &[u8], path: &Path) -> Result<Importer, GltfError> {
        let error = |element: Option<String>, message: String| GltfError {
            file: path.to_path_buf(),
            element,
            message,
        };
        let gltf = ::gltf::Gltf::from_slice_without_validation(bytes)
            .map_err(|e| error(None, format!("cannot parse it: {e}")))?;
        let blob = gltf.blob;
        let mut root = gltf.document.into_json();
        for (i, ext) in root.extensions_required.iter().enumerate() {
            if !SUPPORTED_EXTENSIONS.contains(&ext.as_str()) {
                return Err(error(
                    Some(format!("extensionsRequired[{i}]")),
                    format!("requires the extension {ext}, which striae does not support (supported: {})", SUPPORTED_EXTENSIONS.join(", ")),
                ));
            }
        }
        for ext in &root.extensions_used {
            if !SUPPORTED_EXTENSIONS.contains(&ext.as_str()) {
                warn(
                    path,
                    &format!("uses the extension {ext}, which striae does not support: ignored"),
                );
            }
        }
        let required = std::mem::take(&mut root.extensions_required);
        let document =
            ::gltf::Document::from_json(root).map_err(|e| error(None, format!("invalid: {e}")))?;
        let mut root = document.into_json();
        root.extensions_required = required;
        Ok(Importer {
            file: path.to_path_buf(),
            base: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            root,
            blob,
            buffers: Vec::new(),
            images: HashMap::new(),
        })
    }

    /// The bytes of a `uri`: a base64 data URI or a file relative to the glTF's folder.
    fn read_uri(&self, uri: &str, element: &str) -> Result<Vec<u8>, GltfError> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let (_, data) = rest.split_once(";base64,").ok_or_else(|| {
                self.error(
                    element.to_string(),
                    "a data URI must be base64 (`data:...;base64,...`)",
                )
            })?;
            return base64_decode(data).ok_or_else(|| {
                self.error(element.to_string(), "its data URI is not valid base64")
            });
        }
        let relative = percent_decode(uri).ok_or_else(|| {
            self.error(
                element.to_string(),
                format!("bad percent-encoding in uri {uri:?}"),
            )
        })?;
        if relative.contains("://") {
            return Err(self.error(
                element.to_string(),
                format!("uri {uri:?}: only data URIs and relative files are read"),
            ));
        }
        let path = self.base.join(&relative);
        let size = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        crate::memory::check(&format!("{element} ({})", path.display()), size, None)
            .map_err(|e| self.error(element.to_string(), e))?;
        crate::io::read_bounded(&path, crate::io::MAX_BINARY_BYTES).map_err(|e| {
            self.error(
                element.to_string(),
                format!("cannot read {}: {e}", path.display()),
            )
        })
    }

    /// Every buffer's bytes: the GLB's BIN chunk, data URIs, files; each at least its
    /// `byteLength`.
    fn load_buffers(&mut self) -> Result<(), GltfError> {
        let mut buffers = Vec::with_capacity(self.root.buffers.len());
        for (i, b) in self.root.buffers.iter().enumerate() {
            let element = format!("buffers[{i}]");
            let data = match &b.uri {
                Some(uri) => self.read_uri(uri, &element)?,
                None => match (i, &self.blob) {
                    (0, Some(blob)) => blob.clone(),
                    _ => {
                        return Err(
                            self.error(element, "has no uri and the file has no GLB binary chunk")
                        )
                    }
                },
            };
            let need = b.byte_length.0;
            if (data.len() as u64) < need {
                return Err(self.error(
                    element,
                    format!("holds {} bytes, its byteLength is {need}", data.len()),
                ));
            }
            buffers.push(data);
        }
        self.blob = None;
        self.buffers = buffers;
        Ok(())
    }

    /// The bytes of accessor `index` with `components` values of `component_size` bytes per
    /// element, element by element (stride removed): `count * components * component_size`
    /// bytes, after checking that they lie in the view and the view in its buffer.
    fn accessor_bytes(
        &self,
        index: usize,
        element: &str,
        components: usize,
    ) -> Result<(Vec<u8>, json::accessor::ComponentType, usize, bool), GltfError> {
        let bad = |m: String| self.error(element.to_string(), format!("accessors[{index}]: {m}"));
        let a = &self.root.accessors[index];
        let json::validation::Checked::Valid(ty) = a.type_ else {
            return Err(bad("invalid type".into()));
        };
        if ty.multiplicity() != components {
            return Err(bad(format!(
                "has type {ty:?}, expected {components} components"
            )));
        }
        let json::validation::Checked::Valid(ct) = a.component_type else {
            return Err(bad("invalid componentType".into()));
        };
        let ct = ct.0;
        if a.sparse.is_some() {
            return Err(bad("sparse accessors are not supported".into()));
        }
        let count = a.count.0;
        let Some(view_index) = a.buffer_view else {
            return Err(bad(
                "has no bufferView (zero-filled accessors are not supported)".into(),
            ));
        };
        let view = &self.root.buffer_views[view_index.value()];
        let buffer = &self.buffers[view.buffer.value()];
        let view_offset = view.byte_offset.map_or(0, |o| o.0);
        let view_length = view.byte_length.0;
        if view_offset
            .checked_add(view_length)
            .is_none_or(|end| end > buffer.len() as u64)
        {
            return Err(bad(format!(
                "bufferViews[{}] (offset {view_offset}, length {view_length}) lies beyond buffers[{}] ({} bytes)",
                view_index.value(),
                view.buffer.value(),
                buffer.len()
            )));
        }
        let size = ct.size();
        let element_size = (size * components) as u64;
        let stride = view.byte_stride.map_or(element_size, |s| s.0 as u64);
        if stride < element_size {
            return Err(bad(format!(
                "byteStride {stride} is less than an element's {element_size} bytes"
            )));
        }
        let offset = a.byte_offset.map_or(0, |o| o.0);
        if count > 0 {
            let end = (count - 1)
                .checked_mul(stride)
                .and_then(|x| x.checked_add(offset))
                .and_then(|x| x.checked_add(element_size));
            if end.is_none_or(|end| end > view_length) {
                return Err(bad(format!(
                    "{count} elements of {element_size} bytes at stride {stride} from offset {offset} lie beyond bufferViews[{}] ({view_length} bytes)",
                    view_index.value()
                )));
            }
        }
        let total = count * element_size;
        crate::memory::check(element, total, None)
            .map_err(|e| self.error(element.to_string(), e))?;
        let mut out = crate::memory::try_with_capacity(total as usize, element)
            .map_err(|e| self.error(element.to_string(), e))?;
        let start = (view_offset + offset) as usize;
        for k in 0..count as usize {
            let s = start + k * stride as usize;
            out.extend_from_slice(&buffer[s..s + element_size as usize]);
        }
        Ok((out, ct, count as usize, a.normalized))
    }

    /// Accessor `index` as floats, `components` per element: `FLOAT`, or normalised integers.
    fn floats(
        &self,
        index: usize,
        element: &str,
        components: usize,
    ) -> Result<Vec<f32>, GltfError> {
        use json::accessor::ComponentType as C;
        let (bytes, ct, _, normalized) = self.accessor_bytes(index, element, components)?;
        let values: Vec<f32> = match (ct, normalized) {
            (C::F32, _) => bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect(),
            (C::U8, true) => bytes.iter().map(|&b| b as f32 / 255.0).collect(),
            (C::I8, true) => bytes.iter().map(|&b| (b as i8 as f32 / 127.0).max(-1.0)).collect(),
            (C::U16, true) => bytes.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]]) as f32 / 65535.0).collect(),
            (C::I16, true) => bytes.chunks_exact(2).map(|b| (i16::from_le_bytes([b[0], b[1]]) as f32 / 32767.0).max(-1.0)).collect(),
            _ => {
                return Err(self.error(
                    element.to_string(),
                    format!("accessors[{index}]: component type {ct:?} (normalized: {normalized}) is not a float type"),
                ))
            }
        };
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(self.error(
                element.to_string(),
                format!(
                    "accessors[{index}]: element {} holds a non-finite value ({})",
                    i / components,
                    values[i]
                ),
            ));
        }
        Ok(values)
    }

    /// Accessor `index` as vertex indices (`UNSIGNED_BYTE`, `_SHORT` or `_INT` scalars).
    fn indices(&self, index: usize, element: &str) -> Result<Vec<u32>, GltfError> {
        use json::accessor::ComponentType as C;
        let (bytes, ct, _, _) = self.accessor_bytes(index, element, 1)?;
        Ok(match ct {
            C::U8 => bytes.iter().map(|&b| b as u32).collect(),
            C::U16 => bytes
                .chunks_exact(2)
                .map(|b| u16::from_le_bytes([b[0], b[1]]) as u32)
                .collect(),
            C::U32 => bytes
                .chunks_exact(4)
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            _ => {
                return Err(self.error(
                    element.to_string(),
                    format!("accessors[{index}]: indices must be unsigned integers, not {ct:?}"),
                ))
            }
        })
    }

    /// The default scene's nodes, depth first, each with its world matrix (`transform` last:
    /// it maps the glTF's world into the scene's), and what they hold: the first camera, the
    /// lights, and each mesh primitive once per node that instances it, its material imported
    /// on first use.
    fn walk(mut self, transform: &Transform) -> Result<GltfScene, GltfError> {
        let roots: Vec<usize> = match self.root.scene.map(|s| s.value()).or((!self
            .root
            .scenes
            .is_empty())
        .then_some(0))
        {
            Some(s) => self.root.scenes[s]
                .nodes
                .iter()
                .map(|n| n.value())
                .collect(),
            None => {
                // No scene: every node that is no other's child.
                let mut child = vec![false; self.root.nodes.len()];
                for n in &self.root.nodes {
                    for c in n.children.iter().flatten() {
                        child[c.value()] = true;
                    }
                }
                (0..self.root.nodes.len()).filter(|&i| !child[i]).collect()
            }
        };
        let mut visited = vec![false; self.root.nodes.len()];
        let mut stack: Vec<(usize, Mat4, usize)> = roots
            .into_iter()
            .rev()
            .map(|n| (n, transform.matrix(), 0))
            .collect();
        let mut instances = Vec::new();
        while let Some((n, parent, depth)) = stack.pop() {
            let element = format!("nodes[{n}]");
            if std::mem::replace(&mut visited[n], true) {
                return Err(self.error(
                    element,
                    "is reached twice (a node has one parent, and the hierarchy has no cycles)",
                ));
            }
            if depth > MAX_NODE_DEPTH {
                return Err(self.error(element, format!("lies deeper than {MAX_NODE_DEPTH} nodes")));
            }
            let node = &self.root.nodes[n];
            let local = match node.matrix {
                Some(m) => Mat4::from_cols_array(&m),
                None => {
                    let t = node.translation.unwrap_or([0.0; 3]);
                    let r = node.rotation.map_or([0.0, 0.0, 0.0, 1.0], |r| r.0);
                    let s = node.scale.unwrap_or([1.0; 3]);
                    Mat4::from_scale_rotation_translation(
                        Vec3::from(s),
                        Quat::from_array(r).normalize(),
                        Vec3::from(t),
                    )
                }
            };
            if !local.is_finite() {
                return Err(self.error(element, "its transform has non-finite values"));
            }
            let world = parent * local;
            instances.push((n, world));
            for c in node.children.iter().flatten().rev() {
                stack.push((c.value(), world, depth + 1));
            }
        }
        let mut scene = GltfScene {
            file: self.file.clone(),
            meshes: Vec::new(),
            materials: Vec::new(),
            camera: None,
            lights: Vec::new(),
        };
        // Materials: imported on first use, glTF's default material included.
        let mut material_slots: HashMap<Option<usize>, usize> = HashMap::new();
        let mut names: HashMap<String, usize> = HashMap::new();
        let mut mesh_cache: HashMap<(usize, usize), Option<TriangleMesh>> = HashMap::new();
        for &(n, world) in &instances {
            let node = &self.root.nodes[n];
            if let Some(c) = node.camera {
                if scene.camera.is_none() {
                    scene.camera = Some(self.camera(c.value(), world)?);
                }
            }
            if let Some(l) = node
                .extensions
                .as_ref()
                .and_then(|e| e.khr_lights_punctual.as_ref())
            {
                if let Some(light) = self.light(l.light.value(), world)? {
                    scene.lights.push(light);
                }
            }
            let Some(m) = node.mesh else { continue };
            let m = m.value();
            let t = match Transform::from_matrix(world) {
                Ok(t) => t,
                Err(e) => {
                    warn(&self.file, &format!("nodes[{n}] instances meshes[{m}] under a singular transform ({e}): skipped"));
                    continue;
                }
            };
            for p in 0..self.root.meshes[m].primitives.len() {
                let local = match mesh_cache.get(&(m, p)) {
                    Some(mesh) => mesh.clone(),
                    None => {
                        let mesh = self.primitive(m, p)?;
                        mesh_cache.insert((m, p), mesh.clone());
                        mesh
                    }
                };
                let Some(local) = local else { continue };
                let element = format!("meshes[{m}].primitives[{p}]");
                let mesh = local
                    .transformed(&t)
                    .map_err(|e| self.error(format!("nodes[{n}]"), format!("{element}: {e}")))?;
                let key = self.root.meshes[m].primitives[p]
                    .material
                    .map(|i| i.value());
                let material = match material_slots.get(&key) {
                    Some(&slot) => slot,
                    None => {
                        let mut imported = self.material(key)?;
                        let count = names.entry(imported.name.clone()).or_insert(0);
                        *count += 1;
                        if *count > 1 {
                            imported.name = format!("{}#{count}", imported.name);
                        }
                        scene.materials.push(imported);
                        material_slots.insert(key, scene.materials.len() - 1);
                        scene.materials.len() - 1
                    }
                };
                scene.meshes.push(GltfMesh {
                    element: format!("{element} (nodes[{n}])"),
                    mesh,
                    material,
                });
            }
        }
        Ok(scene)
    }

    /// `cameras[c]` placed by a node's world matrix.
    fn camera(&self, c: usize, world: Mat4) -> Result<GltfCamera, GltfError> {
        let element = format!("cameras[{c}]");
        let cam = &self.root.cameras[c];
        let Some(p) = &cam.perspective else {
            return Err(self.error(
                element,
                "only perspective cameras are supported (this one is orthographic)",
            ));
        };
        let fov_deg = p.yfov.to_degrees();
        if !(fov_deg > 0.0 && fov_deg < 180.0) {
            return Err(self.error(
                element + ".perspective.yfov",
                format!("{} must lie in (0, pi) radians", p.yfov),
            ));
        }
        let position = world.transform_point3(Vec3::ZERO);
        let forward = world.transform_vector3(-Vec3::Z).normalize_or_zero();
        let up = world.transform_vector3(Vec3::Y).normalize_or_zero();
        if forward == Vec3::ZERO || up == Vec3::ZERO || !position.is_finite() {
            return Err(self.error(element, "its node's transform is degenerate"));
        }
        Ok(GltfCamera {
            position,
            forward,
            up,
            fov_deg,
        })
    }

    /// `KHR_lights_punctual.lights[l]` placed by a node's world matrix.
    fn light(&self, l: usize, world: Mat4) -> Result<Option<Light>, GltfError> {
        use json::extensions::scene::khr_lights_punctual::Type;
        let element = format!("extensions.KHR_lights_punctual.lights[{l}]");
        let Some(light) = self
            .root
            .extensions
            .as_ref()
            .and_then(|e| e.khr_lights_punctual.as_ref())
            .and_then(|k| k.lights.get(l))
        else {
            return Err(self.error(element, "no such light"));
        };
        let json::validation::Checked::Valid(kind) = light.type_ else {
            return Err(self.error(element, "invalid type"));
        };
        // Blender's exporter writes a sun's W/m^2 as its "lux" (docs/blender.md): read as written.
        let blender_sun = kind == Type::Directional && self.written_by_blender();
        let lumens_per_watt = if blender_sun { 1.0 } else { LUMENS_PER_WATT };
        if blender_sun {
            warn(&self.file, &format!("{element}: written by Blender's exporter, whose directional intensity is the sun's W/m^2, not lux: read as W/m^2"));
        }
        let intensity = Rgb::from(light.color) * light.intensity / lumens_per_watt;
        if !(intensity.is_finite() && intensity.min_element() >= 0.0) {
            return Err(self.error(element, "color and intensity must be finite and >= 0"));
        }
        if light.range.is_some_and(|r| r.is_finite()) {
            warn(&self.file, &format!("{element}: range is ignored (striae's lights fall off with the inverse square only)"));
        }
        let position = world.transform_point3(Vec3::ZERO);
        let direction = world.transform_vector3(-Vec3::Z).normalize_or_zero();
        Ok(Some(match kind {
            Type::Directional => {
                if direction == Vec3::ZERO {
                    return Err(self.error(element, "its node's transform is degenerate"));
                }
                Light::Sun {
                    direction: -direction,
                    irradiance: intensity,
                }
            }
            Type::Point => Light::Point {
                position,
                intensity,
            },
            Type::Spot => {
                let spot = light
                    .spot
                    .as_ref()
                    .ok_or_else(|| self.error(element.clone(), "a spot light needs `spot`"))?;
                let (inner, outer) = (spot.inner_cone_angle, spot.outer_cone_angle);
                if !(0.0 <= inner && inner < outer && outer <= std::f32::consts::FRAC_PI_2) {
                    return Err(self.error(
                        element + ".spot",
                        format!("cone angles {inner}, {outer}: need 0 <= inner < outer <= pi/2"),
                    ));
                }
                if direction == Vec3::ZERO {
                    return Err(self.error(element, "its node's transform is degenerate"));
                }
                Light::Spot {
                    position,
                    direction,
                    intensity,
                    cos_inner: inner.cos(),
                    cos_outer: outer.cos(),
                }
            }
        }))
    }

    /// Whether `asset.generator` names Blender's glTF exporter ("Khronos glTF Blender I/O").
    fn written_by_blender(&self) -> bool {
        (self.root.asset.generator.as_deref())
            .is_some_and(|g| g.starts_with("Khronos glTF Blender I/O"))
    }

    /// The local mesh of `meshes[m].primitives[p]`, `None` (with a warning) for a primitive
    /// that is not triangles or has no triangles.
    fn primitive(&self, m: usize, p: usize) -> Result<Option<TriangleMesh>, GltfError> {
        use json::mesh::{Mode, Semantic};
        let element = format!("meshes[{m}].primitives[{p}]");
        let prim = &self.root.meshes[m].primitives[p];
        let mesh_name = self.root.meshes[m].name.clone().unwrap_or_default();
        match prim.mode {
            json::validation::Checked::Valid(Mode::Triangles) => {}
            mode => {
                warn(&self.file, &format!("{element} (mesh {mesh_name:?}) has mode {mode:?}: only triangles are rendered, skipped"));
                return Ok(None);
            }
        }
        let attribute = |s: Semantic| {
            prim.attributes
                .get(&json::validation::Checked::Valid(s))
                .map(|a| a.value())
        };
        let Some(pos) = attribute(Semantic::Positions) else {
            warn(
                &self.file,
                &format!("{element} (mesh {mesh_name:?}) has no POSITION: skipped"),
            );
            return Ok(None);
        };
        let pos_el = format!("{element}.attributes.POSITION");
        let positions = self.floats(pos, &pos_el, 3)?;
        let n = positions.len() / 3;
        if n > u32::MAX as usize {
            return Err(self.error(pos_el, format!("{n} vertices: at most 2^32 - 1")));
        }
        let positions: Vec<Vec3> = positions.chunks_exact(3).map(Vec3::from_slice).collect();
        let indices: Vec<u32> = match prim.indices {
            Some(i) => {
                let idx_el = format!("{element}.indices");
                let idx = self.indices(i.value(), &idx_el)?;
                if let Some((k, &v)) = idx.iter().enumerate().find(|(_, &v)| v as usize >= n) {
                    return Err(self.error(
                        idx_el,
                        format!("index {v} (element {k}) is past the vertex count {n}"),
                    ));
                }
                if idx.len() % 3 != 0 {
                    return Err(self.error(
                        idx_el,
                        format!("{} indices are not whole triangles", idx.len()),
                    ));
                }
                idx
            }
            None => {
                if n % 3 != 0 {
                    return Err(self.error(
                        pos_el,
                        format!("{n} vertices without indices are not whole triangles"),
                    ));
                }
                (0..n as u32).collect()
            }
        };
        if indices.is_empty() {
            warn(
                &self.file,
                &format!("{element} (mesh {mesh_name:?}) has no triangles: skipped"),
            );
            return Ok(None);
        }
        let same_count = |what: &str, len: usize| {
            if len != n {
                Err(self.error(
                    format!("{element}.attributes.{what}"),
                    format!("{len} elements for {n} vertices"),
                ))
            } else {
                Ok(())
            }
        };
        let normals = match attribute(Semantic::Normals) {
            Some(a) => {
                let v = self.floats(a, &format!("{element}.attributes.NORMAL"), 3)?;
                same_count("NORMAL", v.len() / 3)?;
                Some(v.chunks_exact(3).map(Vec3::from_slice).collect::<Vec<_>>())
            }
            None => None,
        };
        let uvs = match attribute(Semantic::TexCoords(0)) {
            Some(a) => {
                let v = self.floats(a, &format!("{element}.attributes.TEXCOORD_0"), 2)?;
                same_count("TEXCOORD_0", v.len() / 2)?;
                // glTF's uv origin is the image's top-left, as striae's: no flip.
                Some(v.chunks_exact(2).map(Vec2::from_slice).collect::<Vec<_>>())
            }
            None => None,
        };
        let tangents = match (attribute(Semantic::Tangents), &uvs) {
            (Some(a), Some(uvs)) => {
                let v = self.floats(a, &format!("{element}.attributes.TANGENT"), 4)?;
                same_count("TANGENT", v.len() / 4)?;
                let t: Vec<Vec4> = v.chunks_exact(4).map(Vec4::from_slice).collect();
                Some(tangents_from_gltf(
                    &positions,
                    &indices,
                    uvs,
                    normals.as_deref(),
                    &t,
                ))
            }
            _ => None,
        };
        let triangles: Vec<[u32; 3]> = indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect();
        TriangleMesh::new(positions, triangles, normals, uvs, tangents)
            .map(Some)
            .map_err(|e| self.error(element, e))
    }

    /// `materials[i]`, or glTF's default material for `None`.
    fn material(&mut self, index: Option<usize>) -> Result<ImportedMaterial, GltfError> {
        let default = json::Material::default();
        let mat = match index {
            Some(i) => self.root.materials[i].clone(),
            None => default,
        };
        let element = match index {
            Some(i) => format!("materials[{i}]"),
            None => "(default material)".to_string(),
        };
        let name = match (index, &mat.name) {
            (_, Some(n)) if !n.is_empty() => n.clone(),
            (Some(i), _) => format!("material{i}"),
            (None, _) => "gltf-default".to_string(),
        };
        let pbr = &mat.pbr_metallic_roughness;
        let factor = pbr.base_color_factor.0;
        if !matches!(
            mat.alpha_mode,
            json::validation::Checked::Valid(json::material::AlphaMode::Opaque)
        ) || factor[3] < 1.0
        {
            warn(&self.file, &format!("{element}: alpha (alphaMode, base colour alpha) is ignored: the surface is opaque"));
        }
        let rgb = Rgb::new(factor[0], factor[1], factor[2]);
        let base_color = match &pbr.base_color_texture {
            Some(t) => {
                let img = self.texture(
                    t.index.value(),
                    t.tex_coord,
                    &t.extensions,
                    &format!("{element}.pbrMetallicRoughness.baseColorTexture"),
                    true,
                )?;
                let pixels = img.pixels.iter().map(|&p| p * rgb).collect();
                self.image_texture(
                    t.index.value(),
                    true,
                    Arc::new(RgbImage::new(img.width, img.height, pixels)),
                )
            }
            None => Texture::Constant(rgb),
        };
        let metallic_roughness = match &pbr.metallic_roughness_texture {
            Some(t) => {
                let img = self.texture(
                    t.index.value(),
                    t.tex_coord,
                    &t.extensions,
                    &format!("{element}.pbrMetallicRoughness.metallicRoughnessTexture"),
                    false,
                )?;
                Some(self.image_texture(t.index.value(), false, img))
            }
            None => None,
        };
        let (normal_map, normal_scale) = match &mat.normal_texture {
            Some(t) => {
                let img = self.texture(
                    t.index.value(),
                    t.tex_coord,
                    &None,
                    &format!("{element}.normalTexture"),
                    false,
                )?;
                (
                    Some(self.image_texture(t.index.value(), false, img)),
                    t.scale,
                )
            }
            None => (None, 1.0),
        };
        if mat.occlusion_texture.is_some() {
            warn(
                &self.file,
                &format!(
                    "{element}: occlusionTexture is ignored (a path tracer computes occlusion)"
                ),
            );
        }
        let ext = mat.extensions.as_ref();
        let ior = ext.and_then(|e| e.ior.as_ref()).map_or(1.5, |i| i.ior.0);
        let transmission = ext.and_then(|e| e.transmission.as_ref()).map_or(0.0, |t| {
            if t.transmission_texture.is_some() {
                warn(&self.file, &format!("{element}: KHR_materials_transmission's transmissionTexture is ignored (the factor is used)"));
            }
            t.transmission_factor.0
        });
        let (attenuation_color, attenuation_distance) = ext.and_then(|e| e.volume.as_ref()).map_or(([1.0; 3], None), |v| {
            if v.thickness_texture.is_some() {
                warn(&self.file, &format!("{element}: KHR_materials_volume's thickness is not needed (meshes are closed): ignored"));
            }
            let d = v.attenuation_distance.0;
            (v.attenuation_color.0, d.is_finite().then_some(d))
        });
        let strength = ext
            .and_then(|e| e.emissive_strength.as_ref())
            .map_or(1.0, |s| s.emissive_strength.0);
        let emission = Rgb::from(mat.emissive_factor.0) * strength;
        if !(emission.is_finite() && emission.min_element() >= 0.0) {
            return Err(self.error(
                element,
                "emissiveFactor times emissive strength must be finite and >= 0",
            ));
        }
        if mat.emissive_texture.is_some() {
            warn(
                &self.file,
                &format!(
                    "{element}: emissiveTexture is not supported: the emissiveFactor alone is used"
                ),
            );
        }
        let others = ext.map(|e| e.others.clone()).unwrap_or_default();
        let scratches = match others.get(SCRATCHES_EXTENSION) {
            Some(v) => {
                Some(self.scratch_spec(v, &format!("{element}.extensions.{SCRATCHES_EXTENSION}"))?)
            }
            None => None,
        };
        let (mut anisotropy, mut anisotropy_rotation) = (0.0, 0.0);
        let mut scratch_flow = None;
        if let Some(a) = others.get("KHR_materials_anisotropy") {
            anisotropy = a
                .get("anisotropyStrength")
                .and_then(|v| v.as_f64())
                .unwrap_or(0.0) as f32;
            let rotation = a
                .get("anisotropyRotation")
                .and_then(|v| v.as_f64())
                .unwrap_or(0.0) as f32;
            anisotropy_rotation = rotation.to_degrees();
            if let Some(t) = a.get("anisotropyTexture") {
                let painted = scratches
                    .as_ref()
                    .is_some_and(|s| s.map.is_some() && s.direction.is_none());
                let at = format!("{element}.extensions.KHR_materials_anisotropy.anisotropyTexture");
                if painted {
                    let index = t
                        .get("index")
                        .and_then(|i| i.as_u64())
                        .filter(|&i| i < self.root.textures.len() as u64)
                        .ok_or_else(|| self.error(at.clone(), "needs the index of a texture"))?;
                    let tex_coord = t.get("texCoord").and_then(|v| v.as_u64()).unwrap_or(0);
                    let img = self.texture(index as usize, tex_coord as u32, &None, &at, false)?;
                    scratch_flow = Some(Arc::new(anisotropy_flow(&img, rotation)));
                } else {
                    warn(&self.file, &format!("{at}: orients only a painted scratch map (STRIAE_materials_scratches' `map` without `direction`): ignored"));
                }
            }
        }
        for (key, _) in &others {
            if key != "KHR_materials_anisotropy" && key != SCRATCHES_EXTENSION {
                warn(
                    &self.file,
                    &format!("{element}: extension {key} is not supported: ignored"),
                );
            }
        }
        let (metallic, roughness) = (pbr.metallic_factor.0, pbr.roughness_factor.0);
        Ok(ImportedMaterial {
            index,
            name,
            pbr: PbrDesc {
                base_color,
                metallic,
                roughness,
                metallic_roughness,
                normal_map,
                normal_scale,
                ior,
                transmission,
                attenuation_color,
                attenuation_distance,
                anisotropy,
                anisotropy_rotation,
            },
            emission: (emission.max_element() > 0.0).then_some(emission),
            scratches,
            scratch_flow,
        })
    }

    /// `STRIAE_materials_scratches` read exactly as `[materials.NAME.scratches]`, with the key
    /// path of a bad value; relative paths made relative to the glTF's folder.
    fn scratch_spec(
        &self,
        value: &serde_json::Value,
        element: &str,
    ) -> Result<ScratchSpec, GltfError> {
        use serde::Deserialize;
        let mut track = serde_path_to_error::Track::new();
        let de = serde_path_to_error::Deserializer::new(value, &mut track);
        let mut spec = ScratchSpec::deserialize(de).map_err(|e| {
            let mut at = element.to_string();
            for s in track.path().iter() {
                match s {
                    serde_path_to_error::Segment::Seq { index } => at += &format!("[{index}]"),
                    serde_path_to_error::Segment::Map { key }
                    | serde_path_to_error::Segment::Enum { variant: key } => {
                        at += &format!(".{key}")
                    }
                    serde_path_to_error::Segment::Unknown => at += ".?",
                }
            }
            // An unknown key is reported at its parent: name it.
            let message = e.to_string();
            if let Some(key) = message
                .strip_prefix("unknown field `")
                .and_then(|r| r.split('`').next())
            {
                at += &format!(".{key}");
            }
            self.error(at, message)
        })?;
        let rebase = |p: &mut Option<PathBuf>| {
            if let Some(p) = p {
                if p.is_relative() {
                    *p = self.base.join(&*p);
                }
            }
        };
        for path in [
            &mut spec.curves,
            &mut spec.table,
            &mut spec.map,
            &mut spec.direction,
        ] {
            rebase(path);
        }
        if let Some(profile) = &mut spec.profile {
            if let Some(file) = profile.strip_prefix("file:") {
                if Path::new(file).is_relative() {
                    *profile = format!("file:{}", self.base.join(file).display());
                }
            }
        }
        Ok(spec)
    }

    /// `textures[t]`'s image, decoded (sRGB to linear where `srgb`), cached.
    fn texture(
        &mut self,
        t: usize,
        tex_coord: u32,
        extensions: &Option<json::extensions::texture::Info>,
        element: &str,
        srgb: bool,
    ) -> Result<Arc<RgbImage>, GltfError> {
        if tex_coord != 0 {
            warn(
                &self.file,
                &format!("{element}: texCoord {tex_coord} is not supported: TEXCOORD_0 is used"),
            );
        }
        if extensions
            .as_ref()
            .is_some_and(|e| e.texture_transform.is_some())
        {
            warn(
                &self.file,
                &format!("{element}: KHR_texture_transform is not supported: ignored"),
            );
        }
        let source = self.root.textures[t].source.value();
        if let Some(img) = self.images.get(&(source, srgb)) {
            return Ok(img.clone());
        }
        let image = &self.root.images[source];
        let el = format!("images[{source}]");
        let mime = image.mime_type.as_ref().map(|m| m.0.clone());
        let bytes = match (&image.uri, image.buffer_view) {
            (Some(uri), _) => {
                let is_png = match uri.strip_prefix("data:") {
                    Some(rest) => rest.starts_with("image/png"),
                    None => uri.to_ascii_lowercase().ends_with(".png"),
                };
                if !is_png && mime.as_deref() != Some("image/png") {
                    return Err(self.error(
                        el,
                        format!("uri {:?}: only PNG images are supported", truncate(uri)),
                    ));
                }
                self.read_uri(uri, &el)?
            }
            (None, Some(v)) => {
                if mime.as_deref() != Some("image/png") {
                    return Err(self.error(
                        el,
                        format!(
                            "MIME type {:?}: only image/png is supported",
                            mime.unwrap_or_default()
                        ),
                    ));
                }
                let view = &self.root.buffer_views[v.value()];
                let buffer = &self.buffers[view.buffer.value()];
                let start = view.byte_offset.map_or(0, |o| o.0);
                let end = start
                    .checked_add(view.byte_length.0)
                    .filter(|&e| e <= buffer.len() as u64);
                let Some(end) = end else {
                    return Err(self.error(
                        el,
                        format!("bufferViews[{}] lies beyond its buffer", v.value()),
                    ));
                };
                buffer[start as usize..end as usize].to_vec()
            }
            (None, None) => return Err(self.error(el, "has neither uri nor bufferView")),
        };
        let name = PathBuf::from(format!("{}#images[{source}]", self.file.display()));
        let img =
            Arc::new(RgbImage::from_png_bytes(&bytes, &name, srgb).map_err(|e| self.error(el, e))?);
        self.images.insert((source, srgb), img.clone());
        Ok(img)
    }

    fn image_texture(&self, t: usize, srgb: bool, image: Arc<RgbImage>) -> Texture {
        let source = self.root.textures[t].source.value();
        Texture::Image {
            path: PathBuf::from(format!("{}#images[{source}]", self.file.display())),
            srgb: Some(srgb),
            scale: 1.0,
            image: Some(image),
        }
    }
}

fn truncate(s: &str) -> String {
    match s.char_indices().nth(48) {
        Some((i, _)) => format!("{}...", &s[..i]),
        None => s.to_string(),
    }
}

/// Per-vertex `(dP/du, dP/dv)` from glTF's `TANGENT`: `dP/du` along its `xyz`, `dP/dv` along
/// `-(N x T) w` (glTF's bitangent `(N x T) w` points to the image's top, decreasing `v`), each
/// with the length of the uv parametrisation's derivative averaged over the vertex's triangles
/// (unit where that is degenerate).
fn tangents_from_gltf(
    positions: &[Vec3],
    indices: &[u32],
    uvs: &[Vec2],
    normals: Option<&[Vec3]>,
    tangents: &[Vec4],
) -> (Vec<Vec3>, Vec<Vec3>) {
    let n = positions.len();
    let mut len_u = vec![0.0f32; n];
    let mut len_v = vec![0.0f32; n];
    let mut weight = vec![0.0f32; n];
    let mut face_normal = vec![Vec3::ZERO; n];
    for t in indices.chunks_exact(3) {
        let [i0, i1, i2] = [t[0] as usize, t[1] as usize, t[2] as usize];
        let (p0, p1, p2) = (positions[i0], positions[i1], positions[i2]);
        let (t0, t1, t2) = (uvs[i0], uvs[i1], uvs[i2]);
        let (duv02, duv12) = (t0 - t2, t1 - t2);
        let (dp02, dp12) = (p0 - p2, p1 - p2);
        let det = duv02.x * duv12.y - duv02.y * duv12.x;
        let cross = (p1 - p0).cross(p2 - p0);
        let area = 0.5 * cross.length();
        for i in [i0, i1, i2] {
            face_normal[i] += cross;
        }
        if !(det.abs() > 1e-12 && area > 0.0) {
            continue;
        }
        let dpdu = (duv12.y * dp02 - duv02.y * dp12) / det;
        let dpdv = (duv02.x * dp12 - duv12.x * dp02) / det;
        if !(dpdu.is_finite() && dpdv.is_finite()) {
            continue;
        }
        for i in [i0, i1, i2] {
            len_u[i] += area * dpdu.length();
            len_v[i] += area * dpdv.length();
            weight[i] += area;
        }
    }
    let mut du = Vec::with_capacity(n);
    let mut dv = Vec::with_capacity(n);
    for i in 0..n {
        let (lu, lv) = if weight[i] > 0.0 {
            (len_u[i] / weight[i], len_v[i] / weight[i])
        } else {
            (1.0, 1.0)
        };
        let normal = normals
            .map_or(face_normal[i], |ns| ns[i])
            .normalize_or_zero();
        let t = tangents[i].truncate().normalize_or_zero();
        let w = if tangents[i].w < 0.0 { -1.0 } else { 1.0 };
        du.push(t * lu);
        dv.push(-normal.cross(t) * w * lv);
    }
    (du, dv)
}

impl ImportedMaterial {
    /// The striae material this glTF material maps to.
    ///
    /// With `STRIAE_materials_scratches`: `type = "scratched"`, on glass with the glTF's `ior`
    /// where `transmission > 0`, else on metal where `metallic > 0`, its `eta` and `k` from the
    /// base colour ([`metal_ior_from_color`]); the base is smooth. Without it: `type = "pbr"`
    /// ([`PbrDesc`]), field for field.
    pub fn to_desc(&self, file: &Path) -> Result<MaterialDesc, GltfError> {
        let pbr = &self.pbr;
        let element = match self.index {
            Some(i) => format!("materials[{i}]"),
            None => "(default material)".into(),
        };
        let constant_color = || match &pbr.base_color {
            Texture::Constant(c) => *c,
            Texture::Image {
                image: Some(img), ..
            } => {
                warn(file, &format!("{element}: a metal's IOR comes from the base colour factor; baseColorTexture's mean is used"));
                img.pixels.iter().copied().sum::<Rgb>() / img.pixels.len() as f32
            }
            _ => Rgb::splat(0.5),
        };
        if let Some(spec) = &self.scratches {
            if spec.explicit == Some(true) {
                return Err(GltfError {
                    file: file.to_path_buf(),
                    element: Some(format!("{element}.extensions.{SCRATCHES_EXTENSION}.explicit")),
                    message: "explicit grooves are carved into a TOML scene's rectangles and boxes, not glTF meshes".into(),
                });
            }
            if pbr.roughness > 0.0 {
                warn(
                    file,
                    &format!(
                        "{element}: a scratched material's base is smooth: roughness {} ignored",
                        pbr.roughness
                    ),
                );
            }
            let (base, ior, eta, k) = if pbr.transmission > 0.0 {
                (BaseKind::Glass, Some(pbr.ior), None, None)
            } else if pbr.metallic > 0.0 {
                let (eta, k) = metal_ior_from_color(constant_color());
                (
                    BaseKind::Metal,
                    None,
                    Some(eta.to_array()),
                    Some(k.to_array()),
                )
            } else {
                return Err(GltfError {
                    file: file.to_path_buf(),
                    element: Some(format!("{element}.extensions.{SCRATCHES_EXTENSION}")),
                    message: "scratches need a glass base (KHR_materials_transmission > 0) or a metal one (metallicFactor > 0)".into(),
                });
            };
            return Ok(MaterialDesc::Scratched(ScratchedDesc {
                base,
                ior,
                preset: None,
                eta,
                k,
                scratches: spec.clone(),
                flow_image: self.scratch_flow.clone(),
            }));
        }
        if pbr.base_color.range().is_some_and(|(_, hi)| hi > 1.0) {
            warn(file, &format!("{element}: base colour above 1 clamped"));
        }
        Ok(MaterialDesc::Pbr(PbrDesc {
            base_color: clamp_unit(&pbr.base_color),
            ..pbr.clone()
        }))
    }
}

/// `KHR_materials_anisotropy`'s direction texture as a flow map of striae's (`scratches.direction`,
/// METHOD.md 9.5): each texel's `(2r - 1, 2g - 1)` is a direction in glTF's tangent space
/// (tangent, bitangent), turned counter-clockwise by `rotation` (radians, the extension's
/// `anisotropyRotation`), then written in striae's frame (`dP/du`, `dP/dv`): glTF's bitangent
/// points up the image, toward decreasing `v`, so the second component changes sign.
pub fn anisotropy_flow(texture: &RgbImage, rotation: f32) -> RgbImage {
    let (sin, cos) = rotation.sin_cos();
    let pixels = texture
        .pixels
        .iter()
        .map(|p| {
            let (x, y) = (2.0 * p.x - 1.0, 2.0 * p.y - 1.0);
            let (t, b) = (cos * x - sin * y, sin * x + cos * y);
            Rgb::new(
                (0.5 * (t + 1.0)).clamp(0.0, 1.0),
                (0.5 * (1.0 - b)).clamp(0.0, 1.0),
                0.0,
            )
        })
        .collect();
    RgbImage::new(texture.width, texture.height, pixels)
}

/// A conductor's complex IOR `(eta, k)` whose normal-incidence reflectance is `color`:
/// Gulbrandsen 2014, "Artist Friendly Metallic Fresnel" (JCGT 3(4)), with the reflectivity
/// `r` and the edge tint `g` both the base colour, each channel clamped to `[0.001, 0.999]`.
pub fn metal_ior_from_color(color: Rgb) -> (Rgb, Rgb) {
    let channel = |c: f32| {
        let r = c.clamp(0.001, 0.999);
        let g = r;
        let sr = r.sqrt();
        let n = g * (1.0 - r) / (1.0 + r) + (1.0 - g) * (1.0 + sr) / (1.0 - sr);
        let k2 = (r * (n + 1.0) * (n + 1.0) - (n - 1.0) * (n - 1.0)) / (1.0 - r);
        (n, k2.max(0.0).sqrt())
    };
    let [(n0, k0), (n1, k1), (n2, k2)] = [channel(color.x), channel(color.y), channel(color.z)];
    (Rgb::new(n0, n1, n2), Rgb::new(k0, k1, k2))
}

/// A colour texture with its channels clamped to `[0, 1]` (a base colour factor above 1).
fn clamp_unit(t: &Texture) -> Texture {
    match t {
        Texture::Constant(c) => Texture::Constant(c.clamp(Rgb::ZERO, Rgb::ONE)),
        Texture::Image {
            path,
            srgb,
            scale,
            image: Some(img),
        } if img.pixels.iter().any(|p| p.max_element() > 1.0) => {
            let pixels = img
                .pixels
                .iter()
                .map(|p| p.clamp(Rgb::ZERO, Rgb::ONE))
                .collect();
            Texture::Image {
                path: path.clone(),
                srgb: *srgb,
                scale: *scale,
                image: Some(Arc::new(RgbImage::new(img.width, img.height, pixels))),
            }
        }
        t => t.clone(),
    }
}

/// Standard base64 (RFC 4648, with or without padding); `None` on any other character.
fn base64_decode(s: &str) -> Option<Vec<u8>> {
    let value = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return None,
        } as u32)
    };
    let s = s.trim_end_matches('=').as_bytes();
    let mut out = Vec::with_capacity(s.len() / 4 * 3 + 3);
    for chunk in s.chunks(4) {
        if chunk.len() == 1 {
            return None;
        }
        let mut acc = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            acc |= value(c)? << (18 - 6 * i);
        }
        let bytes = acc.to_be_bytes();
        out.extend_from_slice(&bytes[1..chunk.len()]);
    }
    Some(out)
}

/// A URI's `%XX` escapes decoded; `None` where an escape is malformed or the result is not UTF-8.
fn percent_decode(s: &str) -> Option<String> {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = s.get(i + 1..i + 3)?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests;
