//! Reading and writing images: HDR/EXR environment maps in, float EXR and tone-mapped PNG out.
//!
//! Every error names the file and the problem. Outputs are written atomically: the bytes go to a
//! temporary file in the target's directory, which is synced and then renamed over the target,
//! so an interrupted render never leaves a truncated image behind.
//!
//! EXR text attributes are stored as UTF-8 bytes. The standard text attributes `software`,
//! `owner`, `comments` and `capDate` map to their standard header fields; every other standard
//! OpenEXR attribute name (`channels`, `compression`, …) is reserved and rejected.

use crate::film::Image;
use crate::math::Rgb;
use exr::meta::header::standard_names;
use exr::meta::header::Header;
use exr::prelude as ex;
use exr::prelude::{AttributeValue, Compression, ReadChannels, ReadLayers, Text, WritableImage};
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};
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
    /// Opening, reading, writing, syncing or renaming the file failed.
    #[error("{}: cannot {action}: {source}", path.display())]
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

/// Standard text attributes that [`write_exr`] stores in their header fields.
const STANDARD_TEXT: [&str; 4] = ["software", "owner", "comments", "capDate"];

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
/// [`Image`]), and the header's text attributes sorted by name.
pub fn read_exr(path: impl AsRef<Path>) -> Result<(Image, Vec<(String, String)>), ImageError> {
    let path = path.as_ref();
    check_exists(path)?;
    // Header first: it names the compression for a precise error and bounds the allocation.
    let meta = ex::MetaData::read_from_file(path, false).map_err(|e| exr_read_error(path, e))?;
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
        .from_file(path)
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
        if let AttributeValue::Text(v) = value {
            attributes.push((text_string(name), text_string(v)));
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

/// Writes `image` as a linear f32 RGB EXR (lossless ZIP compression): the display window is the
/// full film and the data window the image's pixel window, so a crop shows in place. `attributes`
/// become text attributes of the header (scene, integrator, spp, seed, render time, …).
pub fn write_exr(
    path: impl AsRef<Path>,
    image: &Image,
    attributes: &[(&str, String)],
) -> Result<(), ImageError> {
    let path = path.as_ref();
    let invalid = |reason: String| ImageError::InvalidData {
        origin: path.display().to_string(),
        reason,
    };
    check_image(image).map_err(invalid)?;

    let mut la = ex::LayerAttributes {
        layer_position: ex::Vec2(image.x0 as i32, image.y0 as i32),
        ..Default::default()
    };
    for (name, value) in attributes {
        let text = utf8_text(value);
        match *name {
            "software" => la.software_name = Some(text),
            "owner" => la.owner = Some(text),
            "comments" => la.comments = Some(text),
            "capDate" => la.capture_date = Some(text),
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
                la.other.insert(utf8_text(n), AttributeValue::Text(text));
            }
        }
    }

    let width = image.width as usize;
    let pixels = &image.pixels;
    let layer = ex::Layer::new(
        (image.width as usize, image.height as usize),
        la,
        ex::Encoding::SMALL_LOSSLESS,
        ex::SpecificChannels::rgb(|pos: ex::Vec2<usize>| {
            let p = pixels[pos.y() * width + pos.x()];
            (p.x, p.y, p.z)
        }),
    );
    let mut exr_image = ex::Image::from_layer(layer);
    exr_image.attributes.display_window = ex::IntegerBounds::new(
        ex::Vec2(0, 0),
        (image.full_width as usize, image.full_height as usize),
    );
    write_atomically(path, |w| {
        exr_image.write().to_buffered(w).map_err(|e| match e {
            exr::error::Error::Io(source) => ImageError::Io {
                path: path.to_owned(),
                action: "write",
                source,
            },
            e => invalid(format!("cannot encode EXR: {e}")),
        })
    })
}

/// Writes an 8-bit sRGB PNG preview of the image's pixel window: each channel is scaled by
/// 2^`exposure_stops`, clamped to [0, 1] (NaN becomes 0) and encoded with the sRGB curve.
pub fn write_png(
    path: impl AsRef<Path>,
    image: &Image,
    exposure_stops: f32,
) -> Result<(), ImageError> {
    let path = path.as_ref();
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
        .flat_map(|p| [p.x, p.y, p.z])
        .map(|c| srgb_byte(c * gain))
        .collect();
    write_atomically(path, |w| {
        use image::ImageEncoder;
        image::codecs::png::PngEncoder::new(w)
            .write_image(
                &bytes,
                image.width,
                image.height,
                image::ExtendedColorType::Rgb8,
            )
            .map_err(|e| match e {
                image::ImageError::IoError(source) => ImageError::Io {
                    path: path.to_owned(),
                    action: "write",
                    source,
                },
                e => invalid(format!("cannot encode PNG: {e}")),
            })
    })
}

/// Linear value → 8-bit sRGB code, clamping to [0, 1].
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

/// A temporary file in `dir` (name ending in `suffix`) for an output to be renamed into
/// place. Created with the mode of an ordinary new file (0666 less the umask) instead of
/// tempfile's private 0600, so the renamed output is readable like any other.
pub fn output_temp_file(dir: &Path, suffix: &str) -> std::io::Result<tempfile::NamedTempFile> {
    let mut builder = tempfile::Builder::new();
    builder.suffix(suffix);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    builder.tempfile_in(dir)
}

/// Runs `write` on a temporary file next to `path`, then syncs it and renames it onto `path`.
/// On any error the temporary file is removed (dropping `NamedTempFile` deletes it).
fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<&File>) -> Result<(), ImageError>,
) -> Result<(), ImageError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let io = |action: &'static str| {
        move |source: std::io::Error| ImageError::Io {
            path: path.to_owned(),
            action,
            source,
        }
    };
    let tmp = output_temp_file(dir, ".tmp").map_err(io("create a temporary file next to it"))?;
    {
        let mut w = BufWriter::new(tmp.as_file());
        write(&mut w)?;
        w.flush().map_err(io("write"))?;
    }
    tmp.as_file().sync_all().map_err(io("sync"))?;
    tmp.persist(path)
        .map_err(|e| io("move the finished temporary file into place")(e.error))?;
    Ok(())
}

