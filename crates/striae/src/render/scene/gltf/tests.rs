//! glTFs built in the test (JSON with base64 data URIs, or a GLB) and imported.

use super::*;
use crate::render::scene::{Overrides, Scene};
use serde_json::{json, Value};

/// Standard base64 with padding.
pub(crate) fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for i in 0..4 {
            if i <= c.len() {
                out.push(A[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Buffer views and accessors over one binary buffer.
#[derive(Default)]
pub(crate) struct Builder {
    pub bin: Vec<u8>,
    pub views: Vec<Value>,
    pub accessors: Vec<Value>,
}

impl Builder {
    fn push(&mut self, bytes: &[u8], accessor: Value) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views
            .push(json!({ "buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len() }));
        self.bin.extend_from_slice(bytes);
        let mut a = accessor;
        a["bufferView"] = json!(self.views.len() - 1);
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    /// A `FLOAT` accessor of type `ty` (`VEC3`, ...).
    pub fn floats(&mut self, data: &[f32], ty: &str, per: usize) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.push(
            &bytes,
            json!({ "componentType": 5126, "count": data.len() / per, "type": ty }),
        )
    }

    /// An `UNSIGNED_INT` index accessor.
    pub fn indices(&mut self, data: &[u32]) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.push(
            &bytes,
            json!({ "componentType": 5125, "count": data.len(), "type": "SCALAR" }),
        )
    }

    /// A primitive from positions (and indices, uvs).
    pub fn primitive(
        &mut self,
        positions: &[f32],
        indices: Option<&[u32]>,
        uvs: Option<&[f32]>,
    ) -> Value {
        let pos = self.floats(positions, "VEC3", 3);
        // The spec requires POSITION's bounds (and the gltf crate checks them).
        let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
        for p in positions.chunks_exact(3) {
            for c in 0..3 {
                lo[c] = lo[c].min(p[c]);
                hi[c] = hi[c].max(p[c]);
            }
        }
        self.accessors[pos]["min"] = json!(lo);
        self.accessors[pos]["max"] = json!(hi);
        let mut p = json!({ "attributes": { "POSITION": pos } });
        if let Some(i) = indices {
            p["indices"] = json!(self.indices(i));
        }
        if let Some(uv) = uvs {
            p["attributes"]["TEXCOORD_0"] = json!(self.floats(uv, "VEC2", 2));
        }
        p
    }

    /// `doc` with the buffer (a data URI), views and accessors added.
    pub fn gltf(&self, mut doc: Value) -> Vec<u8> {
        doc["asset"] = json!({ "version": "2.0" });
        doc["buffers"] = json!([{ "byteLength": self.bin.len(), "uri": format!("data:application/octet-stream;base64,{}", base64(&self.bin)) }]);
        doc["bufferViews"] = json!(self.views);
        doc["accessors"] = json!(self.accessors);
        serde_json::to_vec(&doc).unwrap()
    }

    /// `doc` as a GLB, the buffer its binary chunk.
    pub fn glb(&self, mut doc: Value) -> Vec<u8> {
        doc["asset"] = json!({ "version": "2.0" });
        doc["buffers"] = json!([{ "byteLength": self.bin.len() }]);
        doc["bufferViews"] = json!(self.views);
        doc["accessors"] = json!(self.accessors);
        let mut text = serde_json::to_vec(&doc).unwrap();
        while !text.len().is_multiple_of(4) {
            text.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + text.len() + 8 + bin.len();
        let mut out = Vec::new();
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(text.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&text);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        out
    }
}

/// The unit triangle in the xy plane (indices 0 1 2).
const TRIANGLE: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];

fn import_ok(bytes: &[u8]) -> GltfScene {
    import_bytes(bytes, Path::new("test.gltf"), &Transform::IDENTITY).unwrap()
}

fn import_err(bytes: &[u8]) -> String {
    import_bytes(bytes, Path::new("test.gltf"), &Transform::IDENTITY)
        .unwrap_err()
        .to_string()
}

/// A folder of its own under the temporary folder, removed on drop.
pub(crate) struct TempDir(pub PathBuf);
impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        let d = std::env::temp_dir().join(format!("striae-gltf-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        TempDir(d)
    }
}
impl Drop for TempDir {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

#[test]
fn node_chain_of_trs_and_matrix_places_the_mesh() {
    let mut b = Builder::default();
    let prim = b.primitive(&TRIANGLE, Some(&[0, 1, 2]), None);
    // Parent: translate (1, 2, 3), scale 2; child: a matrix rotating 90 degrees about z
    // (column-major: x -> y, y -> -x).
    let doc = json!({
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [
            { "translation": [1, 2, 3], "scale": [2, 2, 2], "children": [1] },
            { "matrix": [0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1], "mesh": 0 }
        ],
        "meshes": [{ "primitives": [prim] }]
    });
    let g = import_ok(&b.gltf(doc));
    assert_eq!(g.meshes.len(), 1);
    let p = g.meshes[0].mesh.positions();
    let expect = [
        Vec3::new(1.0, 2.0, 3.0),
        Vec3::new(1.0, 4.0, 3.0),
        Vec3::new(-1.0, 2.0, 3.0),
    ];
    for (a, e) in p.iter().zip(expect) {
        assert!((*a - e).length() < 1e-5, "{p:?}");
    }
    // glTF's default material: white, metallic 1, roughness 1.
    assert_eq!(g.materials.len(), 1);
    assert_eq!(g.materials[0].name, "gltf-default");
    assert!(
        matches!(g.materials[0].to_desc(Path::new("t")).unwrap(), MaterialDesc::Pbr(p) if p == PbrDesc::default())
    );
}

#[test]
fn instanced_mesh_appears_once_per_node_and_non_triangles_are_skipped() {
    let mut b = Builder::default();
    let prim = b.primitive(&TRIANGLE, None, None);
    let mut lines = prim.clone();
    lines["mode"] = json!(1);
    let doc = json!({
        "scenes": [{ "nodes": [0, 1] }],
        "nodes": [{ "mesh": 0 }, { "mesh": 0, "translation": [0, 0, 5] }],
        "meshes": [{ "name": "tri", "primitives": [prim, lines] }]
    });
    let g = import_ok(&b.glb(doc));
    assert_eq!(g.meshes.len(), 2);
    assert_eq!(g.meshes[1].mesh.positions()[0], Vec3::new(0.0, 0.0, 5.0));
}

#[test]
fn camera_looks_down_its_local_minus_z() {
    let dir = TempDir::new("camera");
    let mut b = Builder::default();
    let prim = b.primitive(&TRIANGLE, None, None);
    // The camera at (0, 0, 5) turned 90 degrees about y: it looks down world -x.
    let (s, c) = (
        std::f32::consts::FRAC_PI_4.sin(),
        std::f32::consts::FRAC_PI_4.cos(),
    );
    let doc = json!({
        "scenes": [{ "nodes": [0, 1] }],
        "nodes": [{ "mesh": 0 }, { "camera": 0, "translation": [0, 0, 5], "rotation": [0, s, 0, c] }],
        "meshes": [{ "primitives": [prim] }],
        "cameras": [{ "type": "perspective", "perspective": { "yfov": 0.5, "znear": 0.1, "aspectRatio": 3.0 } }]
    });
    let path = dir.0.join("cam.glb");
    std::fs::write(&path, b.glb(doc)).unwrap();
    let o = Overrides {
        resolution: Some((33, 21)),
        ..Default::default()
    };
    let scene = Scene::load(&path, &o).unwrap();
    assert_eq!(scene.settings.width, 33);
    let ray = scene.camera.generate_ray_only(
        crate::math::Vec2::new(16.5, 10.5),
        crate::math::Vec2::splat(0.5),
    );
    assert!(
        (ray.o - Vec3::new(0.0, 0.0, 5.0)).length() < 1e-5,
        "{:?}",
        ray.o
    );
    assert!(
        (ray.d.normalize() - Vec3::new(-1.0, 0.0, 0.0)).length() < 1e-5,
        "{:?}",
        ray.d
    );
    // yfov is vertical: the top edge's centre is 0.25 rad above the axis.
    let top = scene.camera.generate_ray_only(
        crate::math::Vec2::new(16.5, 0.0),
        crate::math::Vec2::splat(0.5),
    );
    let angle = top.d.normalize().dot(Vec3::Y).asin();
    assert!((angle - 0.25).abs() < 1e-4, "{angle}");
    // No camera: an error saying so.
    let doc = json!({ "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }], "meshes": [{ "primitives": [b.primitive(&TRIANGLE, None, None)] }] });
    std::fs::write(&path, b.glb(doc)).unwrap();
    let e = Scene::load(&path, &o).unwrap_err().to_string();
    assert!(e.contains("no camera") && e.contains("cam.glb"), "{e}");
    // Orthographic: an error.
    let doc = json!({
        "scenes": [{ "nodes": [0, 1] }], "nodes": [{ "mesh": 0 }, { "camera": 0 }],
        "meshes": [{ "primitives": [b.primitive(&TRIANGLE, None, None)] }],
        "cameras": [{ "type": "orthographic", "orthographic": { "xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 10 } }]
    });
    std::fs::write(&path, b.glb(doc)).unwrap();
    let e = Scene::load(&path, &o).unwrap_err().to_string();
    assert!(e.contains("cameras[0]") && e.contains("perspective"), "{e}");
}

#[test]
fn punctual_lights_are_converted_to_radiometric_units() {
    // A quarter turn about x: (-sin 45, 0, 0, cos 45).
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let doc = json!({
        "asset": { "version": "2.0" },
        "extensionsUsed": ["KHR_lights_punctual"],
        "scenes": [{ "nodes": [0, 1, 2] }],
        "nodes": [
            { "translation": [1, 2, 3], "extensions": { "KHR_lights_punctual": { "light": 0 } } },
            { "rotation": [-h, 0, 0, h], "extensions": { "KHR_lights_punctual": { "light": 1 } } },
            { "translation": [0, 4, 0], "rotation": [-h, 0, 0, h], "extensions": { "KHR_lights_punctual": { "light": 2 } } }
        ],
        "extensions": { "KHR_lights_punctual": { "lights": [
            { "type": "point", "color": [1, 0.5, 0.25], "intensity": 683 },
            { "type": "directional", "intensity": 1366 },
            { "type": "spot", "intensity": 68.3, "range": 10, "spot": { "innerConeAngle": 0.2, "outerConeAngle": 0.4 } }
        ] } }
    });
    let g = import_ok(&serde_json::to_vec(&doc).unwrap());
    assert_eq!(g.lights.len(), 3);
    assert!(
        matches!(g.lights[0], Light::Point { position, intensity }
            if position == Vec3::new(1.0, 2.0, 3.0) && intensity == Rgb::new(1.0, 0.5, 0.25)),
        "{:?}",
        g.lights[0]
    );
    // Rotated -90 degrees about x: local -z points down, so the sun is straight up.
    let Light::Sun {
        direction,
        irradiance,
    } = g.lights[1]
    else {
        panic!()
    };
    assert!(
        (direction - Vec3::Y).length() < 1e-5 && (irradiance - Rgb::splat(2.0)).length() < 1e-5,
        "{direction} {irradiance}"
    );
    let Light::Spot {
        position,
        direction,
        intensity,
        cos_inner,
        cos_outer,
    } = g.lights[2]
    else {
        panic!()
    };
    assert!((position - Vec3::new(0.0, 4.0, 0.0)).length() < 1e-5);
    assert!((direction + Vec3::Y).length() < 1e-5, "{direction}");
    assert!((intensity - Rgb::splat(0.1)).length() < 1e-6);
    assert!((cos_inner - 0.2f32.cos()).abs() < 1e-6 && (cos_outer - 0.4f32.cos()).abs() < 1e-6);
}

#[test]
fn blenders_sun_is_read_in_watts_per_square_metre() {
    let doc = |generator: &str| {
        json!({
            "asset": { "version": "2.0", "generator": generator },
            "extensionsUsed": ["KHR_lights_punctual"],
            "scenes": [{ "nodes": [0, 1] }],
            "nodes": [
                { "extensions": { "KHR_lights_punctual": { "light": 0 } } },
                { "extensions": { "KHR_lights_punctual": { "light": 1 } } }
            ],
            "extensions": { "KHR_lights_punctual": { "lights": [
                { "type": "directional", "intensity": 3 },
                { "type": "point", "intensity": 683 }
            ] } }
        })
    };
    let irradiance = |g: &GltfScene| match g.lights[0] {
        Light::Sun { irradiance, .. } => irradiance,
        _ => panic!("{:?}", g.lights[0]),
    };
    let blender = import_ok(&serde_json::to_vec(&doc("Khronos glTF Blender I/O v5.0.21")).unwrap());
    let other = import_ok(&serde_json::to_vec(&doc("another exporter")).unwrap());
    assert_eq!(irradiance(&blender), Rgb::splat(3.0));
    assert_eq!(irradiance(&other), Rgb::splat(3.0 / 683.0));
    // Point lights are candela in both.
    for g in [&blender, &other] {
        assert!(matches!(g.lights[1], Light::Point { intensity, .. } if intensity == Rgb::ONE));
    }
}

/// A 2 x 1 PNG: red, then white.
fn png_bytes() -> Vec<u8> {
    let img = image::RgbImage::from_raw(2, 1, vec![255, 0, 0, 255, 255, 255]).unwrap();
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).unwrap();
    out.into_inner()
}

#[test]
fn materials_map_factors_textures_and_extensions() {
    let mut b = Builder::default();
    let prims: Vec<Value> = (0..5)
        .map(|m| {
            let mut p = b.primitive(&TRIANGLE, None, Some(&[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]));
            p["material"] = json!(m);
            p
        })
        .collect();
    let doc = json!({
        "extensionsUsed": ["KHR_materials_ior", "KHR_materials_transmission", "KHR_materials_volume", "KHR_materials_emissive_strength", "KHR_materials_anisotropy", "EXT_unknown_thing"],
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": prims }],
        "images": [{ "uri": format!("data:image/png;base64,{}", base64(&png_bytes())) }],
        "textures": [{ "source": 0 }],
        "materials": [
            { "name": "painted", "pbrMetallicRoughness": { "baseColorFactor": [0.5, 1, 1, 1], "baseColorTexture": { "index": 0 }, "metallicFactor": 0 } },
            { "name": "gold", "pbrMetallicRoughness": { "baseColorFactor": [1.0, 0.78, 0.34, 1], "metallicFactor": 1, "roughnessFactor": 0.5 } },
            { "name": "glass", "pbrMetallicRoughness": { "metallicFactor": 0, "roughnessFactor": 0 },
              "extensions": { "KHR_materials_ior": { "ior": 1.7 }, "KHR_materials_transmission": { "transmissionFactor": 1 },
                              "KHR_materials_volume": { "attenuationColor": [0.9, 0.8, 0.7], "attenuationDistance": 2 },
                              "KHR_materials_anisotropy": { "anisotropyStrength": 0.6, "anisotropyRotation": 1.5707964 } } },
            { "name": "lamp", "emissiveFactor": [1, 0.5, 0.25], "extensions": { "KHR_materials_emissive_strength": { "emissiveStrength": 4 } } },
            { "name": "gold" }
        ]
    });
    let g = import_ok(&b.gltf(doc));
    let names: Vec<&str> = g.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["painted", "gold", "glass", "lamp", "gold#2"]);
    // The factor multiplies the sRGB-decoded texture.
    let Texture::Image {
        image: Some(img),
        srgb: Some(true),
        path,
        ..
    } = &g.materials[0].pbr.base_color
    else {
        panic!()
    };
    assert!(path.to_string_lossy().ends_with("#images[0]"));
    assert_eq!(
        img.pixels,
        vec![Rgb::new(0.5, 0.0, 0.0), Rgb::new(0.5, 1.0, 1.0)]
    );
    assert!(
        matches!(g.materials[0].to_desc(Path::new("t")).unwrap(), MaterialDesc::Pbr(p) if p.metallic == 0.0 && p.base_color == g.materials[0].pbr.base_color)
    );
    let MaterialDesc::Pbr(gold) = g.materials[1].to_desc(Path::new("t")).unwrap() else {
        panic!()
    };
    assert_eq!(
        (gold.metallic, gold.roughness, gold.base_color),
        (1.0, 0.5, Texture::Constant(Rgb::new(1.0, 0.78, 0.34)))
    );
    let glass = &g.materials[2];
    assert_eq!((glass.pbr.ior, glass.pbr.transmission), (1.7, 1.0));
    assert_eq!(
        (glass.pbr.attenuation_color, glass.pbr.attenuation_distance),
        ([0.9, 0.8, 0.7], Some(2.0))
    );
    assert!(
        (glass.pbr.anisotropy - 0.6).abs() < 1e-6
            && (glass.pbr.anisotropy_rotation - 90.0).abs() < 1e-3
    );
    let MaterialDesc::Pbr(p) = glass.to_desc(Path::new("t")).unwrap() else {
        panic!()
    };
    assert_eq!(
        (p.ior, p.transmission, p.roughness, p.attenuation_distance),
        (1.7, 1.0, 0.0, Some(2.0))
    );
    assert_eq!(
        (p.anisotropy, p.attenuation_color),
        (glass.pbr.anisotropy, [0.9, 0.8, 0.7])
    );
    assert_eq!(g.materials[3].emission, Some(Rgb::new(4.0, 2.0, 1.0)));
    assert_eq!(g.materials[0].emission, None);
}

#[test]
fn gulbrandsen_metal_reflects_its_base_colour_at_normal_incidence() {
    for c in [
        Rgb::new(0.95, 0.64, 0.54),
        Rgb::new(0.04, 0.5, 0.99),
        Rgb::splat(0.0),
        Rgb::ONE,
    ] {
        let (eta, k) = metal_ior_from_color(c);
        let f0 = crate::render::bsdf::ConductorIor { eta, k }.fresnel(1.0);
        assert!(
            (f0 - c.clamp(Rgb::splat(0.001), Rgb::splat(0.999)))
                .abs()
                .max_element()
                < 1e-3,
            "{c} {f0}"
        );
    }
}

#[test]
fn tangents_follow_gltfs_bitangent_convention() {
    // A quad in the xy plane, image upright seen from +z: u along +x, v (down the image) along -y.
    let positions = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(2.0, 2.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
    ];
    let uvs = [
        Vec2::new(0.0, 1.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(1.0, 0.0),
        Vec2::new(0.0, 0.0),
    ];
    let normals = [Vec3::Z; 4];
    let t = [Vec4::new(1.0, 0.0, 0.0, 1.0); 4];
    let (du, dv) = tangents_from_gltf(&positions, &[0, 1, 2, 0, 2, 3], &uvs, Some(&normals), &t);
    // As TriangleMesh derives them from the uvs alone.
    let plain = TriangleMesh::new(
        positions.to_vec(),
        vec![[0, 1, 2], [0, 2, 3]],
        None,
        Some(uvs.to_vec()),
        None,
    )
    .unwrap();
    let (_, _, _, _, pu, pv) = plain.surface(0, 0.2, 0.3);
    for i in 0..4 {
        assert!(
            (du[i] - pu).length() < 1e-5 && (dv[i] - pv).length() < 1e-5,
            "{} {} vs {pu} {pv}",
            du[i],
            dv[i]
        );
    }
}

#[test]
fn scratches_extension_reads_the_toml_keys_and_names_bad_ones() {
    let mut b = Builder::default();
    let mut prim = b.primitive(&TRIANGLE, None, None);
    prim["material"] = json!(0);
    let doc = |scratches: Value, transmission: f32| {
        json!({
            "extensionsUsed": ["STRIAE_materials_scratches", "KHR_materials_transmission"],
            "extensionsRequired": ["STRIAE_materials_scratches"],
            "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }],
            "meshes": [{ "primitives": [prim.clone()] }],
            "materials": [{ "name": "scratched", "pbrMetallicRoughness": { "metallicFactor": 0, "baseColorFactor": [0.9, 0.9, 0.9, 1] },
                "extensions": { "KHR_materials_transmission": { "transmissionFactor": transmission }, "KHR_materials_ior": { "ior": 1.45 },
                                "STRIAE_materials_scratches": scratches } }]
        })
    };
    let g = import_ok(&b.gltf(doc(
        json!({ "setting": 1, "layers": 4, "curves": "marks.svg", "profile": "v:angle=60" }),
        1.0,
    )));
    let MaterialDesc::Scratched(d) = g.materials[0].to_desc(Path::new("t")).unwrap() else {
        panic!()
    };
    assert_eq!((d.base, d.ior), (BaseKind::Glass, Some(1.45)));
    assert_eq!(
        (d.scratches.setting, d.scratches.layers),
        (Some(1), Some(4))
    );
    assert_eq!(
        d.scratches.curves.as_deref(),
        Some(Path::new("marks.svg")),
        "relative to the glTF's folder, here none"
    );
    assert_eq!(d.scratches.profile.as_deref(), Some("v:angle=60"));
    // Neither glass nor metal: an error naming the extension.
    let g = import_ok(&b.gltf(doc(json!({ "setting": 1 }), 0.0)));
    let e = g.materials[0]
        .to_desc(Path::new("t"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("materials[0].extensions.STRIAE_materials_scratches") && e.contains("glass"),
        "{e}"
    );
    // An unknown key, a bad type.
    let e = import_err(&b.gltf(doc(json!({ "setting": 1, "widht": 0.1 }), 1.0)));
    assert!(
        e.contains("materials[0].extensions.STRIAE_materials_scratches.widht")
            && e.contains("test.gltf"),
        "{e}"
    );
    let e = import_err(&b.gltf(doc(json!({ "layers": "many" }), 1.0)));
    assert!(e.contains("STRIAE_materials_scratches.layers"), "{e}");
}

#[test]
fn toml_material_overrides_a_gltf_material_by_name_and_transform_applies() {
    let dir = TempDir::new("override");
    let mut b = Builder::default();
    let mut p0 = b.primitive(&TRIANGLE, None, None);
    p0["material"] = json!(0);
    let mut p1 = b.primitive(&TRIANGLE, None, None);
    p1["material"] = json!(1);
    let doc = json!({
        "scenes": [{ "nodes": [0, 1] }],
        "nodes": [{ "mesh": 0 }, { "camera": 0, "translation": [0, 0, 3] }],
        "cameras": [{ "type": "perspective", "perspective": { "yfov": 0.8, "znear": 0.1 } }],
        "meshes": [{ "primitives": [p0, p1] }],
        "materials": [{ "name": "steel", "pbrMetallicRoughness": { "metallicFactor": 1 } }, { "name": "paint", "pbrMetallicRoughness": { "metallicFactor": 0 } }]
    });
    std::fs::write(dir.0.join("part.glb"), b.glb(doc)).unwrap();
    let toml = "[render]\nwidth = 8\nheight = 8\n[materials.steel]\ntype = \"diffuse\"\nreflectance = 0.25\n[[shapes]]\ntype = \"gltf\"\npath = \"part.glb\"\ntransform = { translate = [0, 0, -1] }\n";
    let scene = Scene::parse(toml, &dir.0.join("s.toml"), &dir.0, &Overrides::default()).unwrap();
    let shapes = scene.geometry.shapes();
    assert_eq!(shapes.len(), 2);
    // steel: the TOML's (index 0), paint: the glTF's, after it.
    assert_eq!((shapes[0].material, shapes[1].material), (0, 1));
    assert!(
        matches!(&scene.materials[0], crate::render::material::Material::Diffuse { reflectance: Texture::Constant(c) } if *c == Rgb::splat(0.25))
    );
    assert!(matches!(
        &scene.materials[1],
        crate::render::material::Material::Pbr(_)
    ));
    let crate::render::geometry::ShapeGeometry::Mesh(m) = &shapes[0].geometry else {
        panic!()
    };
    assert_eq!(m.positions()[0], Vec3::new(0.0, 0.0, -1.0));
    // The camera came from the glTF, moved by the transform.
    assert!((scene.camera.position() - Vec3::new(0.0, 0.0, 2.0)).length() < 1e-6);
    // A TOML camera wins.
    let with_camera =
        format!("{toml}[camera]\nposition = [0, 0, 9]\nlook_at = [0, 0, 0]\nfov = 30\n");
    let scene = Scene::parse(
        &with_camera,
        &dir.0.join("s.toml"),
        &dir.0,
        &Overrides::default(),
    )
    .unwrap();
    assert_eq!(scene.camera.position(), Vec3::new(0.0, 0.0, 9.0));
    // `material` does not apply to a glTF shape; a missing file names the key.
    let e = Scene::parse(
        &format!("{toml}material = \"steel\"\n"),
        &dir.0.join("s.toml"),
        &dir.0,
        &Overrides::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("shapes[0].material"), "{e}");
    let e = Scene::parse(
        &toml.replace("part.glb", "nothing.glb"),
        &dir.0.join("s.toml"),
        &dir.0,
        &Overrides::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("shapes[0].path") && e.contains("nothing.glb"),
        "{e}"
    );
}

#[test]
fn a_glb_is_named_by_its_bytes() {
    let dir = TempDir::new("hash");
    let mut b = Builder::default();
    let prim = b.primitive(&TRIANGLE, None, None);
    let doc = |fov: f32| {
        json!({ "scenes": [{ "nodes": [0, 1] }], "nodes": [{ "mesh": 0 }, { "camera": 0, "translation": [0, 0, 3] }],
                "cameras": [{ "type": "perspective", "perspective": { "yfov": fov, "znear": 0.1 } }],
                "meshes": [{ "primitives": [prim.clone()] }] })
    };
    let path = dir.0.join("a.glb");
    std::fs::write(&path, b.glb(doc(0.5))).unwrap();
    let (_, a) = Scene::load_with_text(&path, &Overrides::default()).unwrap();
    std::fs::write(&path, b.glb(doc(0.6))).unwrap();
    let (_, b2) = Scene::load_with_text(&path, &Overrides::default()).unwrap();
    assert!(a.contains("sha256") && a != b2, "{a} {b2}");
}

/// Each bad file: an error naming the file and the element; never a panic.
#[test]
fn bad_gltfs_are_errors_naming_the_element() {
    let mut b = Builder::default();
    let good = b.primitive(&TRIANGLE, Some(&[0, 1, 2]), None);
    let doc = |prim: Value| json!({ "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }], "meshes": [{ "primitives": [good.clone(), prim] }] });
    let check = |bytes: &[u8], needles: &[&str]| {
        let e = import_err(bytes);
        assert!(e.contains("test.gltf"), "{e}");
        for n in needles {
            assert!(e.contains(n), "{n:?} not in {e}");
        }
    };
    check(b"{ \"asset\": ", &["parse"]);
    check(b"glTF\x02\x00\x00\x00\xff\xff\x00\x00", &["parse"]);
    let glb = b.glb(doc(good.clone()));
    check(&glb[..glb.len() - 20], &["parse"]);
    // Indices past the vertex count.
    let mut bad = b.primitive(&TRIANGLE, Some(&[0, 1, 7]), None);
    check(
        &b.gltf(doc(bad.clone())),
        &[
            "meshes[0].primitives[1].indices",
            "index 7",
            "vertex count 3",
        ],
    );
    // NaN positions.
    let nan = b.primitive(
        &[0.0, 0.0, 0.0, f32::NAN, 0.0, 0.0, 0.0, 1.0, 0.0],
        None,
        None,
    );
    check(
        &b.gltf(doc(nan)),
        &["meshes[0].primitives[1].attributes.POSITION", "non-finite"],
    );
    // A count claiming 2^32 vertices over 36 bytes.
    let mut huge = b.clone_accessor(0);
    huge["count"] = json!(1u64 << 32);
    b.accessors.push(huge);
    bad["attributes"]["POSITION"] = json!(b.accessors.len() - 1);
    bad.as_object_mut().unwrap().remove("indices");
    check(
        &b.gltf(doc(bad.clone())),
        &[
            "meshes[0].primitives[1].attributes.POSITION",
            "beyond bufferViews",
        ],
    );
    // An offset past the view, a stride past it.
    let mut off = b.clone_accessor(0);
    off["byteOffset"] = json!(8);
    b.accessors.push(off);
    bad["attributes"]["POSITION"] = json!(b.accessors.len() - 1);
    check(
        &b.gltf(doc(bad.clone())),
        &["meshes[0].primitives[1].attributes.POSITION", "beyond"],
    );
    // A view past its buffer.
    let mut b2 = Builder::default();
    let prim = b2.primitive(&TRIANGLE, None, None);
    b2.views[0]["byteLength"] = json!(1000);
    let only = json!({ "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }], "meshes": [{ "primitives": [prim] }] });
    check(&b2.gltf(only), &["bufferViews[0]", "beyond buffers[0]"]);
    // A buffer shorter than its byteLength, a missing buffer file, a missing image file.
    let mut text: Value = serde_json::from_slice(&b.gltf(doc(good.clone()))).unwrap();
    text["buffers"][0]["byteLength"] = json!(100000);
    check(
        &serde_json::to_vec(&text).unwrap(),
        &["buffers[0]", "byteLength"],
    );
    text["buffers"][0].as_object_mut().unwrap().remove("uri");
    check(
        &serde_json::to_vec(&text).unwrap(),
        &["buffers[0]", "no uri"],
    );
    text["buffers"][0]["uri"] = json!("missing.bin");
    check(
        &serde_json::to_vec(&text).unwrap(),
        &["buffers[0]", "missing.bin"],
    );
    let mut text: Value = serde_json::from_slice(&b.gltf(doc(good.clone()))).unwrap();
    let mut textured = good.clone();
    textured["material"] = json!(0);
    text["meshes"][0]["primitives"][1] = textured;
    text["materials"] = json!([{ "pbrMetallicRoughness": { "baseColorTexture": { "index": 0 } } }]);
    text["textures"] = json!([{ "source": 0 }]);
    text["images"] = json!([{ "uri": "missing.png" }]);
    check(
        &serde_json::to_vec(&text).unwrap(),
        &["images[0]", "missing.png"],
    );
    text["images"] = json!([{ "uri": "photo.jpg" }]);
    check(
        &serde_json::to_vec(&text).unwrap(),
        &["images[0]", "only PNG"],
    );
    // An index to nothing (the gltf crate's check), a required extension striae lacks.
    let mut text: Value = serde_json::from_slice(&b.gltf(doc(good.clone()))).unwrap();
    text["meshes"][0]["primitives"][0]["indices"] = json!(99);
    check(&serde_json::to_vec(&text).unwrap(), &["invalid", "indices"]);
    let mut text: Value = serde_json::from_slice(&b.gltf(doc(good.clone()))).unwrap();
    text["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    text["extensionsUsed"] = json!(["KHR_draco_mesh_compression"]);
    check(
        &serde_json::to_vec(&text).unwrap(),
        &["extensionsRequired[0]", "KHR_draco_mesh_compression"],
    );
}

impl Builder {
    fn clone_accessor(&self, i: usize) -> Value {
        self.accessors[i].clone()
    }
}

/// The rectangle `[-1, 1]^2` (normal +z) exactly as `TriangleMesh::rectangle` builds it.
fn rectangle(b: &mut Builder, material: usize) -> Value {
    let positions = [
        -1.0, -1.0, 0.0, 1.0, -1.0, 0.0, 1.0, 1.0, 0.0, -1.0, 1.0, 0.0,
    ];
    let uvs = [0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0];
    let mut p = b.primitive(&positions, Some(&[0, 1, 2, 0, 2, 3]), Some(&uvs));
    p["material"] = json!(material);
    p
}

/// A floor lit by an emissive quad and a point light, rendered from a glTF and from the same
/// scene written in TOML: the same image within float rounding of the transforms.
#[test]
fn gltf_renders_as_the_same_scene_in_toml() {
    let dir = TempDir::new("render");
    let mut b = Builder::default();
    let floor = rectangle(&mut b, 0);
    let lamp = rectangle(&mut b, 1);
    let (s, c) = (
        std::f32::consts::FRAC_PI_4.sin(),
        std::f32::consts::FRAC_PI_4.cos(),
    );
    let doc = json!({
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_emissive_strength"],
        "scenes": [{ "nodes": [0, 1, 2, 3] }],
        "nodes": [
            { "mesh": 0, "scale": [2, 2, 2], "rotation": [-s, 0, 0, c] },
            { "mesh": 1, "scale": [0.5, 0.5, 0.5], "rotation": [s, 0, 0, c], "translation": [0, 2, 0] },
            { "camera": 0, "translation": [0, 1, 4] },
            { "translation": [0.5, 1.5, 0.5], "extensions": { "KHR_lights_punctual": { "light": 0 } } }
        ],
        "meshes": [{ "primitives": [floor] }, { "primitives": [lamp] }],
        "cameras": [{ "type": "perspective", "perspective": { "yfov": 0.9, "znear": 0.1 } }],
        "materials": [
            { "name": "floor", "pbrMetallicRoughness": { "baseColorFactor": [0.8, 0.6, 0.4, 1], "metallicFactor": 0, "roughnessFactor": 0.7 } },
            { "name": "lamp", "pbrMetallicRoughness": { "baseColorFactor": [0, 0, 0, 1], "metallicFactor": 0 },
              "emissiveFactor": [1, 1, 1], "extensions": { "KHR_materials_emissive_strength": { "emissiveStrength": 5 } } }
        ],
        "extensions": { "KHR_lights_punctual": { "lights": [{ "type": "point", "intensity": 1366, "color": [1, 0.9, 0.8] }] } }
    });
    let glb = dir.0.join("room.glb");
    std::fs::write(&glb, b.glb(doc)).unwrap();
    let fov = 0.9f32.to_degrees();
    let toml = format!(
        r#"
[render]
width = 24
height = 18
spp = 16
[camera]
position = [0, 1, 4]
look_at = [0, 1, 3]
fov = {fov}
[materials.floor]
type = "pbr"
base_color = [0.8, 0.6, 0.4]
metallic = 0
roughness = 0.7
[materials.lamp]
type = "pbr"
base_color = [0, 0, 0]
metallic = 0
[[shapes]]
type = "rectangle"
material = "floor"
transform = [{{ scale = 2 }}, {{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }}]
[[shapes]]
type = "rectangle"
material = "lamp"
emission = 5
transform = [{{ scale = 0.5 }}, {{ rotate = {{ axis = [1, 0, 0], angle = 90 }} }}, {{ translate = [0, 2, 0] }}]
[[lights]]
type = "point"
position = [0.5, 1.5, 0.5]
intensity = [2, 1.8, 1.6]
"#
    );
    let o = Overrides {
        resolution: Some((24, 18)),
        spp: Some(16),
        ..Default::default()
    };
    let from_toml = Scene::parse(&toml, &dir.0.join("room.toml"), &dir.0, &o).unwrap();
    let from_gltf = Scene::load(&glb, &o).unwrap();
    assert_eq!(from_gltf.lights.len(), from_toml.lights.len());
    let (a, _) = crate::render::integrator::render(&from_toml, &|_| {});
    let (g, _) = crate::render::integrator::render(&from_gltf, &|_| {});
    let mean = |img: &crate::render::film::Image| {
        img.pixels.iter().copied().sum::<Rgb>() / img.pixels.len() as f32
    };
    let (ma, mg) = (mean(&a), mean(&g));
    assert!(ma.min_element() > 0.01, "the scene is lit: {ma}");
    assert!(
        ((ma - mg) / ma).abs().max_element() < 1e-3,
        "TOML {ma} vs glTF {mg}"
    );
    let differ = a
        .pixels
        .iter()
        .zip(&g.pixels)
        .filter(|(x, y)| (**x - **y).abs().max_element() > 1e-3 * (1.0 + x.max_element()))
        .count();
    assert!(differ <= a.pixels.len() / 50, "{differ} pixels differ");
}

/// The Blender-exported scene (`scenes/blender/blender-scene.glb`, `docs/blender.md`), where
/// the tree has it: a floor, a glass sphere, a copper cube, a point light, an emissive panel
/// and a camera.
#[test]
fn blender_export_imports() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/blender/blender-scene.glb");
    if !path.exists() {
        eprintln!("skipped: {} is not in this tree", path.display());
        return;
    }
    let g = import(&path, &Transform::IDENTITY).unwrap();
    assert!(g.meshes.len() >= 4, "{}", g.meshes.len());
    assert!(g.camera.is_some());
    assert!(g.lights.iter().any(|l| matches!(l, Light::Point { .. })));
    assert!(g.materials.iter().any(|m| m.pbr.transmission == 1.0));
    assert!(g.materials.iter().any(|m| m.pbr.metallic == 1.0));
    assert!(g.materials.iter().any(|m| m.emission.is_some()));
    let o = Overrides {
        resolution: Some((16, 12)),
        spp: Some(1),
        ..Default::default()
    };
    let scene = Scene::load(&path, &o).unwrap();
    assert!(scene.lights.len() >= 2);
}

/// `STRIAE_materials_scratches`' paths are relative to the glTF file, not to the TOML scene
/// that includes it: a missing drawing is reported under the glTF's folder.
#[test]
fn scratch_paths_are_relative_to_the_gltf() {
    let dir = TempDir::new("paths");
    std::fs::create_dir_all(dir.0.join("sub")).unwrap();
    // Each file is missing: the error names where it was looked for.
    for (key, file) in [("curves", "marks.svg"), ("map", "wear.png")] {
        let mut b = Builder::default();
        let mut prim = b.primitive(&TRIANGLE, None, Some(&[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]));
        prim["material"] = json!(0);
        let doc = json!({
            "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }],
            "meshes": [{ "primitives": [prim] }],
            "materials": [{ "name": "brushed", "pbrMetallicRoughness": { "metallicFactor": 1, "roughnessFactor": 0 },
                "extensions": { "STRIAE_materials_scratches": { key: file } } }]
        });
        std::fs::write(dir.0.join("sub/part.glb"), b.glb(doc)).unwrap();
        let toml = "[camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 40\n[[shapes]]\ntype = \"gltf\"\npath = \"sub/part.glb\"\n";
        let e = Scene::parse(toml, &dir.0.join("s.toml"), &dir.0, &Overrides::default())
            .unwrap_err()
            .to_string();
        let expect = dir.0.join("sub").join(file);
        assert!(
            e.contains(&expect.display().to_string()) && e.contains("brushed"),
            "{e}"
        );
    }
}

/// `KHR_materials_anisotropy`'s texture orients a painted scratch map: its directions, turned by
/// the rotation and written in striae's frame, become the map's flow map, which the scratched
/// material reads (a flow map of another size than the map's is refused, naming the texture).
#[test]
fn anisotropy_texture_orients_a_painted_map() {
    // Along the tangent is +u; up the image (glTF's bitangent) is -v.
    let tex = RgbImage::new(2, 1, vec![Rgb::new(1.0, 0.5, 0.0), Rgb::new(0.5, 1.0, 0.0)]);
    let flow = anisotropy_flow(&tex, 0.0);
    assert_eq!(
        flow.pixels,
        [Rgb::new(1.0, 0.5, 0.0), Rgb::new(0.5, 0.0, 0.0)]
    );
    // A quarter turn counter-clockwise takes the tangent to the bitangent.
    let turned = anisotropy_flow(&tex, std::f32::consts::FRAC_PI_2);
    assert!((turned.pixels[0] - Rgb::new(0.5, 0.0, 0.0)).length() < 1e-6);

    let dir = TempDir::new("anisotropy");
    let mut b = Builder::default();
    let mut prim = b.primitive(&TRIANGLE, None, Some(&[0.0, 0.0, 1.0, 0.0, 0.0, 1.0]));
    prim["material"] = json!(0);
    let doc = json!({
        "extensionsUsed": ["KHR_materials_anisotropy", "STRIAE_materials_scratches"],
        "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [prim] }],
        "images": [{ "uri": format!("data:image/png;base64,{}", base64(&png_bytes())) }],
        "textures": [{ "source": 0 }],
        "materials": [{ "name": "brushed", "pbrMetallicRoughness": { "metallicFactor": 1, "roughnessFactor": 0 },
            "extensions": { "STRIAE_materials_scratches": { "map": "wear.png" },
                            "KHR_materials_anisotropy": { "anisotropyTexture": { "index": 0 } } } }]
    });
    let glb = b.glb(doc);
    std::fs::write(dir.0.join("part.glb"), &glb).unwrap();
    let g = import_bytes(&glb, &dir.0.join("part.glb"), &Transform::IDENTITY).unwrap();
    // The texture is red then white: directions (1, -1) and (1, 1) in (tangent, bitangent).
    let decoded = RgbImage::new(2, 1, vec![Rgb::new(1.0, 0.0, 0.0), Rgb::ONE]);
    assert_eq!(
        g.materials[0].scratch_flow.as_deref(),
        Some(&anisotropy_flow(&decoded, 0.0))
    );
    let toml = "[camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 40\n[[shapes]]\ntype = \"gltf\"\npath = \"part.glb\"\n";
    let parse = || Scene::parse(toml, &dir.0.join("s.toml"), &dir.0, &Overrides::default());
    for (width, ok) in [(2, true), (3, false)] {
        image::GrayImage::from_pixel(width, 1, image::Luma([200]))
            .save(dir.0.join("wear.png"))
            .unwrap();
        match parse() {
            Ok(_) => assert!(ok, "a {width} x 1 map took a 2 x 1 flow map"),
            Err(e) => {
                let e = e.to_string();
                assert!(
                    !ok && e.contains("anisotropyTexture") && e.contains("map's size"),
                    "{e}"
                );
            }
        }
    }
}
