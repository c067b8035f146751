//! Reading and writing images: HDR/EXR environment maps in, float EXR and tone-mapped PNG out.
//!
//! Every error names the file and the problem. Images are written into a [`Sink`] of
//! [`crate::output_file`], which puts them in place atomically (or streams them into a device),
//! so an interrupted render never leaves a truncated image behind.
//!
//! EXR header attributes keep their types ([`Attribute`]: text, int, float, double, 4×4
//! matrix); text is stored as UTF-8 bytes. The standard attributes `software`, `owner`,
//! `comments`, `capDate` (text), `worldToCamera` and `worldToNDC` (matrices) map to their
//! standard header fields; every other standard OpenEXR attribute name (`channels`,
//! `compression`, …) is reserved and rejected.
//!
//! PNG previews are 8-bit sRGB with the `sRGB` chunk, tone-mapped by [`ToneMap`].

use crate::film::Image;
use crate::math::{Mat3, Mat4, Rgb};
use crate::output_file::Sink;
use exr::meta::header::standard_names;
use exr::meta::header::Header;
use exr::prelude as ex;
use exr::prelude::{AttributeValue, Compression, ReadChannels, ReadLayers, Text, WritableImage};
use std::fs::File;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};

/// What can go wrong reading or writing an image.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The file does not exist.
    #[error("{}: file not found", path.display())]
    NotFound {
        /// The missing file.
        path: PathBuf,
    },
    /// Opening, reading, writing, syncing or renaming the file failed. The message leaves the
    /// cause to the source, so that a chain printed whole (`{:#}`) names it once.
    #[error("{}: cannot {action}", path.display())]
    Io {
        /// The file read or written.
        path: PathBuf,
        /// What was attempted, e.g. `open` or `sync`.
        action: &'static str,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The file's extension names no format this operation handles.
    #[error("{}: unsupported image format {extension:?} (expected {expected})", path.display())]
    UnsupportedFormat {
        /// The file concerned.
        path: PathBuf,
        /// The lower-case extension found, or `(none)`.
        extension: String,
        /// The extensions accepted, e.g. `.hdr or .exr`.
        expected: &'static str,
    },
    /// The file is not valid in its format: corrupt, truncated or with a header tress cannot read.
    #[error("{}: not a valid {format} file (corrupt or truncated): {reason}", path.display())]
    Corrupt {
        /// The file concerned.
        path: PathBuf,
        /// The format it was read as, e.g. `OpenEXR` or `Radiance HDR`.
        format: &'static str,
        /// The decoder's description of the problem.
        reason: String,
    },
    /// An EXR uses a compression the EXR reader cannot decode (e.g. DWAA).
    #[error(
        "{}: EXR compression {compression} is not supported by the EXR reader ({reason}); \
         re-save the file with ZIP, PIZ or no compression, or convert it to Radiance .hdr",
        path.display()
    )]
    UnsupportedCompression {
        /// The file concerned.
        path: PathBuf,
        /// The compression's name as OpenEXR tools print it.
        compression: String,
        /// The reader's message.
        reason: String,
    },
    /// A valid file whose content tress cannot use: no RGB layer, too large, or a data window
    /// outside the display window.
    #[error("{}: unsupported image content: {reason}", path.display())]
    UnsupportedContent {
        /// The file concerned.
        path: PathBuf,
        /// What tress cannot use, e.g. the channels found.
        reason: String,
    },
    /// Pixels or metadata that cannot be stored or used; `origin` names the file or the caller.
    #[error("{origin}: {reason}")]
    InvalidData {
        /// The file or caller the data came from.
        origin: String,
        /// What is wrong with the data.
        reason: String,
    },
    /// An environment-map setting is out of range (a non-finite rotation, a negative scale).
    #[error("environment map {name} must be {requirement}, got {value}")]
    InvalidParameter {
        /// The setting, e.g. `scale`.
        name: &'static str,
        /// What it must be, e.g. `finite and non-negative`.
        requirement: &'static str,
        /// The value given.
        value: f32,
    },
}

/// Largest image side and pixel count accepted on input, so that a corrupt header cannot make us
/// attempt a multi-gigabyte allocation.
const MAX_SIDE: usize = 1 << 16;
const MAX_PIXELS: usize = 1 << 28;

/// Standard text attributes that [`write_exr_channels`] stores in their header fields.
const STANDARD_TEXT: [&str; 4] = ["software", "owner", "comments", "capDate"];

/// An EXR header attribute's value, stored with its OpenEXR type.
#[derive(Clone, Debug, PartialEq)]
pub enum Attribute {
    /// `string`, UTF-8.
    Text(String),
    /// `int`.
    Int(i32),
    /// `float`.
    Float(f32),
    /// `double`.
    Double(f64),
    /// `m44f`, in the column-vector convention (`m * p`); OpenEXR stores the transpose, as
    /// Imath multiplies row vectors.
    Matrix(Mat4),
}

impl Attribute {
    /// A whole number that must stay exact (a sample count or index, a seed): an `int` when it
    /// fits, else its decimal text, so that no value is rounded or refused.
    pub fn whole(v: u64) -> Self {
        match i32::try_from(v) {
            Ok(i) => Attribute::Int(i),
            Err(_) => Attribute::Text(v.to_string()),
        }
    }

    /// The whole number of a non-negative `int`, or of decimal text ([`Self::whole`]).
    pub fn as_whole(&self) -> Option<u64> {
        match self {
            Attribute::Int(i) => u64::try_from(*i).ok(),
            Attribute::Text(t) => t.trim().parse().ok(),
            _ => None,
        }
    }

    /// The number of an `int`, `float` or `double`, or of numeric text.
    pub fn as_f64(&self) -> Option<f64> {
        match self {
            Attribute::Int(i) => Some(f64::from(*i)),
            Attribute::Float(f) => Some(f64::from(*f)),
            Attribute::Double(d) => Some(*d),
            Attribute::Text(t) => t.trim().parse().ok(),
            Attribute::Matrix(_) => None,
        }
    }

    /// The text of a `string` attribute.
    pub fn as_text(&self) -> Option<&str> {
        match self {
            Attribute::Text(t) => Some(t),
            _ => None,
        }
    }

    fn to_exr(&self) -> AttributeValue {
        match self {
            Attribute::Text(t) => AttributeValue::Text(utf8_text(t)),
            Attribute::Int(i) => AttributeValue::I32(*i),
            Attribute::Float(f) => AttributeValue::F32(*f),
            Attribute::Double(d) => AttributeValue::F64(*d),
            Attribute::Matrix(m) => AttributeValue::Matrix4x4(m.to_cols_array()),
        }
    }

    fn from_exr(value: &AttributeValue) -> Option<Self> {
        Some(match value {
            AttributeValue::Text(t) => Attribute::Text(text_string(t)),
            AttributeValue::I32(i) => Attribute::Int(*i),
            AttributeValue::F32(f) => Attribute::Float(*f),
            AttributeValue::F64(d) => Attribute::Double(*d),
            AttributeValue::Matrix4x4(m) => Attribute::Matrix(Mat4::from_cols_array(m)),
            _ => return None,
        })
    }
}

