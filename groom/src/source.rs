//! Where a hair object comes from, as written in a scene file, and the per-object options
//! applied when it is added to the scene.

use crate::cyhair::HairFile;
use crate::error::{format_error, Result};
use crate::geometry::HairGeometry;
use crate::pbrt::PbrtFile;
use crate::ply::PlyFile;
use crate::procedural::ProceduralHair;
use crate::tfx::TfxFile;
use crate::usc::UscFile;
use crate::usd::UsdFile;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use tress_core::limits::Limits;

/// The source of a hair object, as scene files write it:
///
/// ```ron
/// File("hair/straight.hair")                    // format from the extension, default options
/// Hair(path: "hair/straight.hair", z_up: true)  // Cem Yuksel .hair
/// Tfx(path: "hair/sintel_hair.tfx", radius: 0.01)
/// Usc(path: "hairstyles/strands00001.data", radius: 0.00004)  // USC-HairSalon
/// Ply(path: "groom.ply", radius: Some(0.0001), z_up: true)    // PLY strands (Blender, Houdini, …)
/// Pbrt(path: "hair.pbrt")                                      // a pbrt scene's Shape "curve"s
/// Procedural(style: Wavy(amplitude: 0.05, frequency: 3.0), strands: 2000)
/// ```
///
/// (Scene files let newtype variants omit their inner parentheses; plain RON needs
/// `Hair((path: …))`. The `tress_loader` tests parse these examples.)
///
/// Paths are used as given; resolve relative paths before loading ([`HairSource::path_mut`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum HairSource {
    /// A `.hair`, `.tfx`, USC-HairSalon `.data`, `.ply`, `.pbrt` or USD (`.usda`, `.usdc`,
    /// `.usd`: its `BasisCurves`, see [`crate::usd`]) file (by extension, case-insensitive)
    /// with default reader options.
    File(PathBuf),
    /// A Cem Yuksel `.hair` file with reader options (`z_up`).
    Hair(HairFile),
    /// An AMD TressFX `.tfx` file with reader options (`radius`).
    Tfx(TfxFile),
    /// A USC-HairSalon `.data` file with reader options (`radius`).
    Usc(UscFile),
    /// A PLY file of strands with reader options (`radius`, `points_per_strand`, `z_up`); the
    /// layouts understood are listed in [`crate::ply`].
    Ply(PlyFile),
    /// The `Shape "curve"` statements of a pbrt-v4 (or v3) scene file, with reader options
    /// (`z_up`); what is read and what is ignored is listed in [`crate::pbrt`].
    Pbrt(PbrtFile),
    /// Hair generated from a seed ([`ProceduralHair`]).
    Procedural(ProceduralHair),
}

impl HairSource {
    /// The file this source reads, if any.
    pub fn path(&self) -> Option<&Path> {
        match self {
            HairSource::File(p) => Some(p),
            HairSource::Hair(f) => Some(&f.path),
            HairSource::Tfx(f) => Some(&f.path),
            HairSource::Usc(f) => Some(&f.path),
            HairSource::Ply(f) => Some(&f.path),
            HairSource::Pbrt(f) => Some(&f.path),
            HairSource::Procedural(_) => None,
        }
    }

    /// The file path, for resolving it relative to the scene file.
    pub fn path_mut(&mut self) -> Option<&mut PathBuf> {
        match self {
            HairSource::File(p) => Some(p),
            HairSource::Hair(f) => Some(&mut f.path),
            HairSource::Tfx(f) => Some(&mut f.path),
            HairSource::Usc(f) => Some(&mut f.path),
            HairSource::Ply(f) => Some(&mut f.path),
            HairSource::Pbrt(f) => Some(&mut f.path),
            HairSource::Procedural(_) => None,
        }
    }

