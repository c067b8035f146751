//! `tress diff A.exr B.exr`: error metrics of an image A against a reference B, and colour-mapped
//! per-pixel error maps. MSE, relMSE, PSNR and the mean difference are
//! [`tress_study::metrics`], which studies compute too.
//!
//! Two perceptual metrics compare the images as they are seen: tone-mapped like the PNG
//! previews (scaled by 2^`--exposure`, mapped by `--tonemap`, sRGB-encoded to [0, 1]).
//! - `SSIM` (Wang, Bovik, Sheikh and Simoncelli 2004), per sRGB channel and averaged: an
//!   11×11 Gaussian window with σ = 1.5, K1 = 0.01, K2 = 0.03 and dynamic range 1, evaluated
//!   wherever the window fits inside the region (no padding; regions under 11×11 have none),
//!   as in the authors' MATLAB code and scikit-image's `gaussian_weights=True`. 1 for identical
//!   images, lower for worse.
//! - `FLIP` (Andersson et al. 2020, LDR-FLIP) of A against the reference B, from NVIDIA's
//!   implementation (the `nv-flip` bindings) on the 8-bit previews, at `--flip-ppd` pixels per
//!   degree of visual angle (67.02 by default: a 0.7 m wide 3840-pixel screen seen from 0.7 m,
//!   FLIP's own default): the mean
//!   and the maximum of its per-pixel error map over the region, 0 for identical images and at
//!   most 1. The region is cropped before the comparison, so its border pixels are filtered
//!   without their neighbours outside.

use crate::logging::Log;
use crate::plot;
use anyhow::{bail, Context, Result};
use clap::Args;
use serde_json::json;
use std::path::{Path, PathBuf};
use tress_core::image_io::{self, ToneMap};
use tress_core::output_file::Inputs;
use tress_core::Image;
use tress_study::metrics::{
    avg3, check_compatible, check_finite, error_map, metrics, resolve_region, MapKind, Metrics,
    Rect, REL_EPSILON,
};
use tress_study::picture::srgb;

/// What an error map shows per pixel (`--map-kind`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum MapArg {
    /// RMS over the channels of |A − B|.
    Abs,
    /// RMS over the channels of |A − B| / sqrt(B² + ε): the per-pixel square root of relMSE.
    Rel,
}

impl From<MapArg> for MapKind {
    fn from(arg: MapArg) -> MapKind {
        match arg {
            MapArg::Abs => MapKind::Abs,
            MapArg::Rel => MapKind::Rel,
        }
    }
}

/// How the perceptual metrics see an image: the PNG previews' exposure and tone mapping.
#[derive(Clone, Copy, Debug)]
pub struct Display {
    /// 2^exposure.
    pub gain: f32,
    pub tonemap: ToneMap,
}

impl Display {
    /// sRGB-encoded display values in [0, 1] (the PNG preview's before 8-bit rounding).
    fn encode(&self, c: glam::Vec3) -> [f32; 3] {
        self.tonemap.apply(c * self.gain).to_array().map(srgb)
    }

    /// The region of `img` as planar display values, one plane per channel, row-major.
    fn planes(&self, img: &Image, rect: Rect) -> [Vec<f32>; 3] {
        let mut planes: [Vec<f32>; 3] = Default::default();
        for y in rect.y..rect.y + rect.h {
            for x in rect.x..rect.x + rect.w {
                let v = self.encode(img.get(x - img.x0, y - img.y0));
                for (p, c) in planes.iter_mut().zip(v) {
                    p.push(c);
                }
            }
        }
        planes
    }
}

/// Side of the SSIM window, and the standard deviation of its Gaussian weights.
pub const SSIM_WINDOW: usize = 11;
const SSIM_SIGMA: f64 = 1.5;

/// The normalised 1-D Gaussian of the SSIM window (the 2-D window is its outer product).
fn ssim_weights() -> [f64; SSIM_WINDOW] {
    let r = (SSIM_WINDOW / 2) as f64;
    let mut w = [0.0; SSIM_WINDOW];
    for (i, v) in w.iter_mut().enumerate() {
        let d = i as f64 - r;
        *v = (-d * d / (2.0 * SSIM_SIGMA * SSIM_SIGMA)).exp();
    }
    let sum: f64 = w.iter().sum();
    w.map(|v| v / sum)
}

