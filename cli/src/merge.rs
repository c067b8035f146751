//! `tress merge`: assembles tiles (`--crop`) and sample-range passes (`--spp-offset`) of one
//! render into the image of one long full render, bit for bit, from the sums the render EXRs
//! carry (`crate::render_file`; `tress render --sums`).

use crate::render_file::{
    parse_crop, read_piece, read_sums, write_render, Identity, Piece, PreviewArgs,
};
use anyhow::{anyhow, bail, Context, Result};
use clap::Args;
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::PathBuf;
use tress_core::image_io::Attribute;
use tress_core::output_file::{self, Inputs};
use tress_core::render::{dyadic_cover, SampleSums};
/// `tress merge`.
#[derive(Args, Debug)]
pub struct MergeArgs {
    /// Output EXR; a PNG preview is written beside it.
    pub out: PathBuf,
    /// Render EXRs to merge: tiles (`tress render --crop`) and sample-range passes
    /// (`--spp-offset`) of one scene and seed.
    #[arg(required = true)]
    pub pieces: Vec<PathBuf>,
    /// The pixel window x0,y0,x1,y1 the result must cover. Default: the whole film, or the
    /// window of the pieces when they all have the same one.
    #[arg(long, value_parser = parse_crop)]
    pub crop: Option<[u32; 4]>,
    /// Refuse unless the merged image holds exactly this many samples per pixel.
    #[arg(long)]
    pub expect_spp: Option<u64>,
    /// Also write the merged sample sums, so that the result can be merged again.
    #[arg(long)]
    pub sums: bool,
    #[command(flatten)]
    pub preview: PreviewArgs,
    /// No summary.
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(args: MergeArgs) -> Result<()> {
    // An input replaced by the merge would be lost.
    let inputs: Inputs = args.pieces.iter().collect();
    check_output(&args, &inputs)?;
    let pieces = args
        .pieces
        .iter()
        .map(|p| read_piece(p))
        .collect::<Result<Vec<_>>>()?;
    let plan = plan(&pieces, args.crop)?;
    let total = plan.samples.end - plan.samples.start;
    if let Some(expected) = args.expect_spp {
        check_expected_spp(&plan, expected)?;
    }
    let merged = merge_sums(&pieces, &plan)?;
    let first = &pieces[0];
    let attributes = merged_attributes(&pieces);
    let identity = Identity {
        seed: first.seed,
        scene_hash: first.scene_hash.clone(),
    };
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating output folder {}", dir.display()))?;
    }
    args.preview.write_with(
        &args.out,
        &inputs,
        |o| write_render(o, &merged, args.sums, &identity, &attributes),
        &merged.image(),
    )?;
    if !args.quiet {
        let [x0, y0, x1, y1] = plan.window;
        eprintln!(
            "merged {} pieces ({} sample ranges) into {}x{} pixels at {total} spp (samples [{}, {}))",
            pieces.len(),
            plan.groups.len(),
            x1 - x0,
            y1 - y0,
            plan.samples.start,
            plan.samples.end
        );
        eprintln!("wrote {}", args.out.display());
    }
    Ok(())
}

/// Refuses, before reading the pieces, an output that is not an EXR or that could not be
/// written ([`output_file::check`]: a directory, one of the pieces).
fn check_output(args: &MergeArgs, inputs: &Inputs) -> Result<()> {
    if !args
        .out
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("exr"))
    {
        bail!(
            "{}: the output must be an .exr file (a .png preview is written beside it)",
            args.out.display()
        );
    }
    for path in args.preview.outputs(&args.out) {
        output_file::check(&path, inputs)?;
    }
    Ok(())
}

/// Refuses pieces that do not hold `expected` samples per pixel (`--expect-spp`).
fn check_expected_spp(plan: &Plan, expected: u64) -> Result<()> {
    let total = plan.samples.end - plan.samples.start;
    if total != expected {
        bail!(
            "the pieces hold samples [{}, {}) = {total} per pixel, but {expected} were expected: \
             {}",
            plan.samples.start,
            plan.samples.end,
            if total < expected {
                "some passes are missing"
            } else {
                "there are more passes than expected"
            }
        );
    }
    Ok(())
}