fn read_hdr(path: &Path) -> Result<(u32, u32, Vec<Rgb>), ImageError> {
    use image::ImageDecoder;
    check_exists(path)?;
    let file = File::open(path).map_err(|source| ImageError::Io {
        path: path.to_owned(),
        action: "open",
        source,
    })?;
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
    File::open(path)
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

/// The file exists and is a regular file (a device such as /dev/zero would be read forever).
fn check_exists(path: &Path) -> Result<(), ImageError> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => Ok(()),
        Ok(_) => Err(ImageError::Io {
            path: path.to_owned(),
            action: "read",
            source: std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                "not a regular file (a directory, device or pipe)",
            ),
        }),
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

    fn files_in(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
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
        write_exr(&path, &img, &attrs).unwrap();
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
        write_exr(&path, &Image::new(2, 2), &[]).unwrap();
        write_exr(&path, &img, &[]).unwrap();
        assert!(same_bits(&read_exr(&path).unwrap().0, &img));
        let before = std::fs::read(&path).unwrap();

        let reserved = write_exr(&path, &Image::new(2, 2), &[("channels", "x".into())]);
        let msg = reserved.unwrap_err().to_string();
        assert!(
            msg.contains("out.exr") && msg.contains("\"channels\""),
            "{msg}"
        );
        let long = "n".repeat(300);
        assert!(write_exr(&path, &Image::new(2, 2), &[(long.as_str(), "x".into())]).is_err());
        let mut short = Image::new(4, 4);
        short.pixels.pop();
        let msg = write_exr(&path, &short, &[]).unwrap_err().to_string();
        assert!(
            msg.contains("out.exr") && msg.contains("15 pixels"),
            "{msg}"
        );
        let mut outside = Image::window([0, 0, 4, 4], 8, 8);
        outside.x0 = 6;
        assert!(write_exr(&path, &outside, &[]).is_err());
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
        let msg = write_exr(&nowhere, &img, &[]).unwrap_err().to_string();
        assert!(msg.contains("missing-dir/out.exr"), "{msg}");
    }

    #[test]
    fn exr_unsupported_compression_is_named_with_a_remedy() {
        // exr 1.74 decodes DWAA/DWAB but not HTJ2K: relabel a ZIP file as HTJ2K32. A single
        // 16-line block keeps the chunk table valid for both (ZIP: 16 lines, HTJ2K32: 32).
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("htj2k.exr");
        write_exr(&path, &Image::new(16, 16), &[]).unwrap();
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
        write_exr(&cut, &Image::new(64, 64), &[]).unwrap();
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
        write_png(&path, &img, 0.0).unwrap();
        let back = image::open(&path).unwrap().into_rgb8();
        assert_eq!(back.dimensions(), (4, 1));
        assert_eq!(back.get_pixel(0, 0).0, [188, 0, 255]);
        assert_eq!(back.get_pixel(1, 0).0, [255, 0, 0]);
        assert_eq!(back.get_pixel(2, 0).0, [3, 137, 118]);
        // One stop up doubles the linear value: 0.25 → 0.5.
        write_png(&path, &img, 1.0).unwrap();
        let back = image::open(&path).unwrap().into_rgb8();
        assert_eq!(back.get_pixel(2, 0).0[1], 188);
        assert_eq!(files_in(dir.path()), ["preview.png"]);
        let msg = write_png(&path, &img, f32::NAN).unwrap_err().to_string();
        assert!(msg.contains("preview.png"), "{msg}");
    }
}