/// `plane` (w × h, row-major) filtered with the window, over the positions where it fits:
/// (w − 10) × (h − 10) values. Separable: rows, then columns.
fn window_filter(plane: &[f64], w: usize, h: usize, g: &[f64; SSIM_WINDOW]) -> Vec<f64> {
    let (ow, oh) = (w + 1 - SSIM_WINDOW, h + 1 - SSIM_WINDOW);
    let mut rows = vec![0.0; ow * h];
    for y in 0..h {
        let line = &plane[y * w..(y + 1) * w];
        for x in 0..ow {
            rows[y * ow + x] = g.iter().zip(&line[x..]).map(|(k, v)| k * v).sum();
        }
    }
    let mut out = vec![0.0; ow * oh];
    for y in 0..oh {
        for x in 0..ow {
            out[y * ow + x] = g
                .iter()
                .enumerate()
                .map(|(k, gk)| gk * rows[(y + k) * ow + x])
                .sum();
        }
    }
    out
}

/// Mean SSIM of two planes of display values in [0, 1] (w × h, row-major); `None` when the
/// planes are smaller than the window.
pub fn ssim_plane(a: &[f32], b: &[f32], w: usize, h: usize) -> Option<f64> {
    if w < SSIM_WINDOW || h < SSIM_WINDOW || a.len() != w * h || b.len() != w * h {
        return None;
    }
    const C1: f64 = 0.01 * 0.01;
    const C2: f64 = 0.03 * 0.03;
    let g = ssim_weights();
    let plane = |f: &dyn Fn(f64, f64) -> f64| -> Vec<f64> {
        let v: Vec<f64> = a
            .iter()
            .zip(b)
            .map(|(&x, &y)| f(x as f64, y as f64))
            .collect();
        window_filter(&v, w, h, &g)
    };
    let (mx, my) = (plane(&|x, _| x), plane(&|_, y| y));
    let (xx, yy, xy) = (
        plane(&|x, _| x * x),
        plane(&|_, y| y * y),
        plane(&|x, y| x * y),
    );
    let n = mx.len();
    let mut sum = 0.0;
    for i in 0..n {
        let (ux, uy) = (mx[i], my[i]);
        let (vx, vy, cxy) = (xx[i] - ux * ux, yy[i] - uy * uy, xy[i] - ux * uy);
        sum +=
            ((2.0 * ux * uy + C1) * (2.0 * cxy + C2)) / ((ux * ux + uy * uy + C1) * (vx + vy + C2));
    }
    Some(sum / n as f64)
}

/// SSIM of `a` against `b` over `rect`, per channel of the display values; `None` when the
/// region is smaller than the 11×11 window.
pub fn ssim(a: &Image, b: &Image, rect: Rect, display: Display) -> Option<[f64; 3]> {
    let (pa, pb) = (display.planes(a, rect), display.planes(b, rect));
    let (w, h) = (rect.w as usize, rect.h as usize);
    let mut out = [0.0; 3];
    for c in 0..3 {
        out[c] = ssim_plane(&pa[c], &pb[c], w, h)?;
    }
    Some(out)
}

/// LDR-FLIP of a test image against a reference over one region.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Flip {
    pub mean: f64,
    pub max: f64,
}

/// The region of `img` as the 8-bit sRGB bytes of its preview.
fn preview_bytes(img: &Image, rect: Rect, display: Display) -> Vec<u8> {
    let planes = display.planes(img, rect);
    (0..planes[0].len())
        .flat_map(|i| planes.iter().map(move |p| (p[i] * 255.0 + 0.5) as u8))
        .collect()
}

/// LDR-FLIP of `test` against `reference` over `rect`, their previews seen at
/// `pixels_per_degree`.
pub fn flip(
    test: &Image,
    reference: &Image,
    rect: Rect,
    display: Display,
    pixels_per_degree: f32,
) -> Flip {
    flip_rgb8(
        &preview_bytes(test, rect, display),
        &preview_bytes(reference, rect, display),
        rect.w,
        rect.h,
        pixels_per_degree,
    )
}

/// LDR-FLIP of two 8-bit sRGB images (`w × h`, RGB, row-major).
fn flip_rgb8(test: &[u8], reference: &[u8], w: u32, h: u32, pixels_per_degree: f32) -> Flip {
    let image = |bytes: &[u8]| nv_flip::FlipImageRgb8::with_data(w, h, bytes);
    let errors = nv_flip::flip(image(reference), image(test), pixels_per_degree).to_vec();
    let sum: f64 = errors.iter().map(|&e| e as f64).sum();
    Flip {
        mean: sum / errors.len().max(1) as f64,
        max: errors.iter().fold(0.0f32, |m, &e| m.max(e)) as f64,
    }
}