/// The sums of the pieces, sample range after sample range, over the merged window.
fn merge_sums(pieces: &[Piece], plan: &Plan) -> Result<SampleSums> {
    let first = &pieces[0];
    let outputs = first.outputs.clone();
    let mut merged = SampleSums::empty(
        plan.window,
        first.film.0,
        first.film.1,
        plan.samples.start,
        outputs.clone(),
    );
    for group in &plan.groups {
        let blocks = dyadic_cover(group.samples.clone());
        let per_pixel = blocks.len() * merged.quantity_count();
        let [wx0, wy0, wx1, wy1] = plan.window;
        let ww = (wx1 - wx0) as usize;
        let mut sums = vec![0.0f64; ww * (wy1 - wy0) as usize * per_pixel];
        for &i in &group.pieces {
            let part = read_sums(&pieces[i])?;
            let [x0, y0, x1, _] = part.window;
            let pw = (x1 - x0) as usize;
            for p in 0..part.pixel_count() {
                let (x, y) = (x0 as usize + p % pw, y0 as usize + p / pw);
                let q = (y - wy0 as usize) * ww + (x - wx0 as usize);
                sums[q * per_pixel..(q + 1) * per_pixel].copy_from_slice(part.pixel(p));
            }
        }
        let group_sums = SampleSums {
            window: plan.window,
            full_width: first.film.0,
            full_height: first.film.1,
            samples: group.samples.clone(),
            blocks,
            outputs: outputs.clone(),
            sums,
        };
        merged
            .append(&group_sums)
            .map_err(|e| anyhow!("merging the pieces: {e}"))?;
    }
    Ok(merged)
}

/// The merged image's header: what the pieces share (scene, integrator, camera) from the first,
/// their statistics summed, and how many they were.
fn merged_attributes(pieces: &[Piece]) -> Vec<(&'static str, Attribute)> {
    let first = &pieces[0];
    let sum_attr = |name: &str| -> f64 {
        pieces
            .iter()
            .filter_map(|p| p.attributes.get(name)?.as_f64())
            .sum()
    };
    // What the pieces share (scene, integrator, camera) is copied from the first.
    let mut attributes: Vec<(&'static str, Attribute)> = [
        "tress:scene",
        "tress:integrator",
        "worldToCamera",
        "worldToNDC",
    ]
    .into_iter()
    .filter_map(|k| Some((k, first.attributes.get(k)?.clone())))
    .collect();
    for statistic in ["tress:render_time_s", "tress:rays", "tress:dropped_samples"] {
        attributes.push((statistic, Attribute::Double(sum_attr(statistic))));
    }
    attributes.push(("tress:merged_from", Attribute::whole(pieces.len() as u64)));
    attributes
}

/// Pieces that render the same sample range.
struct Group {
    samples: Range<u64>,
    pieces: Vec<usize>,
}

struct Plan {
    window: [u32; 4],
    samples: Range<u64>,
    groups: Vec<Group>,
}

/// Checks that the pieces belong together and tile the window for every sample range, and that
/// the ranges follow each other without gaps or overlaps.
fn plan(pieces: &[Piece], crop: Option<[u32; 4]>) -> Result<Plan> {
    check_compatible(pieces)?;
    let window = merged_window(pieces, crop)?;
    let groups = sample_groups(pieces)?;
    check_coverage(pieces, window, &groups)?;
    let samples = groups[0].samples.start..groups[groups.len() - 1].samples.end;
    Ok(Plan {
        window,
        samples,
        groups,
    })
}

/// Refuses pieces of different films, seeds, scenes or outputs.
fn check_compatible(pieces: &[Piece]) -> Result<()> {
    let first = &pieces[0];
    for p in &pieces[1..] {
        let mismatch = |what: &str, a: String, b: String| {
            anyhow!(
                "{} and {} cannot be merged: {what} differs ({a} vs {b})",
                first.path.display(),
                p.path.display()
            )
        };
        if p.film != first.film {
            return Err(mismatch(
                "the film size",
                format!("{}x{}", first.film.0, first.film.1),
                format!("{}x{}", p.film.0, p.film.1),
            ));
        }
        if p.seed != first.seed {
            return Err(mismatch(
                "the seed",
                first.seed.to_string(),
                p.seed.to_string(),
            ));
        }
        if p.scene_hash != first.scene_hash {
            return Err(mismatch(
                "the scene (description or integrator)",
                format!("hash {}", first.scene_hash),
                format!("hash {}", p.scene_hash),
            ));
        }
        if p.outputs != first.outputs {
            return Err(mismatch(
                "what is recorded (render all pieces with the same --alpha and --aov)",
                first.outputs.channel_names().join(", "),
                p.outputs.channel_names().join(", "),
            ));
        }
    }
    Ok(())
}

