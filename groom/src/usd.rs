//! Reader for the `BasisCurves` prims of a USD stage (`.usda` text, `.usdc` binary, or `.usd`
//! either), through the pure-Rust `openusd` crate, which composes the stage (sublayers,
//! references, variants) before tress reads it.
//!
//! **What is read.** Every `BasisCurves` prim the stage's default traversal reaches (active,
//! loaded, defined, not abstract), instance proxies included (so each instance of an
//! `instanceable` prim gives its own copy), becomes strands, one per entry of
//! `curveVertexCounts`, in traversal order: `type` `linear` or `cubic` (the schema's default) with `basis` `bezier`
//! (default), `bspline` or `catmullRom`; `wrap` `nonperiodic` only. `points` and `widths` (a
//! width is a diameter: radius = width / 2) with any interpolation — `constant`, `uniform` (one
//! per curve), `varying` (one per segment end; `faceVarying` counts as `varying`, as in USD) or
//! `vertex` (one per control point, the default, interpolated by the curve's basis) — and
//! `primvars:displayColor` the same way, as the hair's colours (what a hair object's
//! `variation: Some(file_colors: true)` takes) when every prim read has them. Values are the earliest time sample where an
//! attribute has samples, else its default.
//!
//! **Cubic curves to points.** Each segment is turned into an exact cubic Bézier (B-spline
//! and Catmull-Rom segments converted, one per four consecutive control points, as USD's
//! nonperiodic curves define them) and sampled on the curve as the pbrt reader does
//! ([`crate::pbrt`]): at 2^d + 1 parameters, d the fewest halvings that bring every chord
//! within a twentieth of the fiber width. Linear curves keep their points.
//!
//! **Transforms and units.** Each prim's points are mapped by its local-to-world transform
//! (the `xformOpOrder` of the prim and of its `Xform` ancestors, up to a
//! `!resetXformStack!`), then scaled by the stage's `metersPerUnit` (USD's fallback: 0.01,
//! centimetres) so that the groom is in metres, and turned Y-up when the stage's `upAxis` is
//! `Z`. Widths scale by the cube root of the transform's determinant, and by `metersPerUnit`.
//!
//! **Refused**, naming the file and the prim: `periodic` or `pinned` wrap, the `hermite` basis,
//! `curveVertexCounts` that do not add up to the points or are too short for the basis, widths
//! or colours whose count does not match their interpolation, missing `points` or `widths`, a
//! transform on an ancestor that is not an `Xform`, and a stage without `BasisCurves`.

use crate::error::{format_error, Result};
use crate::geometry::{HairAttribute, HairGeometry};
use crate::pbrt::{bezier, bezier_segments, refinement_depth};
use glam::{DMat3, DMat4, DVec3};
use openusd::schemas::geom::{BasisCurves, Curves, Gprim, PointBased, Xform, Xformable};
use openusd::{ar, sdf, usd};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use tress_core::limits::Limits;
use tress_core::math::Rgb;

/// Layers a stage may open in all (its root, sublayers, references, payloads): a groom needs a
/// handful, and each is parsed.
const MAX_LAYERS: usize = 10_000;
/// How deep prims may nest: the USD library composes a prim in time growing with its depth
/// (2,000 levels took over 20 s); grooms nest a few levels. A text layer's blocks are bounded
/// by the library itself (`openusd::usda::parser::MAX_BLOCK_DEPTH`).
const MAX_PRIM_DEPTH: usize = 256;
/// What each prim the traversal reaches is counted as against the memory limit: instance
/// proxies of nested instances multiply prims without end (5 KB of text grew to 1.6 GB).
/// 111,111 instanced one-curve prims take 1.5 GB (14 KB each) and 19 s, in time linear in the
/// prims, so 16 GiB, the default limit, allows about a million, in some three minutes.
const BYTES_PER_PRIM: f64 = 16384.0;
/// The longest stretch of a USD library message kept: messages may quote a whole token of the
/// file (a megabyte).
const MAX_MESSAGE_RUN: usize = 200;

/// A USD file whose `BasisCurves` to load.
#[derive(Clone, Debug, PartialEq)]
pub struct UsdFile {
    /// Path of the `.usda`, `.usdc` or `.usd` file, used as given.
    pub path: PathBuf,
}

/// How a primvar's values map onto a batch of curves.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Interpolation {
    Constant,
    Uniform,
    Varying,
    Vertex,
}

/// The cubic bases tress reads.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Basis {
    Bezier,
    BSpline,
    CatmullRom,
}

/// The value of `attr` (its earliest time sample, else its default) cast to `T`.
fn value<T: sdf::FromValueCast>(attr: &usd::Attribute) -> anyhow::Result<Option<T>> {
    match attr.get_at::<sdf::Value>(usd::TimeCode::EARLIEST)? {
        Some(v) => Ok(Some(v.cast::<T>()?)),
        None => Ok(None),
    }
}

