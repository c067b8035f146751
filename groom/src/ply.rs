//! Reader for hair strands in PLY files (ascii, binary little- and big-endian), through the
//! `ply-rs-bw` crate.
//!
//! PLY has no standard for curves, so this reader understands the layouts that tools write
//! for strands. Always needed: an element `vertex` with properties `x`, `y`, `z` (any numeric
//! type). Which vertices form which strand comes from the first of these the file has:
//!
//! 1. **A per-strand element** named `strand`, `curve` or `hair` (or the plural), one record
//!    per strand, with either
//!    - a vertex count (`vertex_count`, `num_vertices`, `nverts`, `num_points`, `point_count`,
//!      `npoints`): each strand takes that many vertices, in file order; or
//!    - a segment count (`nsegs`, `segments`, `num_segments`, `segment_count`; points =
//!      segments + 1), as cyHair-to-PLY converters write it; or
//!    - a list of vertex indices (`vertex_indices`, `vertex_index`, `indices`): the strand's
//!      polyline, root first.
//! 2. **A per-vertex strand id** (`strand`, `strand_id`, `strand_index`, `curve`, `curve_id`,
//!    `curve_index`, `hair_id`): consecutive vertices with the same id form a strand; the
//!    vertices of a strand must be consecutive.
//! 3. **An `edge` element** (`vertex1`, `vertex2`), as Blender writes loose edges (hair curves
//!    converted to a mesh): edges chain into polylines. A vertex may have at most two edges
//!    (strands do not branch) and chains may not close into loops. Each strand starts at the
//!    end with the lower vertex index (exporters write roots first).
//! 4. **Nothing but vertices** (e.g. Neural Haircut's output): every `points_per_strand`
//!    consecutive vertices are one strand; the option must be given.
//!
//! Strands of one point are skipped. `face` elements (surfaces) and every other element or
//! property are ignored.
//!
//! **Radius.** The `radius` option, when given, sets every fiber's radius. Otherwise a vertex
//! property `radius`, or `width`, `thickness` or `diameter` (full widths, halved), gives
//! per-point radii; failing that, the same names on the per-strand element give per-strand
//! radii; failing that, the radius is 0.00004 (80 µm hair in metres, as for USC-HairSalon).
//!
//! **Colour.** Vertex properties `red`, `green`, `blue` (or `diffuse_red`, … or `r`, `g`, `b`)
//! give per-point colours (what a hair object's `variation` can take as pigments): integer
//! types are 8-bit-style display colours, scaled by the type's largest value (255 for
//! `uchar`) and decoded from sRGB to linear, as exporters write them; `float` and `double`
//! are linear values, taken as they are. Colours need all three channels: a vertex element
//! with only some is read without colours (with a warning).

use crate::error::{format_error, Result};
use crate::geometry::{HairAttribute, HairGeometry};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    ElementDef, Encoding, Header, PropertyAccess, PropertyAccessResult, PropertyType, ScalarType,
};
use serde::{Deserialize, Serialize};
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use tress_core::math::{Rgb, Vec3};

/// Fiber radius used when neither the option nor the file gives one: 80 µm hair in metres.
const FALLBACK_RADIUS: f32 = 0.00004;

/// A PLY strand file to load.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PlyFile {
    /// Path of the `.ply` file, used as given (resolve relative paths first).
    pub path: PathBuf,
    /// Fiber radius for every point, in file units, overriding any radius in the file. `None`
    /// (the default): the file's radius or width, else 0.00004.
    #[serde(default)]
    pub radius: Option<f32>,
    /// For files with vertices only: every this many consecutive vertices form one strand.
    /// Ignored (with a warning) when the file says where strands start.
    #[serde(default)]
    pub points_per_strand: Option<u32>,
    /// Rotate Z-up data (Blender's default export) to tress's Y-up world ((x, y, z) →
    /// (x, z, −y)). Default false.
    #[serde(default)]
    pub z_up: bool,
}

impl PlyFile {
    /// The file at `path` with default options (radius from the file, Y-up).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        PlyFile {
            path: path.into(),
            radius: None,
            points_per_strand: None,
            z_up: false,
        }
    }

    /// Reads and validates the file.
    pub fn read(&self) -> Result<HairGeometry> {
        if let Some(r) = self.radius {
            if !(r.is_finite() && r > 0.0) {
                return Err(crate::Error::InvalidOption(crate::InvalidOption {
                    object: self.path.display().to_string(),
                    field: "radius",
                    reason: format!("must be finite and positive, got {r}"),
                }));
            }
        }
        if self.points_per_strand.is_some_and(|n| n < 2) {
            return Err(crate::Error::InvalidOption(crate::InvalidOption {
                object: self.path.display().to_string(),
                field: "points_per_strand",
                reason: format!(
                    "a strand needs at least 2 points, got {}",
                    self.points_per_strand.unwrap_or(0)
                ),
            }));
        }
        let bytes =
            tress_core::files::read_regular(&self.path).map_err(|source| crate::Error::Io {
                path: self.path.clone(),
                source,
            })?;
        let mut hair = parse(&bytes, &self.path, self)?;
        if self.z_up {
            hair.z_up_to_y_up();
        }
        Ok(hair)
    }
}