impl std::fmt::Display for Attribute {
    /// Text as it is, numbers as Rust prints them (shortest exact form), a matrix as its 16
    /// entries row by row.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Attribute::Text(t) => f.write_str(t),
            Attribute::Int(i) => write!(f, "{i}"),
            Attribute::Float(x) => write!(f, "{x}"),
            Attribute::Double(x) => write!(f, "{x}"),
            Attribute::Matrix(m) => {
                let rows = m.transpose().to_cols_array().map(|v| v.to_string());
                f.write_str(&rows.join(" "))
            }
        }
    }
}

/// The samples of one EXR channel, a value per pixel of the data window, row by row.
#[derive(Clone, Debug, PartialEq)]
pub enum ChannelSamples {
    /// 32-bit float samples.
    F32(Vec<f32>),
    /// 32-bit unsigned integer samples.
    U32(Vec<u32>),
}

impl ChannelSamples {
    fn len(&self) -> usize {
        match self {
            ChannelSamples::F32(v) => v.len(),
            ChannelSamples::U32(v) => v.len(),
        }
    }
}

/// Reads an RGB image (`.hdr` Radiance RGBE or `.exr` OpenEXR) as `(width, height, pixels)`,
/// row-major linear RGB with the top row first. For EXR the R, G, B channels of the first layer
/// that has them are read over its data window; alpha and other channels are ignored.
pub fn read_rgb(path: impl AsRef<Path>) -> Result<(u32, u32, Vec<Rgb>), ImageError> {
    let path = path.as_ref();
    match extension(path).as_str() {
        "hdr" => read_hdr(path),
        "exr" => read_exr(path).map(|(img, _)| (img.width, img.height, img.pixels)),
        other => Err(ImageError::UnsupportedFormat {
            path: path.to_owned(),
            extension: if other.is_empty() { "(none)" } else { other }.to_owned(),
            expected: ".hdr or .exr",
        }),
    }
}