/// `message` with every run of more than [`MAX_MESSAGE_RUN`] characters without a line break
/// cut to its start and end.
fn bounded(message: &str) -> String {
    message
        .split('\n')
        .map(|line| {
            let chars: Vec<char> = line.chars().collect();
            if chars.len() <= MAX_MESSAGE_RUN {
                return line.to_string();
            }
            let half = MAX_MESSAGE_RUN / 2;
            let head: String = chars[..half].iter().collect();
            let tail: String = chars[chars.len() - half..].iter().collect();
            format!("{head} … ({} characters) … {tail}", chars.len())
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// What the resolver has let the USD library read, and why it refused something.
#[derive(Default)]
struct Reads {
    bytes: u64,
    layers: usize,
    refused: Option<String>,
}

/// The USD library's file-system resolver, with every file it reads going through tress's own
/// checks first: regular files only, opened without blocking (a FIFO as a sublayer blocked in
/// `open`), and no more layers or bytes in all than the limits allow. The library sees the
/// bytes, never the files.
struct GuardedResolver {
    inner: ar::DefaultResolver,
    limit_bytes: u64,
    reads: Arc<Mutex<Reads>>,
}

impl GuardedResolver {
    /// An error for the library, kept to report as the reason (the library may word it as a
    /// layer that failed to load, or drop it).
    fn refuse(&self, message: String) -> std::io::Error {
        let mut reads = self.reads.lock().unwrap_or_else(|p| p.into_inner());
        reads.refused.get_or_insert_with(|| message.clone());
        std::io::Error::new(std::io::ErrorKind::InvalidData, message)
    }

    /// Counts a layer of `len` bytes, refused beyond the limits.
    fn admit(&self, name: &str, len: u64) -> std::io::Result<()> {
        let mut reads = self.reads.lock().unwrap_or_else(|p| p.into_inner());
        reads.layers += 1;
        reads.bytes = reads.bytes.saturating_add(len);
        let (layers, bytes) = (reads.layers, reads.bytes);
        drop(reads);
        if layers > MAX_LAYERS {
            return Err(self.refuse(format!(
                "{name}: more than {MAX_LAYERS} layers opened in all (layers that sublayer or \
                 reference each other many times over?)"
            )));
        }
        if bytes > self.limit_bytes {
            return Err(self.refuse(format!(
                "{name}: the layers read come to {bytes} bytes, over the memory limit ({} GiB); \
                 set {} to more GiB to read them",
                self.limit_bytes as f64 / (1u64 << 30) as f64,
                tress_core::limits::MEMORY_LIMIT_VAR
            )));
        }
        Ok(())
    }

    /// Entry `inner` of the `.usdz` package at `package`, read no further than the size it
    /// declares, which counts against the limits before anything is decompressed.
    fn read_packaged(&self, package: &Path, inner: &str) -> std::io::Result<Vec<u8>> {
        let file = tress_core::files::open_regular(package)?;
        let mut archive = zip::ZipArchive::new(file).map_err(std::io::Error::other)?;
        let entry = archive.by_name(inner).map_err(std::io::Error::other)?;
        let len = entry.size();
        self.admit(&format!("{}[{inner}]", package.display()), len)?;
        let mut bytes = Vec::new();
        entry.take(len).read_to_end(&mut bytes)?;
        Ok(bytes)
    }
}

impl ar::Resolver for GuardedResolver {
    fn create_identifier(&self, asset_path: &str, anchor: Option<&ar::ResolvedPath>) -> String {
        self.inner.create_identifier(asset_path, anchor)
    }

    fn resolve(&self, asset_path: &str) -> Option<ar::ResolvedPath> {
        // The library opens a package to look inside it while resolving: the file (the
        // package, for a path into one) must be a regular file before that.
        let package = ar::split_package_relative_path_outer(asset_path).map(|(p, _)| p);
        let file = self
            .inner
            .resolve(package.as_deref().unwrap_or(asset_path))?;
        // Named as the library identifies it: canonical, a link followed.
        if !std::fs::metadata(&*file).is_ok_and(|m| m.is_file()) {
            self.refuse(format!(
                "{}: not a regular file (a directory, device or pipe)",
                file.display()
            ));
            return None;
        }
        match package {
            Some(_) => self.inner.resolve(asset_path),
            None => Some(file),
        }
    }

    fn resolve_for_new_asset(&self, asset_path: &str) -> Option<ar::ResolvedPath> {
        self.inner.resolve_for_new_asset(asset_path)
    }

    fn open_asset(&self, resolved: &ar::ResolvedPath) -> std::io::Result<Box<dyn ar::Asset>> {
        let name = resolved.to_string_lossy();
        let bytes = match ar::split_package_relative_path_outer(&name) {
            Some((package, inner)) => self.read_packaged(Path::new(&package), &inner)?,
            None => {
                let file = tress_core::files::open_regular(resolved)
                    .map_err(|e| self.refuse(format!("{name}: {e}")))?;
                let len = file.metadata()?.len();
                self.admit(&name, len)?;
                let mut bytes = Vec::new();
                file.take(len).read_to_end(&mut bytes)?;
                bytes
            }
        };
        Ok(Box::new(std::io::Cursor::new(bytes)))
    }

    fn identity(&self) -> String {
        self.inner.identity()
    }
}

/// The message of a panic caught from the USD library.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "no message".into())
}

/// An openusd matrix (row vectors, rows stored in order) as a glam matrix acting on column
/// vectors: the same array read column by column is its transpose, which is what that takes.
fn to_dmat4(m: &openusd::gf::Matrix4d) -> DMat4 {
    DMat4::from_cols_array(&m.0)
}

impl UsdFile {
    /// The file at `path`.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        UsdFile { path: path.into() }
    }

    /// `f`, which calls the USD library, with a panic inside it turned into an error naming
    /// the file: a last resort for faults of the library that tress's bounds do not prevent.
    fn contained<T>(&self, f: impl FnOnce() -> Result<T>) -> Result<T> {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|panic| {
            Err(format_error(
                &self.path,
                format!(
                    "the USD library failed on it ({}): a fault of the library, please report it \
                     with the file",
                    bounded(&panic_message(&*panic))
                ),
            ))
        })
    }

    /// The stage composed, and the paths of the prims its default traversal reaches, within
    /// the limits: the library is given files only through [`GuardedResolver`], its
    /// traversal (through instance `proxies` or not) stops at [`MAX_PRIM_DEPTH`] or when the prims reached would pass the memory
    /// limit, and every composition error (a reference, payload, sublayer or prim that is
    /// missing or cannot be read) is an error.
    fn compose(&self, limits: &Limits, proxies: bool) -> Result<(usd::Stage, Vec<sdf::Path>)> {
        let path = &self.path;
        // The usual messages for a missing file or a folder, before openusd's own.
        let io = |source| crate::Error::Io {
            path: path.to_owned(),
            source,
        };
        tress_core::files::open_regular(path).map_err(io)?;
        let fail = |reason: String| format_error(path, reason);
        let name = path
            .to_str()
            .ok_or_else(|| fail("the path is not valid UTF-8".into()))?;
        let reads = Arc::new(Mutex::new(Reads::default()));
        let resolver = GuardedResolver {
            inner: ar::DefaultResolver::new(),
            limit_bytes: (limits.memory_gib * (1u64 << 30) as f64) as u64,
            reads: reads.clone(),
        };
        // What the resolver refused is the reason, however the library words its failure.
        let fail_with = |library: String| {
            let refused = reads
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .refused
                .clone();
            fail(refused.unwrap_or_else(|| bounded(&library)))
        };
        let stage = usd::Stage::builder()
            .resolver(resolver)
            .open(name)
            .map_err(|e| fail_with(format!("cannot read it as a USD stage: {e:#}")))?;
        let mut paths = Vec::new();
        let mut stopped = None;
        stage
            .traverse_while(
                usd::PrimPredicate::DEFAULT.with_instance_proxies(proxies),
                |p| {
                    let depth = p.as_str().matches('/').count();
                    if depth > MAX_PRIM_DEPTH {
                        stopped = Some(format!(
                            "<{}>: prims nested more than {MAX_PRIM_DEPTH} deep",
                            bounded(p.as_str())
                        ));
                        return false;
                    }
                    let need_gib = (paths.len() + 1) as f64 * BYTES_PER_PRIM / (1u64 << 30) as f64;
                    if let Err(reason) = limits.check_scene_memory(need_gib) {
                        stopped = Some(format!(
                            "{} prims and counting (instances of instances?) take {reason}",
                            paths.len() + 1
                        ));
                        return false;
                    }
                    paths.push(p.clone());
                    true
                },
            )
            .map_err(|e| fail_with(format!("traversing the stage: {e:#}")))?;
        if let Some(reason) = stopped {
            return Err(fail(reason));
        }
        // Composition errors are recorded as prims compose, during the traversal: a missing
        // reference or prim was dropped without a word when they were checked before it.
        if let Some(e) = stage.composition_errors().first() {
            return Err(fail_with(format!("composing the stage: {e}")));
        }
        Ok((stage, paths))
    }

    /// Every file [`read`](Self::read) reads: this one and the layers its composition loads
    /// (sublayers, references, payloads, each once; a layer inside a `.usdz` package is its
    /// package), so that caches can key on their contents.
    pub fn files(&self) -> Result<Vec<PathBuf>> {
        self.contained(|| {
            // The prims as authored: an instance composes its arcs (loading their layers)
            // without its prototype being walked once per instance, which nested instancing
            // multiplies (the reading itself is bounded by the memory limit it is given).
            let (stage, _) = self.compose(&Limits::default(), false)?;
            let mut files = vec![self.path.clone()];
            let root = std::fs::canonicalize(&self.path).ok();
            for id in stage.layer_identifiers() {
                let file = match ar::split_package_relative_path_outer(&id) {
                    Some((package, _)) => PathBuf::from(package),
                    None => PathBuf::from(id),
                };
                // Session and anonymous layers are not files; the root is listed as given.
                let is_root = root.is_some() && std::fs::canonicalize(&file).ok() == root;
                if file.is_file() && !is_root && !files.contains(&file) {
                    files.push(file);
                }
            }
            Ok(files)
        })
    }

    /// Reads the stage's `BasisCurves` and validates them, within the memory limit of
    /// `limits` (the layers read, the prims reached and the points made).
    pub fn read(&self, limits: &Limits) -> Result<HairGeometry> {
        self.contained(|| self.read_contained(limits))
    }

    fn read_contained(&self, limits: &Limits) -> Result<HairGeometry> {
        let path = &self.path;
        let fail = |reason: String| format_error(path, reason);
        let (stage, paths) = self.compose(limits, true)?;
        let metadata = |field: &str| {
            stage
                .stage_metadata(field)
                .map_err(|e| fail(format!("{field}: {e:#}")))
        };
        let meters_per_unit = match metadata("metersPerUnit")? {
            None => 0.01,
            Some(v) => v
                .cast::<f64>()
                .ok()
                .filter(|m| m.is_finite() && *m > 0.0)
                .ok_or_else(|| fail("metersPerUnit must be a positive number".into()))?,
        };
        let z_up = match metadata("upAxis")? {
            None => false,
            Some(v) => match v.cast::<String>().as_deref() {
                Ok("Y") => false,
                Ok("Z") => true,
                _ => return Err(fail("upAxis must be \"Y\" or \"Z\"".into())),
            },
        };
        let mut reader = Reader {
            hair: HairGeometry::empty(path.display().to_string()),
            colors: Colors::None,
            normals: Some(Vec::new()),
            scale: DMat4::from_scale(DVec3::splat(meters_per_unit)),
            limits: *limits,
        };
        let mut others = 0;
        for p in &paths {
            let at = |e: anyhow::Error| fail(bounded(&format!("<{}>: {e:#}", p.as_str())));
            match BasisCurves::get(&stage, p.clone()).map_err(at)? {
                Some(curves) => reader.add(&stage, &curves).map_err(at)?,
                None => others += 1,
            }
        }
        if reader.hair.strand_count() == 0 {
            return Err(fail(format!(
                "no BasisCurves with curves on the stage ({others} other prims)"
            )));
        }
        let mut hair = reader.hair;
        hair.colors = match reader.colors {
            Colors::None => None,
            Colors::Incomplete => {
                tracing::warn!(
                    "{}: some BasisCurves have primvars:displayColor and some not: the colours \
                     are not used",
                    path.display()
                );
                None
            }
            Colors::PerStrand(c) => Some(HairAttribute::PerStrand(c)),
            Colors::PerPoint(c) => Some(HairAttribute::PerPoint(c)),
        };
        hair.orientations = reader
            .normals
            .filter(|n| !n.is_empty())
            .map(HairAttribute::PerPoint);
        if z_up {
            hair.z_up_to_y_up();
        }
        hair.validate()?;
        Ok(hair)
    }
}

