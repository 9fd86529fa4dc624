//! Wavefront OBJ meshes, loaded with `tobj` (triangulated, single index) into one
//! [`TriangleMesh`] per file: all models of the file are merged. Normals and uvs are kept
//! when every model has them.

use std::path::Path;

use super::{GeometryError, TriangleMesh};
use crate::math::{Vec2, Vec3};

impl TriangleMesh {
    /// Loads `path`; errors name the path for a missing, unreadable or corrupt file, and for
    /// a file without triangles.
    pub fn from_obj(path: impl AsRef<Path>) -> Result<TriangleMesh, GeometryError> {
        let path = path.as_ref();
        let options = tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ..Default::default()
        };
        let (models, _materials) =
            tobj::load_obj(path, &options).map_err(|e| GeometryError::ObjLoad {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
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
                        .map(|c| Vec2::new(c[0], c[1])),
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
}