/// Property names by role, most specific first; matched case-sensitively, as PLY names are.
const RADIUS_NAMES: [&str; 1] = ["radius"];
const WIDTH_NAMES: [&str; 3] = ["width", "thickness", "diameter"];
const STRAND_ID_NAMES: [&str; 7] = [
    "strand",
    "strand_id",
    "strand_index",
    "curve",
    "curve_id",
    "curve_index",
    "hair_id",
];
const VERTEX_COUNT_NAMES: [&str; 6] = [
    "vertex_count",
    "num_vertices",
    "nverts",
    "num_points",
    "point_count",
    "npoints",
];
const SEGMENT_COUNT_NAMES: [&str; 4] = ["nsegs", "segments", "num_segments", "segment_count"];
const INDEX_LIST_NAMES: [&str; 3] = ["vertex_indices", "vertex_index", "indices"];
/// Per channel (red, green, blue): the names of a vertex colour property.
const COLOR_NAMES: [[&str; 3]; 3] = [
    ["red", "diffuse_red", "r"],
    ["green", "diffuse_green", "g"],
    ["blue", "diffuse_blue", "b"],
];
const STRAND_ELEMENT_NAMES: [&str; 6] = ["strand", "strands", "curve", "curves", "hair", "hairs"];

/// The rank of `name` among the radius names (radius first, then full widths), and whether it
/// is a full width.
fn radius_rank(name: &str) -> Option<(u8, bool)> {
    if let Some(i) = RADIUS_NAMES.iter().position(|&n| n == name) {
        return Some((i as u8, false));
    }
    WIDTH_NAMES
        .iter()
        .position(|&n| n == name)
        .map(|i| ((RADIUS_NAMES.len() + i) as u8, true))
}

fn rank_in(names: &[&str], name: &str) -> Option<u8> {
    names.iter().position(|&n| n == name).map(|i| i as u8)
}

/// A value kept by rank: when an element has several properties for one role (say `radius`
/// and `width`), the best-ranked one wins whatever their order in the file.
#[derive(Clone, Copy, Debug)]
struct Ranked {
    value: f64,
    rank: u8,
}

impl Ranked {
    const NONE: Ranked = Ranked {
        value: f64::NAN,
        rank: u8::MAX,
    };

    fn offer(&mut self, rank: u8, value: f64) {
        if rank <= self.rank {
            *self = Ranked { value, rank };
        }
    }

    fn get(&self) -> Option<f64> {
        (self.rank != u8::MAX).then_some(self.value)
    }
}

/// The value of a PLY scalar type that stands for full intensity in a colour channel: the
/// type's largest value for integers, 1 for floating-point types (see the module docs).
trait FullIntensity {
    const FULL: f64;
}

macro_rules! full_intensity {
    ($($t:ty => $full:expr),*) => {
        $(impl FullIntensity for $t {
            const FULL: f64 = $full;
        })*
    };
}

full_intensity!(i8 => i8::MAX as f64, u8 => u8::MAX as f64, i16 => i16::MAX as f64,
                u16 => u16::MAX as f64, i32 => i32::MAX as f64, u32 => u32::MAX as f64,
                f32 => 1.0, f64 => 1.0);

/// Implements every numeric scalar setter of [`PropertyAccess`] through `set_number`, which
/// also gets the type's [`FullIntensity`].
macro_rules! numeric_setters {
    ($($method:ident: $t:ty),*) => {
        $(fn $method(&mut self, name: &str, value: $t) -> PropertyAccessResult {
            self.set_number(name, value as f64, <$t as FullIntensity>::FULL)
        })*
    };
}

/// The linear value of an sRGB-encoded channel in [0, 1] (IEC 61966-2-1).
fn srgb_to_linear(c: f64) -> f64 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// One `vertex` record: position, radius (already halved if the file gave a width), strand
/// id and linear colour, where present.
#[derive(Clone, Copy, Debug)]
struct VertexRecord {
    p: [f32; 3],
    radius: Ranked,
    strand: Ranked,
    color: [Ranked; 3],
}

impl VertexRecord {
    fn set_number(&mut self, name: &str, v: f64, full: f64) -> PropertyAccessResult {
        match name {
            "x" => self.p[0] = v as f32,
            "y" => self.p[1] = v as f32,
            "z" => self.p[2] = v as f32,
            _ => {
                if let Some((rank, full_width)) = radius_rank(name) {
                    self.radius
                        .offer(rank, if full_width { 0.5 * v } else { v });
                } else if let Some(rank) = rank_in(&STRAND_ID_NAMES, name) {
                    self.strand.offer(rank, v);
                } else if let Some((channel, rank)) =
                    (0..3).find_map(|c| rank_in(&COLOR_NAMES[c], name).map(|r| (c, r)))
                {
                    let linear = if full == 1.0 {
                        v
                    } else {
                        srgb_to_linear(v / full)
                    };
                    self.color[channel].offer(rank, linear);
                } else {
                    return PropertyAccessResult::Ignored;
                }
            }
        }
        PropertyAccessResult::Set
    }

    /// The vertex's colour, if the file gives one (all three channels; see [`vertex_colors`]).
    fn color(&self) -> Option<Rgb> {
        let [r, g, b] = self.color.map(|c| c.get());
        Some(Rgb::new(r? as f32, g? as f32, b? as f32))
    }
}

impl PropertyAccess for VertexRecord {
    fn new() -> Self {
        VertexRecord {
            p: [0.0; 3],
            radius: Ranked::NONE,
            strand: Ranked::NONE,
            color: [Ranked::NONE; 3],
        }
    }
    numeric_setters!(set_char: i8, set_uchar: u8, set_short: i16, set_ushort: u16,
                     set_int: i32, set_uint: u32, set_float: f32, set_double: f64);
}

