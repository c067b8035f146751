//! Error metrics of an image A against a reference B, and per-pixel error maps: what `tress
//! diff` prints and what studies tabulate.
//!
//! Over the pixels of the compared region, per channel, then over all channels:
//! - `MSE    = mean (A − B)²`
//! - `relMSE = mean (A − B)² / (B² + ε)` with ε = [`REL_EPSILON`] = 1e-2, so dark pixels do not
//!   dominate and bright ones do not drown the rest (docs/src/reference/hair-maths.md#measuring-an-estimator);
//! - `PSNR   = 10 log10(peak² / MSE)` dB, peak = the largest value of B over the region and all
//!   channels (1 when B is black there), the same peak for every channel;
//! - `mean difference = mean (A − B)`: the bias when A averages independent renders.

use std::path::{Path, PathBuf};
use tress_core::Image;

/// ε of the relative MSE.
pub const REL_EPSILON: f64 = 1e-2;

/// A pixel rectangle in film coordinates (the full film, not the rendered window).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    /// Left column.
    pub x: u32,
    /// Top row.
    pub y: u32,
    /// Width in pixels.
    pub w: u32,
    /// Height in pixels.
    pub h: u32,
}

impl Rect {
    /// Parses `x,y,w,h`.
    pub fn parse(s: &str) -> Result<Rect, String> {
        let parts: Vec<&str> = s.split(',').collect();
        if parts.len() != 4 {
            return Err(format!("expected x,y,w,h, got '{s}'"));
        }
        let mut v = [0u32; 4];
        for (o, p) in v.iter_mut().zip(&parts) {
            *o = p
                .trim()
                .parse()
                .map_err(|_| format!("'{p}' is not a non-negative integer"))?;
        }
        if v[2] == 0 || v[3] == 0 {
            return Err(format!("region '{s}' is empty"));
        }
        Ok(Rect {
            x: v[0],
            y: v[1],
            w: v[2],
            h: v[3],
        })
    }

    /// The rendered window of `img`, in film coordinates.
    pub fn window_of(img: &Image) -> Rect {
        Rect {
            x: img.x0,
            y: img.y0,
            w: img.width,
            h: img.height,
        }
    }

    fn contains(&self, o: &Rect) -> bool {
        o.x >= self.x
            && o.y >= self.y
            && o.x as u64 + o.w as u64 <= self.x as u64 + self.w as u64
            && o.y as u64 + o.h as u64 <= self.y as u64 + self.h as u64
    }
}

impl std::fmt::Display for Rect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{} at ({}, {})", self.w, self.h, self.x, self.y)
    }
}

/// Describes an image's geometry for mismatch messages.
fn geometry(img: &Image) -> String {
    format!(
        "window {} of a {}x{} film",
        Rect::window_of(img),
        img.full_width,
        img.full_height
    )
}

/// Checks that `a` and `b` cover the same window of the same film; the error describes both.
pub fn check_compatible(a: &Image, b: &Image) -> Result<(), String> {
    if (a.full_width, a.full_height, a.x0, a.y0, a.width, a.height)
        != (b.full_width, b.full_height, b.x0, b.y0, b.width, b.height)
    {
        return Err(format!(
            "the images differ in size: {} vs {}",
            geometry(a),
            geometry(b)
        ));
    }
    Ok(())
}

/// The region to compare: `region`, checked to lie inside the rendered window, or the window.
pub fn resolve_region(img: &Image, region: Option<Rect>) -> Result<Rect, String> {
    let window = Rect::window_of(img);
    match region {
        None => Ok(window),
        Some(r) if window.contains(&r) => Ok(r),
        Some(r) => Err(format!(
            "region {r} is not inside the rendered {}",
            geometry(img)
        )),
    }
}

/// Errors of A against the reference B over one region.
#[derive(Clone, Debug, PartialEq)]
pub struct Metrics {
    /// MSE per channel.
    pub mse: [f64; 3],
    /// Relative MSE per channel.
    pub relmse: [f64; 3],
    /// Mean of A − B per channel.
    pub mean_diff: [f64; 3],
    /// Mean of A per channel.
    pub mean_a: [f64; 3],
    /// Mean of B per channel.
    pub mean_b: [f64; 3],
    /// PSNR peak: the largest value of B (1 if B is black).
    pub peak: f64,
}

/// The mean of three channels.
pub fn avg3(v: [f64; 3]) -> f64 {
    (v[0] + v[1] + v[2]) / 3.0
}

impl Metrics {
    /// The MSE over all channels.
    pub fn mse_all(&self) -> f64 {
        avg3(self.mse)
    }
    /// The relative MSE over all channels.
    pub fn relmse_all(&self) -> f64 {
        avg3(self.relmse)
    }
    /// The mean of A − B over all channels.
    pub fn mean_diff_all(&self) -> f64 {
        avg3(self.mean_diff)
    }
    /// The mean of A over all channels.
    pub fn mean_a_all(&self) -> f64 {
        avg3(self.mean_a)
    }
    /// The mean of B over all channels.
    pub fn mean_b_all(&self) -> f64 {
        avg3(self.mean_b)
    }
    /// PSNR in dB for a given MSE (infinite for identical images).
    pub fn psnr(&self, mse: f64) -> f64 {
        10.0 * (self.peak * self.peak / mse).log10()
    }
}