/// Reads an RGB EXR: the data-window pixels placed in the display window (the full film, see
/// [`Image`]), and the header's text and numeric attributes as text ([`Attribute`]'s
/// `Display`), sorted by name; matrices are left out ([`read_exr_attributes`] has them).
pub fn read_exr(path: impl AsRef<Path>) -> Result<(Image, Vec<(String, String)>), ImageError> {
    let path = path.as_ref();
    // Header first: it names the compression for a precise error and bounds the allocation.
    let meta = ex::MetaData::read_from_unbuffered(open(path)?, false)
        .map_err(|e| exr_read_error(path, e))?;
    let Some(header) = meta.headers.iter().find(|h| has_rgb(h)) else {
        let channels: Vec<String> = meta
            .headers
            .iter()
            .flat_map(|h| h.channels.list.iter().map(|c| text_string(&c.name)))
            .collect();
        return Err(ImageError::UnsupportedContent {
            path: path.to_owned(),
            reason: format!(
                "no layer has R, G and B channels (channels: {})",
                channels.join(", ")
            ),
        });
    };
    check_size(path, header.layer_size.width(), header.layer_size.height())?;
    let compression = header.compression;

    let image = ex::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgb_channels(
            |res: ex::Vec2<usize>, _: &ex::RgbChannels| {
                (res.width(), vec![Rgb::ZERO; res.width() * res.height()])
            },
            |(w, px): &mut (usize, Vec<Rgb>), pos: ex::Vec2<usize>, (r, g, b): (f32, f32, f32)| {
                px[pos.y() * *w + pos.x()] = Rgb::new(r, g, b);
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_unbuffered(open(path)?)
        .map_err(|e| match e {
            exr::error::Error::NotSupported(reason) if reason.contains("compression") => {
                ImageError::UnsupportedCompression {
                    path: path.to_owned(),
                    compression: compression_name(compression).to_owned(),
                    reason: reason.into_owned(),
                }
            }
            e => exr_read_error(path, e),
        })?;

    let layer = &image.layer_data;
    let display = image.attributes.display_window;
    let (w, h) = (layer.size.width(), layer.size.height());
    let x0 = i64::from(layer.attributes.layer_position.x()) - i64::from(display.position.x());
    let y0 = i64::from(layer.attributes.layer_position.y()) - i64::from(display.position.y());
    let (fw, fh) = (display.size.width(), display.size.height());
    if x0 < 0 || y0 < 0 || x0 as usize + w > fw || y0 as usize + h > fh {
        return Err(ImageError::UnsupportedContent {
            path: path.to_owned(),
            reason: format!(
                "data window {w}x{h} at ({x0}, {y0}) is not inside the {fw}x{fh} display window"
            ),
        });
    }

    let mut attributes: Vec<(String, String)> = Vec::new();
    let la = &layer.attributes;
    for (name, value) in
        STANDARD_TEXT
            .iter()
            .zip([&la.software_name, &la.owner, &la.comments, &la.capture_date])
    {
        if let Some(v) = value {
            attributes.push((name.to_string(), text_string(v)));
        }
    }
    for (name, value) in la.other.iter().chain(image.attributes.other.iter()) {
        match Attribute::from_exr(value) {
            Some(Attribute::Matrix(_)) | None => {}
            Some(a) => attributes.push((text_string(name), a.to_string())),
        }
    }
    attributes.sort();

    let (_, pixels) = &layer.channel_data.pixels;
    Ok((
        Image {
            width: w as u32,
            height: h as u32,
            x0: x0 as u32,
            y0: y0 as u32,
            full_width: fw as u32,
            full_height: fh as u32,
            pixels: pixels.clone(),
        },
        attributes,
    ))
}

/// Every header attribute of the first part of an EXR, typed, sorted by name: the standard
/// text and matrix attributes tress writes ([`write_exr_channels`]) and all others of a type
/// [`Attribute`] holds.
pub fn read_exr_attributes(path: impl AsRef<Path>) -> Result<Vec<(String, Attribute)>, ImageError> {
    let path = path.as_ref();
    let meta = ex::MetaData::read_from_unbuffered(open(path)?, false)
        .map_err(|e| exr_read_error(path, e))?;
    let Some(header) = meta.headers.first() else {
        return Ok(Vec::new());
    };
    let la = &header.own_attributes;
    let mut attributes: Vec<(String, Attribute)> = Vec::new();
    for (name, value) in
        STANDARD_TEXT
            .iter()
            .zip([&la.software_name, &la.owner, &la.comments, &la.capture_date])
    {
        if let Some(v) = value {
            attributes.push((name.to_string(), Attribute::Text(text_string(v))));
        }
    }
    for (name, value) in [
        ("worldToCamera", &la.world_to_camera),
        ("worldToNDC", &la.world_to_normalized_device),
    ] {
        if let Some(m) = value {
            attributes.push((
                name.to_string(),
                Attribute::Matrix(Mat4::from_cols_array(m)),
            ));
        }
    }
    for (name, value) in la.other.iter().chain(&header.shared_attributes.other) {
        if let Some(a) = Attribute::from_exr(value) {
            attributes.push((text_string(name), a));
        }
    }
    attributes.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(attributes)
}

/// Writes `image` as a linear f32 RGB EXR (lossless ZIP compression): the display window is the
/// full film and the data window the image's pixel window, so a crop shows in place. `attributes`
/// become text attributes of the header (scene, integrator, spp, seed, render time, …).
pub fn write_exr(
    out: &mut Sink,
    image: &Image,
    attributes: &[(&str, String)],
) -> Result<(), ImageError> {
    let path = out.path();
    check_image(image).map_err(|reason| ImageError::InvalidData {
        origin: path.display().to_string(),
        reason,
    })?;
    let channels = (0..3)
        .map(|c| {
            let values = image.pixels.iter().map(|p| p[c]).collect();
            (["R", "G", "B"][c].to_string(), ChannelSamples::F32(values))
        })
        .collect();
    let attributes: Vec<(&str, Attribute)> = attributes
        .iter()
        .map(|(n, v)| (*n, Attribute::Text(v.clone())))
        .collect();
    write_exr_channels(
        out,
        [
            image.x0,
            image.y0,
            image.x0 + image.width,
            image.y0 + image.height,
        ],
        (image.full_width, image.full_height),
        channels,
        &attributes,
    )
}

/// Writes a single-part EXR of named channels (lossless ZIP compression): the display window is the `film` (width, height) and the data window `window` = `[x0, y0, x1,
/// y1)`, whose pixels every channel holds row by row. Names follow OpenEXR's layer convention
/// (`R`, `A`, `depth.Z`, `albedo.R`). `attributes` keep their types; the standard ones go to
/// their header fields (module notes).
pub fn write_exr_channels(
    out: &mut Sink,
    window: [u32; 4],
    film: (u32, u32),
    channels: Vec<(String, ChannelSamples)>,
    attributes: &[(&str, Attribute)],
) -> Result<(), ImageError> {
    let path = out.path().to_owned();
    let path = path.as_path();
    let invalid = |reason: String| ImageError::InvalidData {
        origin: path.display().to_string(),
        reason,
    };
    let [x0, y0, x1, y1] = window;
    let (full_width, full_height) = film;
    let fits = |a: u32, b: u32, full: u32| a < b && b <= full && full <= i32::MAX as u32;
    if !fits(x0, x1, full_width) || !fits(y0, y1, full_height) {
        return Err(invalid(format!(
            "pixel window [{x0}, {x1})x[{y0}, {y1}) is empty or not inside the \
             {full_width}x{full_height} film"
        )));
    }
    let (w, h) = ((x1 - x0) as usize, (y1 - y0) as usize);
    if channels.is_empty() {
        return Err(invalid("an EXR needs at least one channel".into()));
    }
    for (name, samples) in &channels {
        if samples.len() != w * h {
            return Err(invalid(format!(
                "channel {name} of the {w}x{h} image has {} samples instead of {}",
                samples.len(),
                w * h
            )));
        }
        if name.is_empty() || name.len() > 255 || name.contains('\0') {
            return Err(invalid(format!(
                "EXR channel name {name:?} must be 1 to 255 bytes without NUL"
            )));
        }
    }

    let mut la = ex::LayerAttributes {
        layer_position: ex::Vec2(x0 as i32, y0 as i32),
        ..Default::default()
    };
    for (name, value) in attributes {
        let text = || match value {
            Attribute::Text(t) => Ok(utf8_text(t)),
            _ => Err(invalid(format!("EXR attribute {name:?} must be text"))),
        };
        let matrix = || match value {
            Attribute::Matrix(m) => Ok(m.to_cols_array()),
            _ => Err(invalid(format!(
                "EXR attribute {name:?} must be a 4x4 matrix"
            ))),
        };
        match *name {
            "software" => la.software_name = Some(text()?),
            "owner" => la.owner = Some(text()?),
            "comments" => la.comments = Some(text()?),
            "capDate" => la.capture_date = Some(text()?),
            "worldToCamera" => la.world_to_camera = Some(matrix()?),
            "worldToNDC" => la.world_to_normalized_device = Some(matrix()?),
            n if n.is_empty() || n.len() > 255 || n.contains('\0') => {
                return Err(invalid(format!(
                    "EXR attribute name {n:?} must be 1 to 255 bytes without NUL"
                )));
            }
            n if standard_names::ALL.contains(&n.as_bytes()) => {
                return Err(invalid(format!(
                    "EXR attribute name {n:?} is reserved by the OpenEXR standard"
                )));
            }
            n => {
                la.other.insert(utf8_text(n), value.to_exr());
            }
        }
    }

    let mut list: ex::SmallVec<[ex::AnyChannel<ex::FlatSamples>; 4]> = ex::SmallVec::new();
    for (name, samples) in channels {
        let samples = match samples {
            ChannelSamples::F32(v) => ex::FlatSamples::F32(v),
            ChannelSamples::U32(v) => ex::FlatSamples::U32(v),
        };
        list.push(ex::AnyChannel::new(utf8_text(&name), samples));
    }
    let layer = ex::Layer::new(
        (w, h),
        la,
        ex::Encoding::SMALL_LOSSLESS,
        ex::AnyChannels::sort(list),
    );
    let mut exr_image = ex::Image::from_layer(layer);
    exr_image.attributes.display_window =
        ex::IntegerBounds::new(ex::Vec2(0, 0), (full_width as usize, full_height as usize));
    exr_image.write().to_buffered(out).map_err(|e| match e {
        exr::error::Error::Io(source) => ImageError::Io {
            path: path.to_owned(),
            action: "write",
            source,
        },
        e => invalid(format!("cannot encode EXR: {e}")),
    })
}

/// How a PNG preview maps linear radiance (after exposure) to display values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ToneMap {
    /// Each channel clamped to [0, 1]: exact below 1, everything brighter clips to white (and
    /// bright colours shift toward the hue of their clipped channels).
    Clamp,
    /// AgX, the view transform Blender uses by default since 4.0 (Troy Sobotka's design in
    /// Eary Chow's version, as simplified without its gamut guard rails by Allen Pestaluky,
    /// github.com/allenwp/AgX-GLSL-Shaders): linear Rec. 709 goes to Rec. 2020 and through
    /// AgX's inset matrix, is log-encoded from 10 stops below to 6.5 stops above middle grey,
    /// shaped by AgX's sigmoid and brought back through the outset matrix. Middle grey 0.18 stays
    /// 0.18 and black stays black; highlights roll off smoothly and desaturate toward white,
    /// which they reach at about 16 (4 stops above 1) instead of clipping at 1.
    Filmic,
}

impl ToneMap {
    /// Both, as `--tonemap` lists them.
    pub const ALL: [ToneMap; 2] = [ToneMap::Clamp, ToneMap::Filmic];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ToneMap::Clamp => "clamp",
            ToneMap::Filmic => "filmic",
        }
    }

    /// Display-linear RGB in [0, 1] for linear scene radiance `c` (NaN counts as 0).
    pub fn apply(self, c: Rgb) -> Rgb {
        match self {
            ToneMap::Clamp => {
                let c = Rgb::select(c.is_nan_mask(), Rgb::ZERO, c);
                c.clamp(Rgb::ZERO, Rgb::ONE)
            }
            ToneMap::Filmic => agx(c),
        }
    }
}

