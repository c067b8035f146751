//! The render EXR, shared by `tress render` and `tress merge`: the output channels (radiance,
//! alpha, AOVs), optionally the exact sample sums that let `tress merge` assemble tiles
//! (`--crop`) and sample-range passes (`--spp-offset`) into the image of one long full render,
//! bit for bit; and the PNG preview beside it.
//!
//! Channels: `R`, `G`, `B`, then `A` with alpha, then the AOVs as OpenEXR layers (`depth.Z`,
//! `tangent.X`…, `albedo.R`…, `variance.R`…; see `tress_core::film::Aov`), all 32-bit float.
//! With sums (`--sums`), for every pixel the f64 sums of every recorded quantity
//! (`tress_core::render::Quantity`) over the aligned sample blocks that cover its sample range:
//! block `k` of the [`dyadic_cover`] of the range, quantity `q`, is stored as two u32 channels
//! `tress.sumKKK.<q>hi` and `<q>lo` (the high and low halves of the f64's bits), e.g.
//! `tress.sum000.Rhi`, `tress.sum001.hitslo`. The header records the sample range
//! (`tress:spp_offset`, `tress:spp`), the seed, the film (display window) and crop (data
//! window), a hash of the scene description and, with sums, their format (`tress:sums`).
//! Merging checks all of these, then joins the blocks exactly and recomputes every channel.
//!
//! Whole numbers that must stay exact (spp, offset, seed) are EXR `int` attributes, or decimal
//! text beyond the int range; statistics (render time, rays, dropped samples) are `double`s.

use anyhow::{anyhow, bail, Result};
use clap::Args;
use exr::prelude as ex;
use exr::prelude::{ReadChannels, ReadLayers};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use tress_core::film::{Aov, Outputs};
use tress_core::image_io::{self, Attribute, ChannelSamples, ToneMap};
use tress_core::output_file::{Batch, Inputs, Sink};
use tress_core::render::{dyadic_cover, quantities, Quantity, SampleSums};

/// Value of the `tress:sums` attribute: the layout of the sum channels. Version 2 sums every
/// recorded quantity; version 1 (radiance only, same channel names) is still read.
pub const SUMS_FORMAT: &str = "dyadic-f64-blocks-2";
const SUMS_FORMAT_RADIANCE_ONLY: &str = "dyadic-f64-blocks-1";

/// The `software` attribute of every EXR tress writes.
pub fn software() -> String {
    format!("tress {}", env!("CARGO_PKG_VERSION"))
}

/// Largest film side and pixel count accepted when reading, so that a corrupt header cannot
/// make us attempt a huge allocation.
const MAX_SIDE: u32 = 1 << 16;
const MAX_PIXELS: u64 = 1 << 28;

fn sum_channel(block: usize, quantity: Quantity, high: bool) -> String {
    let half = if high { "hi" } else { "lo" };
    format!("tress.sum{block:03}.{}{half}", quantity.name())
}

/// What identifies the render a piece belongs to, besides the film.
#[derive(Clone, Debug)]
pub struct Identity {
    pub seed: u64,
    /// Hash of the scene description (after overrides, without spp and crop).
    pub scene_hash: String,
}