fn parse_ppd(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!(
            "'{s}' is not a positive number of pixels per degree"
        )),
    }
}

fn parse_exposure(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() && v.abs() <= 100.0 => Ok(v),
        _ => Err(format!("'{s}' is not an exposure in stops within ±100")),
    }
}

#[derive(Args, Debug)]
pub struct DiffArgs {
    /// The image to measure (EXR).
    pub a: PathBuf,
    /// The reference (EXR).
    pub b: PathBuf,
    /// Compare only the film pixels x,y,w,h (film coordinates, inside the rendered window).
    #[arg(long, value_parser = Rect::parse)]
    pub region: Option<Rect>,
    /// Write a colour-mapped per-pixel error map (PNG, log scale with a colour bar).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// What the error map shows.
    #[arg(long, value_enum, default_value_t = MapArg::Abs)]
    pub map_kind: MapArg,
    /// Exposure of the previews SSIM and FLIP compare, in stops (as `tress render --exposure`).
    #[arg(long, default_value_t = 0.0, value_parser = parse_exposure, allow_hyphen_values = true)]
    pub exposure: f32,
    /// Tone mapping of the previews SSIM and FLIP compare: filmic or clamp (as `tress render`).
    #[arg(long, default_value_t = ToneMap::Filmic)]
    pub tonemap: ToneMap,
    /// FLIP's viewing condition in pixels per degree of visual angle (default: FLIP's, a
    /// 0.7 m wide 3840-pixel screen seen from 0.7 m).
    #[arg(long, default_value_t = nv_flip::pixels_per_degree(0.7, 3840.0, 0.7), value_parser = parse_ppd)]
    pub flip_ppd: f32,
}

pub fn run(args: DiffArgs, log: &mut Log) -> Result<()> {
    let (a, _) = image_io::read_exr(&args.a)?;
    let (b, _) = image_io::read_exr(&args.b)?;
    let both = || format!("{} vs {}", args.a.display(), args.b.display());
    check_compatible(&a, &b).map_err(|e| anyhow::anyhow!("{}: {e}", both()))?;
    let rect = resolve_region(&a, args.region).map_err(|e| anyhow::anyhow!("{}: {e}", both()))?;
    check_finite(&a, &args.a)?;
    check_finite(&b, &args.b)?;
    let m = metrics(&a, &b, rect);
    let display = Display {
        gain: args.exposure.exp2(),
        tonemap: args.tonemap,
    };
    let ssim = ssim(&a, &b, rect, display);
    let flip = flip(&a, &b, rect, display, args.flip_ppd);

    let map = match &args.map {
        Some(map) => Some(write_map(&args, &a, &b, rect, map)?),
        None => None,
    };
    for (key, value) in summary_fields(&args, rect, &m, ssim, flip, map) {
        log.record(&key, value);
    }
    if !log.json() {
        print_table(&args, rect, &m, ssim, flip);
        if let (Some(path), Some(scale)) = (&args.map, map) {
            println!(
                "error map: {} ({}, log colour scale {:.3e} to {:.3e})",
                path.display(),
                MapKind::from(args.map_kind).label(),
                scale.lo,
                scale.hi
            );
        }
    }
    Ok(())
}

/// Writes the error map; returns its colour scale.
fn write_map(
    args: &DiffArgs,
    a: &Image,
    b: &Image,
    rect: Rect,
    map: &Path,
) -> Result<plot::LogScale> {
    if map.extension().and_then(|e| e.to_str()) != Some("png") {
        bail!("--map {}: the error map must be a .png file", map.display());
    }
    let values = error_map(a, b, rect, args.map_kind.into());
    let scale = plot::LogScale::fit(&values);
    let panel = plot::HeatPanel {
        title: format!("{} vs {}", file_name(&args.a), file_name(&args.b)),
        width: rect.w,
        height: rect.h,
        values,
    };
    let inputs: Inputs = [&args.a, &args.b].into_iter().collect();
    plot::write_heat_maps(
        map,
        &inputs,
        &[panel],
        scale,
        MapKind::from(args.map_kind).label(),
    )
    .with_context(|| format!("writing the error map {}", map.display()))?;
    Ok(scale)
}