/// One record of the per-strand element.
#[derive(Clone, Debug)]
struct StrandRecord {
    /// Points of the strand (segment counts already turned into point counts).
    points: Ranked,
    radius: Ranked,
    /// The strand's vertex indices, when given as a list (negative values kept, to be
    /// reported).
    indices: Option<Vec<i64>>,
}

impl StrandRecord {
    fn set_number(&mut self, name: &str, v: f64, _full: f64) -> PropertyAccessResult {
        if let Some(rank) = rank_in(&VERTEX_COUNT_NAMES, name) {
            self.points.offer(rank, v);
        } else if let Some(rank) = rank_in(&SEGMENT_COUNT_NAMES, name) {
            self.points
                .offer(VERTEX_COUNT_NAMES.len() as u8 + rank, v + 1.0);
        } else if let Some((rank, full_width)) = radius_rank(name) {
            self.radius
                .offer(rank, if full_width { 0.5 * v } else { v });
        } else {
            return PropertyAccessResult::Ignored;
        }
        PropertyAccessResult::Set
    }

    fn set_list(&mut self, name: &str, values: impl Iterator<Item = i64>) -> PropertyAccessResult {
        if INDEX_LIST_NAMES.contains(&name) {
            self.indices = Some(values.collect());
            PropertyAccessResult::Set
        } else {
            PropertyAccessResult::Ignored
        }
    }
}

/// Implements the integer list setters of [`PropertyAccess`] through `set_list`.
macro_rules! list_setters {
    ($($method:ident: $t:ty),*) => {
        $(fn $method(&mut self, name: &str, values: Vec<$t>) -> PropertyAccessResult {
            self.set_list(name, values.into_iter().map(i64::from))
        })*
    };
}

impl PropertyAccess for StrandRecord {
    fn new() -> Self {
        StrandRecord {
            points: Ranked::NONE,
            radius: Ranked::NONE,
            indices: None,
        }
    }
    numeric_setters!(set_char: i8, set_uchar: u8, set_short: i16, set_ushort: u16,
                     set_int: i32, set_uint: u32, set_float: f32, set_double: f64);
    list_setters!(set_list_char: i8, set_list_uchar: u8, set_list_short: i16,
                  set_list_ushort: u16, set_list_int: i32, set_list_uint: u32);
}

/// One `edge` record.
#[derive(Clone, Copy, Debug)]
struct EdgeRecord {
    ends: [f64; 2],
}

impl EdgeRecord {
    fn set_number(&mut self, name: &str, v: f64, _full: f64) -> PropertyAccessResult {
        match name {
            "vertex1" => self.ends[0] = v,
            "vertex2" => self.ends[1] = v,
            _ => return PropertyAccessResult::Ignored,
        }
        PropertyAccessResult::Set
    }
}

impl PropertyAccess for EdgeRecord {
    fn new() -> Self {
        EdgeRecord {
            ends: [f64::NAN; 2],
        }
    }
    numeric_setters!(set_char: i8, set_uchar: u8, set_short: i16, set_ushort: u16,
                     set_int: i32, set_uint: u32, set_float: f32, set_double: f64);
}

/// A record type that reads nothing, for the elements the reader skips.
#[derive(Clone, Copy, Debug)]
struct Skipped;

impl PropertyAccess for Skipped {
    fn new() -> Self {
        Skipped
    }
}

/// How the file says which vertices form a strand (see the module docs), chosen from the
/// header.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Layout {
    StrandElement,
    StrandIds,
    Edges,
    FixedLength(u32),
}

fn has_property(element: &ElementDef, names: &[&str]) -> bool {
    names.iter().any(|n| element.properties.contains_key(*n))
}

/// Whether the `vertex` element has colours: all three channels (some alone are ignored, with
/// a warning naming the file).
fn vertex_colors(vertex: &ElementDef, path: &Path) -> bool {
    let present = COLOR_NAMES.map(|names| has_property(vertex, &names));
    if present.iter().any(|&p| p) && !present.iter().all(|&p| p) {
        let missing: Vec<&str> = (0..3)
            .filter(|&c| !present[c])
            .map(|c| COLOR_NAMES[c][0])
            .collect();
        tracing::warn!(
            "{}: vertex colours ignored: the `vertex` element has no {}",
            path.display(),
            missing.join(" or ")
        );
    }
    present.iter().all(|&p| p)
}

