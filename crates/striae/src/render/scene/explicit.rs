//! Explicit scratch geometry in a scene (METHOD.md 8.3, 9.6): `scratches.explicit = true`
//! turns a scratched material's scratches (its layers' and its curves', `scratches.curves` or
//! `scratches.pattern`) on every rectangle and box that uses it into grooves
//! ([`crate::render::geometry::carve`]): each face gets its [`Carving`], the walls become one more mesh
//! shape with the wall material, and the face keeps the smooth base. Everything is checked
//! before the walls are built: the shape must be planar, the curves valid, the estimated
//! memory under [`MAX_EXPLICIT_BYTES`], and the grooves must fit in a box's thickness.

use super::file::{ShapeSection, ShapeType};
use super::scratches::ExplicitSpec;
use super::{invalid, SceneError};
use crate::curves::CurveSet;
use crate::layers::Scratch;
use crate::render::geometry::carve::{
    triangles_per_curve, triangles_per_groove, Carve, CarveRole, Carving, Face,
};
use crate::render::geometry::{Shape, ShapeGeometry, TriangleMesh};
use crate::render::material::Material;
use std::path::Path;
use std::time::Instant;

/// Memory per wall triangle: mesh vertices and indices, BVH primitives and nodes, the build's
/// temporaries. Measured as the peak address space (`VmPeak`, what `ulimit -v` limits; the
/// resident peak is 377 bytes a triangle) of `striae render` of a gold rectangle with
/// explicit setting-2 scratches, 64 layers: 1.11 GB at 2,352,730 triangles (`stations = 50`),
/// 2.16 GB at 4,777,401 (`stations = 100`), 443 bytes a triangle between them.
pub const BYTES_PER_TRIANGLE: usize = 450;
/// The most memory explicit geometry may take (estimated up front).
pub const MAX_EXPLICIT_BYTES: usize = 6 << 30;

/// The faces of a rectangle or box mesh: face `f` is vertices `4f..4f + 4` with uv `(0, 0),
/// (1, 0), (1, 1), (0, 1)` (`TriangleMesh::rectangle`, `TriangleMesh::cuboid`; a transform
/// keeps the vertex order), its triangles `2f`, `2f + 1`.
fn faces(mesh: &TriangleMesh) -> Vec<Face> {
    let p = mesh.positions();
    (0..mesh.triangle_count() / 2)
        .map(|f| {
            let [a, b, c] = mesh.triangle(2 * f);
            Face {
                origin: p[4 * f],
                dpdu: p[4 * f + 1] - p[4 * f],
                dpdv: p[4 * f + 3] - p[4 * f],
                n: (b - a).cross(c - a).normalize(),
            }
        })
        .collect()
}

/// The distance from face `f` of a box to the opposite face (`f ^ 1`, `TriangleMesh::cuboid`'s
/// order), or infinity for a rectangle.
fn thickness(kind: ShapeType, faces: &[Face], f: usize) -> f32 {
    match kind {
        ShapeType::Box => (faces[f ^ 1].origin - faces[f].origin)
            .dot(faces[f].n)
            .abs(),
        _ => f32::INFINITY,
    }
}