impl std::fmt::Display for ToneMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for ToneMap {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        ToneMap::ALL
            .into_iter()
            .find(|t| t.name() == s.trim())
            .ok_or_else(|| format!("unknown tone mapping '{s}' (expected clamp or filmic)"))
    }
}

/// The AgX transform of [`ToneMap::Filmic`]: linear Rec. 709 radiance → display-linear Rec. 709
/// in [0, 1]. The constants are those of the simplified AgX named there.
fn agx(c: Rgb) -> Rgb {
    // Linear Rec. 709 → Rec. 2020 → AgX inset, as one matrix (given column by column).
    const INSET: Mat3 = Mat3::from_cols_array(&[
        0.544_908_14,
        0.140_440_06,
        0.088_827_41,
        0.373_779_46,
        0.754_109_6,
        0.178_877_12,
        0.081_384_98,
        0.105_433_58,
        0.732_25,
    ]);
    // AgX outset → linear Rec. 2020 → Rec. 709.
    const OUTSET: Mat3 = Mat3::from_cols_array(&[
        1.964_551,
        -0.299_322_43,
        -0.164_368_34,
        -0.855_858_45,
        1.326_451_1,
        -0.238_224_64,
        -0.108_867_11,
        -0.027_084_02,
        1.402_665_4,
    ]);
    // log2 of middle grey 0.18 times 2^-10 and 2^6.5: the encoded range.
    const MIN_EV: f32 = -12.473_931;
    const MAX_EV: f32 = 4.026_069;
    // The sigmoid: pivot at middle grey (x = 10 / 16.5, y = 0.18^(1/2.4)), slope 2.4, toe and
    // shoulder powers 1.5; (a, b) below and above the pivot.
    const X_PIVOT: f32 = 10.0 / 16.5;
    const Y_PIVOT: f32 = 0.489_437_1;
    const BOTTOM: (f32, f32) = (-58.337_322, 35.355_953);
    const TOP: (f32, f32) = (46.141_05, -27.964_273);
    const SCALE: f32 = 0.019_613_087;
    // Negative and NaN radiance count as (nearly) zero; the floor keeps log2 finite.
    let c = INSET * c.max(Rgb::splat(2e-10));
    let curve = |v: f32| {
        let x = ((v.log2() - MIN_EV) / (MAX_EV - MIN_EV)).clamp(0.0, 1.0);
        let (a, b) = if x < X_PIVOT { BOTTOM } else { TOP };
        let y = Y_PIVOT
            + 2.4 * (x - X_PIVOT) / (1.0 + SCALE * (b + a * x).abs().powf(1.5)).powf(1.0 / 1.5);
        y.max(0.0).powf(2.4)
    };
    let display = OUTSET * Rgb::new(curve(c.x), curve(c.y), curve(c.z));
    display.clamp(Rgb::ZERO, Rgb::ONE)
}

/// Writes an 8-bit sRGB PNG preview of the image's pixel window, each channel scaled by
/// 2^`exposure_stops` and clamped to [0, 1] ([`ToneMap::Clamp`]).
pub fn write_png(out: &mut Sink, image: &Image, exposure_stops: f32) -> Result<(), ImageError> {
    write_png_tonemapped(out, image, exposure_stops, ToneMap::Clamp)
}

/// Writes an 8-bit PNG preview of the image's pixel window: the radiance scaled by
/// 2^`exposure_stops`, mapped to display values by `tonemap`, encoded with the sRGB curve, and
/// marked as sRGB (the `sRGB` chunk, perceptual intent).
pub fn write_png_tonemapped(
    out: &mut Sink,
    image: &Image,
    exposure_stops: f32,
    tonemap: ToneMap,
) -> Result<(), ImageError> {
    let path = out.path().to_owned();
    let invalid = |reason: String| ImageError::InvalidData {
        origin: path.display().to_string(),
        reason,
    };
    check_image(image).map_err(invalid)?;
    if !exposure_stops.is_finite() {
        return Err(invalid(format!(
            "exposure must be finite, got {exposure_stops}"
        )));
    }
    let gain = exposure_stops.exp2();
    let bytes: Vec<u8> = image
        .pixels
        .iter()
        .flat_map(|p| tonemap.apply(*p * gain).to_array())
        .map(srgb_byte)
        .collect();
    write_srgb_png(out, image.width, image.height, &bytes)
}

