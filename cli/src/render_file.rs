//! The render EXR, shared by `tress render` and `tress merge`: pixel values plus the exact
//! sample sums that let `tress merge` assemble tiles (`--crop`) and sample-range passes
//! (`--spp-offset`) into the image of one long full render, bit for bit; and the PNG preview
//! beside it.
//!
//! Besides the R, G, B pixel values, a render EXR holds, for every pixel, the f64 RGB sums of
//! the aligned sample blocks that cover its sample range (see `tress_core::render`): block `k`
//! of the [`dyadic_cover`] of the range is stored as six u32 channels `tress.sumKKK.Rhi`,
//! `Rlo`, `Ghi`, … (the high and low halves of each f64's bits). The header records the sample
//! range (`tress:spp_offset`, `tress:spp`), the seed, the film (display window) and crop (data
//! window), a hash of the scene description and the format version (`tress:sums`). Merging
//! checks all of these, then joins the blocks exactly.

use anyhow::{anyhow, bail, Result};
use clap::Args;
use exr::meta::header::Header;
use exr::prelude as ex;
use exr::prelude::{AttributeValue, ReadChannels, ReadLayers, Text, WritableImage};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use tress_core::image_io;
use tress_core::render::{dyadic_cover, SampleSums};

/// Value of the `tress:sums` attribute: the layout of the sum channels.
pub const SUMS_FORMAT: &str = "dyadic-f64-blocks-1";

/// Largest film side and pixel count accepted when reading, so that a corrupt header cannot
/// make us attempt a huge allocation.
const MAX_SIDE: u32 = 1 << 16;
const MAX_PIXELS: u64 = 1 << 28;

const RGB: [&str; 3] = ["R", "G", "B"];

fn sum_channel(block: usize, channel: usize, high: bool) -> String {
    let half = if high { "hi" } else { "lo" };
    format!("tress.sum{block:03}.{}{half}", RGB[channel])
}

fn text(s: &str) -> Text {
    Text::from_bytes_unchecked(s.as_bytes().into())
}

fn text_string(t: &Text) -> String {
    String::from_utf8_lossy(t.as_slice()).into_owned()
}

/// What identifies the render a piece belongs to, besides the film.
#[derive(Clone, Debug)]
pub struct Identity {
    pub seed: u64,
    /// Hash of the scene description (after overrides, without spp and crop).
    pub scene_hash: String,
}

/// Writes the image of `sums` and the sums themselves as an EXR (ZIP compressed), atomically:
/// display window = the film, data window = the pixel window. `attributes` are added as text
/// attributes to the sample range, seed, scene hash and format that merging needs.
pub fn write_render(
    path: &Path,
    sums: &SampleSums,
    identity: &Identity,
    attributes: &[(&str, String)],
) -> Result<()> {
    let [x0, y0, x1, y1] = sums.window;
    let (w, h) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let image = sums.image();
    let mut channels: ex::SmallVec<[ex::AnyChannel<ex::FlatSamples>; 4]> = ex::SmallVec::new();
    for (c, name) in RGB.iter().enumerate() {
        let values = image.pixels.iter().map(|p| p[c]).collect();
        channels.push(ex::AnyChannel::new(*name, ex::FlatSamples::F32(values)));
    }
    for k in 0..sums.blocks.len() {
        for c in 0..3 {
            for high in [true, false] {
                let values = (0..sums.pixel_count())
                    .map(|p| {
                        let bits = sums.pixel(p)[k][c].to_bits();
                        if high {
                            (bits >> 32) as u32
                        } else {
                            bits as u32
                        }
                    })
                    .collect();
                channels.push(ex::AnyChannel::new(
                    text(&sum_channel(k, c, high)),
                    ex::FlatSamples::U32(values),
                ));
            }
        }
    }

    let mut la = ex::LayerAttributes {
        layer_position: ex::Vec2(x0 as i32, y0 as i32),
        ..Default::default()
    };
    let own = [
        ("tress:sums", SUMS_FORMAT.to_string()),
        (
            "tress:spp",
            (sums.samples.end - sums.samples.start).to_string(),
        ),
        ("tress:spp_offset", sums.samples.start.to_string()),
        ("tress:seed", identity.seed.to_string()),
        ("tress:scene_hash", identity.scene_hash.clone()),
    ];
    for (name, value) in own.iter().chain(attributes) {
        la.other
            .insert(text(name), AttributeValue::Text(text(value)));
    }
    let layer = ex::Layer::new(
        (w, h),
        la,
        ex::Encoding::SMALL_LOSSLESS,
        ex::AnyChannels::sort(channels),
    );
    let mut exr_image = ex::Image::from_layer(layer);
    exr_image.attributes.display_window = ex::IntegerBounds::new(
        ex::Vec2(0, 0),
        (sums.full_width as usize, sums.full_height as usize),
    );
    let mut bytes = Vec::new();
    exr_image
        .write()
        .to_buffered(std::io::Cursor::new(&mut bytes))
        .map_err(|e| anyhow!("{}: cannot encode EXR: {e}", path.display()))?;
    crate::atomic_write(path, &bytes)
}