/// Carves the shapes whose material is explicit (`specs[material]`), `sections[i]` the TOML
/// shape (with its index in the file) that made `shapes[i]`, appending the wall
/// shapes and their materials; `None` when no material is explicit.
pub(super) fn carve(
    sections: &[(usize, &ShapeSection)],
    file: &Path,
    names: &[&String],
    specs: &[Option<ExplicitSpec>],
    materials: &mut Vec<Material>,
    shapes: &mut Vec<Shape>,
) -> Result<Option<Carve>, SceneError> {
    if specs.iter().all(Option::is_none) {
        return Ok(None);
    }
    let start = Instant::now();
    let mut carve = Carve::default();
    let mut walls = Vec::new();
    let mut bytes = 0usize;
    for (i, &(at, s)) in sections.iter().enumerate() {
        let m = shapes[i].material;
        let Some(spec) = specs.get(m as usize).and_then(Option::as_ref) else {
            continue;
        };
        let key = format!("materials.{}.scratches.explicit", names[m as usize]);
        let ShapeGeometry::Mesh(mesh) = &shapes[i].geometry else {
            return Err(not_planar(file, &key, at, s.kind));
        };
        if !matches!(s.kind, ShapeType::Rectangle | ShapeType::Box) {
            return Err(not_planar(file, &key, at, s.kind));
        }
        let faces = faces(mesh);
        let (curves, to_uv) = match &spec.curves {
            Some(d) => {
                // The SV-BRDF's checks (each polyline valid, the segments within bounds).
                CurveSet::new(&d.polylines, d.to_uv).map_err(|e| {
                    invalid(
                        file,
                        format!("materials.{}.scratches.curves", names[m as usize]),
                        "",
                        e,
                    )
                })?;
                (d.polylines.as_slice(), d.to_uv)
            }
            None => (&[][..], glam::DVec2::ONE),
        };
        // Up front, before anything is enumerated: a layer has about one scratch per noise cell,
        // `1 / (L W)` cells per face (the texture square), plus a rim of cells the ellipses
        // reach in from outside; every face holds every curve at most.
        let p = spec.layers.params();
        let per_face = p.layers as f64 * (1.0 + 2.0 * p.threshold).powi(2) / (p.length * p.width);
        let segments = spec.profile.points.len() - 1;
        let curve_triangles: usize = curves
            .iter()
            .map(|l| triangles_per_curve(segments, l.points.len()))
            .sum();
        bytes = bytes.saturating_add(
            (faces.len() as f64
                * (per_face * triangles_per_groove(segments, spec.stations) as f64
                    + curve_triangles as f64)
                * BYTES_PER_TRIANGLE as f64)
                .min(usize::MAX as f64) as usize,
        );
        if bytes > MAX_EXPLICIT_BYTES {
            return Err(invalid(
                file,
                key,
                true,
                format!(
                    "the grooves would take about {:.1} GiB (over the {} GiB allowed): use fewer layers or curves, wider scratches or fewer explicit shapes",
                    bytes as f64 / (1u64 << 30) as f64,
                    MAX_EXPLICIT_BYTES >> 30
                ),
            ));
        }
        // What the machine has left (ulimit -v, a cgroup): the BVH builder panics, rather than
        // fails, where an allocation is refused.
        crate::memory::check("the explicit grooves and their BVH", bytes as u64, None)
            .map_err(|e| invalid(file, key.as_str(), true, e))?;
        let scratches: Vec<Scratch> = Face::scratches(&spec.layers);
        let wall_material = materials.len() as u32;
        materials.push(spec.wall.clone());
        let first = carve.carvings.len() as u32;
        for (f, face) in faces.iter().enumerate() {
            let mut carving = Carving::new(
                face,
                &scratches,
                curves,
                to_uv,
                &spec.profile.points,
                spec.stations,
            );
            let (depth, room) = (carving.max_depth(), thickness(s.kind, &faces, f));
            if !(depth < room) {
                return Err(invalid(file, key, true, format!("grooves up to {depth} deep do not fit in shapes[{at}], {room} thick: make it thicker or the scratches narrower or shallower")));
            }
            if carving.is_empty() {
                carve.carvings.push(carving);
                continue;
            }
            let (positions, indices) = carving.walls();
            let mesh = TriangleMesh::new(positions, indices, None, None, None)
                .map_err(|e| invalid(file, format!("shapes[{at}]"), s.kind, e))?;
            walls.push((carve.carvings.len() as u32, wall_material, mesh));
            carve.carvings.push(carving);
        }
        set_role(&mut carve.roles, i, CarveRole::Faces { first });
    }
    let triangles: usize = walls.iter().map(|w| w.2.triangle_count()).sum();
    for (carving, material, mesh) in walls {
        set_role(&mut carve.roles, shapes.len(), CarveRole::Walls { carving });
        shapes.push(Shape {
            geometry: ShapeGeometry::Mesh(mesh),
            material,
            area_light: None,
        });
    }
    crate::log::info(&format!(
        "explicit scratches: {} grooves, {} wall triangles (about {} MiB estimated), built in {:.2} s",
        carve.grooves(),
        triangles,
        (triangles * BYTES_PER_TRIANGLE) >> 20,
        start.elapsed().as_secs_f64()
    ));
    Ok(Some(carve))
}

