//! Triangle meshes from Wavefront OBJ files.

use crate::error::{Error, Result};
use std::path::Path;
use tress_core::math::{Aabb, Vec3};

/// An indexed triangle mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct TriangleMesh {
    /// Where the mesh came from, used in errors.
    pub name: String,
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Vertex indices of each triangle, into `positions`.
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
        let text = String::from_utf8_lossy(&bytes);
        let at_line = |line: usize, reason: String| Error::Obj {
            path: path.to_owned(),
            line: Some(line),
            reason: format!(
                "{reason}: `{}`",
                text.lines().nth(line - 1).unwrap_or("").trim()
            ),
        };
        if let Some(line) = non_finite_vertex_line(&text) {
            return Err(at_line(line, "a vertex coordinate is not finite".into()));
        }
        // Materials are assigned per object in the scene file, so .mtl files are not read.
        let (models, _) =
            tobj::load_obj_buf(&mut bytes.as_slice(), &options, |_| Ok(Default::default()))
                .map_err(|e| match fault_line(&text, &e) {
                    Some(line) => at_line(line, e.to_string()),
                    None => Error::Obj {
                        path: path.to_owned(),
                        line: None,
                        reason: e.to_string(),
                    },
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
                    return Err(Error::InvalidGeometry(tress_groom::InvalidGeometry {
                        object: mesh.name,
                        reason: format!(
                            "object '{}' refers to vertex {} but has {count}",
                            model.name,
                            bad + 1
                        ),
                    }));
                }
                mesh.triangles.push([base + t[0], base + t[1], base + t[2]]);
            }
        }
        mesh.validate()?;
        Ok(mesh)
    }

    /// Checks for at least one triangle, indices in range and finite coordinates.
    pub fn validate(&self) -> Result<()> {
        let fail = |reason: String| {
            Error::InvalidGeometry(tress_groom::InvalidGeometry {
                object: self.name.clone(),
                reason,
            })
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

    /// Bounds of the vertex positions.
    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for &p in &self.positions {
            b.grow(p);
        }
        b
    }
}

/// The statement of an OBJ line: its tag and arguments, comments dropped.
fn statement(line: &str) -> Option<(&str, Vec<&str>)> {
    let mut words = line.split('#').next().unwrap_or("").split_whitespace();
    let tag = words.next()?;
    Some((tag, words.collect()))
}

/// The first `v` line holding a NaN or infinite coordinate (1-based).
fn non_finite_vertex_line(text: &str) -> Option<usize> {
    text.lines()
        .position(|line| {
            statement(line).is_some_and(|(tag, args)| {
                tag == "v"
                    && args
                        .iter()
                        .any(|w| w.parse::<f32>().is_ok_and(|x| !x.is_finite()))
            })
        })
        .map(|i| i + 1)
}

/// The first line (1-based) that explains `tobj`'s error, which names none: a vertex,
/// texture or normal line that does not parse, or a face with a bad or out-of-range index
/// (indices count the lines of each kind read so far; negative ones count back).
fn fault_line(text: &str, err: &tobj::LoadError) -> Option<usize> {
    use tobj::LoadError as E;
    let mut counts = [0i64; 3]; // v, vt, vn
    for (i, line) in text.lines().enumerate() {
        let Some((tag, args)) = statement(line) else {
            continue;
        };
        let floats = |n: usize| args.len() >= n && args.iter().all(|w| w.parse::<f32>().is_ok());
        let (bad, kind) = match tag {
            "v" => (matches!(err, E::PositionParseError) && !floats(3), Some(0)),
            "vt" => (matches!(err, E::TexcoordParseError) && !floats(1), Some(1)),
            "vn" => (matches!(err, E::NormalParseError) && !floats(3), Some(2)),
            "f" => {
                let index_ok = |word: Option<&str>, n: i64, required: bool| match word {
                    None | Some("") => !required,
                    Some(w) => w
                        .parse::<i64>()
                        .is_ok_and(|k| k != 0 && k.unsigned_abs() <= n.unsigned_abs()),
                };
                let bad_face = args.len() < 3
                    || args.iter().any(|w| {
                        let mut parts = w.split('/');
                        !(index_ok(parts.next(), counts[0], true)
                            && index_ok(parts.next(), counts[1], false)
                            && index_ok(parts.next(), counts[2], false))
                    });
                let face_error = matches!(
                    err,
                    E::FaceParseError
                        | E::InvalidPolygon
                        | E::FaceVertexOutOfBounds
                        | E::FaceTexCoordOutOfBounds
                        | E::FaceNormalOutOfBounds
                );
                (face_error && bad_face, None)
            }
            _ => (false, None),
        };
        if bad {
            return Some(i + 1);
        }
        if let Some(k) = kind {
            counts[k] += 1;
        }
    }
    None
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
        assert!(e.contains("nan.obj:2:") && e.contains("`v nan 0 0`"), "{e}");
        let empty = dir.path().join("empty.obj");
        std::fs::write(&empty, "v 0 0 0\n").unwrap();
        let e = TriangleMesh::load_obj(&empty).unwrap_err().to_string();
        assert!(e.contains("no triangles"), "{e}");
        let out_of_range = dir.path().join("range.obj");
        std::fs::write(&out_of_range, "v 0 0 0\nv 1 0 0\nf 1 2 9\n").unwrap();
        assert!(TriangleMesh::load_obj(&out_of_range).is_err());
        // tobj names no line: the reader finds the one at fault.
        for (text, line, shows) in [
            ("v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n", 2, "`v 1 x 0`"),
            (
                "# c\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 q\n",
                6,
                "`f 1 2 q`",
            ),
            (
                "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0\nf 1 2 3\n",
                4,
                "`vn 0 0`",
            ),
        ] {
            let bad = dir.path().join("bad.obj");
            std::fs::write(&bad, text).unwrap();
            let e = TriangleMesh::load_obj(&bad).unwrap_err().to_string();
            assert!(
                e.contains(&format!("bad.obj:{line}:")) && e.contains(shows),
                "{text:?}: {e}"
            );
        }
    }
}