/// The table for people.
fn print_table(args: &DiffArgs, rect: Rect, m: &Metrics, ssim: Option<[f64; 3]>, flip: Flip) {
    println!("A: {}", args.a.display());
    println!("B (reference): {}", args.b.display());
    println!(
        "region: {rect}; relMSE epsilon = {REL_EPSILON}; PSNR peak = {:.6e} (max of B)",
        m.peak
    );
    println!(
        "{:<8}{:>14}{:>14}{:>12}{:>15}{:>14}{:>14}{:>10}",
        "channel", "MSE", "relMSE", "PSNR_dB", "mean(A-B)", "mean(A)", "mean(B)", "SSIM"
    );
    let row = |name: &str, mse: f64, rel: f64, diff: f64, ma: f64, mb: f64, ssim: Option<f64>| {
        let ssim = ssim.map_or("n/a".to_string(), |s| format!("{s:.6}"));
        println!(
            "{name:<8}{mse:>14.6e}{rel:>14.6e}{:>12.3}{diff:>15.6e}{ma:>14.6e}{mb:>14.6e}{ssim:>10}",
            m.psnr(mse)
        );
    };
    for (c, name) in ["R", "G", "B"].iter().enumerate() {
        row(
            name,
            m.mse[c],
            m.relmse[c],
            m.mean_diff[c],
            m.mean_a[c],
            m.mean_b[c],
            ssim.map(|s| s[c]),
        );
    }
    row(
        "all",
        m.mse_all(),
        m.relmse_all(),
        m.mean_diff_all(),
        m.mean_a_all(),
        m.mean_b_all(),
        ssim.map(avg3),
    );
    if ssim.is_none() {
        println!("SSIM: n/a, the region is smaller than its {SSIM_WINDOW}x{SSIM_WINDOW} window");
    }
    println!(
        "FLIP (LDR, {} previews at {:+} stops, {} px/deg): mean {:.6}, max {:.6}",
        args.tonemap, args.exposure, args.flip_ppd, flip.mean, flip.max
    );
}

/// The fields of the JSON summary of `tress diff`.
fn summary_fields(
    args: &DiffArgs,
    rect: Rect,
    m: &Metrics,
    ssim: Option<[f64; 3]>,
    flip: Flip,
    map: Option<plot::LogScale>,
) -> Vec<(String, serde_json::Value)> {
    let psnr = |mse: f64| {
        let p = m.psnr(mse);
        // Identical images: infinite PSNR, which JSON cannot write.
        if p.is_finite() {
            json!(p)
        } else {
            json!(null)
        }
    };
    let channels = |v: [f64; 3], all: f64| json!({"r": v[0], "g": v[1], "b": v[2], "all": all});
    vec![
        ("a".into(), json!(args.a)),
        ("reference".into(), json!(args.b)),
        (
            "region".into(),
            json!({"x": rect.x, "y": rect.y, "w": rect.w, "h": rect.h}),
        ),
        ("mse".into(), channels(m.mse, m.mse_all())),
        ("relmse".into(), channels(m.relmse, m.relmse_all())),
        ("relmse_epsilon".into(), json!(REL_EPSILON)),
        (
            "psnr_db".into(),
            json!({"r": psnr(m.mse[0]), "g": psnr(m.mse[1]), "b": psnr(m.mse[2]), "all": psnr(m.mse_all())}),
        ),
        ("psnr_peak".into(), json!(m.peak)),
        ("mean_diff".into(), channels(m.mean_diff, m.mean_diff_all())),
        (
            "ssim".into(),
            ssim.map_or(json!(null), |s| channels(s, avg3(s))),
        ),
        (
            "flip".into(),
            json!({"mean": flip.mean, "max": flip.max, "pixels_per_degree": args.flip_ppd}),
        ),
        (
            "display".into(),
            json!({"exposure": args.exposure, "tonemap": args.tonemap.name()}),
        ),
        ("map".into(), json!(args.map)),
        ("map_scale".into(), json!(map.map(|s| [s.lo, s.hi]))),
    ]
}