/// A render EXR's header: what merging checks before reading any pixels.
#[derive(Clone, Debug)]
pub struct Piece {
    pub path: PathBuf,
    pub window: [u32; 4],
    pub film: (u32, u32),
    pub samples: Range<u64>,
    pub seed: u64,
    pub scene_hash: String,
    /// Every text attribute.
    pub attributes: BTreeMap<String, String>,
}

impl Piece {
    pub fn describe_window(&self) -> String {
        let [x0, y0, x1, y1] = self.window;
        format!("pixels [{x0}, {x1})x[{y0}, {y1})")
    }
}

/// Reads and checks a render EXR's header.
pub fn read_piece(path: &Path) -> Result<Piece> {
    let here = |reason: String| anyhow!("{}: {reason}", path.display());
    if !path.exists() {
        return Err(here("file not found".into()));
    }
    let meta = ex::MetaData::read_from_file(path, false)
        .map_err(|e| here(format!("not a readable OpenEXR file: {e}")))?;
    let [header] = meta.headers.as_slice() else {
        bail!(
            "{}: has {} layers; a tress render has one",
            path.display(),
            meta.headers.len()
        );
    };
    let mut attributes = BTreeMap::new();
    for (name, value) in header
        .own_attributes
        .other
        .iter()
        .chain(&header.shared_attributes.other)
    {
        if let AttributeValue::Text(v) = value {
            attributes.insert(text_string(name), text_string(v));
        }
    }
    match attributes.get("tress:sums").map(String::as_str) {
        Some(SUMS_FORMAT) => {}
        Some(other) => {
            return Err(here(format!(
                "sample sums in format {other:?}; this tress reads {SUMS_FORMAT:?} (render it again with this version)"
            )))
        }
        None => {
            return Err(here(
                "not a mergeable tress render: it has no sample sums (tress:sums attribute); \
                 only EXRs written by `tress render` or `tress merge` can be merged"
                    .into(),
            ))
        }
    }
    let number = |name: &str| -> Result<u64> {
        let v = attributes
            .get(name)
            .ok_or_else(|| here(format!("the {name} attribute is missing")))?;
        v.parse()
            .map_err(|_| here(format!("the {name} attribute {v:?} is not a whole number")))
    };
    let spp = number("tress:spp")?;
    let offset = number("tress:spp_offset")?;
    let seed = number("tress:seed")?;
    let end = offset
        .checked_add(spp)
        .ok_or_else(|| here(format!("sample range {offset} + {spp} overflows")))?;
    if spp == 0 {
        return Err(here("holds no samples (tress:spp is 0)".into()));
    }
    let scene_hash = attributes
        .get("tress:scene_hash")
        .cloned()
        .ok_or_else(|| here("the tress:scene_hash attribute is missing".into()))?;

    let display = header.shared_attributes.display_window;
    let (fw, fh) = (display.size.width(), display.size.height());
    let (w, h) = (header.layer_size.width(), header.layer_size.height());
    let x0 = i64::from(header.own_attributes.layer_position.x()) - i64::from(display.position.x());
    let y0 = i64::from(header.own_attributes.layer_position.y()) - i64::from(display.position.y());
    if fw == 0 || fh == 0 || fw > MAX_SIDE as usize || fh > MAX_SIDE as usize {
        return Err(here(format!(
            "film {fw}x{fh} is empty or larger than {MAX_SIDE} pixels a side"
        )));
    }
    if w == 0 || h == 0 || x0 < 0 || y0 < 0 || x0 as usize + w > fw || y0 as usize + h > fh {
        return Err(here(format!(
            "data window {w}x{h} at ({x0}, {y0}) is empty or not inside the {fw}x{fh} film"
        )));
    }
    if (w as u64) * (h as u64) > MAX_PIXELS {
        return Err(here(format!("data window {w}x{h} is too large")));
    }
    let blocks = dyadic_cover(offset..end);
    check_channels(header, blocks.len()).map_err(here)?;
    Ok(Piece {
        path: path.to_owned(),
        window: [
            x0 as u32,
            y0 as u32,
            (x0 as usize + w) as u32,
            (y0 as usize + h) as u32,
        ],
        film: (fw as u32, fh as u32),
        samples: offset..end,
        seed,
        scene_hash,
        attributes,
    })
}