/// Writes the output channels of `sums` (and with `with_sums` the sums themselves) as an EXR
/// (ZIP compressed) into `out`: display window = the film, data window = the pixel window.
/// `attributes` are added to the sample range, seed, scene hash, software and sums format.
pub fn write_render(
    out: &mut Sink,
    sums: &SampleSums,
    with_sums: bool,
    identity: &Identity,
    attributes: &[(&str, Attribute)],
) -> Result<()> {
    let mut channels: Vec<(String, ChannelSamples)> = sums
        .channels()
        .into_iter()
        .map(|(name, values)| (name.to_string(), ChannelSamples::F32(values)))
        .collect();
    let mut own = vec![
        ("software", Attribute::Text(software())),
        (
            "tress:spp",
            Attribute::whole(sums.samples.end - sums.samples.start),
        ),
        ("tress:spp_offset", Attribute::whole(sums.samples.start)),
        ("tress:seed", Attribute::whole(identity.seed)),
        (
            "tress:scene_hash",
            Attribute::Text(identity.scene_hash.clone()),
        ),
    ];
    if with_sums {
        own.push(("tress:sums", Attribute::Text(SUMS_FORMAT.into())));
        let quantities = quantities(&sums.outputs);
        let stride = sums.blocks.len() * quantities.len();
        for k in 0..sums.blocks.len() {
            for (q, &quantity) in quantities.iter().enumerate() {
                let at = k * quantities.len() + q;
                let bits: Vec<u64> = sums
                    .sums
                    .iter()
                    .skip(at)
                    .step_by(stride.max(1))
                    .map(|v| v.to_bits())
                    .collect();
                for high in [true, false] {
                    let half = bits
                        .iter()
                        .map(|b| if high { (b >> 32) as u32 } else { *b as u32 })
                        .collect();
                    channels.push((sum_channel(k, quantity, high), ChannelSamples::U32(half)));
                }
            }
        }
    }
    let all: Vec<(&str, Attribute)> = own.into_iter().chain(attributes.iter().cloned()).collect();
    Ok(image_io::write_exr_channels(
        out,
        sums.window,
        (sums.full_width, sums.full_height),
        channels,
        &all,
    )?)
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
    /// What the piece records besides radiance (from its channels).
    pub outputs: Outputs,
    /// Every header attribute, typed.
    pub attributes: BTreeMap<String, Attribute>,
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
    let file = tress_core::files::open_regular(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => here("file not found".into()),
        _ => here(e.to_string()),
    })?;
    let meta = ex::MetaData::read_from_unbuffered(file, false)
        .map_err(|e| here(format!("not a readable OpenEXR file: {e}")))?;
    let [header] = meta.headers.as_slice() else {
        bail!(
            "{}: has {} layers; a tress render has one",
            path.display(),
            meta.headers.len()
        );
    };
    let attributes: BTreeMap<String, Attribute> =
        image_io::read_exr_attributes(path)?.into_iter().collect();
    let sums_format = attributes.get("tress:sums").map(|a| a.to_string());
    match sums_format.as_deref() {
        Some(SUMS_FORMAT | SUMS_FORMAT_RADIANCE_ONLY) => {}
        Some(other) => {
            return Err(here(format!(
                "sample sums in format {other:?}; this tress reads {SUMS_FORMAT:?} (render it again with this version)"
            )))
        }
        None if attributes.contains_key("tress:spp") => {
            return Err(here(
                "has no sample sums (tress:sums attribute), which merging needs: render the \
                 pieces with `tress render --sums` (the job lines of `tress farm` do)"
                    .into(),
            ))
        }
        None => {
            return Err(here(
                "not a mergeable tress render: it has no sample sums (tress:sums attribute); \
                 only EXRs written by `tress render --sums` or `tress merge --sums` can be merged"
                    .into(),
            ))
        }
    }
    let number = |name: &str| -> Result<u64> {
        let v = attributes
            .get(name)
            .ok_or_else(|| here(format!("the {name} attribute is missing")))?;
        v.as_whole()
            .ok_or_else(|| here(format!("the {name} attribute {v:?} is not a whole number")))
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
        .and_then(|a| a.as_text())
        .map(str::to_owned)
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
    let have: BTreeMap<String, ex::SampleType> = header
        .channels
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_type))
        .collect();
    let outputs = outputs_of(&have).map_err(here)?;
    if sums_format.as_deref() == Some(SUMS_FORMAT_RADIANCE_ONLY) && outputs != Outputs::default() {
        return Err(here(format!(
            "sums in format {SUMS_FORMAT_RADIANCE_ONLY:?} hold radiance only, but the file has \
             channels {}",
            outputs.channel_names().join(", ")
        )));
    }
    let blocks = dyadic_cover(offset..end);
    check_channels(&have, &outputs, blocks.len()).map_err(here)?;
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
        outputs,
        attributes,
    })
}

/// What a render EXR records besides radiance, from its output channels: alpha when it has
/// `A`, each AOV whose channels it has (all of them, or it is refused).
fn outputs_of(have: &BTreeMap<String, ex::SampleType>) -> Result<Outputs, String> {
    let mut outputs = Outputs {
        alpha: have.contains_key("A"),
        ..Default::default()
    };
    for aov in Aov::ALL {
        let present: Vec<&str> = aov
            .channels()
            .iter()
            .copied()
            .filter(|c| have.contains_key(*c))
            .collect();
        if present.len() == aov.channels().len() {
            outputs.aovs.insert(aov);
        } else if !present.is_empty() {
            return Err(format!(
                "the {aov} layer is incomplete: it has {} of the channels {}",
                present.join(", "),
                aov.channels().join(", ")
            ));
        }
    }
    Ok(outputs)
}

