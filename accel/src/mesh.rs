//! Triangle meshes from Wavefront OBJ files.

use crate::error::{Error, Result};
use std::path::Path;
use tress_core::math::{Aabb, Vec3};

/// An indexed triangle mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct TriangleMesh {
    /// Where the mesh came from, used in errors.
    pub name: String,
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

impl TriangleMesh {
    /// Loads every object of an OBJ file as one mesh (faces triangulated as fans, points and
    /// lines ignored, materials ignored), and validates it.
    pub fn load_obj(path: &Path) -> Result<TriangleMesh> {
        let bytes = tress_core::files::read_regular(path).map_err(|source| Error::Io {
            path: path.to_owned(),
            source,
        })?;
        let options = tobj::LoadOptions {
            triangulate: true,
            ignore_points: true,
            ignore_lines: true,
            ..Default::default()
        };
        // Materials are assigned per object in the scene file, so .mtl files are not read.
        let (models, _) =
            tobj::load_obj_buf(&mut bytes.as_slice(), &options, |_| Ok(Default::default()))
                .map_err(|source| Error::Obj {
                    path: path.to_owned(),
                    source,
                })?;
        let mut mesh = TriangleMesh {
            name: path.display().to_string(),
            positions: Vec::new(),
            triangles: Vec::new(),
        };
        for model in models {
            let m = model.mesh;
            let base = mesh.positions.len() as u32;
            let count = (m.positions.len() / 3) as u32;
            mesh.positions.extend(
                m.positions
                    .chunks_exact(3)
                    .map(|c| Vec3::new(c[0], c[1], c[2])),
            );
            for t in m.indices.chunks_exact(3) {
                if let Some(&bad) = t.iter().find(|&&i| i >= count) {
                    return Err(Error::InvalidGeometry {
                        object: mesh.name,
                        reason: format!(
                            "object '{}' refers to vertex {} but has {count}",
                            model.name,
                            bad + 1
                        ),
                    });
                }
                mesh.triangles.push([base + t[0], base + t[1], base + t[2]]);
            }
        }
        mesh.validate()?;
        Ok(mesh)
    }

    /// Checks for at least one triangle, indices in range and finite coordinates.
    pub fn validate(&self) -> Result<()> {
        let fail = |reason: String| Error::InvalidGeometry {
            object: self.name.clone(),
            reason,
        };
        if self.triangles.is_empty() {
            return Err(fail("has no triangles".into()));
        }
        let n = self.positions.len();
        if let Some(t) = self
            .triangles
            .iter()
            .position(|t| t.iter().any(|&i| i as usize >= n))
        {
            return Err(fail(format!(
                "triangle {t} refers to a vertex beyond the {n} vertices"
            )));
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(fail(format!(
                "vertex {i} has a non-finite coordinate {:?}",
                self.positions[i]
            )));
        }
        Ok(())
    }

    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for &p in &self.positions {
            b.grow(p);
        }
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loads_and_triangulates() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("quad.obj");
        std::fs::write(
            &path,
            "o a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\no b\nv 5 5 5\nv 6 5 5\nv 5 6 5\nf 5 6 7\n",
        )
        .unwrap();
        let m = TriangleMesh::load_obj(&path).unwrap();
        assert_eq!(m.positions.len(), 7);
        assert_eq!(m.triangles.len(), 3);
        assert_eq!(m.triangles[2], [4, 5, 6]);
    }

    #[test]
    fn bad_files_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.obj");
        let e = TriangleMesh::load_obj(&missing).unwrap_err().to_string();
        assert!(e.contains("missing.obj"), "{e}");
        let nan = dir.path().join("nan.obj");
        std::fs::write(&nan, "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let e = TriangleMesh::load_obj(&nan).unwrap_err().to_string();
        assert!(e.contains("nan.obj"), "{e}");
        let empty = dir.path().join("empty.obj");
        std::fs::write(&empty, "v 0 0 0\n").unwrap();
        let e = TriangleMesh::load_obj(&empty).unwrap_err().to_string();
        assert!(e.contains("no triangles"), "{e}");
        let out_of_range = dir.path().join("range.obj");
        std::fs::write(&out_of_range, "v 0 0 0\nv 1 0 0\nf 1 2 9\n").unwrap();
        assert!(TriangleMesh::load_obj(&out_of_range).is_err());
    }
}