/// The colours read so far: none, one per strand or per point for every strand so far, or
/// some strands with and some without (then none are used: a hair's colours are all or
/// nothing). Prims with `displayColor` per curve and per vertex share one array per point.
enum Colors {
    None,
    PerStrand(Vec<Rgb>),
    PerPoint(Vec<Rgb>),
    Incomplete,
}

struct Reader {
    hair: HairGeometry,
    colors: Colors,
    /// `normals` (the fibers' orientation) per point so far; `None` once a prim lacks them,
    /// and then none are used, like colours.
    normals: Option<Vec<tress_core::math::Vec3>>,
    /// `metersPerUnit` as a transform, applied after every prim's own.
    scale: DMat4,
    /// The memory limit the points made are checked against.
    limits: Limits,
}

/// A primvar's values (widths, or colours as vectors) with their interpolation.
struct Primvar {
    values: Vec<DVec3>,
    interpolation: Interpolation,
}

impl Primvar {
    /// `attr`'s values and its `interpolation` metadata (default `vertex`); `None` when the
    /// attribute has no value.
    fn read(
        attr: &usd::Attribute,
        values: impl FnOnce(&usd::Attribute) -> anyhow::Result<Option<Vec<DVec3>>>,
    ) -> anyhow::Result<Option<Primvar>> {
        let Some(values) = values(attr)? else {
            return Ok(None);
        };
        let interpolation = match attr
            .get_metadata::<sdf::Value>("interpolation")?
            .map(|v| v.cast::<String>())
            .transpose()?
            .as_deref()
        {
            None | Some("vertex") => Interpolation::Vertex,
            Some("constant") => Interpolation::Constant,
            Some("uniform") => Interpolation::Uniform,
            Some("varying") | Some("faceVarying") => Interpolation::Varying,
            Some(other) => anyhow::bail!("{}: unknown interpolation \"{other}\"", attr_name(attr)),
        };
        Ok(Some(Primvar {
            values,
            interpolation,
        }))
    }

    /// The values this primvar needs, for curves of `counts` control points and `segments`
    /// segments each.
    fn expected(&self, counts: &[usize], segments: &[usize]) -> usize {
        match self.interpolation {
            Interpolation::Constant => 1,
            Interpolation::Uniform => counts.len(),
            Interpolation::Varying => segments.iter().map(|s| s + 1).sum(),
            Interpolation::Vertex => counts.iter().sum(),
        }
    }
}

fn attr_name(attr: &usd::Attribute) -> String {
    attr.path()
        .as_str()
        .rsplit('.')
        .next()
        .unwrap_or_default()
        .to_string()
}

/// A `BasisCurves` prim's curves: their kind, points and how the points split into curves.
struct CurveLayout {
    /// Cubic curves (through `basis`), else linear.
    cubic: bool,
    basis: Basis,
    points: Vec<DVec3>,
    /// Points per curve.
    counts: Vec<usize>,
    /// Each curve's first point.
    starts: Vec<usize>,
    /// Segments per curve: Béziers for cubic curves, chords for linear ones.
    segments: Vec<usize>,
}

impl CurveLayout {
    /// The prim's `type`, `basis`, `wrap`, `curveVertexCounts` and `points`, checked against
    /// each other.
    fn read(curves: &BasisCurves) -> anyhow::Result<Self> {
        let token = |attr: usd::Attribute, default: &str| -> anyhow::Result<String> {
            Ok(value::<String>(&attr)?.unwrap_or_else(|| default.into()))
        };
        let cubic = match token(curves.type_attr(), "cubic")?.as_str() {
            "linear" => false,
            "cubic" => true,
            other => anyhow::bail!("type \"{other}\": expected \"linear\" or \"cubic\""),
        };
        let basis = match token(curves.basis_attr(), "bezier")?.as_str() {
            "bezier" => Basis::Bezier,
            "bspline" => Basis::BSpline,
            "catmullRom" => Basis::CatmullRom,
            other => anyhow::bail!(
                "basis \"{other}\": only \"bezier\", \"bspline\" and \"catmullRom\" are supported"
            ),
        };
        match token(curves.wrap_attr(), "nonperiodic")?.as_str() {
            "nonperiodic" => {}
            other => anyhow::bail!("wrap \"{other}\": only \"nonperiodic\" curves are supported"),
        }
        let counts = match curves
            .curve_vertex_counts_attr()
            .get_at::<sdf::Value>(usd::TimeCode::EARLIEST)?
        {
            None => Vec::new(),
            Some(sdf::Value::IntVec(c)) => c,
            Some(_) => anyhow::bail!("curveVertexCounts: not an int[]"),
        };
        let points: Vec<DVec3> = value::<Vec<openusd::gf::Vec3f>>(&curves.points_attr())?
            .ok_or_else(|| anyhow::anyhow!("no points"))?
            .iter()
            .map(|p| DVec3::new(p.x as f64, p.y as f64, p.z as f64))
            .collect();
        let counts: Vec<usize> = counts
            .iter()
            .map(|&c| usize::try_from(c))
            .collect::<Result<_, _>>()
            .map_err(|_| anyhow::anyhow!("curveVertexCounts: a count is negative"))?;
        let total: usize = counts.iter().sum();
        if total != points.len() {
            anyhow::bail!(
                "curveVertexCounts add up to {total} points, but there are {}",
                points.len()
            );
        }
        let mut layout = CurveLayout {
            cubic,
            basis,
            points,
            starts: Vec::with_capacity(counts.len()),
            segments: Vec::with_capacity(counts.len()),
            counts,
        };
        let mut start = 0;
        for (i, &n) in layout.counts.iter().enumerate() {
            let s = if cubic {
                layout
                    .as_segments(&layout.points[start..start + n])
                    .map_err(|e| anyhow::anyhow!("curve {i}: {e}"))?
                    .len()
            } else if n >= 2 {
                n - 1
            } else {
                anyhow::bail!("curve {i}: {n} points: a linear curve needs at least 2");
            };
            layout.starts.push(start);
            layout.segments.push(s);
            start += n;
        }
        Ok(layout)
    }

