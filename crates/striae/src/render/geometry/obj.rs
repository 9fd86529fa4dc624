//! Wavefront OBJ meshes, loaded with `tobj` (triangulated, single index) into one
//! [`TriangleMesh`] per file: all models of the file are merged. Normals and uvs are kept
//! when every model has them. [`TriangleMesh::write_obj`] exports a mesh (e.g. the built-in
//! teapot, so Mitsuba can render the identical geometry).
//!
//! An OBJ file's `vt` puts `(0, 0)` at the bottom-left of a texture image, while striae's
//! image textures put the image's top row at `v = 0` (`texture.rs`). So `v` is flipped to
//! `1 - v` on load and back on export, as Mitsuba 3's OBJ loader does: an image on an OBJ
//! mesh appears the same way up in both renderers (`docs/validation.md`, scene `features`).

use std::io::Write;
use std::path::Path;

use super::{GeometryError, TriangleMesh};
use crate::math::{Vec2, Vec3};

/// Every face (`f`) must have at least three vertices: `tobj` would turn a two-vertex face into
/// a degenerate triangle that renders as nothing, hiding the broken file.
fn check_faces(text: &str) -> Result<(), String> {
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split('#').next().unwrap_or("").split_whitespace();
        if words.next() == Some("f") {
            let n = words.count();
            if n < 3 {
                return Err(format!(
                    "the face on line {} has {n} vertices; a face needs at least 3",
                    i + 1
                ));
            }
        }
    }
    Ok(())
}

/// Every vertex (`v`) within [`super::MAX_COORDINATE`], the bound of the scene file's points:
/// `tobj` reads `1e39` as infinity and `1e30` as it is, which would overflow the BVH's and the
/// intersection's arithmetic. The line and the vertex as written name a bad one.
fn check_vertices(text: &str) -> Result<(), String> {
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split('#').next().unwrap_or("").split_whitespace();
        if words.next() != Some("v") {
            continue;
        }
        // (Words that are not numbers are left to `tobj`'s own errors.)
        let beyond = words
            .take(3)
            .filter_map(|w| w.parse::<f64>().ok())
            .any(|x| !(x.abs() <= super::MAX_COORDINATE as f64));
        if beyond {
            return Err(format!(
                "the vertex on line {} (`{}`) has a coordinate beyond +-{:e}, the bound of the scene's points",
                i + 1,
                line.trim().chars().take(80).collect::<String>(),
                super::MAX_COORDINATE
            ));
        }
    }
    Ok(())
}