fn choose_layout(header: &Header, options: &PlyFile) -> std::result::Result<Layout, String> {
    let vertex = header
        .elements
        .get("vertex")
        .ok_or("no `vertex` element: a PLY strand file needs vertices with x, y, z")?;
    if let Some(axis) = ["x", "y", "z"]
        .into_iter()
        .find(|a| !vertex.properties.contains_key(*a))
    {
        return Err(format!("the `vertex` element has no `{axis}` property"));
    }
    let strand_element = header
        .elements
        .values()
        .find(|e| STRAND_ELEMENT_NAMES.contains(&e.name.as_str()));
    let layout = if let Some(e) = strand_element {
        if !has_property(e, &VERTEX_COUNT_NAMES)
            && !has_property(e, &SEGMENT_COUNT_NAMES)
            && !has_property(e, &INDEX_LIST_NAMES)
        {
            return Err(format!(
                "the `{}` element has neither a vertex count ({}), a segment count ({}) nor a \
                 vertex index list ({})",
                e.name,
                VERTEX_COUNT_NAMES.join(", "),
                SEGMENT_COUNT_NAMES.join(", "),
                INDEX_LIST_NAMES.join(", ")
            ));
        }
        Layout::StrandElement
    } else if has_property(vertex, &STRAND_ID_NAMES) {
        Layout::StrandIds
    } else if let Some(edge) = header.elements.get("edge") {
        if !(edge.properties.contains_key("vertex1") && edge.properties.contains_key("vertex2")) {
            return Err("the `edge` element lacks `vertex1` and `vertex2`".into());
        }
        Layout::Edges
    } else if let Some(n) = options.points_per_strand {
        return Ok(Layout::FixedLength(n));
    } else {
        let faces = if header.elements.contains_key("face") {
            " (its faces describe a surface, not strands)"
        } else {
            ""
        };
        return Err(format!(
            "no strand structure{faces}: expected a `strand` or `curve` element (vertex or \
             segment counts, or vertex index lists), a per-vertex strand id (`strand`, \
             `curve_id`, …) or an `edge` element (vertex1, vertex2); for a file of vertices \
             only, set `points_per_strand`"
        ));
    };
    if options.points_per_strand.is_some() {
        tracing::warn!(
            "{}: `points_per_strand` ignored: the file says where strands start",
            options.path.display()
        );
    }
    Ok(layout)
}

/// A strand as the indices of its vertices, root first, with its per-strand radius if the
/// file gives one.
type Polyline = (Vec<u32>, Option<f64>);

/// Parses a whole PLY file held in memory; `options.path` names it in errors.
/// How tress reads a property it uses.
#[derive(Clone, Copy, PartialEq)]
enum Reads {
    Number,
    IntegerList,
}

/// Refuses a property tress reads whose declared type it would not read as declared (a list
/// `x`, `radius`, strand id or count was skipped silently; a float index list gave NaN).
fn check_declared(
    element: &ElementDef,
    reads: impl Fn(&str) -> Option<Reads>,
) -> std::result::Result<(), String> {
    for property in element.properties.values() {
        let Some(wanted) = reads(&property.name) else {
            continue;
        };
        let fits = match (wanted, &property.data_type) {
            (Reads::Number, PropertyType::Scalar(_)) => true,
            (Reads::IntegerList, PropertyType::List(_, item)) => {
                !matches!(item, ScalarType::Float | ScalarType::Double)
            }
            _ => false,
        };
        if !fits {
            let declared = match &property.data_type {
                PropertyType::Scalar(t) => format!("a {t:?}"),
                PropertyType::List(_, t) => format!("a list of {t:?}"),
            };
            return Err(format!(
                "the `{}` element's `{}` is declared as {declared}; tress reads it as {}",
                element.name,
                property.name,
                match wanted {
                    Reads::Number => "one number",
                    Reads::IntegerList => "a list of integers",
                }
            ));
        }
    }
    Ok(())
}

/// Checks the declared type of every property the chosen layout reads.
fn check_layout_types(header: &Header, layout: Layout) -> std::result::Result<(), String> {
    let number = |yes: bool| yes.then_some(Reads::Number);
    if let Some(vertex) = header.elements.get("vertex") {
        check_declared(vertex, |n| {
            number(
                matches!(n, "x" | "y" | "z")
                    || radius_rank(n).is_some()
                    || STRAND_ID_NAMES.contains(&n)
                    || COLOR_NAMES.iter().any(|c| c.contains(&n)),
            )
        })?;
    }
    match layout {
        Layout::StrandElement => {
            let strand = header
                .elements
                .values()
                .find(|e| STRAND_ELEMENT_NAMES.contains(&e.name.as_str()));
            if let Some(strand) = strand {
                check_declared(strand, |n| {
                    if INDEX_LIST_NAMES.contains(&n) {
                        Some(Reads::IntegerList)
                    } else {
                        number(
                            VERTEX_COUNT_NAMES.contains(&n)
                                || SEGMENT_COUNT_NAMES.contains(&n)
                                || radius_rank(n).is_some(),
                        )
                    }
                })?;
            }
        }
        Layout::Edges => {
            if let Some(edge) = header.elements.get("edge") {
                check_declared(edge, |n| number(matches!(n, "vertex1" | "vertex2")))?;
            }
        }
        _ => {}
    }
    Ok(())
}

fn parse(bytes: &[u8], path: &Path, options: &PlyFile) -> Result<HairGeometry> {
    let fail = |reason: String| format_error(path, reason);
    let mut reader = Reader::new(bytes);
    let header = Parser::<Skipped>::new()
        .read_header(&mut reader)
        .map_err(|e| fail(crate_error("the header", &e.to_string(), Encoding::Ascii)))?;
    let layout = choose_layout(&header, options).map_err(&fail)?;
    check_layout_types(&header, layout).map_err(&fail)?;
    let has_colors = header
        .elements
        .get("vertex")
        .is_some_and(|v| vertex_colors(v, path));
    let records = read_records(&mut reader, &header, layout, path)?;
    let n = records.vertices.len();
    let polylines = match layout {
        Layout::StrandElement => strand_element_polylines(&records, n),
        Layout::StrandIds => strand_id_polylines(&records.vertices),
        Layout::Edges => chain_edges(&records.edges, n),
        Layout::FixedLength(per) => fixed_length_polylines(n, per),
    }
    .map_err(fail)?;
    assemble(path, options, &records.vertices, &polylines, has_colors)
}