    /// The Bézier segments of one cubic curve's control points `cp` through the basis.
    fn as_segments(&self, cp: &[DVec3]) -> Result<Vec<[DVec3; 4]>, String> {
        match self.basis {
            Basis::Bezier => bezier_segments(cp, 3.0, false),
            Basis::BSpline => bezier_segments(cp, 3.0, true),
            Basis::CatmullRom => catmull_rom_segments(cp),
        }
    }
}

/// A prim's primvars, each checked to have as many values as its interpolation needs.
struct CurvePrimvars {
    /// Widths, in the vectors' x.
    widths: Primvar,
    colors: Option<Primvar>,
    normals: Option<Primvar>,
}

impl CurvePrimvars {
    /// The `widths`, `primvars:displayColor` and `normals` of `curves`, laid out as `layout`.
    fn read(curves: &BasisCurves, layout: &CurveLayout) -> anyhow::Result<Self> {
        let vectors = |a: &usd::Attribute| -> anyhow::Result<Option<Vec<DVec3>>> {
            Ok(value::<Vec<openusd::gf::Vec3f>>(a)?.map(|c| {
                c.iter()
                    .map(|c| DVec3::new(c.x as f64, c.y as f64, c.z as f64))
                    .collect()
            }))
        };
        let widths = Primvar::read(&curves.widths_attr(), |a| {
            Ok(value::<Vec<f32>>(a)?
                .map(|w| w.iter().map(|&w| DVec3::new(w as f64, 0.0, 0.0)).collect()))
        })?
        .ok_or_else(|| anyhow::anyhow!("no widths"))?;
        let primvars = CurvePrimvars {
            widths,
            colors: Primvar::read(&curves.display_color_attr(), vectors)?,
            normals: Primvar::read(&curves.normals_attr(), vectors)?,
        };
        for (what, primvar) in [
            ("widths", Some(&primvars.widths)),
            ("primvars:displayColor", primvars.colors.as_ref()),
            ("normals", primvars.normals.as_ref()),
        ] {
            let Some(p) = primvar else { continue };
            let expected = p.expected(&layout.counts, &layout.segments);
            if p.values.len() != expected {
                anyhow::bail!(
                    "{what}: {} values, but {:?} interpolation over these curves needs {expected}",
                    p.values.len(),
                    p.interpolation
                );
            }
        }
        Ok(primvars)
    }
}

/// Where a prim's curves go: its transform, and what it does to widths and normals.
struct Placement {
    transform: DMat4,
    /// Widths scale by the cube root of the transform's determinant.
    width_scale: f64,
    /// Normals transform by the inverse transpose.
    normal_matrix: DMat3,
}

impl Reader {
    /// Adds the strands of one `BasisCurves` prim.
    fn add(&mut self, stage: &usd::Stage, curves: &BasisCurves) -> anyhow::Result<()> {
        let layout = CurveLayout::read(curves)?;
        let primvars = CurvePrimvars::read(curves, &layout)?;
        let transform = self.scale * world_transform(stage, curves)?;
        let placement = Placement {
            transform,
            width_scale: DMat3::from_mat4(transform).determinant().abs().cbrt(),
            normal_matrix: DMat3::from_mat4(transform).inverse().transpose(),
        };
        let mut varying_start = 0;
        for i in 0..layout.counts.len() {
            self.add_curve(&layout, &primvars, &placement, i, varying_start)?;
            varying_start += layout.segments[i] + 1;
        }
        Ok(())
    }

    /// Adds curve `i` of `layout` as one strand; its `varying` primvar values start at
    /// `varying_start`.
    fn add_curve(
        &mut self,
        layout: &CurveLayout,
        primvars: &CurvePrimvars,
        placement: &Placement,
        i: usize,
        varying_start: usize,
    ) -> anyhow::Result<()> {
        let (cubic, start, n) = (layout.cubic, layout.starts[i], layout.counts[i]);
        let cp = &layout.points[start..start + n];
        let Placement {
            transform,
            width_scale,
            normal_matrix,
        } = *placement;
        let CurvePrimvars {
            widths,
            colors,
            normals,
        } = primvars;
        // A primvar's value at parameter u of segment s of this curve.
        let at = |p: &Primvar, seg: &[[DVec3; 4]], s: usize, u: f64| -> DVec3 {
            match p.interpolation {
                Interpolation::Constant => p.values[0],
                Interpolation::Uniform => p.values[i],
                Interpolation::Varying => {
                    let v = &p.values[varying_start..];
                    v[s].lerp(v[s + 1], u)
                }
                Interpolation::Vertex if cubic => bezier(&seg[s], u),
                Interpolation::Vertex => p.values[start + s].lerp(p.values[start + s + 1], u),
            }
        };
        // The Béziers of the vertex primvars, through the same basis as the points.
        let vertex_segments = |p: &Primvar| -> Vec<[DVec3; 4]> {
            if cubic && p.interpolation == Interpolation::Vertex {
                layout
                    .as_segments(&p.values[start..start + n])
                    .expect("checked with the points")
            } else {
                Vec::new()
            }
        };
        let width_segments = vertex_segments(widths);
        let color_segments = colors.as_ref().map(vertex_segments).unwrap_or_default();
        let normal_segments = normals.as_ref().map(vertex_segments).unwrap_or_default();
        // The (segment, u) each point is made from, for the normals there.
        let mut params = Vec::new();
        let push = |hair: &mut HairGeometry, point: DVec3, s: usize, u: f64| -> Option<Rgb> {
            hair.points.push(point.as_vec3());
            let width = at(widths, &width_segments, s, u).x;
            hair.radii.push((0.5 * width * width_scale) as f32);
            colors
                .as_ref()
                .map(|c| -> Rgb { at(c, &color_segments, s, u).as_vec3() })
        };
        let mut point_colors = Vec::new();
        if cubic {
            let beziers = layout.as_segments(cp).expect("checked above");
            for (s, b) in beziers.iter().enumerate() {
                let b = b.map(|p| transform.transform_point3(p));
                let w0 = at(widths, &width_segments, s, 0.0).x;
                let w1 = at(widths, &width_segments, s, 1.0).x;
                let pieces = 1u32 << refinement_depth(&b, w0.max(w1) * width_scale);
                self.check_points(pieces as usize)?;
                if s == 0 {
                    point_colors.extend(push(&mut self.hair, b[0], 0, 0.0));
                    params.push((0, 0.0));
                }
                for k in 1..=pieces {
                    let u = k as f64 / pieces as f64;
                    point_colors.extend(push(&mut self.hair, bezier(&b, u), s, u));
                    params.push((s, u));
                }
            }
        } else {
            self.check_points(n)?;
            for (k, p) in cp.iter().enumerate() {
                let (s, u) = if k + 1 < n { (k, 0.0) } else { (k - 1, 1.0) };
                let color = push(&mut self.hair, transform.transform_point3(*p), s, u);
                point_colors.extend(color);
                params.push((s, u));
            }
        }
        self.hair.strand_offsets.push(self.hair.points.len() as u32);
        // The normals at the points just added, at the (segment, u) each was made from.
        match (&mut self.normals, normals) {
            (Some(all), Some(p)) => all.extend((params.iter()).map(|&(s, u)| {
                // Only the direction matters (models project it across the fiber).
                (normal_matrix * at(p, &normal_segments, s, u))
                    .normalize_or_zero()
                    .as_vec3()
            })),
            (normals, _) => *normals = None,
        }
        self.add_colors(colors.as_ref(), point_colors);
        Ok(())
    }