fn set_role(roles: &mut Vec<Option<CarveRole>>, shape: usize, role: CarveRole) {
    if roles.len() <= shape {
        roles.resize(shape + 1, None);
    }
    roles[shape] = Some(role);
}

fn not_planar(file: &Path, key: &str, i: usize, kind: ShapeType) -> SceneError {
    invalid(
        file,
        key,
        true,
        format!("explicit scratch grooves are carved into planar faces (a rectangle or a box); shapes[{i}] is a {kind:?}"),
    )
}

#[cfg(test)]
mod tests {
    use crate::render::scene::{Overrides, Scene, SceneError};
    use std::path::Path;

    /// A metal scene whose one shape (`shape`, TOML lines) uses `scratches` (TOML lines).
    fn scene(shape: &str, scratches: &str) -> Result<Scene, SceneError> {
        let text = format!(
            "[render]\nwidth = 8\nheight = 8\nspp = 1\n\
             [camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 30\n\
             [materials.plate]\ntype = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"\n\
             [materials.plate.scratches]\nexplicit = true\n{scratches}\n\
             [[shapes]]\nmaterial = \"plate\"\n{shape}\n"
        );
        Scene::parse(
            &text,
            Path::new("t.toml"),
            Path::new("."),
            &Overrides::default(),
        )
    }