/// Writes 8-bit sRGB pixels (`rgb`: R, G, B per pixel, rows top to bottom) as a PNG marked as
/// sRGB (the `sRGB` chunk, perceptual intent).
pub fn write_srgb_png(
    out: &mut Sink,
    width: u32,
    height: u32,
    rgb: &[u8],
) -> Result<(), ImageError> {
    let path = out.path().to_owned();
    let encode_error = |e: png::EncodingError| match e {
        png::EncodingError::IoError(source) => ImageError::Io {
            path: path.clone(),
            action: "write",
            source,
        },
        e => ImageError::InvalidData {
            origin: path.display().to_string(),
            reason: format!("cannot encode PNG: {e}"),
        },
    };
    let mut encoder = png::Encoder::new(out, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    let mut writer = encoder.write_header().map_err(encode_error)?;
    writer.write_image_data(rgb).map_err(encode_error)?;
    writer.finish().map_err(encode_error)
}

/// Display-linear value in [0, 1] → 8-bit sRGB code (clamped; NaN becomes 0).
fn srgb_byte(c: f32) -> u8 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    let s = if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

fn check_image(image: &Image) -> Result<(), String> {
    let (w, h) = (image.width as usize, image.height as usize);
    if w == 0 || h == 0 {
        return Err(format!("image {w}x{h} is empty"));
    }
    if image.pixels.len() != w * h {
        return Err(format!(
            "image {w}x{h} has {} pixels instead of {}",
            image.pixels.len(),
            w * h
        ));
    }
    let fits = |start: u32, len: u32, full: u32| {
        start.checked_add(len).is_some_and(|end| end <= full) && full <= i32::MAX as u32
    };
    if !fits(image.x0, image.width, image.full_width)
        || !fits(image.y0, image.height, image.full_height)
    {
        return Err(format!(
            "pixel window {w}x{h} at ({}, {}) is not inside the {}x{} film",
            image.x0, image.y0, image.full_width, image.full_height
        ));
    }
    Ok(())
}

fn read_hdr(path: &Path) -> Result<(u32, u32, Vec<Rgb>), ImageError> {
    use image::ImageDecoder;
    let file = open(path)?;
    let decoder = image::codecs::hdr::HdrDecoder::new(BufReader::new(file))
        .map_err(|e| hdr_error(path, e))?;
    let (w, h) = decoder.dimensions();
    check_size(path, w as usize, h as usize)?;
    let img = image::DynamicImage::from_decoder(decoder)
        .map_err(|e| hdr_error(path, e))?
        .into_rgb32f();
    let pixels = img
        .pixels()
        .map(|p| Rgb::new(p.0[0], p.0[1], p.0[2]))
        .collect();
    Ok((w, h, pixels))
}

fn hdr_error(path: &Path, e: image::ImageError) -> ImageError {
    if let Some(line) = hdr_nonstandard_orientation(path) {
        return ImageError::Corrupt {
            path: path.to_owned(),
            format: "Radiance HDR",
            reason: format!(
                "the resolution line `{line}` gives an orientation tress does not read; only \
                 the standard `-Y height +X width` (rows top to bottom, left to right) is \
                 supported: convert the map (e.g. re-save it from an image editor)"
            ),
        };
    }
    match e {
        image::ImageError::IoError(source)
            if source.kind() != std::io::ErrorKind::UnexpectedEof =>
        {
            ImageError::Io {
                path: path.to_owned(),
                action: "read",
                source,
            }
        }
        e => ImageError::Corrupt {
            path: path.to_owned(),
            format: "Radiance HDR",
            reason: e.to_string(),
        },
    }
}

/// The resolution line of a Radiance file when it is well formed but not the standard
/// `-Y h +X w` (e.g. `+Y 512 -X 1024`), which the decoder reports only as a bad header.
fn hdr_nonstandard_orientation(path: &Path) -> Option<String> {
    let mut head = Vec::new();
    crate::files::open_regular(path)
        .ok()?
        .take(64 * 1024)
        .read_to_end(&mut head)
        .ok()?;
    let end = head.windows(2).position(|w| w == b"\n\n")? + 2;
    let line = head[end..].split(|&b| b == b'\n').next()?;
    let line = std::str::from_utf8(line).ok()?.trim();
    let words: Vec<&str> = line.split_whitespace().collect();
    let axis = |w: &str| matches!(w, "-Y" | "+Y" | "-X" | "+X");
    let numbers = |w: &str| w.parse::<u32>().is_ok();
    let well_formed = words.len() == 4
        && axis(words[0])
        && numbers(words[1])
        && axis(words[2])
        && numbers(words[3]);
    (well_formed && !(words[0] == "-Y" && words[2] == "+X")).then(|| line.to_owned())
}

fn exr_read_error(path: &Path, e: exr::error::Error) -> ImageError {
    use exr::error::Error as E;
    match e {
        E::Io(source) if source.kind() == std::io::ErrorKind::NotFound => ImageError::NotFound {
            path: path.to_owned(),
        },
        E::Io(source) => ImageError::Io {
            path: path.to_owned(),
            action: "read",
            source,
        },
        E::NotSupported(reason) => ImageError::UnsupportedContent {
            path: path.to_owned(),
            reason: reason.into_owned(),
        },
        E::Invalid(reason) => ImageError::Corrupt {
            path: path.to_owned(),
            format: "OpenEXR",
            reason: reason.into_owned(),
        },
        E::Aborted => ImageError::Corrupt {
            path: path.to_owned(),
            format: "OpenEXR",
            reason: "reading was aborted".into(),
        },
    }
}

/// The compression's name as OpenEXR tools print it.
fn compression_name(c: Compression) -> &'static str {
    match c {
        Compression::Uncompressed => "NONE",
        Compression::RLE => "RLE",
        Compression::ZIP1 => "ZIPS",
        Compression::ZIP16 => "ZIP",
        Compression::PIZ => "PIZ",
        Compression::PXR24 => "PXR24",
        Compression::B44 => "B44",
        Compression::B44A => "B44A",
        Compression::DWAA(_) => "DWAA",
        Compression::DWAB(_) => "DWAB",
        Compression::HTJ2K256 => "HTJ2K256",
        Compression::HTJ2K32 => "HTJ2K32",
    }
}