    /// Refuses `more` points when the hair would then pass the memory limit.
    fn check_points(&self, more: usize) -> anyhow::Result<()> {
        let points = (self.hair.points.len() + more) as f64;
        self.limits
            .check_scene_memory(points * crate::geometry::BYTES_PER_POINT / (1u64 << 30) as f64)
            .map_err(|reason| {
                anyhow::anyhow!("the curves up to here make {points:.3e} points: {reason}")
            })
    }

    /// Records the colours of the strand just added: one per point, or none when its prim has
    /// no `displayColor`.
    fn add_colors(&mut self, primvar: Option<&Primvar>, colors: Vec<Rgb>) {
        let strands_before = self.hair.strand_count() - 1;
        let per_strand = matches!(
            primvar.map(|p| p.interpolation),
            Some(Interpolation::Constant | Interpolation::Uniform)
        );
        match (&mut self.colors, primvar) {
            (Colors::None, None) | (Colors::Incomplete, _) => {}
            (Colors::None, Some(_)) if strands_before > 0 => self.colors = Colors::Incomplete,
            (_, None) => self.colors = Colors::Incomplete,
            (Colors::None, Some(_)) if per_strand => {
                self.colors = Colors::PerStrand(vec![colors[0]])
            }
            (Colors::None, Some(_)) => self.colors = Colors::PerPoint(colors),
            (Colors::PerStrand(c), Some(_)) if per_strand => c.push(colors[0]),
            (Colors::PerPoint(c), Some(_)) => c.extend(colors),
            (Colors::PerStrand(c), Some(_)) => {
                // Per-strand colours so far, now per-point ones: spread the former over their
                // strands' points.
                let offsets = &self.hair.strand_offsets;
                let mut all = Vec::with_capacity(offsets[offsets.len() - 1] as usize);
                for (s, color) in c.iter().enumerate() {
                    all.extend(std::iter::repeat_n(
                        *color,
                        (offsets[s + 1] - offsets[s]) as usize,
                    ));
                }
                all.extend(colors);
                self.colors = Colors::PerPoint(all);
            }
        }
    }
}

/// The Bézier segments of a nonperiodic Catmull-Rom curve: one per four consecutive control
/// points, running from the second to the third.
fn catmull_rom_segments(cp: &[DVec3]) -> Result<Vec<[DVec3; 4]>, String> {
    if cp.len() < 4 {
        return Err(format!(
            "{} control points: a Catmull-Rom curve needs at least 4",
            cp.len()
        ));
    }
    Ok(cp
        .windows(4)
        .map(|w| {
            [
                w[1],
                w[1] + (w[2] - w[0]) / 6.0,
                w[2] - (w[3] - w[1]) / 6.0,
                w[2],
            ]
        })
        .collect())
}

/// `curves`' local-to-world transform: its own `xformOpOrder` and its ancestors', up to a
/// `!resetXformStack!`. Only `Xform` ancestors may carry transforms.
fn world_transform(stage: &usd::Stage, curves: &BasisCurves) -> anyhow::Result<DMat4> {
    check_xform_ops(stage, curves.path(), false)?;
    let mut m = to_dmat4(&curves.local_to_parent_transform(usd::TimeCode::EARLIEST)?);
    if curves.resets_xform_stack()? {
        return Ok(m);
    }
    let mut path = curves.path().parent();
    while let Some(p) = path {
        if p.as_str() == "/" || p.as_str().is_empty() {
            break;
        }
        match Xform::get(stage, p.clone())? {
            Some(x) => {
                check_xform_ops(stage, &p, true)?;
                m = to_dmat4(&x.local_to_parent_transform(usd::TimeCode::EARLIEST)?) * m;
                if x.resets_xform_stack()? {
                    break;
                }
            }
            None => {
                let order = stage.prim(p.clone()).attribute("xformOpOrder");
                if order.get::<sdf::Value>()?.is_some() {
                    anyhow::bail!(
                        "the ancestor <{}> has a transform but is not an Xform: only Xform \
                         ancestors' transforms are read",
                        p.as_str()
                    );
                }
            }
        }
        path = p.parent();
    }
    Ok(m)
}