/// The records of a PLY file's elements that its layout reads.
struct Records {
    vertices: Vec<VertexRecord>,
    strands: Vec<StrandRecord>,
    edges: Vec<EdgeRecord>,
    /// The name of the element `strands` came from.
    strand_element: Option<&'static str>,
}

/// Reads the elements after the header: those `layout` uses into records, the others skipped.
fn read_records(
    reader: &mut Reader<&[u8]>,
    header: &Header,
    layout: Layout,
    path: &Path,
) -> Result<Records> {
    let fail = |reason: String| format_error(path, reason);
    let encoding = header.encoding;
    let mut records = Records {
        vertices: Vec::new(),
        strands: Vec::new(),
        edges: Vec::new(),
        strand_element: None,
    };
    // Elements are stored in header order, so each is read (or skipped) in turn.
    for element in header.elements.values() {
        let read_error = |e: ply_rs_bw::parser::ParseError| {
            fail(crate_error(
                &format!("the `{}` element", element.name),
                &e.to_string(),
                encoding,
            ))
        };
        // Records without properties take no bytes in a binary file, so there is nothing to
        // read: read one by one, `element junk 18446744073709551615` never ended. (An ascii
        // record is a line, so there the end of the file stops a false count.)
        if element.properties.is_empty() && encoding != Encoding::Ascii {
            continue;
        }
        let name = element.name.as_str();
        if name == "vertex" {
            records.vertices = Parser::<VertexRecord>::new()
                .read_payload_for_element(reader, element, header)
                .map_err(read_error)?;
        } else if layout == Layout::StrandElement
            && records.strand_element.is_none()
            && STRAND_ELEMENT_NAMES.contains(&name)
        {
            records.strands = Parser::<StrandRecord>::new()
                .read_payload_for_element(reader, element, header)
                .map_err(read_error)?;
            records.strand_element = STRAND_ELEMENT_NAMES.iter().copied().find(|&n| n == name);
        } else if layout == Layout::Edges && name == "edge" {
            records.edges = Parser::<EdgeRecord>::new()
                .read_payload_for_element(reader, element, header)
                .map_err(read_error)?;
        } else {
            Parser::<Skipped>::new()
                .read_payload_for_element(reader, element, header)
                .map_err(read_error)?;
        }
    }
    Ok(records)
}

/// The polylines of a strand element: each record lists its vertices, or counts them from
/// where the previous one ended.
fn strand_element_polylines(
    records: &Records,
    n: usize,
) -> std::result::Result<Vec<Polyline>, String> {
    let mut polylines = Vec::new();
    let element = records.strand_element.unwrap_or("strand");
    let mut next = 0usize;
    for (s, record) in records.strands.iter().enumerate() {
        let radius = record.radius.get();
        let indices = if let Some(list) = &record.indices {
            list.iter()
                .map(|&i| {
                    u32::try_from(i)
                        .ok()
                        .filter(|&i| (i as usize) < n)
                        .ok_or_else(|| {
                            format!(
                                "{element} {s} refers to vertex {i}, but there are {n} vertices"
                            )
                        })
                })
                .collect::<std::result::Result<Vec<u32>, String>>()?
        } else {
            let count = record.points.get().unwrap_or(f64::NAN);
            if !(count.fract() == 0.0 && count >= 1.0) {
                return Err(format!(
                    "{element} {s} has {} points; a strand needs a whole number, at least 1",
                    count
                ));
            }
            let end = next as f64 + count;
            if end > n as f64 {
                return Err(format!(
                    "{element} {s} needs vertices {next}..{end}, but there are {n} vertices"
                ));
            }
            let range = next as u32..end as u32;
            next = end as usize;
            range.collect()
        };
        polylines.push((indices, radius));
    }
    let by_count = records.strands.iter().any(|r| r.indices.is_none());
    if by_count && next != n {
        return Err(format!(
            "the {} {element} records take {next} vertices, but the file has {n}",
            records.strands.len()
        ));
    }
    Ok(polylines)
}

/// The polylines of per-vertex strand ids: runs of consecutive vertices with one id.
fn strand_id_polylines(vertices: &[VertexRecord]) -> std::result::Result<Vec<Polyline>, String> {
    let n = vertices.len();
    let mut polylines = Vec::new();
    let mut finished: HashSet<u64> = HashSet::new();
    let mut start = 0usize;
    for i in 1..=n {
        let id = |i: usize| vertices[i].strand.get().unwrap_or(f64::NAN);
        if i < n && id(i).to_bits() == id(start).to_bits() {
            continue;
        }
        if !finished.insert(id(start).to_bits()) {
            return Err(format!(
                "vertex {start} has strand id {}, which an earlier run of vertices \
                 already had: the vertices of a strand must be consecutive",
                id(start)
            ));
        }
        polylines.push(((start as u32..i as u32).collect(), None));
        start = i;
    }
    Ok(polylines)
}

/// The polylines of a file of vertices only, `per` points a strand.
fn fixed_length_polylines(n: usize, per: u32) -> std::result::Result<Vec<Polyline>, String> {
    if !n.is_multiple_of(per as usize) {
        return Err(format!(
            "{n} vertices are not a whole number of strands of {per} points \
             (points_per_strand)"
        ));
    }
    Ok((0..(n / per as usize) as u32)
        .map(|s| ((s * per..(s + 1) * per).collect(), None))
        .collect())
}