/// The window to merge: `--crop`, the pieces' common window, or the whole film; every piece
/// must lie in it.
fn merged_window(pieces: &[Piece], crop: Option<[u32; 4]>) -> Result<[u32; 4]> {
    let first = &pieces[0];
    let window = match crop {
        Some(c) => {
            let [x0, y0, x1, y1] = c;
            if x0 >= x1 || y0 >= y1 || x1 > first.film.0 || y1 > first.film.1 {
                bail!(
                    "--crop [{x0}, {y0}, {x1}, {y1}) is empty or outside the {}x{} film",
                    first.film.0,
                    first.film.1
                );
            }
            c
        }
        None if pieces.iter().all(|p| p.window == first.window) => first.window,
        None => [0, 0, first.film.0, first.film.1],
    };
    for p in pieces {
        let [x0, y0, x1, y1] = p.window;
        if x0 < window[0] || y0 < window[1] || x1 > window[2] || y1 > window[3] {
            bail!(
                "{}: {} lie outside the merged window [{}, {})x[{}, {})",
                p.path.display(),
                p.describe_window(),
                window[0],
                window[2],
                window[1],
                window[3]
            );
        }
    }
    Ok(window)
}

/// The pieces grouped by sample range, in order; the ranges must follow each other without
/// gaps or overlaps.
fn sample_groups(pieces: &[Piece]) -> Result<Vec<Group>> {
    let mut by_range: BTreeMap<(u64, u64), Vec<usize>> = BTreeMap::new();
    for (i, p) in pieces.iter().enumerate() {
        by_range
            .entry((p.samples.start, p.samples.end))
            .or_default()
            .push(i);
    }
    let groups: Vec<Group> = by_range
        .into_iter()
        .map(|((a, b), pieces)| Group {
            samples: a..b,
            pieces,
        })
        .collect();
    for pair in groups.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        let (pa, pb) = (&pieces[a.pieces[0]], &pieces[b.pieces[0]]);
        if b.samples.start < a.samples.end {
            bail!(
                "{} has samples [{}, {}) and {} has samples [{}, {}): sample ranges overlap \
                 (each pass must render its own range, see --spp-offset)",
                pa.path.display(),
                a.samples.start,
                a.samples.end,
                pb.path.display(),
                b.samples.start,
                b.samples.end
            );
        }
        if b.samples.start > a.samples.end {
            bail!(
                "samples [{}, {}) are missing: {} ends at sample {} and {} starts at {}",
                a.samples.end,
                b.samples.start,
                pa.path.display(),
                a.samples.end,
                pb.path.display(),
                b.samples.start
            );
        }
    }
    Ok(groups)
}

/// Every sample range must cover every pixel of the window exactly once.
fn check_coverage(pieces: &[Piece], window: [u32; 4], groups: &[Group]) -> Result<()> {
    let [wx0, wy0, wx1, wy1] = window;
    let ww = (wx1 - wx0) as usize;
    let mut owner = vec![usize::MAX; ww * (wy1 - wy0) as usize];
    for g in groups {
        owner.fill(usize::MAX);
        for &i in &g.pieces {
            let [x0, y0, x1, y1] = pieces[i].window;
            for y in y0..y1 {
                for x in x0..x1 {
                    let o = &mut owner[(y - wy0) as usize * ww + (x - wx0) as usize];
                    if *o != usize::MAX {
                        bail!(
                            "{} and {} both cover pixel ({x}, {y}) with samples [{}, {}): tiles \
                             overlap",
                            pieces[*o].path.display(),
                            pieces[i].path.display(),
                            g.samples.start,
                            g.samples.end
                        );
                    }
                    *o = i;
                }
            }
        }
        if let Some(q) = owner.iter().position(|&o| o == usize::MAX) {
            let names: Vec<String> = g
                .pieces
                .iter()
                .map(|&i| pieces[i].path.display().to_string())
                .collect();
            bail!(
                "no piece covers pixel ({}, {}) with samples [{}, {}): a tile is missing (pieces \
                 with these samples: {})",
                wx0 as usize + q % ww,
                wy0 as usize + q / ww,
                g.samples.start,
                g.samples.end,
                names.join(", ")
            );
        }
    }
    Ok(())
}