/// Refuses an `xformOpOrder` on `prim` (an `ancestor` of the curves read, or the curves) that
/// names an op the prim does not have: the library skips it, and the prim lands elsewhere than
/// its file says.
fn check_xform_ops(stage: &usd::Stage, prim: &sdf::Path, ancestor: bool) -> anyhow::Result<()> {
    let order = stage.prim(prim.clone()).attribute("xformOpOrder");
    let ops = match value::<Vec<String>>(&order)? {
        Some(ops) => ops,
        None => return Ok(()),
    };
    for op in &ops {
        if op == "!resetXformStack!" {
            continue;
        }
        let name = op.strip_prefix("!invert!").unwrap_or(op);
        let attr = stage.prim(prim.clone()).attribute(name);
        let authored = attr.get::<sdf::Value>()?.is_some() || attr.num_time_samples()? > 0;
        if !authored {
            let whose = if ancestor {
                format!(" of the ancestor <{}>", prim.as_str())
            } else {
                String::new()
            };
            anyhow::bail!(
                "xformOpOrder{whose} names \"{}\", which is not authored there",
                bounded(op)
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::HairSource;
    use std::path::Path;
    use tress_core::math::Vec3;

    /// A groom that `tests/usd_grooms.py` wrote with Pixar's USD library.
    fn groom(name: &str) -> HairGeometry {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data")
            .join(name);
        HairSource::File(path)
            .load(&tress_core::limits::Limits::default())
            .unwrap_or_else(|e| panic!("{e}"))
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() <= 1e-6 * (1.0 + b.length())
    }

    fn assert_points(hair: &HairGeometry, expect: &[Vec3]) {
        assert_eq!(hair.points.len(), expect.len(), "{:?}", hair.points);
        for (i, (p, e)) in hair.points.iter().zip(expect).enumerate() {
            assert!(close(*p, *e), "point {i}: {p}, expected {e}");
        }
    }

    fn assert_near(values: &[f32], expect: &[f32]) {
        assert_eq!(values.len(), expect.len(), "{values:?}");
        for (v, e) in values.iter().zip(expect) {
            assert!(
                (v - e).abs() <= 1e-6 * e.abs().max(1e-3),
                "{values:?} vs {expect:?}"
            );
        }
    }

    #[test]
    fn linear_curves_take_the_transforms_widths_and_colours_per_curve() {
        for file in ["usd_linear.usda", "usd_linear.usdc"] {
            let g = groom(file);
            assert_eq!(g.strand_offsets, vec![0, 3, 5], "{file}");
            // Scaled by 2 on the curves, then translated by (1, 2, 3) on their Xform.
            let v = Vec3::new;
            assert_points(
                &g,
                &[
                    v(1.0, 2.0, 3.0),
                    v(1.0, 4.0, 3.0),
                    v(1.0, 6.0, 4.0),
                    v(3.0, 2.0, 3.0),
                    v(3.0, 4.0, 3.0),
                ],
            );
            // Widths are diameters, doubled by the scale: the radii are the widths.
            assert_near(&g.radii, &[0.1, 0.08, 0.06, 0.2, 0.1]);
            let Some(HairAttribute::PerStrand(colors)) = &g.colors else {
                panic!("{file}: {:?}", g.colors)
            };
            assert_eq!(colors, &vec![v(0.5, 0.3, 0.1), v(0.2, 0.4, 0.6)]);
        }
    }

    #[test]
    fn cubic_bases_are_sampled_on_the_curve_in_metres_y_up() {
        let (text, binary) = (groom("usd_cubic.usda"), groom("usd_cubic.usdc"));
        assert_eq!(
            text,
            HairGeometry {
                name: text.name.clone(),
                ..binary
            }
        );
        let g = text;
        // Z up and 0.01 m per unit: (x, y, z) → 0.01·(x, z, −y).
        let world = |p: DVec3| Vec3::new(0.01 * p.x as f32, 0.01 * p.z as f32, -0.01 * p.y as f32);
        assert_eq!(g.strand_count(), 3);
        // The hook: refined, every point on the Bézier of its control points.
        let hook = &g.points[g.strand(0)];
        let pieces = hook.len() - 1;
        assert!(pieces.is_power_of_two() && pieces >= 4, "{pieces}");
        let cp = [
            DVec3::ZERO,
            DVec3::new(0.0, 0.0, 3.0),
            DVec3::new(2.0, 0.0, 3.0),
            DVec3::new(2.0, 0.0, 0.5),
        ];
        for (k, p) in hook.iter().enumerate() {
            let u = k as f64 / pieces as f64;
            let s = 1.0 - u;
            let b = s * s * s * cp[0]
                + 3.0 * s * s * u * cp[1]
                + 3.0 * s * u * u * cp[2]
                + u * u * u * cp[3];
            assert!(close(*p, world(b)), "hook point {k}: {p} vs {}", world(b));
        }
        assert!(g.radii[g.strand(0)]
            .iter()
            .all(|&r| (r - 0.00025).abs() < 1e-9));
        // The B-spline spans (p0 + 4p1 + p2)/6 … (p2 + 4p3 + p4)/6: z 1, 2, 3, with its vertex
        // widths and colours weighted the same way.
        let bspline = g.strand(1);
        let v = Vec3::new;
        assert_points(
            &HairGeometry {
                points: g.points[bspline.clone()].to_vec(),
                ..HairGeometry::empty("b")
            },
            &[v(0.05, 0.01, 0.0), v(0.05, 0.02, 0.0), v(0.05, 0.03, 0.0)],
        );
        assert_near(&g.radii[bspline.clone()], &[0.002, 0.0025, 0.002]);
        let Some(HairAttribute::PerPoint(colors)) = &g.colors else {
            panic!("{:?}", g.colors)
        };
        for (c, e) in colors[bspline].iter().zip([0.4, 0.6, 0.8]) {
            assert!(close(*c, Vec3::splat(e)), "{c} vs {e}");
        }
        // The Catmull-Rom curve runs from its second point to its third, varying widths and
        // vertex colours from the second colour to the third.
        let catmull = g.strand(2);
        assert!(close(g.points[catmull.start], v(0.11, 0.0, 0.0)));
        assert!(close(g.points[catmull.end - 1], v(0.12, 0.0, 0.0)));
        assert_eq!(catmull.len(), 2);
        assert_near(&g.radii[catmull.clone()], &[0.001, 0.002]);
        assert!(close(colors[catmull.start], v(0.5, 0.5, 0.5)));
        assert!(close(colors[catmull.end - 1], v(0.3, 0.2, 0.1)));
        assert_eq!(colors.len(), g.points.len());
    }

    #[test]
    fn every_instance_of_an_instanceable_prim_gives_its_strands() {
        for file in ["usd_instanced.usda", "usd_instanced.usdc"] {
            let g = groom(file);
            // The class prim itself is abstract: only its two instances, moved by theirs.
            assert_eq!(g.strand_offsets, vec![0, 2, 4], "{file}");
            let v = Vec3::new;
            assert_points(
                &g,
                &[
                    v(5.0, 0.0, 0.0),
                    v(5.0, 1.0, 0.0),
                    v(10.0, 0.0, 0.0),
                    v(10.0, 1.0, 0.0),
                ],
            );
        }
    }

    /// The error reading `text` as `name` in a temporary folder.
    fn error(name: &str, text: &str) -> String {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        match UsdFile::new(&path).read(&Limits::default()) {
            Ok(g) => panic!("{text}: read {} strands", g.strand_count()),
            Err(e) => e.to_string(),
        }
    }

    /// `normals` become the strands' orientations, per point and unit, through the prim's
    /// transform (here `metersPerUnit` 0.01) and the Z-up turn; a stage where one prim lacks them has none.
    #[test]
    fn normals_are_the_fibers_orientation() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("normals.usda");
        let prim = |name: &str, normals: &str| {
            format!(
                "def BasisCurves \"{name}\"\n{{\n    uniform token type = \"linear\"\n    \
                 int[] curveVertexCounts = [3]\n    \
                 point3f[] points = [(0, 0, 0), (0, 0, 1), (0, 0, 2)]\n    \
                 float[] widths = [0.1, 0.1, 0.1]\n{normals}}}\n"
            )
        };
        let normals = "    normal3f[] normals = [(1, 0, 0), (0, 1, 0), (1, 1, 0)]\n";
        let text = format!(
            "#usda 1.0\n(\n    upAxis = \"Z\"\n)\n{}",
            prim("A", normals)
        );
        std::fs::write(&path, text).unwrap();
        let hair = UsdFile::new(&path).read(&Limits::default()).unwrap();
        let Some(HairAttribute::PerPoint(o)) = &hair.orientations else {
            panic!("{:?}", hair.orientations)
        };
        // Z-up (x, y, z) → Y-up (x, z, −y).
        let expect = [
            Vec3::X,
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, -1.0).normalize(),
        ];
        for (v, e) in o.iter().zip(expect) {
            assert!(close(*v, e), "{v} vs {e}");
        }
        let text = format!("#usda 1.0\n{}{}", prim("A", normals), prim("B", ""));
        std::fs::write(&path, text).unwrap();
        assert!(UsdFile::new(&path)
            .read(&Limits::default())
            .unwrap()
            .orientations
            .is_none());
    }

    const CURVES: &str = r#"#usda 1.0
def BasisCurves "Hair"
{
    uniform token type = "cubic"
    uniform token basis = "bezier"
    uniform token wrap = "nonperiodic"
    int[] curveVertexCounts = [4]
    point3f[] points = [(0, 0, 0), (0, 1, 0), (0, 2, 0), (0, 3, 0)]
    float[] widths = [0.1, 0.1, 0.1, 0.1]
}
"#;

    #[test]
    fn unsupported_or_inconsistent_curves_are_refused_naming_the_file_and_prim() {
        for (from, to, expect) in [
            (
                "\"nonperiodic\"",
                "\"periodic\"",
                "</Hair>: wrap \"periodic\"",
            ),
            ("\"bezier\"", "\"hermite\"", "</Hair>: basis \"hermite\""),
            ("\"cubic\"", "\"quintic\"", "</Hair>: type \"quintic\""),
            (
                "[4]",
                "[5]",
                "</Hair>: curveVertexCounts add up to 5 points, but there are 4",
            ),
            ("[4]", "[2, 2]", "</Hair>: curve 0: 2 control points"),
            (
                "[0.1, 0.1, 0.1, 0.1]",
                "[0.1, 0.1, 0.1]",
                "</Hair>: widths: 3 values",
            ),
            (
                "float[] widths = [0.1, 0.1, 0.1, 0.1]",
                "",
                "</Hair>: no widths",
            ),
            ("point3f[] points", "point3f[] pts", "</Hair>: no points"),
            (
                "def BasisCurves",
                "def Mesh",
                "no BasisCurves with curves on the stage (1 other",
            ),
        ] {
            assert!(CURVES.contains(from), "{from}");
            let e = error("groom.usda", &CURVES.replace(from, to));
            assert!(
                e.contains("groom.usda") && e.contains(expect),
                "{expect}: {e}"
            );
        }
        let nested = CURVES.replace(
            "def BasisCurves \"Hair\"\n{",
            "def Scope \"S\"\n{\n    double3 xformOp:translate = (1, 0, 0)\n    uniform token[] \
             xformOpOrder = [\"xformOp:translate\"]\n    def BasisCurves \"Hair\"\n    {",
        ) + "}\n";
        let e = error("groom.usda", &nested);
        assert!(e.contains("</S>") && e.contains("not an Xform"), "{e}");
        // Colours on some prims only: none are used, the strands are read.
        let two = CURVES.to_string()
            + &CURVES
                .replace("#usda 1.0", "")
                .replace("\"Hair\"", "\"Coloured\"")
                .replace(
                    "float[] widths",
                    "color3f[] primvars:displayColor = [(1, 0, 0)] (interpolation = \"constant\")\n    float[] widths",
                );
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("two.usda"), &two).unwrap();
        let g = UsdFile::new(dir.path().join("two.usda"))
            .read(&Limits::default())
            .unwrap();
        assert_eq!((g.strand_count(), g.colors), (2, None));
        std::fs::write(
            dir.path().join("one.usda"),
            two.replace("def BasisCurves \"Hair\"", "over \"Hair\""),
        )
        .unwrap();
        let g = UsdFile::new(dir.path().join("one.usda"))
            .read(&Limits::default())
            .unwrap();
        assert_eq!(
            g.colors,
            Some(HairAttribute::PerStrand(vec![Vec3::new(1.0, 0.0, 0.0)]))
        );
        let e = error("groom.usdc", "not a USD file");
        assert!(e.contains("groom.usdc") && e.contains("USD"), "{e}");
        let e = HairSource::File(PathBuf::from("/nowhere/groom.usd"))
            .load(&tress_core::limits::Limits::default())
            .unwrap_err();
        assert!(e.to_string().contains("/nowhere/groom.usd"), "{e}");
    }

    /// Reads `text` as `groom.usda` in `dir` with `limits`.
    fn read_in(dir: &Path, text: &str, limits: &Limits) -> Result<HairGeometry> {
        let path = dir.join("groom.usda");
        std::fs::write(&path, text).unwrap();
        UsdFile::new(&path).read(limits)
    }

    const LINEAR: &str = r#"#usda 1.0
def BasisCurves "Hair"
{
    uniform token type = "linear"
    int[] curveVertexCounts = [3]
    point3f[] points = [(0, 0, 0), (0, 1, 0), (0, 2, 0)]
    float[] widths = [0.1] (interpolation = "constant")
    color3f[] primvars:displayColor = [(0.5, 0.3, 0.1)] (interpolation = "constant")
}
"#;

    #[test]
    fn short_tuples_are_refused_where_they_stand() {
        let dir = tempfile::tempdir().unwrap();
        for (from, to, expect) in [
            ("(0, 2, 0)]", "(0, 2)]", "line 6, column "),
            ("(0, 2, 0)]", "()]", "tuple has 0 elements, expected 3"),
            ("[(0.5, 0.3, 0.1)]", "[(0.5, 0.3)]", "line 8"),
            ("(0, 2, 0)]", "(0, 2, 0, 1)]", "too many elements"),
        ] {
            let e = read_in(dir.path(), &LINEAR.replace(from, to), &Limits::default())
                .unwrap_err()
                .to_string();
            assert!(e.contains("groom.usda") && e.contains(expect), "{to}: {e}");
        }
    }

    #[test]
    fn deep_nesting_and_long_tokens_are_refused_quickly_with_short_messages() {
        let dir = tempfile::tempdir().unwrap();
        let deep = |n: usize, open: &str, close: &str| {
            format!("#usda 1.0\n{}{}", open.repeat(n), close.repeat(n))
        };
        let started = std::time::Instant::now();
        for text in [
            deep(6000, "def Xform \"a\" {\n", "}\n"),
            deep(300, "def Xform \"a\" {\n", "}\n"),
            format!(
                "#usda 1.0\ndef \"A\" (customData = {}1{})\n{{\n}}\n",
                "{ dictionary d = ".repeat(5000),
                "}".repeat(5000)
            ),
            format!(
                "#usda 1.0\ndef \"A\" {{\n int[] a = {}{}\n}}\n",
                "[".repeat(100_000),
                "]".repeat(100_000)
            ),
        ] {
            let e = read_in(dir.path(), &text, &Limits::default())
                .unwrap_err()
                .to_string();
            assert!(e.contains("groom.usda") && e.len() < 1000, "{e}");
        }
        // 2,000 levels took over 20 s before the bound.
        assert!(started.elapsed().as_secs() < 20, "{:?}", started.elapsed());
        let token = "x".repeat(1 << 20);
        let e = read_in(
            dir.path(),
            &LINEAR.replace("(0, 0, 0), ", &format!("{token}, ")),
            &Limits::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("line 6") && e.len() < 1000,
            "{}",
            &e[..e.len().min(2000)]
        );
    }

    #[test]
    fn missing_layers_prims_and_ops_are_errors_naming_them() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("other.usda"), "#usda 1.0\ndef \"X\" {}\n").unwrap();
        let arc = |arc: &str| {
            LINEAR.replace(
                "def BasisCurves \"Hair\"",
                &format!("def BasisCurves \"Hair\" ({arc})"),
            )
        };
        for (text, expect) in [
            (arc("references = @missing.usda@</X>"), "missing.usda"),
            (arc("payload = @missing.usda@</X>"), "missing.usda"),
            (arc("references = @other.usda@</Nope>"), "</Nope>"),
            (arc("payload = @other.usda@</Nope>"), "</Nope>"),
            (arc("references = </Nope>"), "</Nope>"),
            (
                LINEAR.replace("#usda 1.0", "#usda 1.0\n(subLayers = [@gone.usda@])"),
                "gone.usda",
            ),
            (
                LINEAR.replace(
                    "uniform token type",
                    "double3 xformOp:translate = (1, 0, 0)\n    uniform token[] xformOpOrder = \
                     [\"xformOp:translate\", \"xformOp:scale\"]\n    uniform token type",
                ),
                "xformOpOrder names \"xformOp:scale\"",
            ),
            (
                format!(
                    "#usda 1.0\ndef Xform \"S\"\n{{\n    uniform token[] xformOpOrder = \
                     [\"!invert!xformOp:rotateX\"]\n{}}}\n",
                    LINEAR.replace("#usda 1.0", "")
                ),
                "xformOpOrder of the ancestor </S> names \"!invert!xformOp:rotateX\"",
            ),
        ] {
            let e = read_in(dir.path(), &text, &Limits::default())
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("groom.usda") && e.contains(expect),
                "{expect}: {e}"
            );
        }
        // An op that is there, inverted, is read.
        let moved = LINEAR.replace(
            "uniform token type",
            "double3 xformOp:translate = (1, 0, 0)\n    uniform token[] xformOpOrder = \
             [\"!invert!xformOp:translate\"]\n    uniform token type",
        );
        let g = read_in(dir.path(), &moved, &Limits::default()).unwrap();
        assert_eq!(g.points[0], Vec3::new(-0.01, 0.0, 0.0));
    }

    /// Paths and names outside SdfPath's grammar are parse errors where they stand: a
    /// reference path running on over lines to the next `>` (a fuzzer's find) made the
    /// composition walk up its ancestors without end.
    #[test]
    fn ill_formed_paths_and_names_are_refused_where_they_stand() {
        let dir = tempfile::tempdir().unwrap();
        let instanced = include_str!("../tests/data/usd_instanced.usda");
        let run_on = instanced.replacen("</Proto>\n)\n{", "</Proto", 1);
        let arc = |arc: &str| {
            LINEAR.replace(
                "def BasisCurves \"Hair\"",
                &format!("def BasisCurves \"Hair\" ({arc})"),
            )
        };
        let named = |name: &str| LINEAR.replace("\"Hair\"", &format!("{name:?}"));
        for (text, expect) in [
            (
                run_on,
                "references: not a valid path: \"/Proto\\n    double3",
            ),
            (arc("references = </A}>"), "not a valid path: \"/A}\""),
            (arc("references = </A/>"), "not a valid path"),
            (arc("references = </A//B>"), "not a valid path"),
            (arc("inherits = </A B>"), "not a valid path"),
            (arc("specializes = </A\nB>"), "not a valid path"),
            (arc("payload = </A.b.c>"), "not a valid path"),
            (named("A}"), "not a valid prim name: \"A}\""),
            (named("A/B"), "not a valid prim name"),
            (named("1A"), "not a valid prim name"),
            (
                LINEAR.replace(
                    "{",
                    "(variantSets = \"v\")\n{\n variantSet \"v}\" = { \"a\" {} }",
                ),
                "not a valid variant set name",
            ),
            (
                LINEAR.replace(
                    "{",
                    "(variantSets = \"v\")\n{\n variantSet \"v\" = { \"a}\" {} }",
                ),
                "not a valid variant name",
            ),
            (
                LINEAR.replace("{", "(variants = { string v = \"a/b\" })\n{"),
                "not a valid variant selection",
            ),
        ] {
            let e = read_in(dir.path(), &text, &Limits::default())
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("groom.usda") && e.contains(expect) && e.len() < 1000,
                "{expect}: {e}"
            );
        }
        // The grammar's other forms still read: a property, a target, a variant selection.
        for arc in [
            "rel r = </Hair.widths>",
            "rel r = </Hair.r[/Hair].x>",
            "rel r = </Hair{v=a-b|c}Child>",
        ] {
            let text = LINEAR.replace(
                "uniform token type",
                &format!("{arc}\n    uniform token type"),
            );
            read_in(dir.path(), &text, &Limits::default()).unwrap_or_else(|e| panic!("{arc}: {e}"));
        }
    }

    #[test]
    fn the_earliest_time_sample_is_read_whatever_the_order_written() {
        let dir = tempfile::tempdir().unwrap();
        let samples = LINEAR.replace(
            "point3f[] points = [(0, 0, 0), (0, 1, 0), (0, 2, 0)]",
            "point3f[] points.timeSamples = {\n        5: [(5, 0, 0), (5, 1, 0), (5, 2, 0)],\n        \
             -2: [(2, 0, 0), (2, 1, 0), (2, 2, 0)],\n        1: [(1, 0, 0), (1, 1, 0), (1, 2, 0)],\n    }",
        );
        let g = read_in(dir.path(), &samples, &Limits::default()).unwrap();
        assert_eq!(g.points[0], Vec3::new(0.02, 0.0, 0.0));
    }

    #[cfg(unix)]
    #[test]
    fn layers_that_are_not_regular_files_are_refused_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo.usda");
        assert!(std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        std::os::unix::fs::symlink("/dev/zero", dir.path().join("zero.usda")).unwrap();
        std::fs::create_dir(dir.path().join("folder.usda")).unwrap();
        for layer in ["fifo.usda", "zero.usda", "folder.usda"] {
            for text in [
                LINEAR.replace(
                    "#usda 1.0",
                    &format!("#usda 1.0\n(subLayers = [@{layer}@])"),
                ),
                LINEAR.replace(
                    "def BasisCurves \"Hair\"",
                    &format!("def BasisCurves \"Hair\" (references = @{layer}@</X>)"),
                ),
                LINEAR.replace(
                    "def BasisCurves \"Hair\"",
                    &format!("def BasisCurves \"Hair\" (payload = @{layer}@</X>)"),
                ),
            ] {
                let e = read_in(dir.path(), &text, &Limits::default())
                    .unwrap_err()
                    .to_string();
                let named = if layer == "zero.usda" {
                    "/dev/zero"
                } else {
                    layer
                };
                assert!(
                    e.contains("groom.usda") && e.contains(named) && e.contains("not a regular"),
                    "{e}"
                );
            }
        }
    }

    #[test]
    fn instances_of_instances_stop_at_the_memory_limit() {
        let dir = tempfile::tempdir().unwrap();
        let mut text = LINEAR.replace(
            "def BasisCurves \"Hair\"",
            "class \"L0\" {\ndef BasisCurves \"C\"",
        ) + "}\n";
        for level in 1..8 {
            text += &format!("class \"L{level}\"\n{{\n");
            for i in 0..10 {
                text += &format!(
                    "    def \"I{i}\" (instanceable = true\n        references = </L{}>) {{}}\n",
                    level - 1
                );
            }
            text += "}\n";
        }
        text += "def \"Top\" (instanceable = true\n    references = </L7>) {}\n";
        let limits = Limits {
            memory_gib: 0.01,
            ..Limits::default()
        };
        let e = read_in(dir.path(), &text, &limits).unwrap_err().to_string();
        assert!(e.contains("groom.usda") && e.contains("prims"), "{e}");
        // Within the limit, each instance gives its strand.
        let few = text.replace("references = </L7>", "references = </L2>");
        assert_eq!(
            read_in(dir.path(), &few, &limits).unwrap().strand_count(),
            100
        );
    }

    /// A binary groom builds its paths from its token table: a prim name changed in place to
    /// one outside the grammar (`Bezier` → `Bez}er`, `Bez er`) or to two names (`Bez/er`) is
    /// refused naming it, as the text reader refuses it, and the unchanged file reads.
    #[test]
    fn ill_formed_prim_names_of_a_usdc_are_refused() {
        let original =
            std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/usd_cubic.usdc"))
                .unwrap();
        let at = original
            .windows(6)
            .position(|w| w == b"Bezier")
            .expect("the prim name is stored as it is");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("groom.usdc");
        std::fs::write(&path, &original).unwrap();
        assert!(UsdFile::new(&path).read(&Limits::default()).is_ok());
        for bad in [b'}', b'/', b' '] {
            let mut bytes = original.clone();
            bytes[at + 3] = bad;
            std::fs::write(&path, &bytes).unwrap();
            let e = UsdFile::new(&path)
                .read(&Limits::default())
                .unwrap_err()
                .to_string();
            let name = format!("Bez{}er", bad as char);
            let why = if bad == b'/' {
                format!("not a valid path element: {name:?} under /Groom")
            } else {
                format!("not a valid path: \"/Groom/{name}\"")
            };
            assert!(e.contains("groom.usdc") && e.contains(&why), "{name}: {e}");
            assert!(!e.contains("USD library failed"), "{name}: {e}");
        }
    }

    /// A fuzzer's `.usdc` (kept as it was found) whose `primChildren` named a child that
    /// appends to the root itself: the walk over the stage went round forever. A child must
    /// be one prim name below its parent.
    #[test]
    fn a_child_that_is_not_one_name_below_its_parent_is_refused() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/usd_child_names_root.usdc");
        let e = UsdFile::new(&path)
            .read(&Limits::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("usd_child_names_root.usdc") && e.contains("is not one prim name"),
            "{e}"
        );
    }

    /// Every one-byte change of a binary groom is read or refused, never a panic inside the
    /// USD library (the reader would contain it and say so) or an abort.
    #[test]
    fn one_byte_changes_of_a_usdc_are_read_or_refused() {
        let original =
            std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/usd_linear.usdc"))
                .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("groom.usdc");
        let mut refused = 0;
        for i in 0..original.len() {
            for byte in [0x00, 0xff, original[i] ^ 0x80, original[i].wrapping_add(1)] {
                let mut bytes = original.clone();
                bytes[i] = byte;
                std::fs::write(&path, &bytes).unwrap();
                if let Err(e) = UsdFile::new(&path).read(&Limits::default()) {
                    let e = e.to_string();
                    assert!(
                        !e.contains("USD library failed"),
                        "byte {i} = {byte:#x}: {e}"
                    );
                    refused += 1;
                }
            }
        }
        assert!(refused > 0);
    }
}