fn check_channels(
    have: &BTreeMap<String, ex::SampleType>,
    outputs: &Outputs,
    blocks: usize,
) -> Result<(), String> {
    let mut want: Vec<(String, ex::SampleType)> = outputs
        .channel_names()
        .into_iter()
        .map(|n| (n.to_string(), ex::SampleType::F32))
        .collect();
    let outputs_end = want.len();
    let quantities = quantities(outputs);
    for k in 0..blocks {
        for &q in &quantities {
            for high in [true, false] {
                want.push((sum_channel(k, q, high), ex::SampleType::U32));
            }
        }
    }
    for (i, (name, kind)) in want.iter().enumerate() {
        match have.get(name) {
            Some(t) if t == kind => {}
            Some(t) => return Err(format!("channel {name} holds {t:?} samples, not {kind:?}")),
            None if i < outputs_end => return Err(format!("channel {name} is missing")),
            None => {
                return Err(format!(
                    "channel {name} is missing ({blocks} sample blocks of {} quantities need {} \
                     sum channels)",
                    quantities.len(),
                    want.len() - outputs_end
                ))
            }
        }
    }
    // Sums of quantities these outputs do not record: the file was edited or is foreign.
    if let Some(extra) = have
        .keys()
        .find(|n| n.starts_with("tress.sum") && !want.iter().any(|(w, _)| w == *n))
    {
        return Err(format!(
            "channel {extra} is not a sum of this render's outputs ({})",
            outputs.channel_names().join(", ")
        ));
    }
    Ok(())
}

/// Reads a piece's sums and checks that its channels are the ones they define.
pub fn read_sums(piece: &Piece) -> Result<SampleSums> {
    let path = &piece.path;
    let here = |reason: String| anyhow!("{}: {reason}", path.display());
    let image = ex::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_unbuffered(tress_core::files::open_regular(path).map_err(|e| here(e.to_string()))?)
        .map_err(|e| here(format!("cannot read the pixels: {e}")))?;
    let channels: BTreeMap<String, &ex::FlatSamples> = image
        .layer_data
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), &c.sample_data))
        .collect();
    let blocks = dyadic_cover(piece.samples.clone());
    let quantities = quantities(&piece.outputs);
    let [x0, y0, x1, y1] = piece.window;
    let pixels = (x1 - x0) as usize * (y1 - y0) as usize;
    let u32s = |name: String| -> Result<&Vec<u32>> {
        match channels.get(&name) {
            Some(ex::FlatSamples::U32(v)) if v.len() == pixels => Ok(v),
            _ => Err(here(format!("channel {name} is missing or malformed"))),
        }
    };
    let (nb, nq) = (blocks.len(), quantities.len());
    let mut sums = vec![0.0f64; pixels * nb * nq];
    for k in 0..nb {
        for (q, &quantity) in quantities.iter().enumerate() {
            let hi = u32s(sum_channel(k, quantity, true))?;
            let lo = u32s(sum_channel(k, quantity, false))?;
            for (p, v) in sums
                .iter_mut()
                .skip(k * nq + q)
                .step_by(nb * nq)
                .enumerate()
            {
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
        outputs: piece.outputs.clone(),
        sums,
    };
    for (name, expected) in sums.channels() {
        let Some(ex::FlatSamples::F32(values)) = channels.get(name) else {
            return Err(here(format!(
                "channel {name} is missing or not 32-bit float"
            )));
        };
        if let Some(p) =
            (0..pixels).find(|&p| values.get(p).map(|v| v.to_bits()) != Some(expected[p].to_bits()))
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
    /// Tone mapping of the PNG preview: filmic (AgX, Blender's default: highlights roll off to
    /// white, middle grey unchanged) or clamp (each channel clipped at 1).
    #[arg(long, default_value_t = ToneMap::Filmic, value_parser = parse_tonemap)]
    pub tonemap: ToneMap,
    /// Do not write the PNG preview.
    #[arg(long)]
    pub no_preview: bool,
}

impl PreviewArgs {
    /// The outputs written for the EXR at `exr`: itself and, unless disabled, its preview.
    pub fn outputs(&self, exr: &Path) -> Vec<PathBuf> {
        let mut paths = vec![exr.to_owned()];
        if !self.no_preview {
            paths.push(exr.with_extension("png"));
        }
        paths
    }

    /// Writes the EXR at `exr` with `write_exr` and the preview of `image` beside it (same
    /// name, `.png`) unless disabled: both or neither ([`Batch`]), as an EXR without its
    /// preview would look like a success. Neither may replace one of `inputs`.
    pub fn write_with(
        &self,
        exr: &Path,
        inputs: &Inputs,
        write_exr: impl FnOnce(&mut Sink) -> Result<()>,
        image: &tress_core::Image,
    ) -> Result<()> {
        let mut batch = Batch::new(inputs);
        batch.add(exr, write_exr)?;
        if !self.no_preview {
            batch.add(&exr.with_extension("png"), |out| {
                Ok::<_, anyhow::Error>(image_io::write_png_tonemapped(
                    out,
                    image,
                    self.exposure,
                    self.tonemap,
                )?)
            })?;
        }
        Ok(batch.commit()?)
    }
}

fn parse_tonemap(s: &str) -> Result<ToneMap, String> {
    s.parse()
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