fn file_name(p: &Path) -> String {
    p.file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| p.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Display values in [0, 1] from integer patterns, so that the scikit-image script that
    /// produced the reference values below builds exactly the same planes.
    fn ssim_planes() -> (Vec<f32>, Vec<f32>, usize, usize) {
        let (w, h) = (48usize, 40usize);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for y in 0..h {
            for x in 0..w {
                let av = 0.1
                    + 0.8 * (x + y) as f64 / (w + h - 2) as f64
                    + 0.05 * (((x * 31 + y * 17) % 11) as f64 / 10.0 - 0.5);
                let bv = av + 0.1 * (((x * 13 + y * 7 + x * y) % 23) as f64 / 22.0 - 0.5);
                a.push(av as f32);
                b.push(bv as f32);
            }
        }
        (a, b, w, h)
    }

    #[test]
    fn ssim_matches_scikit_image() {
        // skimage.metrics.structural_similarity(a, b, gaussian_weights=True, sigma=1.5,
        // use_sample_covariance=False, data_range=1.0), scikit-image 0.26.0.
        let (a, b, w, h) = ssim_planes();
        let s = ssim_plane(&a, &b, w, h).unwrap();
        assert!((s - 0.701_445_647_284).abs() < 1e-9, "SSIM {s}");
        assert_eq!(ssim_plane(&a, &a, w, h), Some(1.0));
        // Symmetric, and undefined below the window size.
        assert!((ssim_plane(&b, &a, w, h).unwrap() - s).abs() < 1e-12);
        assert_eq!(ssim_plane(&a[..10 * 48], &b[..10 * 48], 48, 10), None);
    }

    /// Two 8-bit sRGB images from integer patterns (the reference values below were computed
    /// from the same bytes by NVIDIA's flip-evaluator 1.7).
    fn flip_images() -> (Vec<u8>, Vec<u8>, u32, u32) {
        let (w, h) = (64u32, 48u32);
        let (mut reference, mut test) = (Vec::new(), Vec::new());
        for y in 0..h as i32 {
            for x in 0..w as i32 {
                for c in 0..3 {
                    let r = (40 + 2 * x + y + 30 * c) % 256;
                    let t = (r + 3 * ((x * 13 + y * 7 + x * y + c * 5) % 23 - 11)).clamp(0, 255);
                    reference.push(r as u8);
                    test.push(t as u8);
                }
            }
        }
        (test, reference, w, h)
    }

    #[test]
    fn flip_matches_nvidias_reference_implementation() {
        // flip_evaluator.evaluate(reference / 255, test / 255, "LDR") of flip-evaluator 1.7
        // (NVIDIA's own package): mean 0.151177183 at its default 67.02 px/deg, 0.286874145 at
        // 30 px/deg; maximum 0.523064017.
        let (test, reference, w, h) = flip_images();
        let ppd = nv_flip::pixels_per_degree(0.7, 3840.0, 0.7);
        let f = flip_rgb8(&test, &reference, w, h, ppd);
        assert!((f.mean - 0.151_177_183).abs() < 1e-5, "FLIP {f:?}");
        assert!((f.max - 0.523_064_017).abs() < 1e-4, "FLIP {f:?}");
        let f30 = flip_rgb8(&test, &reference, w, h, 30.0);
        assert!((f30.mean - 0.286_874_145).abs() < 1e-5, "FLIP {f30:?}");
        let same = flip_rgb8(&reference, &reference, w, h, ppd);
        assert_eq!(
            same,
            Flip {
                mean: 0.0,
                max: 0.0
            }
        );
    }

    /// A smooth test picture: radiance from 0 to about 1 with some structure.
    fn picture(w: u32, h: u32) -> Image {
        Image::from_fn(w, h, |x, y| {
            let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
            Vec3::new(
                0.9 * u,
                0.5 + 0.4 * (9.0 * u).sin() * (7.0 * v).cos(),
                0.2 + 0.6 * v,
            )
        })
    }

    #[test]
    fn perceptual_metrics_order_perturbations() {
        let b = picture(64, 64);
        let window = Rect::window_of(&b);
        let display = Display {
            gain: 1.0,
            tonemap: ToneMap::Clamp,
        };
        // Identical images: SSIM exactly 1, FLIP exactly 0.
        assert_eq!(ssim(&b, &b, window, display), Some([1.0; 3]));
        assert_eq!(
            flip(&b, &b, window, display, 67.0),
            Flip {
                mean: 0.0,
                max: 0.0
            }
        );
        // Noise of growing amplitude (fixed seed): SSIM falls and FLIP rises at every step.
        let mut rng = tress_core::rng::Pcg32::new(7, 0);
        let mut u = || rng.next_f32() - 0.5;
        let noise: Vec<Vec3> = (0..64 * 64).map(|_| Vec3::new(u(), u(), u())).collect();
        let noisy = |amplitude: f32| {
            let mut a = b.clone();
            for (p, n) in a.pixels.iter_mut().zip(&noise) {
                *p += *n * amplitude;
            }
            a
        };
        let mut last = (1.0f64, 0.0f64);
        for amplitude in [0.01, 0.04, 0.16, 0.64] {
            let a = noisy(amplitude);
            let s = ssim(&a, &b, window, display).unwrap().iter().sum::<f64>() / 3.0;
            let f = flip(&a, &b, window, display, 67.0).mean;
            assert!(
                s < last.0 && f > last.1,
                "amplitude {amplitude}: SSIM {s}, FLIP {f}, before {last:?}"
            );
            last = (s, f);
        }
        // A uniform 10 % brightening keeps the structure: SSIM stays far above the strongest noise.
        let mut brighter = b.clone();
        brighter.pixels.iter_mut().for_each(|p| *p *= 1.1);
        let s = ssim(&brighter, &b, window, display).unwrap();
        assert!(s.iter().all(|&c| c > 0.95 && c < 1.0), "{s:?}");
        // Regions under the window have no SSIM; FLIP still measures them.
        let small = Rect {
            x: 0,
            y: 0,
            w: 10,
            h: 64,
        };
        assert_eq!(ssim(&noisy(0.1), &b, small, display), None);
        assert!(flip(&noisy(0.1), &b, small, display, 67.0).mean > 0.0);
    }

    #[test]
    fn the_json_summary_has_every_metric() {
        let b = picture(32, 32);
        let mut a = b.clone();
        a.pixels[5] += Vec3::splat(0.25);
        #[derive(clap::Parser)]
        struct Command {
            #[command(flatten)]
            args: DiffArgs,
        }
        let args = <Command as clap::Parser>::try_parse_from(["diff", "a.exr", "b.exr"])
            .unwrap()
            .args;
        let rect = Rect::window_of(&b);
        let display = Display {
            gain: 1.0,
            tonemap: args.tonemap,
        };
        let m = metrics(&a, &b, rect);
        let fields = summary_fields(
            &args,
            rect,
            &m,
            ssim(&a, &b, rect, display),
            flip(&a, &b, rect, display, args.flip_ppd),
            None,
        );
        let line = serde_json::Value::Object(fields.into_iter().collect()).to_string();
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        for key in ["mse", "relmse", "psnr_db", "mean_diff", "ssim"] {
            for c in ["r", "g", "b", "all"] {
                assert!(v[key][c].is_number(), "{key}.{c} in {line}");
            }
        }
        assert!(v["flip"]["mean"].as_f64().unwrap() > 0.0);
        assert!((v["flip"]["pixels_per_degree"].as_f64().unwrap() - 67.02).abs() < 0.01);
        assert_eq!(v["region"]["w"], 32);
        assert_eq!(v["reference"], "b.exr");
        assert!(v["ssim"]["all"].as_f64().unwrap() < 1.0);
        assert_eq!(v["display"]["tonemap"], "filmic");
        // Identical images: infinite PSNR is written as null, not as an invalid number.
        let m = metrics(&b, &b, rect);
        let fields = summary_fields(
            &args,
            rect,
            &m,
            None,
            Flip {
                mean: 0.0,
                max: 0.0,
            },
            None,
        );
        let v = serde_json::Value::Object(fields.into_iter().collect());
        assert!(v["psnr_db"]["all"].is_null() && v["ssim"].is_null());
    }

    #[test]
    fn mismatches_are_described() {
        let a = Image::new(4, 3);
        let b = Image::new(3, 4);
        let e = check_compatible(&a, &b).unwrap_err();
        assert!(e.contains("4x3") && e.contains("3x4"), "{e}");
        let e = resolve_region(
            &a,
            Some(Rect {
                x: 2,
                y: 0,
                w: 3,
                h: 1,
            }),
        )
        .unwrap_err();
        assert!(e.contains("3x1 at (2, 0)"), "{e}");
        assert!(Rect::parse("1,2,3").is_err());
        assert!(Rect::parse("1,2,0,4").is_err());
        assert_eq!(
            Rect::parse(" 1, 2,3,4").unwrap(),
            Rect {
                x: 1,
                y: 2,
                w: 3,
                h: 4
            }
        );
    }
}