    fn error_of(r: Result<Scene, SceneError>) -> String {
        match r {
            Ok(_) => panic!("expected an error"),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn explicit_grooves_are_carved_into_a_rectangle() {
        let s = scene("type = \"rectangle\"", "setting = 2\nlayers = 2").unwrap();
        let carve = s.geometry.carve().expect("carved");
        assert!(carve.grooves() > 100, "{} grooves", carve.grooves());
        // The face and one wall shape.
        assert_eq!(s.geometry.shapes().len(), 2);
    }

    #[test]
    fn stations_set_the_walls_triangles_and_are_checked() {
        let triangles = |stations: &str| {
            let s = scene(
                "type = \"rectangle\"",
                &format!("setting = 2\nlayers = 1\n{stations}"),
            )
            .unwrap();
            let walls = &s.geometry.shapes()[1];
            let crate::render::geometry::ShapeGeometry::Mesh(m) = &walls.geometry else {
                panic!("walls are a mesh")
            };
            (s.geometry.carve().unwrap().grooves(), m.triangle_count())
        };
        // A V has two segments: 2 x 2 x (stations - 1) triangles a groove, less the pointed
        // ends' degenerate ones (one per segment at each tip of a whole groove).
        let (g16, t16) = triangles("");
        let (g64, t64) = triangles("stations = 64");
        assert_eq!(g16, g64);
        assert!(
            t16 <= 4 * 15 * g16 && t16 >= 4 * 15 * g16 - 4 * g16,
            "{t16}, {g16}"
        );
        assert!(
            t64 <= 4 * 63 * g64 && t64 >= 4 * 63 * g64 - 4 * g64,
            "{t64}, {g64}"
        );
        for bad in ["stations = 2", "stations = 5000"] {
            let e = error_of(scene(
                "type = \"rectangle\"",
                &format!("setting = 2\n{bad}"),
            ));
            assert!(e.contains("materials.plate.scratches.stations"), "{e}");
        }
    }

    #[test]
    fn explicit_on_a_shape_that_cannot_be_carved_names_the_key() {
        let e = error_of(scene("type = \"sphere\"", "setting = 2"));
        assert!(e.contains("materials.plate.scratches.explicit"), "{e}");
        assert!(e.contains("planar"), "{e}");
        let e = error_of(scene("type = \"teapot\"\nsubdivisions = 2", "setting = 2"));
        assert!(e.contains("materials.plate.scratches.explicit"), "{e}");
        // Curves (METHOD.md 9.6), alone or beside layers: the same error.
        for scratches in [CIRCLES.to_string(), format!("setting = 2\n{CIRCLES}")] {
            let e = error_of(scene("type = \"sphere\"", &scratches));
            assert!(
                e.contains("materials.plate.scratches.explicit") && e.contains("planar"),
                "{e}"
            );
        }
    }

    /// Four concentric circles about the face's centre (uv), 0.01 wide.
    const CIRCLES: &str =
        "pattern = { kind = \"circles\", radius = [0.1, 0.4], count = 4, width = 0.01 }";

    /// A render of `s` at its settings: every pixel finite.
    fn renders(s: &crate::render::scene::Scene) {
        let (image, _) = crate::render::integrator::render(s, &|_| {});
        assert!(image.pixels.iter().all(|p| p.is_finite()));
    }

    #[test]
    fn explicit_curves_are_carved_alone_or_beside_layers_and_render() {
        // Curves only (no layer keys: no layers): a groove a circle, one wall shape.
        let s = scene("type = \"rectangle\"", CIRCLES).unwrap();
        assert_eq!(s.geometry.carve().expect("carved").grooves(), 4);
        assert_eq!(s.geometry.shapes().len(), 2);
        renders(&s);
        // Beside layers: both, in one wall shape.
        let grooves = |s: &crate::render::scene::Scene| s.geometry.carve().unwrap().grooves();
        let layers = grooves(&scene("type = \"rectangle\"", "setting = 2\nlayers = 1").unwrap());
        let both = scene(
            "type = \"rectangle\"",
            &format!("setting = 2\nlayers = 1\n{CIRCLES}"),
        )
        .unwrap();
        assert_eq!(grooves(&both), layers + 4);
        assert_eq!(both.geometry.shapes().len(), 2);
        renders(&both);
        // A box: every face carved with the whole drawing (its uv square).
        let b = scene("type = \"box\"", CIRCLES).unwrap();
        assert_eq!(grooves(&b), 6 * 4);
        renders(&b);
        // A worn, dashed pattern on glass: caps at every dash's ends.
        let glass = "[render]\nwidth = 8\nheight = 8\nspp = 2\n\
             [camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 30\n\
             [materials.pane]\ntype = \"scratched\"\nbase = \"glass\"\n\
             [materials.pane.scratches]\nexplicit = true\nwalls = \"dielectric\"\n\
             pattern = { kind = \"swirl\", count = 20, radius = [0.05, 0.2], width = 0.004 }\n\
             dashes = [0.02, 0.01]\nwear = 0.5\nwear_length = 0.05\n\
             [[shapes]]\ntype = \"rectangle\"\nmaterial = \"pane\"\n\
             [environment]\ntype = \"constant\"\nradiance = [1, 1, 1]\n";
        let s = Scene::parse(
            glass,
            Path::new("t.toml"),
            Path::new("."),
            &Overrides::default(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert!(grooves(&s) > 20, "{}", grooves(&s));
        renders(&s);
    }

    #[test]
    fn curves_count_against_the_memory_and_the_thickness() {
        // 200 circles 1e-4 wide (about 160 000 segments) with a 32-segment round profile on
        // the six faces of a box: about 28 GB of walls.
        let many = "profile = \"round:depth=0.3,segments=32\"\n\
             pattern = { kind = \"circles\", radius = [0.1, 0.45], count = 200, width = 1e-4 }";
        let e = error_of(scene("type = \"box\"", many));
        assert!(
            e.contains("materials.plate.scratches.explicit") && e.contains("GiB"),
            "{e}"
        );
        // Grooves 5e-3 deep in a box 1e-4 thick.
        let thin = "type = \"box\"\ntransform = [{ scale = [1, 1, 0.00005] }]";
        let e = error_of(scene(thin, CIRCLES));
        assert!(
            e.contains("materials.plate.scratches.explicit") && e.contains("thick"),
            "{e}"
        );
    }

    /// A render's check counts the grooves the loaded scene holds against `--max-memory`.
    #[test]
    fn a_render_counts_the_grooves_it_holds_against_max_memory() {
        let s = scene("type = \"rectangle\"", "setting = 2\nlayers = 2").unwrap();
        let held = s.geometry.primitive_count() as u64 * super::BYTES_PER_TRIANGLE as u64;
        assert!(held > 1 << 20, "{held}");
        let check = |cap| crate::render::integrator::check_memory(&s, 64, "--res 8x8", Some(cap));
        assert!(check(held + (64 << 20)).is_ok());
        let e = check(held).unwrap_err().to_string();
        assert!(
            e.contains("--res 8x8") && e.ends_with("Lower --res or raise --max-memory."),
            "{e}"
        );
    }

    #[test]
    fn grooves_deeper_than_a_box_and_sets_too_large_are_errors() {
        // Setting 2 (W 0.01): grooves about 1e-3 deep on a face 2 wide, in a box 1e-4 thick.
        let thin = "type = \"box\"\ntransform = [{ scale = [1, 1, 0.00005] }]";
        let e = error_of(scene(thin, "setting = 2\nlayers = 1"));
        assert!(
            e.contains("materials.plate.scratches.explicit") && e.contains("thick"),
            "{e}"
        );
        let e = error_of(scene(
            "type = \"rectangle\"",
            "length = 0.3\nwidth = 0.00001\nthreshold = 0.1\nlayers = 64",
        ));
        assert!(
            e.contains("materials.plate.scratches.explicit") && e.contains("GiB"),
            "{e}"
        );
        let e = error_of(scene("type = \"rectangle\"", "table = \"t.npz\""));
        assert!(e.contains("scratches.explicit"), "{e}");
    }

    /// An asymmetric groove faces the same way cut and modelled on curves too (METHOD.md
    /// section 1, 9.6: the profile's `x` along `b = t x n`, `t` the curve's tangent): a
    /// mirror-walled metal plate with arcs of a sawtooth groove (large circles, nearly parallel
    /// across the view), lit from one side, renders the same mean either way, far from the
    /// mirrored sawtooth's. (`layer_mix = "max"` pinned: what the tolerance was measured
    /// with; `union`, the default for curves alone, reads 1 % brighter on these side-by-side
    /// circles, whose coverages it takes for independent.)
    #[test]
    fn asymmetric_curved_grooves_face_the_same_way_cut_and_modelled() {
        let dir = std::env::temp_dir().join(format!("striae-curved-saw-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("saw.txt"), "-0.5 0\n0.3 -0.4\n0.5 0\n").unwrap();
        std::fs::write(dir.join("mirrored.txt"), "-0.5 0\n-0.3 -0.4\n0.5 0\n").unwrap();
        let mean = |profile: &str, explicit: bool| {
            let text = format!(
                r#"
[render]
width = 48
height = 48
spp = 16
max_depth = 8
[camera]
position = [-0.36, 0.12, 0.76]
look_at = [-0.4, 0.0, 0.6]
fov = 40
[materials.plate]
type = "scratched"
base = "metal"
preset = "mirror"
[materials.plate.scratches]
profile = "file:{profile}.txt"
walls = "specular"
fresnel_law = "none"
pattern = {{ kind = "circles", centre = [0.3, -1.5], radius = [1.6, 2.0], count = 100, width = 0.002 }}
layer_mix = "max"
explicit = {explicit}
[[shapes]]
type = "rectangle"
material = "plate"
transform = [{{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }}]
[[shapes]]
type = "rectangle"
emission = [12.0, 12.0, 12.0]
transform = [{{ look_at = {{ origin = [-2.0, 1.5, 1.0], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }} }}]
[environment]
type = "constant"
radiance = [0.02, 0.02, 0.02]
"#
            );
            let s = Scene::parse(&text, &dir.join("saw.toml"), &dir, &Overrides::default())
                .unwrap_or_else(|e| panic!("{e}"));
            let (image, _) = crate::render::integrator::render(&s, &|_| {});
            image.pixels.iter().map(|p| p.y as f64).sum::<f64>() / image.pixels.len() as f64
        };
        let (cut, modelled) = (mean("saw", true), mean("saw", false));
        let (cut_mirrored, modelled_mirrored) = (mean("mirrored", true), mean("mirrored", false));
        std::fs::remove_dir_all(&dir).ok();
        eprintln!("saw: cut {cut}, modelled {modelled}; mirrored: cut {cut_mirrored}, modelled {modelled_mirrored}");
        // Lit from one side, one facing reflects the light away (mean 0.05), the other toward
        // the eye (0.92): cut and modelled agree within 0.005 either way (a wrong side would
        // swap them).
        for (c, m) in [(cut, modelled), (cut_mirrored, modelled_mirrored)] {
            assert!((m - c).abs() < 0.01, "cut {c}, modelled {m}");
        }
        assert!(
            cut_mirrored > 5.0 * cut,
            "{cut} against {cut_mirrored} mirrored"
        );
    }
}