impl TriangleMesh {
    /// Loads `path`; errors name the path for a missing, unreadable or corrupt file, and for
    /// a file without triangles.
    pub fn from_obj(path: impl AsRef<Path>) -> Result<TriangleMesh, GeometryError> {
        let path = path.as_ref();
        let load_error = |message: String| GeometryError::ObjLoad {
            path: path.to_path_buf(),
            message,
        };
        let text = crate::io::read_text(path).map_err(|e| load_error(e.to_string()))?;
        check_faces(&text)
            .and_then(|()| check_vertices(&text))
            .map_err(|reason| GeometryError::ObjInvalid {
                path: path.to_path_buf(),
                reason,
            })?;
        // Points (`p`) and polylines (`l`) are not surfaces: skipped, not made into degenerate
        // triangles. Materials (`mtllib`) are not read: striae's materials come from the scene.
        let options = tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ignore_points: true,
            ignore_lines: true,
        };
        let (models, _materials) = tobj::load_obj_buf(&mut text.as_bytes(), &options, |_| {
            Err(tobj::LoadError::OpenFileFailed)
        })
        .map_err(|e| load_error(e.to_string()))?;
        let mut positions = Vec::new();
        let mut indices = Vec::new();
        let mut normals = Vec::new();
        let mut uvs = Vec::new();
        let all_normals = models
            .iter()
            .all(|m| !m.mesh.normals.is_empty() || m.mesh.indices.is_empty());
        let all_uvs = models
            .iter()
            .all(|m| !m.mesh.texcoords.is_empty() || m.mesh.indices.is_empty());
        for m in &models {
            let mesh = &m.mesh;
            if mesh.indices.is_empty() {
                continue;
            }
            let base = positions.len() as u32;
            let n = mesh.positions.len() / 3;
            positions.extend(
                mesh.positions
                    .chunks_exact(3)
                    .map(|c| Vec3::new(c[0], c[1], c[2])),
            );
            if all_normals {
                if mesh.normals.len() != 3 * n {
                    return Err(GeometryError::ObjInvalid {
                        path: path.to_path_buf(),
                        reason: format!(
                            "model '{}' has {} normals for {n} vertices",
                            m.name,
                            mesh.normals.len() / 3
                        ),
                    });
                }
                normals.extend(
                    mesh.normals
                        .chunks_exact(3)
                        .map(|c| Vec3::new(c[0], c[1], c[2])),
                );
            }
            if all_uvs {
                if mesh.texcoords.len() != 2 * n {
                    return Err(GeometryError::ObjInvalid {
                        path: path.to_path_buf(),
                        reason: format!(
                            "model '{}' has {} uvs for {n} vertices",
                            m.name,
                            mesh.texcoords.len() / 2
                        ),
                    });
                }
                uvs.extend(
                    mesh.texcoords
                        .chunks_exact(2)
                        .map(|c| Vec2::new(c[0], 1.0 - c[1])),
                );
            }
            indices.extend(
                mesh.indices
                    .chunks_exact(3)
                    .map(|c| [base + c[0], base + c[1], base + c[2]]),
            );
        }
        if indices.is_empty() {
            return Err(GeometryError::ObjEmpty {
                path: path.to_path_buf(),
            });
        }
        TriangleMesh::new(
            positions,
            indices,
            all_normals.then_some(normals),
            all_uvs.then_some(uvs),
            None,
        )
        .map_err(|e| GeometryError::ObjInvalid {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })
    }

    /// Writes the mesh as OBJ (positions, uvs and normals when present; counter-clockwise faces,
    /// the same winding as here), atomically (`io::write_atomically`). Floats are written in
    /// their shortest exact form, so loading the file back gives identical positions.
    /// Tangents are not part of OBJ and are not written.
    pub fn write_obj(&self, path: impl AsRef<Path>) -> std::io::Result<()> {
        let path = path.as_ref();
        crate::io::write_atomically(path, |tmp: &Path| -> std::io::Result<()> {
            let mut f = std::io::BufWriter::new(std::fs::File::create(tmp)?);
            writeln!(
                f,
                "# striae {} mesh: {} vertices, {} triangles",
                crate::VERSION,
                self.positions().len(),
                self.triangle_count()
            )?;
            for p in self.positions() {
                writeln!(f, "v {} {} {}", p.x, p.y, p.z)?;
            }
            if let Some(uvs) = self.uvs() {
                for t in uvs {
                    writeln!(f, "vt {} {}", t.x, 1.0 - t.y)?;
                }
            }
            if let Some(ns) = self.normals() {
                for n in ns {
                    writeln!(f, "vn {} {} {}", n.x, n.y, n.z)?;
                }
            }
            let (has_uv, has_n) = (self.uvs().is_some(), self.normals().is_some());
            for tri in self.indices() {
                write!(f, "f")?;
                for &i in tri {
                    let k = i + 1;
                    match (has_uv, has_n) {
                        (true, true) => write!(f, " {k}/{k}/{k}")?,
                        (true, false) => write!(f, " {k}/{k}")?,
                        (false, true) => write!(f, " {k}//{k}")?,
                        (false, false) => write!(f, " {k}")?,
                    }
                }
                writeln!(f)?;
            }
            f.into_inner().map_err(|e| e.into_error())?.sync_all()
        })
    }
}