/// The hair of `polylines` over `vertices`, with the radius the options, the vertices or the
/// strands give (in that order of precedence) and the vertices' colours.
fn assemble(
    path: &Path,
    options: &PlyFile,
    vertices: &[VertexRecord],
    polylines: &[Polyline],
    has_colors: bool,
) -> Result<HairGeometry> {
    let n = vertices.len();
    let mut hair = HairGeometry::empty(path.display().to_string());
    let mut colors: Vec<Rgb> = Vec::new();
    let vertex_radius = vertices.iter().any(|v| v.radius.get().is_some());
    let strand_radius = polylines.iter().any(|(_, r)| r.is_some());
    if options.radius.is_none() && !vertex_radius && !strand_radius {
        tracing::info!(
            "{}: no radius in the file: fibers get radius {FALLBACK_RADIUS} (set `radius` to \
             choose)",
            path.display()
        );
    }
    for (indices, strand_r) in polylines {
        // One point: no segment, as in the other readers.
        if indices.len() < 2 {
            continue;
        }
        for &i in indices {
            let v = &vertices[i as usize];
            hair.points.push(Vec3::from_array(v.p));
            let r = options.radius.map(f64::from).unwrap_or_else(|| {
                if vertex_radius {
                    v.radius.get().unwrap_or(f64::NAN)
                } else {
                    strand_r.unwrap_or(FALLBACK_RADIUS as f64)
                }
            });
            hair.radii.push(r as f32);
            // Every record has all the header's properties, so a colour file gives each
            // vertex one.
            colors.extend(v.color());
        }
        hair.strand_offsets.push(hair.points.len() as u32);
    }
    if hair.strand_count() == 0 {
        return Err(format_error(
            path,
            format!("no strand has two points or more ({} vertices)", n),
        ));
    }
    if has_colors {
        hair.colors = Some(HairAttribute::PerPoint(colors));
    }
    hair.validate()?;
    Ok(hair)
}

/// The polylines an `edge` element describes (no per-strand radius), ordered by the index of
/// their first vertex; see the module docs.
fn chain_edges(edges: &[EdgeRecord], n: usize) -> std::result::Result<Vec<Polyline>, String> {
    const NONE: u32 = u32::MAX;
    let mut neighbours = vec![[NONE; 2]; n];
    for (e, edge) in edges.iter().enumerate() {
        let [a, b] = edge.ends.map(|v| {
            (v.fract() == 0.0 && v >= 0.0 && v < n as f64)
                .then_some(v as u32)
                .ok_or_else(|| format!("edge {e} refers to vertex {v}, but there are {n} vertices"))
        });
        let (a, b) = (a?, b?);
        if a == b {
            return Err(format!("edge {e} joins vertex {a} to itself"));
        }
        for (from, to) in [(a, b), (b, a)] {
            let slot = &mut neighbours[from as usize];
            if slot[0] == to || slot[1] == to {
                return Err(format!(
                    "edge {e} joins vertices {a} and {b}, already joined"
                ));
            }
            let free = slot.iter().position(|&s| s == NONE).ok_or_else(|| {
                format!(
                    "vertex {from} has more than two edges (edge {e} is its third): strands \
                     cannot branch"
                )
            })?;
            slot[free] = to;
        }
    }
    let degree = |v: usize| neighbours[v].iter().filter(|&&s| s != NONE).count();
    let mut visited = vec![false; n];
    let mut polylines = Vec::new();
    // Visiting ends in index order starts each chain at its lower-index end.
    for start in 0..n {
        if visited[start] || degree(start) != 1 {
            continue;
        }
        let mut chain = vec![start as u32];
        visited[start] = true;
        let (mut prev, mut at) = (start as u32, neighbours[start][0]);
        loop {
            chain.push(at);
            visited[at as usize] = true;
            let next = neighbours[at as usize]
                .into_iter()
                .find(|&s| s != NONE && s != prev);
            match next {
                Some(next) => (prev, at) = (at, next),
                None => break,
            }
        }
        polylines.push((chain, None));
    }
    if let Some(v) = (0..n).find(|&v| !visited[v] && degree(v) == 2) {
        return Err(format!(
            "the edges through vertex {v} close into a loop: strands need two ends"
        ));
    }
    Ok(polylines)
}