fn check_channels(header: &Header, blocks: usize) -> Result<(), String> {
    let have: BTreeMap<String, ex::SampleType> = header
        .channels
        .list
        .iter()
        .map(|c| (text_string(&c.name), c.sample_type))
        .collect();
    let mut want: Vec<(String, ex::SampleType)> = RGB
        .iter()
        .map(|n| (n.to_string(), ex::SampleType::F32))
        .collect();
    for k in 0..blocks {
        for c in 0..3 {
            for high in [true, false] {
                want.push((sum_channel(k, c, high), ex::SampleType::U32));
            }
        }
    }
    for (name, kind) in &want {
        match have.get(name) {
            Some(t) if t == kind => {}
            Some(t) => return Err(format!("channel {name} holds {t:?} samples, not {kind:?}")),
            None => {
                return Err(format!(
                    "channel {name} is missing ({} sample blocks need {} channels)",
                    blocks,
                    want.len()
                ))
            }
        }
    }
    Ok(())
}

/// Reads a piece's sums and checks that its pixel values are the ones they define.
pub fn read_sums(piece: &Piece) -> Result<SampleSums> {
    let path = &piece.path;
    let here = |reason: String| anyhow!("{}: {reason}", path.display());
    let image = ex::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| here(format!("cannot read the pixels: {e}")))?;
    let channels: BTreeMap<String, &ex::FlatSamples> = image
        .layer_data
        .channel_data
        .list
        .iter()
        .map(|c| (text_string(&c.name), &c.sample_data))
        .collect();
    let blocks = dyadic_cover(piece.samples.clone());
    let [x0, y0, x1, y1] = piece.window;
    let pixels = (x1 - x0) as usize * (y1 - y0) as usize;
    let u32s = |name: String| -> Result<&Vec<u32>> {
        match channels.get(&name) {
            Some(ex::FlatSamples::U32(v)) if v.len() == pixels => Ok(v),
            _ => Err(here(format!("channel {name} is missing or malformed"))),
        }
    };
    let nb = blocks.len();
    let mut sums = vec![[0.0f64; 3]; pixels * nb];
    for k in 0..nb {
        let halves = (0..3)
            .map(|c| {
                Ok((
                    u32s(sum_channel(k, c, true))?,
                    u32s(sum_channel(k, c, false))?,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        for (p, px) in sums.iter_mut().skip(k).step_by(nb).enumerate() {
            for (v, (hi, lo)) in px.iter_mut().zip(&halves) {
                *v = f64::from_bits((u64::from(hi[p]) << 32) | u64::from(lo[p]));
            }
        }
    }
    let sums = SampleSums {
        window: piece.window,
        full_width: piece.film.0,
        full_height: piece.film.1,
        samples: piece.samples.clone(),
        blocks,
        sums,
    };
    let expected = sums.image();
    for (c, name) in RGB.iter().enumerate() {
        let Some(ex::FlatSamples::F32(values)) = channels.get(*name) else {
            return Err(here(format!(
                "channel {name} is missing or not 32-bit float"
            )));
        };
        if let Some(p) = (0..pixels)
            .find(|&p| values.get(p).map(|v| v.to_bits()) != Some(expected.pixels[p][c].to_bits()))
        {
            let w = (x1 - x0) as usize;
            return Err(here(format!(
                "pixel ({}, {}) channel {name} does not match its stored sample sums: the file \
                 was modified after rendering",
                x0 as usize + p % w,
                y0 as usize + p / w
            )));
        }
    }
    Ok(sums)
}

/// The tone-mapped PNG written beside an output EXR (render and merge).
#[derive(Args, Debug)]
pub struct PreviewArgs {
    /// Exposure of the PNG preview, in stops.
    #[arg(long, default_value_t = 0.0, value_parser = parse_exposure, allow_hyphen_values = true)]
    pub exposure: f32,
    /// Do not write the PNG preview.
    #[arg(long)]
    pub no_preview: bool,
}

impl PreviewArgs {
    /// Writes the preview of `image` beside `exr` (same name, `.png`) unless disabled.
    pub fn write(&self, exr: &Path, image: &tress_core::Image) -> Result<()> {
        if !self.no_preview {
            image_io::write_png(exr.with_extension("png"), image, self.exposure)?;
        }
        Ok(())
    }
}

/// Checked before rendering: a NaN or overflowing gain made the PNG fail after the EXR was
/// written.
fn parse_exposure(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.abs() <= 100.0 => Ok(v),
        _ => Err(format!("'{s}' is not an exposure in stops within ±100")),
    }
}

/// Parses a pixel window `x0,y0,x1,y1` (`--crop`).
pub fn parse_crop(s: &str) -> Result<[u32; 4], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 4 {
        return Err(format!("expected x0,y0,x1,y1, got '{s}'"));
    }
    let mut out = [0u32; 4];
    for (o, p) in out.iter_mut().zip(parts) {
        *o = p
            .trim()
            .parse()
            .map_err(|_| format!("'{p}' is not a non-negative integer"))?;
    }
    Ok(out)
}