fn has_rgb(h: &Header) -> bool {
    ["R", "G", "B"].iter().all(|n| {
        h.channels
            .list
            .iter()
            .any(|c| c.name.bytes() == n.as_bytes())
    })
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// `path` opened through [`crate::files::open_regular`], with a missing file named as such.
fn open(path: &Path) -> Result<File, ImageError> {
    match crate::files::open_regular(path) {
        Ok(file) => Ok(file),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Err(ImageError::NotFound {
            path: path.to_owned(),
        }),
        Err(source) => Err(ImageError::Io {
            path: path.to_owned(),
            action: "read",
            source,
        }),
    }
}

fn check_size(path: &Path, w: usize, h: usize) -> Result<(), ImageError> {
    if w == 0 || h == 0 || w > MAX_SIDE || h > MAX_SIDE || w * h > MAX_PIXELS {
        return Err(ImageError::UnsupportedContent {
            path: path.to_owned(),
            reason: format!(
                "image size {w}x{h} is empty or too large (at most {MAX_SIDE} pixels a side and \
                 {MAX_PIXELS} in all)"
            ),
        });
    }
    Ok(())
}

fn utf8_text(s: &str) -> Text {
    Text::from_bytes_unchecked(s.as_bytes().into())
}

/// Attribute text as UTF-8, falling back to Latin-1 (the byte-per-char reading of older files).
fn text_string(t: &Text) -> String {
    String::from_utf8(t.bytes().to_vec()).unwrap_or_else(|_| t.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::output_file::{self, Inputs};
    use crate::test_util::files_in;

    /// Writes one output at `path` with `write`, as every caller does.
    fn to_file(
        path: impl AsRef<Path>,
        write: impl FnOnce(&mut Sink) -> Result<(), ImageError>,
    ) -> Result<(), Box<dyn std::error::Error + Send + Sync>> {
        output_file::write(path.as_ref(), &Inputs::default(), |out| {
            write(out).map_err(Box::from)
        })
    }

    const SUNSET_DWAB: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/envmaps/blender_studiolights_exr/sunset.exr"
    );
    const VENICE: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/envmaps/venice_sunset_1k.hdr"
    );

    fn test_image() -> Image {
        let mut img = Image::window([3, 5, 13, 12], 20, 16);
        for y in 0..img.height {
            for x in 0..img.width {
                let k = (y * img.width + x) as f32;
                img.set(x, y, Rgb::new(k * 0.25, -k * 1e-3, 1.0 / (k + 1.0)));
            }
        }
        // Values that a lossy or half-float path would not return bit for bit.
        img.set(0, 0, Rgb::new(f32::NAN, f32::INFINITY, 1e-40));
        img.set(1, 0, Rgb::new(3.4e38, 1.000_000_1, -0.0));
        img
    }

    fn same_bits(a: &Image, b: &Image) -> bool {
        a.pixels.len() == b.pixels.len()
            && a.pixels
                .iter()
                .zip(&b.pixels)
                .all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits))
    }

    #[test]
    fn exr_round_trip_keeps_window_pixels_and_attributes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("render.exr");
        let img = test_image();
        let attrs = [
            ("scene", "scènes/hair ball.ron".to_string()),
            ("integrator", "path".to_string()),
            ("spp", "64".to_string()),
            ("seed", "7".to_string()),
            ("render_time_s", "12.5".to_string()),
            ("software", "tress 0.0.0".to_string()),
            (
                "a.long.attribute.name.of.more.than.32.bytes",
                "x".to_string(),
            ),
        ];
        to_file(&path, |o| write_exr(o, &img, &attrs)).unwrap();
        assert_eq!(
            files_in(dir.path()),
            ["render.exr"],
            "temporary file left behind"
        );

        let (back, back_attrs) = read_exr(&path).unwrap();
        assert!(same_bits(&img, &back));
        assert_eq!(
            (back.x0, back.y0, back.width, back.height),
            (img.x0, img.y0, img.width, img.height)
        );
        assert_eq!((back.full_width, back.full_height), (20, 16));
        let mut expected: Vec<(String, String)> = attrs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect();
        expected.sort();
        assert_eq!(back_attrs, expected);

        // What other tools see: display window = film, data window = crop.
        let meta = ex::MetaData::read_from_file(&path, true).unwrap();
        let h = &meta.headers[0];
        assert_eq!(h.shared_attributes.display_window.size, ex::Vec2(20, 16));
        assert_eq!(h.shared_attributes.display_window.position, ex::Vec2(0, 0));
        assert_eq!(h.own_attributes.layer_position, ex::Vec2(3, 5));
        assert_eq!(h.layer_size, ex::Vec2(10, 7));
        assert_eq!(h.compression, Compression::ZIP16);

        // read_rgb returns the data window; R, G, B are not permuted (the file stores B, G, R).
        let (w, hgt, px) = read_rgb(&path).unwrap();
        assert_eq!((w, hgt), (10, 7));
        assert_eq!(px[7 * 10 - 1], img.get(9, 6));
        assert!(px[5].x > 0.0 && px[5].y < 0.0 && px[5].z < 1.0);
    }

    #[test]
    fn exr_write_replaces_atomically_and_rejects_bad_input() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.exr");
        let img = test_image();
        to_file(&path, |o| write_exr(o, &Image::new(2, 2), &[])).unwrap();
        to_file(&path, |o| write_exr(o, &img, &[])).unwrap();
        assert!(same_bits(&read_exr(&path).unwrap().0, &img));
        let before = std::fs::read(&path).unwrap();

        let reserved = to_file(&path, |o| {
            write_exr(o, &Image::new(2, 2), &[("channels", "x".into())])
        });
        let msg = reserved.unwrap_err().to_string();
        assert!(
            msg.contains("out.exr") && msg.contains("\"channels\""),
            "{msg}"
        );
        let long = "n".repeat(300);
        assert!(to_file(&path, |o| write_exr(
            o,
            &Image::new(2, 2),
            &[(long.as_str(), "x".into())]
        ))
        .is_err());
        let mut short = Image::new(4, 4);
        short.pixels.pop();
        let msg = to_file(&path, |o| write_exr(o, &short, &[]))
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("out.exr") && msg.contains("15 pixels"),
            "{msg}"
        );
        let mut outside = Image::window([0, 0, 4, 4], 8, 8);
        outside.x0 = 6;
        assert!(to_file(&path, |o| write_exr(o, &outside, &[])).is_err());
        assert_eq!(
            std::fs::read(&path).unwrap(),
            before,
            "failed writes touched the file"
        );
        assert_eq!(files_in(dir.path()), ["out.exr"]);
        // The mode of any new file (0666 less the umask), not tempfile's private 0600.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode();
            let plain = dir.path().join("plain");
            std::fs::write(&plain, b"").unwrap();
            assert_eq!(mode(&path), mode(&plain));
            std::fs::remove_file(plain).unwrap();
        }

        let nowhere = dir.path().join("missing-dir/out.exr");
        let msg = to_file(&nowhere, |o| write_exr(o, &img, &[]))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("missing-dir/out.exr"), "{msg}");
    }

    #[test]
    fn exr_unsupported_compression_is_named_with_a_remedy() {
        // exr 1.74 decodes DWAA/DWAB but not HTJ2K: relabel a ZIP file as HTJ2K32. A single
        // 16-line block keeps the chunk table valid for both (ZIP: 16 lines, HTJ2K32: 32).
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("htj2k.exr");
        to_file(&path, |o| write_exr(o, &Image::new(16, 16), &[])).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        let key = b"compression\0compression\0\x01\0\0\0";
        let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len();
        assert_eq!(bytes[at], 3, "expected ZIP compression");
        bytes[at] = 11;
        std::fs::write(&path, &bytes).unwrap();
        let err = read_rgb(&path).unwrap_err();
        assert!(
            matches!(err, ImageError::UnsupportedCompression { .. }),
            "{err:?}"
        );
        let msg = err.to_string();
        assert!(
            msg.contains("htj2k.exr") && msg.contains("HTJ2K32") && msg.contains("re-save"),
            "{msg}"
        );
    }

    #[test]
    fn exr_dwab_file_is_read() {
        if !Path::new(SUNSET_DWAB).exists() {
            eprintln!("skipping exr_dwab_file_is_read: {SUNSET_DWAB} is absent");
            return;
        }
        let meta = ex::MetaData::read_from_file(SUNSET_DWAB, false).unwrap();
        assert!(matches!(meta.headers[0].compression, Compression::DWAB(_)));
        let (w, h, px) = read_rgb(SUNSET_DWAB).unwrap();
        assert_eq!((w, h), (1024, 512));
        assert!(px.iter().all(|p| p.is_finite()));
        let mean = px.iter().map(|p| luminance_f64(*p)).sum::<f64>() / px.len() as f64;
        assert!(mean > 0.01 && mean < 100.0, "{mean}");
    }

    fn luminance_f64(p: Rgb) -> f64 {
        crate::math::luminance(p) as f64
    }

    #[test]
    fn exr_without_rgb_channels_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("luma.exr");
        let channels = ex::SpecificChannels::build()
            .with_channel("Y")
            .with_pixel_fn(|_: ex::Vec2<usize>| (0.5f32,));
        ex::Image::from_channels((4, 4), channels)
            .write()
            .to_file(&path)
            .unwrap();
        let msg = read_rgb(&path).unwrap_err().to_string();
        assert!(
            msg.contains("luma.exr") && msg.contains("channels: Y"),
            "{msg}"
        );
    }

    #[test]
    fn hdr_is_read_and_broken_files_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("small.hdr");
        let (w, h) = (37usize, 5usize);
        let src: Vec<image::Rgb<f32>> = (0..w * h)
            .map(|k| image::Rgb([k as f32 * 0.5 + 0.1, 1.0, 100.0 / (k as f32 + 1.0)]))
            .collect();
        let mut bytes = Vec::new();
        image::codecs::hdr::HdrEncoder::new(&mut bytes)
            .encode(&src, w, h)
            .unwrap();
        std::fs::write(&path, &bytes).unwrap();
        let (rw, rh, px) = read_rgb(&path).unwrap();
        assert_eq!((rw as usize, rh as usize), (w, h));
        for (p, s) in px.iter().zip(&src) {
            for c in 0..3 {
                // RGBE keeps 8 mantissa bits per pixel (shared exponent).
                let max = s.0.iter().cloned().fold(0.0, f32::max);
                assert!((p[c] - s.0[c]).abs() <= max / 128.0, "{p} vs {:?}", s.0);
            }
        }

        let truncated = dir.path().join("truncated.hdr");
        std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
        let err = read_rgb(&truncated).unwrap_err();
        assert!(err.to_string().contains("truncated.hdr"), "{err}");
        assert!(matches!(err, ImageError::Corrupt { .. }), "{err:?}");

        for name in ["garbage.hdr", "garbage.exr"] {
            let p = dir.path().join(name);
            std::fs::write(&p, b"this is not an image at all, just some text bytes").unwrap();
            let err = read_rgb(&p).unwrap_err();
            assert!(err.to_string().contains(name), "{err}");
            assert!(matches!(err, ImageError::Corrupt { .. }), "{err:?}");
        }
        let cut = dir.path().join("cut.exr");
        to_file(&cut, |o| write_exr(o, &Image::new(64, 64), &[])).unwrap();
        let exr_bytes = std::fs::read(&cut).unwrap();
        std::fs::write(&cut, &exr_bytes[..exr_bytes.len() * 2 / 3]).unwrap();
        let err = read_rgb(&cut).unwrap_err();
        assert!(matches!(err, ImageError::Corrupt { .. }), "{err:?}");
        assert!(err.to_string().contains("cut.exr"), "{err}");
        let empty = dir.path().join("empty.exr");
        std::fs::write(&empty, b"").unwrap();
        assert!(read_rgb(&empty)
            .unwrap_err()
            .to_string()
            .contains("empty.exr"));
    }

    #[test]
    fn missing_and_unsupported_files_are_named() {
        for p in ["/nonexistent/a.hdr", "/nonexistent/b.exr"] {
            let err = read_rgb(p).unwrap_err();
            assert!(matches!(err, ImageError::NotFound { .. }), "{err:?}");
            assert_eq!(err.to_string(), format!("{p}: file not found"));
        }
        assert!(matches!(
            read_exr("/nonexistent/c.exr"),
            Err(ImageError::NotFound { .. })
        ));
        let err = read_rgb("/tmp/picture.png").unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("picture.png") && msg.contains("\"png\""),
            "{msg}"
        );
    }

    #[test]
    fn real_hdr_map_reads() {
        if !Path::new(VENICE).exists() {
            eprintln!("skipping real_hdr_map_reads: {VENICE} is absent");
            return;
        }
        let (w, h, px) = read_rgb(VENICE).unwrap();
        assert_eq!((w, h), (1024, 512));
        assert!(px.iter().all(|p| p.is_finite() && p.min_element() >= 0.0));
    }

    #[test]
    fn png_preview_is_exposed_clamped_and_srgb_encoded() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("preview.png");
        let mut img = Image::window([1, 1, 5, 2], 8, 8);
        img.pixels = vec![
            Rgb::new(0.5, 0.0, 1.0),
            Rgb::new(2.0, -1.0, f32::NAN),
            Rgb::new(0.001, 0.25, 0.18),
            Rgb::ONE,
        ];
        to_file(&path, |o| write_png(o, &img, 0.0)).unwrap();
        let back = image::open(&path).unwrap().into_rgb8();
        assert_eq!(back.dimensions(), (4, 1));
        assert_eq!(back.get_pixel(0, 0).0, [188, 0, 255]);
        assert_eq!(back.get_pixel(1, 0).0, [255, 0, 0]);
        assert_eq!(back.get_pixel(2, 0).0, [3, 137, 118]);
        // One stop up doubles the linear value: 0.25 → 0.5.
        to_file(&path, |o| write_png(o, &img, 1.0)).unwrap();
        let back = image::open(&path).unwrap().into_rgb8();
        assert_eq!(back.get_pixel(2, 0).0[1], 188);
        assert_eq!(files_in(dir.path()), ["preview.png"]);
        let msg = to_file(&path, |o| write_png(o, &img, f32::NAN))
            .unwrap_err()
            .to_string();
        assert!(msg.contains("preview.png"), "{msg}");
    }

    #[test]
    fn typed_attributes_and_named_channels_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("layers.exr");
        let to_camera = Mat4::from_cols_array(&std::array::from_fn(|i| i as f32 - 3.5));
        let to_ndc = Mat4::from_diagonal(glam::Vec4::new(0.5, -2.0, 0.0, 1.0));
        let (w, h) = (3usize, 2usize);
        let ramp = |k: f32| (0..w * h).map(|i| i as f32 * k).collect::<Vec<f32>>();
        let channels = vec![
            ("R".to_string(), ChannelSamples::F32(ramp(1.0))),
            ("G".to_string(), ChannelSamples::F32(ramp(2.0))),
            ("B".to_string(), ChannelSamples::F32(ramp(3.0))),
            ("A".to_string(), ChannelSamples::F32(ramp(0.1))),
            (
                "depth.Z".to_string(),
                ChannelSamples::F32(vec![f32::INFINITY; w * h]),
            ),
            (
                "x.count".to_string(),
                ChannelSamples::U32(vec![u32::MAX; w * h]),
            ),
        ];
        let attributes = [
            ("software", Attribute::Text("tress 9.9.9".into())),
            ("worldToCamera", Attribute::Matrix(to_camera)),
            ("worldToNDC", Attribute::Matrix(to_ndc)),
            ("tress:spp", Attribute::whole(64)),
            ("tress:seed", Attribute::whole(1 << 40)),
            ("tress:render_time_s", Attribute::Double(12.5)),
            ("tress:gain", Attribute::Float(0.25)),
            ("tress:scene", Attribute::Text("scènes/a.ron".into())),
        ];
        to_file(&path, |o| {
            write_exr_channels(o, [4, 1, 7, 3], (10, 5), channels, &attributes)
        })
        .unwrap();

        let back = read_exr_attributes(&path).unwrap();
        let mut expected: Vec<(String, Attribute)> = attributes
            .iter()
            .map(|(n, a)| (n.to_string(), a.clone()))
            .collect();
        expected.sort_by(|a, b| a.0.cmp(&b.0));
        assert_eq!(back, expected);
        assert_eq!(
            Attribute::whole(1 << 40),
            Attribute::Text("1099511627776".into())
        );
        assert_eq!(
            back.iter()
                .find(|a| a.0 == "tress:seed")
                .unwrap()
                .1
                .as_whole(),
            Some(1 << 40)
        );
        assert_eq!(Attribute::Int(-1).as_whole(), None);
        assert_eq!(Attribute::Double(12.5).as_f64(), Some(12.5));

        // Other tools see OpenEXR's types and standard fields; matrices as Imath stores them
        // (row vectors: the translation in the last row).
        let meta = ex::MetaData::read_from_file(&path, false).unwrap();
        let header = &meta.headers[0];
        let la = &header.own_attributes;
        assert_eq!(la.world_to_camera, Some(to_camera.to_cols_array()));
        assert_eq!(la.world_to_camera.unwrap()[12], to_camera.w_axis.x);
        assert_eq!(la.world_to_normalized_device, Some(to_ndc.to_cols_array()));
        assert_eq!(
            la.software_name.as_ref().map(text_string).as_deref(),
            Some("tress 9.9.9")
        );
        let other = |n: &str| la.other.get(&utf8_text(n)).cloned();
        assert_eq!(other("tress:spp"), Some(AttributeValue::I32(64)));
        assert_eq!(
            other("tress:render_time_s"),
            Some(AttributeValue::F64(12.5))
        );
        assert_eq!(other("tress:gain"), Some(AttributeValue::F32(0.25)));
        let names: Vec<String> = header
            .channels
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect();
        assert_eq!(names, ["A", "B", "G", "R", "depth.Z", "x.count"]);
        assert_eq!(header.layer_size, ex::Vec2(3, 2));
        assert_eq!(header.own_attributes.layer_position, ex::Vec2(4, 1));

        // read_exr: the RGB pixels, the attributes as text without the matrices.
        let (image, text) = read_exr(&path).unwrap();
        assert_eq!(image.get(2, 1), Rgb::new(5.0, 10.0, 15.0));
        let get = |n: &str| text.iter().find(|a| a.0 == n).map(|a| a.1.as_str());
        assert_eq!(get("tress:spp"), Some("64"));
        assert_eq!(get("tress:render_time_s"), Some("12.5"));
        assert_eq!(get("software"), Some("tress 9.9.9"));
        assert_eq!(get("worldToCamera"), None);
    }

    #[test]
    fn bad_channels_and_mistyped_standard_attributes_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.exr");
        let one = || vec![("R".to_string(), ChannelSamples::F32(vec![0.0; 4]))];
        let write = |channels, attributes: &[(&str, Attribute)]| {
            to_file(&path, |o| {
                write_exr_channels(o, [0, 0, 2, 2], (2, 2), channels, attributes)
            })
            .unwrap_err()
            .to_string()
        };
        let msg = write(one(), &[("worldToNDC", Attribute::Text("identity".into()))]);
        assert!(
            msg.contains("bad.exr") && msg.contains("worldToNDC") && msg.contains("matrix"),
            "{msg}"
        );
        let msg = write(one(), &[("software", Attribute::Int(1))]);
        assert!(msg.contains("\"software\" must be text"), "{msg}");
        let msg = write(one(), &[("dataWindow", Attribute::Int(1))]);
        assert!(msg.contains("reserved"), "{msg}");
        let short = vec![("R".to_string(), ChannelSamples::F32(vec![0.0; 3]))];
        let msg = write(short, &[]);
        assert!(
            msg.contains("channel R") && msg.contains("3 samples instead of 4"),
            "{msg}"
        );
        assert!(write(Vec::new(), &[]).contains("at least one channel"));
        let msg = to_file(&path, |o| {
            write_exr_channels(o, [0, 0, 3, 2], (2, 2), one(), &[])
        })
        .unwrap_err()
        .to_string();
        assert!(msg.contains("not inside the 2x2 film"), "{msg}");
        assert!(!path.exists());
    }

    /// The filmic curve on grey and on coloured ramps: black stays black, nothing decreases as
    /// the light grows, middle grey is kept, and the output approaches white without passing 1
    /// (clamp instead reaches 1 at 1 and clips everything brighter).
    #[test]
    fn filmic_curve_is_monotone_keeps_black_and_saturates_below_one() {
        let filmic = |c: Rgb| ToneMap::Filmic.apply(c);
        assert_eq!(filmic(Rgb::ZERO), Rgb::ZERO);
        assert_eq!(filmic(Rgb::splat(-3.0)), Rgb::ZERO);
        assert_eq!(filmic(Rgb::splat(f32::NAN)), Rgb::ZERO);
        let grey = filmic(Rgb::splat(0.18));
        assert!(
            (grey - Rgb::splat(0.18)).abs().max_element() < 0.005,
            "{grey}"
        );
        for colour in [
            Rgb::ONE,
            Rgb::new(1.0, 0.5, 0.2),
            Rgb::new(0.05, 0.3, 1.0),
            Rgb::new(1.0, 0.0, 0.0),
        ] {
            let mut previous = Rgb::ZERO;
            // 2^-14 … 2^12 in steps of 1/16 stop.
            for step in 0..=26 * 16 {
                let v = filmic(colour * (step as f32 / 16.0 - 14.0).exp2());
                assert!(
                    v.min_element() >= 0.0 && v.max_element() <= 1.0,
                    "{v} for {colour}"
                );
                assert!(
                    crate::math::luminance(v) >= crate::math::luminance(previous) - 1e-6,
                    "luminance decreases at step {step} of {colour}: {previous} → {v}"
                );
                if colour == Rgb::ONE {
                    assert!(v.cmpge(previous - 1e-6).all(), "grey: {previous} → {v}");
                }
                previous = v;
            }
        }
        // Highlights roll off instead of clipping: 1 and 4 stay apart and below white, and
        // white is approached from below.
        let (one, four) = (filmic(Rgb::ONE).x, filmic(Rgb::splat(4.0)).x);
        assert!(one < four && four < 0.99, "{one} {four}");
        let white = filmic(Rgb::splat(1e6)).x;
        assert!(white > 0.99 && white <= 1.0, "{white}");
        assert_eq!(ToneMap::Clamp.apply(Rgb::splat(4.0)), Rgb::ONE);
        assert_eq!("filmic".parse::<ToneMap>(), Ok(ToneMap::Filmic));
        assert!("aces"
            .parse::<ToneMap>()
            .unwrap_err()
            .contains("clamp or filmic"));
    }

    #[test]
    fn png_previews_carry_the_srgb_chunk() {
        let dir = tempfile::tempdir().unwrap();
        let mut img = Image::new(3, 2);
        img.pixels = (0..6).map(|i| Rgb::splat(i as f32 * 0.5)).collect();
        for tonemap in ToneMap::ALL {
            let path = dir.path().join(format!("{tonemap}.png"));
            to_file(&path, |o| write_png_tonemapped(o, &img, 0.0, tonemap)).unwrap();
            let file = BufReader::new(File::open(&path).unwrap());
            let reader = png::Decoder::new(file).read_info().unwrap();
            let info = reader.info();
            assert_eq!(
                info.srgb,
                Some(png::SrgbRenderingIntent::Perceptual),
                "{tonemap}"
            );
            assert_eq!((info.width, info.height), (3, 2));
            assert_eq!(info.color_type, png::ColorType::Rgb);
        }
        let clamp = image::open(dir.path().join("clamp.png"))
            .unwrap()
            .into_rgb8();
        let filmic = image::open(dir.path().join("filmic.png"))
            .unwrap()
            .into_rgb8();
        // 1.0 and 1.5 clip to white with clamp; filmic keeps them apart, below white.
        assert_eq!(clamp.get_pixel(2, 0).0, [255; 3]);
        assert_eq!(clamp.get_pixel(0, 1).0, [255; 3]);
        let (a, b) = (filmic.get_pixel(2, 0).0[0], filmic.get_pixel(0, 1).0[0]);
        assert!(a < b && b < 255, "{a} {b}");
        assert_eq!(filmic.get_pixel(0, 0).0, [0; 3]);
    }
}