/// A `ply-rs-bw` error met reading `part` (the header or an element) as tress words it: in
/// ascii files with its `line N`; binary positions are given by the crate's message (element
/// and record), its "line" counting binary records.
fn crate_error(part: &str, message: &str, encoding: Encoding) -> String {
    let (line, rest) = match message
        .strip_prefix("Line ")
        .and_then(|m| m.split_once(": "))
    {
        Some((line, rest)) => (Some(line), rest),
        None => (None, message),
    };
    let rest = rest.replace(".\n\tError: ", ": ").replace("\n\t", "; ");
    match (encoding, line) {
        (Encoding::Ascii, Some(line)) => format!("line {line}: {rest}"),
        _ => format!("reading {part}: {rest}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_with(text: &[u8], options: impl FnOnce(&mut PlyFile)) -> Result<HairGeometry> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.ply");
        std::fs::write(&path, text).unwrap();
        let mut file = PlyFile::new(&path);
        options(&mut file);
        file.read()
    }

    fn read(text: &[u8]) -> Result<HairGeometry> {
        read_with(text, |_| ())
    }

    #[test]
    fn strand_element_with_segment_counts_and_widths() {
        // The layout of cyHair-to-PLY converters: per-vertex thickness (a diameter), a
        // `strand` element with segment counts, and redundant edges.
        let text = b"ply\nformat ascii 1.0\ncomment from a cyHair converter\n\
            element vertex 5\nproperty float x\nproperty float y\nproperty float z\n\
            property float thickness\n\
            element strand 2\nproperty ushort nsegs\n\
            element edge 3\nproperty int vertex1\nproperty int vertex2\nend_header\n\
            0 0 0 0.2\n0 1 0 0.2\n0 2 0 0.1\n1 0 0 0.4\n1 1 0 0.4\n2\n1\n0 1\n1 2\n3 4\n";
        let g = read(text).unwrap();
        assert_eq!(g.strand_offsets, vec![0, 3, 5]);
        assert_eq!(g.points[2], Vec3::new(0.0, 2.0, 0.0));
        assert_eq!(g.radii, vec![0.1, 0.1, 0.05, 0.2, 0.2]);
    }

    #[test]
    fn strand_element_with_index_lists_and_strand_radius() {
        let text = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\n\
            property double y\nproperty double z\nelement curve 2\n\
            property list uchar int vertex_indices\nproperty float radius\nend_header\n\
            0 0 0\n0 1 0\n5 0 0\n5 1 0\n2 3 2 0.5\n3 0 1 0 0.25\n";
        let g = read(text).unwrap();
        assert_eq!(g.strand_offsets, vec![0, 2, 5]);
        assert_eq!(g.points[0], Vec3::new(5.0, 1.0, 0.0));
        assert_eq!(g.points[4], Vec3::new(0.0, 0.0, 0.0));
        assert_eq!(g.radii, vec![0.5, 0.5, 0.25, 0.25, 0.25]);
    }

    #[test]
    fn per_vertex_strand_ids_and_radius_override() {
        let text = b"ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\n\
            property float y\nproperty float z\nproperty int strand_id\n\
            property float width\nend_header\n\
            0 0 0 7 1\n0 1 0 7 1\n9 9 9 8 1\n1 0 0 3 1\n1 1 0 3 1\n";
        // The one-point strand 8 is skipped; the option overrides the widths.
        let g = read_with(text, |o| o.radius = Some(0.01)).unwrap();
        assert_eq!(g.strand_offsets, vec![0, 2, 4]);
        assert!(g.radii.iter().all(|&r| r == 0.01));
        let g = read(text).unwrap();
        assert!(g.radii.iter().all(|&r| r == 0.5));
        // An id coming back after another strand is an error.
        let split = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
            property float y\nproperty float z\nproperty uchar curve\nend_header\n\
            0 0 0 1\n0 1 0 2\n0 2 0 1\n";
        let e = read(split).unwrap_err().to_string();
        assert!(e.contains("h.ply") && e.contains("consecutive"), "{e}");
    }

    #[test]
    fn edges_chain_into_strands_root_first() {
        // Blender's layout: loose edges, listed in any order and direction.
        let text = b"ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\n\
            property float y\nproperty float z\nelement edge 4\nproperty int vertex1\n\
            property int vertex2\nend_header\n\
            0 0 0\n0 1 0\n0 2 0\n3 0 0\n3 1 0\n7 7 7\n4 3\n2 1\n0 1\n";
        // Only 3 of the 4 declared edges: truncated.
        let e = read(text).unwrap_err().to_string();
        assert!(
            e.contains("h.ply") && e.contains("line 20") && e.contains("expected 4"),
            "{e}"
        );
        let mut full = text.to_vec();
        full.extend_from_slice(b"4 3\n");
        let e = read(&full).unwrap_err().to_string();
        assert!(e.contains("already joined"), "{e}");
        let mut good = text.to_vec();
        good.extend_from_slice(b"5 5\n");
        let e = read(&good).unwrap_err().to_string();
        assert!(e.contains("itself"), "{e}");
        let text = b"ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\n\
            property float y\nproperty float z\nelement edge 3\nproperty int vertex1\n\
            property int vertex2\nend_header\n\
            0 0 0\n0 1 0\n0 2 0\n3 0 0\n3 1 0\n7 7 7\n4 3\n2 1\n0 1\n";
        let g = read(text).unwrap();
        assert_eq!(g.strand_offsets, vec![0, 3, 5]);
        assert_eq!(
            g.points,
            [
                [0., 0., 0.],
                [0., 1., 0.],
                [0., 2., 0.],
                [3., 0., 0.],
                [3., 1., 0.]
            ]
            .map(Vec3::from_array)
        );
        assert!(g.radii.iter().all(|&r| r == FALLBACK_RADIUS));
        // Branches and loops are refused.
        let branch = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n\
            property float y\nproperty float z\nelement edge 3\nproperty int vertex1\n\
            property int vertex2\nend_header\n0 0 0\n0 1 0\n0 2 0\n1 1 0\n0 1\n1 2\n1 3\n";
        assert!(read(branch).unwrap_err().to_string().contains("branch"));
        let ring = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
            property float y\nproperty float z\nelement edge 3\nproperty int vertex1\n\
            property int vertex2\nend_header\n0 0 0\n0 1 0\n1 1 0\n0 1\n1 2\n2 0\n";
        assert!(read(ring).unwrap_err().to_string().contains("loop"));
    }

    #[test]
    fn vertex_colours_are_read_per_point() {
        // uchar channels: display colours, decoded from sRGB.
        let text = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n\
            property float y\nproperty float z\nproperty uchar red\nproperty uchar green\n\
            property uchar blue\nproperty uchar alpha\nelement strand 2\n\
            property int vertex_count\nend_header\n\
            0 0 0 255 0 128 255\n0 1 0 255 0 128 255\n1 0 0 10 200 30 0\n1 1 0 11 201 31 0\n2\n2\n";
        let g = read(text).unwrap();
        let Some(HairAttribute::PerPoint(c)) = &g.colors else {
            panic!("expected colours per point, got {:?}", g.colors)
        };
        assert_eq!(c.len(), 4);
        // sRGB 128/255 is 0.2158605 linear; 10/255 is on the linear toe (÷ 12.92).
        assert!(
            (c[0] - Rgb::new(1.0, 0.0, 0.2158605)).abs().max_element() < 1e-6,
            "{}",
            c[0]
        );
        assert!((c[2].x - 10.0 / 255.0 / 12.92).abs() < 1e-7, "{}", c[2]);
        assert!(c[3].y > c[2].y && c[3].y < 1.0);
        // Float channels are linear and taken as they are; they follow the vertices when
        // edges put them in another order than the file's.
        let text = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
            property float y\nproperty float z\nproperty float r\nproperty float g\n\
            property float b\nelement edge 2\nproperty int vertex1\nproperty int vertex2\n\
            end_header\n0 0 0 0.1 0.2 0.3\n0 2 0 0.5 0.25 0.125\n0 1 0 0.7 0.8 0.9\n1 2\n2 0\n";
        let g = read(text).unwrap();
        assert_eq!(g.points[1], Vec3::Y);
        assert_eq!(
            g.colors,
            Some(HairAttribute::PerPoint(vec![
                Rgb::new(0.1, 0.2, 0.3),
                Rgb::new(0.7, 0.8, 0.9),
                Rgb::new(0.5, 0.25, 0.125)
            ]))
        );
        // No colour properties: no colours.
        let plain = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n\
            property float y\nproperty float z\nproperty int strand_id\nend_header\n\
            0 0 0 1\n0 1 0 1\n";
        assert!(read(plain).unwrap().colors.is_none());
        // Some channels but not all: no colours (and a warning).
        let partial = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n\
            property float y\nproperty float z\nproperty uchar red\nproperty int strand_id\n\
            end_header\n0 0 0 1 1\n0 1 0 1 1\n";
        let g = read(partial).unwrap();
        assert!(g.colors.is_none() && g.strand_count() == 1);
    }

    #[test]
    fn binary_vertex_colours() {
        let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\n\
            property float x\nproperty float y\nproperty float z\nproperty uchar red\n\
            property uchar green\nproperty uchar blue\nend_header\n"
            .to_vec();
        for (y, rgb) in [(0.0f32, [255u8, 255, 255]), (1.0, [0, 0, 255])] {
            for v in [0.0f32, y, 0.0] {
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            bytes.extend_from_slice(&rgb);
        }
        let g = read_with(&bytes, |o| o.points_per_strand = Some(2)).unwrap();
        assert_eq!(
            g.colors,
            Some(HairAttribute::PerPoint(vec![Rgb::ONE, Rgb::Z]))
        );
    }

    #[test]
    fn vertex_only_files_need_points_per_strand() {
        let text = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\n\
            property float y\nproperty float z\nelement face 0\n\
            property list uchar int vertex_indices\nend_header\n0 0 0\n0 1 0\n1 0 0\n1 1 0\n";
        let e = read(text).unwrap_err().to_string();
        assert!(
            e.contains("h.ply") && e.contains("points_per_strand") && e.contains("surface"),
            "{e}"
        );
        let g = read_with(text, |o| o.points_per_strand = Some(2)).unwrap();
        assert_eq!(g.strand_offsets, vec![0, 2, 4]);
        let e = read_with(text, |o| o.points_per_strand = Some(3))
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a whole number"), "{e}");
        assert!(read_with(text, |o| o.points_per_strand = Some(1)).is_err());
    }

    #[test]
    fn layout_errors_say_what_was_expected() {
        let cases: [(&[u8], &str); 6] = [
            (b"", "header"),
            (b"plx\n", "ply"),
            (
                b"ply\nformat ascii 1.0\nelement face 0\nend_header\n",
                "no `vertex` element",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nend_header\n",
                "no `z` property",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                  property float z\nelement strand 1\nproperty float radius\nend_header\n0 0 0\n1\n",
                "neither a vertex count",
            ),
            (
                b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n\
                  property float z\nelement strand 1\nproperty int vertex_count\nend_header\n\
                  0 0 0\n0 1 0\n3\n",
                "needs vertices 0..3",
            ),
        ];
        for (text, expect) in cases {
            let e = read(text).unwrap_err().to_string();
            assert!(e.contains("h.ply") && e.contains(expect), "{expect}: {e}");
        }
        let zero_width = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n\
            property float y\nproperty float z\nproperty float radius\nend_header\n\
            0 0 0 0\n0 1 0 0\n";
        let e = read_with(zero_width, |o| o.points_per_strand = Some(2))
            .unwrap_err()
            .to_string();
        assert!(e.contains("h.ply") && e.contains("radius 0"), "{e}");
        let e = read_with(zero_width, |o| o.radius = Some(-1.0))
            .unwrap_err()
            .to_string();
        assert!(e.contains("radius"), "{e}");
    }
}