    /// Every file [`load`](Self::load) reads: the source's file, those a pbrt file includes
    /// and the layers a USD stage composes (sublayers, references, payloads). Empty for
    /// generated hair.
    pub fn files(&self) -> Result<Vec<PathBuf>> {
        let extension = |p: &Path, of: &[&str]| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| of.iter().any(|x| e.eq_ignore_ascii_case(x)))
        };
        match self {
            HairSource::Pbrt(f) => f.files(),
            HairSource::File(p) if extension(p, &["pbrt"]) => PbrtFile::new(p).files(),
            HairSource::File(p) if extension(p, &["usda", "usdc", "usd"]) => {
                UsdFile::new(p).files()
            }
            other => Ok(other.path().map(Path::to_path_buf).into_iter().collect()),
        }
    }

    /// Reads or generates the hair (validated), within the memory limit of `limits`.
    pub fn load(&self, limits: &Limits) -> Result<HairGeometry> {
        match self {
            HairSource::File(path) => {
                let ext = path
                    .extension()
                    .and_then(|e| e.to_str())
                    .map(str::to_ascii_lowercase);
                match ext.as_deref() {
                    Some("hair") => HairFile::new(path).read(),
                    Some("tfx") => TfxFile::new(path).read(),
                    Some("data") => UscFile::new(path).read(),
                    Some("ply") => PlyFile::new(path).read(),
                    Some("pbrt") => PbrtFile::new(path).read(limits),
                    Some("usda" | "usdc" | "usd") => UsdFile::new(path).read(limits),
                    _ => Err(format_error(
                        path,
                        "unknown hair file type: expected a .hair, .tfx, .data, .ply, .pbrt, \
                         .usda, .usdc or .usd extension",
                    )),
                }
            }
            HairSource::Hair(f) => f.read(),
            HairSource::Tfx(f) => f.read(),
            HairSource::Usc(f) => f.read(),
            HairSource::Ply(f) => f.read(),
            HairSource::Pbrt(f) => f.read(limits),
            HairSource::Procedural(p) => p.generate(limits),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_source_dispatches_on_the_extension() {
        let e = HairSource::File("x.obj".into())
            .load(&Limits::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.obj") && e.contains("extension"), "{e}");
        for missing in ["missing.PLY", "missing.pbrt"] {
            let e = HairSource::File(missing.into())
                .load(&Limits::default())
                .unwrap_err()
                .to_string();
            assert!(e.contains(missing) && !e.contains("extension"), "{e}");
        }
        let e = HairSource::File("missing.HAIR".into())
            .load(&Limits::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.HAIR"), "{e}");
        let mut s = HairSource::Tfx(TfxFile::new("a.tfx"));
        *s.path_mut().unwrap() = PathBuf::from("/abs/a.tfx");
        assert_eq!(s.path(), Some(Path::new("/abs/a.tfx")));
        assert!(HairSource::Procedural(Default::default()).path().is_none());
    }

    #[test]
    fn scene_file_syntax_deserialises() {
        let parse = |s: &str| ron::from_str::<HairSource>(s);
        assert_eq!(
            parse(r#"File("hair/straight.hair")"#).unwrap(),
            HairSource::File("hair/straight.hair".into())
        );
        assert_eq!(
            parse(r#"Hair((path: "s.hair"))"#).unwrap(),
            HairSource::Hair(HairFile::new("s.hair"))
        );
        assert_eq!(
            parse(r#"Hair((path: "s.hair", z_up: false))"#).unwrap(),
            HairSource::Hair(HairFile {
                path: "s.hair".into(),
                z_up: false
            })
        );
        assert_eq!(
            parse(r#"Tfx((path: "a.tfx", radius: 0.01))"#).unwrap(),
            HairSource::Tfx(TfxFile {
                path: "a.tfx".into(),
                radius: 0.01
            })
        );
        let p = parse(
            "Procedural((style: Curly(amplitude: 0.04, frequency: 6.0), strands: 3000, points_per_strand: 48))",
        )
        .unwrap();
        let HairSource::Procedural(p) = p else {
            panic!("{p:?}")
        };
        assert_eq!(
            p.style,
            crate::HairStyle::Curly {
                amplitude: 0.04,
                frequency: 6.0
            }
        );
        assert_eq!((p.strands, p.points_per_strand, p.seed), (3000, 48, 0));
        assert_eq!(
            parse("Procedural((style: Ball))").unwrap(),
            HairSource::Procedural(ProceduralHair {
                style: crate::HairStyle::Ball,
                ..Default::default()
            })
        );
        assert_eq!(
            parse(r#"Ply((path: "g.ply", radius: Some(0.001), z_up: true))"#).unwrap(),
            HairSource::Ply(PlyFile {
                radius: Some(0.001),
                z_up: true,
                ..PlyFile::new("g.ply")
            })
        );
        assert_eq!(
            parse(r#"Ply((path: "g.ply", points_per_strand: Some(100)))"#).unwrap(),
            HairSource::Ply(PlyFile {
                points_per_strand: Some(100),
                ..PlyFile::new("g.ply")
            })
        );
        assert_eq!(
            parse(r#"Pbrt((path: "h.pbrt"))"#).unwrap(),
            HairSource::Pbrt(PbrtFile::new("h.pbrt"))
        );
        // Typos are errors.
        assert!(parse(r#"Hair((path: "s.hair", zup: false))"#).is_err());
        assert!(parse(r#"Ply((path: "g.ply", width: 1))"#).is_err());
        assert!(parse("Procedural((strand: 5))").is_err());
    }
}