/// Iterates the pixel pairs of `rect` (film coordinates), which must lie in the shared window.
fn pairs<'a>(
    a: &'a Image,
    b: &'a Image,
    rect: Rect,
) -> impl Iterator<Item = (glam::Vec3, glam::Vec3)> + 'a {
    (rect.y..rect.y + rect.h).flat_map(move |y| {
        (rect.x..rect.x + rect.w)
            .map(move |x| (a.get(x - a.x0, y - a.y0), b.get(x - b.x0, y - b.y0)))
    })
}

/// Metrics of `a` against the reference `b` over `rect`. The images must be compatible
/// ([`check_compatible`]) and `rect` inside their window ([`resolve_region`]).
pub fn metrics(a: &Image, b: &Image, rect: Rect) -> Metrics {
    let mut m = Metrics {
        mse: [0.0; 3],
        relmse: [0.0; 3],
        mean_diff: [0.0; 3],
        mean_a: [0.0; 3],
        mean_b: [0.0; 3],
        peak: 0.0,
    };
    for (pa, pb) in pairs(a, b, rect) {
        for c in 0..3 {
            let (va, vb) = (pa[c] as f64, pb[c] as f64);
            let d = va - vb;
            m.mse[c] += d * d;
            m.relmse[c] += d * d / (vb * vb + REL_EPSILON);
            m.mean_diff[c] += d;
            m.mean_a[c] += va;
            m.mean_b[c] += vb;
            m.peak = m.peak.max(vb);
        }
    }
    let n = rect.w as f64 * rect.h as f64;
    for v in [
        &mut m.mse,
        &mut m.relmse,
        &mut m.mean_diff,
        &mut m.mean_a,
        &mut m.mean_b,
    ] {
        for c in v.iter_mut() {
            *c /= n;
        }
    }
    if m.peak <= 0.0 {
        m.peak = 1.0;
    }
    m
}

/// What an error map shows per pixel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapKind {
    /// RMS over the channels of |A − B|.
    Abs,
    /// RMS over the channels of |A − B| / sqrt(B² + ε): the per-pixel square root of relMSE.
    Rel,
}

impl MapKind {
    /// Colour-bar label.
    pub fn label(self) -> &'static str {
        match self {
            MapKind::Abs => "|A - B| (RMS over RGB)",
            MapKind::Rel => "|A - B| / sqrt(B² + 0.01) (RMS over RGB)",
        }
    }
}

/// Per-pixel error of `a` against `b` over `rect`, row-major (`rect.w × rect.h`).
pub fn error_map(a: &Image, b: &Image, rect: Rect, kind: MapKind) -> Vec<f32> {
    pairs(a, b, rect)
        .map(|(pa, pb)| {
            let mut s = 0.0f64;
            for c in 0..3 {
                let d = (pa[c] - pb[c]) as f64;
                s += match kind {
                    MapKind::Abs => d * d,
                    MapKind::Rel => d * d / ((pb[c] as f64).powi(2) + REL_EPSILON),
                };
            }
            (s / 3.0).sqrt() as f32
        })
        .collect()
}

/// Refuses an image (read from `path`) holding NaN or infinite pixels, to be compared with
/// another: one NaN makes every metric NaN, which `diff` printed, and a study wrote into its
/// summary, with success.
pub fn check_finite(image: &Image, path: &Path) -> Result<(), NotFinite> {
    let pixels = image.pixels.iter().filter(|p| !p.is_finite()).count();
    if pixels > 0 {
        return Err(NotFinite {
            path: path.to_owned(),
            pixels,
        });
    }
    Ok(())
}

/// An image holding NaN or infinite pixels ([`check_finite`]).
#[derive(Debug, thiserror::Error)]
#[error("{}: {pixels} pixels are NaN or infinite; the error metrics would be NaN", path.display())]
pub struct NotFinite {
    /// The image's file.
    pub path: PathBuf,
    /// How many of its pixels are NaN or infinite.
    pub pixels: usize,
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn hand_computed_metrics() {
        let b = Image::from_fn(2, 1, |x, _| Vec3::splat(x as f32 + 1.0)); // 1, 2
        let a = Image::from_fn(2, 1, |x, _| Vec3::new(x as f32 + 1.5, x as f32 + 1.0, 0.0)); // +0.5, 0, −B
        let m = metrics(&a, &b, Rect::window_of(&a));
        assert_eq!(m.mse[0], 0.25);
        assert_eq!(m.mse[1], 0.0);
        assert_eq!(m.mse[2], (1.0 + 4.0) / 2.0);
        let rel_r = (0.25 / (1.0 + REL_EPSILON) + 0.25 / (4.0 + REL_EPSILON)) / 2.0;
        assert!((m.relmse[0] - rel_r).abs() < 1e-15);
        assert_eq!(m.mean_diff, [0.5, 0.0, -1.5]);
        assert_eq!(m.peak, 2.0);
        assert!((m.psnr(0.25) - 10.0 * 16f64.log10()).abs() < 1e-12);
        // A region: only the second pixel.
        let r = resolve_region(
            &a,
            Some(Rect {
                x: 1,
                y: 0,
                w: 1,
                h: 1,
            }),
        )
        .unwrap();
        assert_eq!(metrics(&a, &b, r).mse, [0.25, 0.0, 4.0]);
        assert_eq!(
            error_map(&a, &b, r, MapKind::Abs),
            vec![((0.25f64 + 4.0) / 3.0).sqrt() as f32]
        );
    }
}
