//! Equirectangular environment map with importance sampling.
//!
//! Directions map to texels as documented at the top of `crate::light`. Lookups return the
//! nearest texel (radiance is piecewise constant), so each texel's radiance is constant over exactly the (u, v) cell that
//! the sampling distribution assigns to it: sampling, `pdf` and `radiance` share one grid and
//! there is no half-texel shift between them (the bug of pbrt-v3#62).
//!
//! Sampling picks a texel ∝ luminance × sin θ (sin θ averaged over the texel's row) from one
//! alias table over all texels, places (u, v) uniformly in it and maps it to the sphere; the
//! solid-angle density is pdf(ω) = pdf_uv(u, v) / (2π² sin θ), since
//! dω = sin θ dθ dφ = 2π² sin θ du dv. With a 1k map beside the BVH every table read is a
//! cache miss, and they were the largest item of the path tracer's profile: a marginal and
//! conditional distribution read four to five scattered entries. Here one 32-byte record per
//! texel holds its radiance, its alias entry and the radiance of that entry's alias, and
//! pdf_uv is recomputed from the radiance and a per-row factor, so a light sample reads one
//! record whichever texel it draws, and an escape one record.

use crate::image_io::{read_rgb, ImageError};
use crate::light_sample::{LightSample, MAX_LIGHT};
use crate::math::{luminance, Rgb, Vec2, Vec3};
use crate::sampling::{alias_choose, prefetch, Distribution1D};
use std::f32::consts::{FRAC_1_PI, PI, TAU};
use std::path::Path;

/// An equirectangular environment map (see `crate::light` for the direction convention).
#[derive(Clone, Debug)]
pub struct EnvironmentMap {
    width: usize,
    height: usize,
    /// Row-major, top row (zenith) first.
    cells: Vec<Cell>,
    /// Per row: the mean sin θ, which weighs its texels' luminance in the sampling density.
    row_sin: Vec<f32>,
    /// Mean importance over the texels (0 for a black map, which is sampled uniformly).
    integral: f32,
    /// Rotation about +y in radians.
    rotation: f32,
    /// How far inside its texel, as a fraction of the texel's width and height, a sampled
    /// point must lie for the texel that `uv_of` finds for its direction to be certainly the
    /// one drawn (see [`EnvironmentMap::sample`]).
    interior: Vec2,
}

/// Texel k and entry k of the alias table over the texels, with the radiance of the entry's
/// alias: a light sample reads this one record whichever of the two texels it takes. 32 bytes,
/// aligned, so a record never straddles two cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct Cell {
    /// Already multiplied by the scale.
    radiance: Rgb,
    /// The probability that entry k takes texel k, else it takes texel `alias`.
    keep: f32,
    alias: u32,
    /// The radiance of texel `alias`.
    alias_radiance: Rgb,
}

impl EnvironmentMap {
    /// Loads a Radiance `.hdr` or OpenEXR `.exr` lat-long map. `rotation_deg` turns it about +y
    /// and `scale` multiplies its radiance.
    pub fn from_file(
        path: impl AsRef<Path>,
        rotation_deg: f32,
        scale: f32,
    ) -> Result<Self, ImageError> {
        let path = path.as_ref();
        let (w, h, pixels) = read_rgb(path)?;
        Self::build(
            w,
            h,
            pixels,
            rotation_deg,
            scale,
            &path.display().to_string(),
        )
    }

    /// A map from row-major pixels (top row = zenith). Non-finite pixels are an error; negative
    /// components (lossy-compression undershoot) are clamped to 0.
    pub fn from_pixels(
        width: u32,
        height: u32,
        pixels: Vec<Rgb>,
        rotation_deg: f32,
        scale: f32,
    ) -> Result<Self, ImageError> {
        Self::build(
            width,
            height,
            pixels,
            rotation_deg,
            scale,
            "environment map pixels",
        )
    }

    /// A procedural 256×128 HDR sky: a blue zenith-to-horizon gradient with a bright horizon
    /// band, a dark ground and a sun disc 3° across (radiance ≈ 500) at 35° elevation, whose
    /// azimuth in the unrotated map is φ = 40° (from −z toward +x).
    pub fn builtin_sky(rotation_deg: f32, scale: f32) -> Result<Self, ImageError> {
        const W: usize = 256;
        const H: usize = 128;
        const SUN_RADIUS: f32 = 1.5 * PI / 180.0;
        const SUN_RADIANCE: Rgb = Rgb::new(520.0, 490.0, 440.0);
        const SUPER: usize = 8;
        let sun_dir = map_direction(35f32.to_radians(), 40f32.to_radians());
        let cos_sun = SUN_RADIUS.cos();
        let mut pixels = Vec::with_capacity(W * H);
        for j in 0..H {
            for i in 0..W {
                let (v, u) = ((j as f32 + 0.5) / H as f32, (i as f32 + 0.5) / W as f32);
                let elevation = 0.5 * PI - v * PI;
                let d = map_direction(elevation, (u - 0.5) * TAU);
                let mut c = if elevation >= 0.0 {
                    let t = 1.0 - elevation / (0.5 * PI);
                    let zenith = Rgb::new(0.10, 0.22, 0.55);
                    let horizon = Rgb::new(0.55, 0.65, 0.80);
                    zenith.lerp(horizon, t * t)
                        + Rgb::new(0.35, 0.30, 0.25) * (-elevation / 0.08).exp()
                } else {
                    Rgb::new(0.09, 0.08, 0.07) * (0.6 + 0.4 * (elevation / 0.15).exp())
                };
                // A soft aureole around the sun, then the disc's coverage of this texel.
                let cos_to_sun = d.dot(sun_dir);
                c += Rgb::new(2.0, 1.7, 1.3) * ((cos_to_sun - 1.0) / 0.002).exp();
                if cos_to_sun > (SUN_RADIUS + 2.0 * PI / H as f32).cos() {
                    let mut covered = 0;
                    for a in 0..SUPER {
                        for b in 0..SUPER {
                            let vs = (j as f32 + (a as f32 + 0.5) / SUPER as f32) / H as f32;
                            let us = (i as f32 + (b as f32 + 0.5) / SUPER as f32) / W as f32;
                            let ds = map_direction(0.5 * PI - vs * PI, (us - 0.5) * TAU);
                            covered += usize::from(ds.dot(sun_dir) >= cos_sun);
                        }
                    }
                    c += SUN_RADIANCE * (covered as f32 / (SUPER * SUPER) as f32);
                }
                pixels.push(c);
            }
        }
        Self::build(
            W as u32,
            H as u32,
            pixels,
            rotation_deg,
            scale,
            "built-in sky",
        )
    }

    fn build(
        width: u32,
        height: u32,
        mut pixels: Vec<Rgb>,
        rotation_deg: f32,
        scale: f32,
        origin: &str,
    ) -> Result<Self, ImageError> {
        if !rotation_deg.is_finite() {
            return Err(ImageError::InvalidParameter {
                name: "rotation",
                requirement: "finite",
                value: rotation_deg,
            });
        }
        if !(scale.is_finite() && scale >= 0.0) {
            return Err(ImageError::InvalidParameter {
                name: "scale",
                requirement: "finite and non-negative",
                value: scale,
            });
        }
        let invalid = |reason: String| ImageError::InvalidData {
            origin: origin.to_owned(),
            reason,
        };
        let (w, h) = (width as usize, height as usize);
        if w == 0 || h == 0 || pixels.len() != w * h {
            return Err(invalid(format!(
                "{} pixels do not make a non-empty {width}x{height} image",
                pixels.len()
            )));
        }
        let mut clamped = 0usize;
        for (k, p) in pixels.iter_mut().enumerate() {
            if !p.is_finite() {
                return Err(invalid(format!(
                    "pixel ({}, {}) is not finite: {p}",
                    k % w,
                    k / w
                )));
            }
            if p.min_element() < 0.0 {
                clamped += 1;
                *p = p.max(Rgb::ZERO);
            }
            let scaled = *p * scale;
            // Finite texels can overflow once scaled (3e38 × 10): refuse, or the image is black;
            // beyond the lights' limit, paths multiplying them overflow.
            if !(scaled.is_finite() && scaled.max_element() <= MAX_LIGHT) {
                return Err(invalid(format!(
                    "pixel ({}, {}) = {p} times scale {scale} is beyond {:e} (a path's \
                     throughput times it overflows f32)",
                    k % w,
                    k / w,
                    MAX_LIGHT
                )));
            }
            *p = scaled;
        }
        if clamped > 0 {
            tracing::warn!("{origin}: clamped {clamped} pixels with negative components to 0");
        }
        // Importance ∝ luminance × the row's mean sin θ, i.e. ∝ the texel's power.
        let row_sin: Vec<f32> = (0..h)
            .map(|j| {
                let (t0, t1) = (PI * j as f32 / h as f32, PI * (j + 1) as f32 / h as f32);
                (t0.cos() - t1.cos()) / (t1 - t0)
            })
            .collect();
        let func: Vec<f32> = pixels
            .iter()
            .enumerate()
            .map(|(k, &p)| importance(p, row_sin[k / w]))
            .collect();
        let distribution = Distribution1D::new(&func);
        let rotation = rotation_deg.to_radians();
        let cells = pixels
            .iter()
            .enumerate()
            .map(|(k, &radiance)| {
                let (keep, alias) = distribution.alias_entry(k);
                Cell {
                    radiance,
                    keep,
                    alias,
                    alias_radiance: pixels[alias as usize],
                }
            })
            .collect();
        Ok(EnvironmentMap {
            width: w,
            height: h,
            cells,
            row_sin,
            integral: distribution.integral(),
            rotation,
            interior: interior_margins(w, h, rotation),
        })
    }

    /// Map resolution `(width, height)` in texels.
    pub fn resolution(&self) -> (u32, u32) {
        (self.width as u32, self.height as u32)
    }

    /// (u, v) ∈ [0, 1)² and sin θ of a world direction (need not be normalised).
    #[inline]
    fn uv_of(&self, d: Vec3) -> (Vec2, f32) {
        let r = d.x.hypot(d.z);
        let theta = r.atan2(d.y);
        let phi = d.x.atan2(-d.z) + self.rotation;
        let u = (phi * (0.5 * FRAC_1_PI) + 0.5).rem_euclid(1.0);
        (Vec2::new(u, theta * FRAC_1_PI), sin_theta_of(d, r))
    }

    /// The direction of map point `uv`: the inverse of [`Self::uv_of`].
    #[inline]
    fn direction_at(&self, uv: Vec2) -> Vec3 {
        map_direction(0.5 * PI - uv.y * PI, (uv.x - 0.5) * TAU - self.rotation)
    }

    /// Radiance arriving from direction `dir` (nearest texel).
    pub fn radiance(&self, dir: Vec3) -> Rgb {
        self.cells[self.texel_at(self.uv_of(dir).0).0].radiance
    }

    /// Radiance from `dir` interpolated bilinearly between the four nearest texel centres (u
    /// wraps around, v is clamped at the poles): the map as the camera sees it directly,
    /// without the blocks of [`Self::radiance`]. Lighting keeps the nearest texel, which the
    /// sampling density matches exactly.
    pub fn radiance_bilinear(&self, dir: Vec3) -> Rgb {
        let (uv, _) = self.uv_of(dir);
        let (w, h) = (self.width as i64, self.height as i64);
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let column = |i: i64| i.rem_euclid(w) as usize;
        let row = |j: i64| j.clamp(0, h - 1) as usize;
        let (i0, j0) = (x0 as i64, y0 as i64);
        let at = |i: i64, j: i64| self.cells[row(j) * self.width + column(i)].radiance;
        let top = at(i0, j0) * (1.0 - fx) + at(i0 + 1, j0) * fx;
        let bottom = at(i0, j0 + 1) * (1.0 - fx) + at(i0 + 1, j0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }

    /// The texel whose cell holds `uv`, as its index and row: the one cell arithmetic of
    /// lookups, densities and sampling.
    #[inline]
    fn texel_at(&self, uv: Vec2) -> (usize, usize) {
        let i = ((uv.x * self.width as f32) as usize).min(self.width - 1);
        let j = ((uv.y * self.height as f32) as usize).min(self.height - 1);
        (j * self.width + i, j)
    }

    /// Density of sampling (u, v) in a texel of row `row` with this radiance, w.r.t. area in
    /// [0, 1)²: the distribution's `Distribution1D::pdf_cell`, recomputed from the radiance in
    /// the same operations (bit for bit: tested), so that no table of densities is read.
    #[inline]
    fn pdf_uv(&self, radiance: Rgb, row: usize) -> f32 {
        if self.integral > 0.0 {
            importance(radiance, self.row_sin[row]) / self.integral
        } else {
            1.0
        }
    }

    /// Solid-angle density of a direction at polar angle sin θ (0 at the poles) in a texel
    /// of row `row` with this radiance.
    #[inline]
    fn solid_angle_pdf(&self, radiance: Rgb, row: usize, sin_theta: f32) -> f32 {
        if sin_theta <= 0.0 {
            return 0.0;
        }
        self.pdf_uv(radiance, row) / (2.0 * PI * PI * sin_theta)
    }

    /// `(radiance(dir), pdf(dir))`, locating the texel once: what a path that escapes toward
    /// the map needs for its MIS weight.
    pub fn radiance_pdf(&self, dir: Vec3) -> (Rgb, f32) {
        let (uv, sin_theta) = self.uv_of(dir);
        let (k, row) = self.texel_at(uv);
        let radiance = self.cells[k].radiance;
        (radiance, self.solid_angle_pdf(radiance, row, sin_theta))
    }

    /// Asks for the record that [`EnvironmentMap::radiance_pdf`] reads for `dir` to be
    /// brought into the cache (a hint; it changes no result).
    pub fn prefetch_radiance(&self, dir: Vec3) {
        prefetch(&self.cells[self.texel_at(self.uv_of(dir).0).0]);
    }

    /// Asks for the record that [`EnvironmentMap::sample`] reads for `u` to be brought into
    /// the cache (a hint; it changes no result).
    pub fn prefetch_sample(&self, u: Vec2) {
        prefetch(&self.cells[self.entry_of(u.x).0]);
    }

    /// The alias entry `u_entry` picks, and what is left of `u_entry`, uniform in [0, 1].
    #[inline]
    fn entry_of(&self, u_entry: f32) -> (usize, f32) {
        let n = self.cells.len();
        let scaled = u_entry.clamp(0.0, 1.0) * n as f32;
        let entry = (scaled as usize).min(n - 1);
        (entry, (scaled - entry as f32).clamp(0.0, 1.0))
    }

    /// Solid-angle density with which [`EnvironmentMap::sample`] returns `wi`.
    pub fn pdf(&self, wi: Vec3) -> f32 {
        self.radiance_pdf(wi).1
    }

    /// A direction toward the environment, importance sampled ∝ luminance, from two uniform
    /// numbers. `None` only for the measure-zero poles.
    pub fn sample(&self, u: Vec2) -> Option<LightSample> {
        // u.x picks the alias entry, u.y the texel of the entry with all its bits (one number
        // would leave the choice 24 − log₂ n bits: 5 on a 1k × 512 map, which skews every
        // texel's probability to a multiple of 1/32); what is left of u.y places the point in
        // the texel (its top 12 bits the row offset, the others the column offset) and what
        // is left of u.x refines the row offset.
        let (entry, rest_entry) = self.entry_of(u.x);
        let cell = &self.cells[entry];
        let (k, rest_choice) = alias_choose(cell.keep, cell.alias, entry, u.y.clamp(0.0, 1.0));
        let drawn = if k == entry {
            cell.radiance
        } else {
            cell.alias_radiance
        };
        let (i, j) = (k % self.width, k / self.width);
        let split = rest_choice * JITTER_STEPS;
        let row_step = split.floor().min(JITTER_STEPS - 1.0);
        let (dv, du) = ((row_step + rest_entry) / JITTER_STEPS, split - row_step);
        let uv = Vec2::new(
            (i as f32 + du) / self.width as f32,
            (j as f32 + dv) / self.height as f32,
        );
        let wi = self.direction_at(uv);
        // Density and radiance are those `pdf(wi)` and `radiance(wi)` return, bit for bit: of
        // the texel `uv_of(wi)` falls in, which is the one drawn unless rounding moved `wi`
        // across its edge. Inside the margins it cannot have, and the drawn texel is taken
        // without `uv_of`'s two arc tangents (a quarter of a light sample's time).
        let inside = |d: f32, margin: f32| d >= margin && d <= 1.0 - margin;
        let (t, row) = if inside(du, self.interior.x) && inside(dv, self.interior.y) {
            (k, j)
        } else {
            self.texel_at(self.uv_of(wi).0)
        };
        let sin_theta = sin_theta_of(wi, wi.x.hypot(wi.z));
        let radiance = if t == k {
            drawn
        } else {
            self.cells[t].radiance
        };
        let pdf = self.solid_angle_pdf(radiance, row, sin_theta);
        if !(pdf > 0.0 && pdf.is_finite()) {
            return None;
        }
        Some(LightSample {
            wi,
            radiance,
            pdf,
            distance: f32::INFINITY,
            is_delta: false,
        })
    }
}

/// Steps of the row offset inside a texel taken from the top bits of what is left of the
/// second sampling number (the other bits give the column offset).
const JITTER_STEPS: f32 = 4096.0;

/// sin θ of direction `d` (need not be normalised) whose distance from the y axis is `r`; 0
/// for the zero vector.
#[inline]
fn sin_theta_of(d: Vec3, r: f32) -> f32 {
    let len = d.length();
    if len > 0.0 {
        r / len
    } else {
        0.0
    }
}

/// Fractions of a texel's width and height that bound how far rounding can move a point
/// sampled in the texel, on its way to a direction and back through `uv_of`, on a `width` ×
/// `height` map rotated by `rotation` radians. Each step (the point's (u, v), the angles,
/// their sines and cosines, the arc tangents, adding the rotation) is accurate to a few units
/// of f32 rounding (ε) of the angles involved, which reach π + |rotation|: 64 ε of those,
/// over the angle a texel spans, is over ten times what they can add up to.
fn interior_margins(width: usize, height: usize, rotation: f32) -> Vec2 {
    let slack = 64.0 * f32::EPSILON;
    Vec2::new(
        slack * (TAU + rotation.abs()) / TAU * width as f32,
        slack * height as f32,
    )
}

/// A texel's sampling weight: its luminance times its row's mean sin θ, i.e. ∝ its power.
#[inline]
fn importance(radiance: Rgb, row_sin: f32) -> f32 {
    luminance(radiance) * row_sin
}

/// World direction at `elevation` above the horizon and azimuth `phi` = atan2(x, −z).
#[inline]
fn map_direction(elevation: f32, phi: f32) -> Vec3 {
    let (sin_e, cos_e) = elevation.sin_cos();
    let (sin_p, cos_p) = phi.sin_cos();
    Vec3::new(cos_e * sin_p, sin_e, -cos_e * cos_p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Frame;
    use crate::rng::Sampler;
    use crate::stats::{sidak_alpha, Chi2Outcome, SphereChi2};

    const VENICE: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/envmaps/venice_sunset_1k.hdr"
    );
    /// χ² tests expected to pass in this module (synthetic map, built-in sky, real map).
    const CHI2_TESTS: usize = 3;

    /// A map with a gradient, a black band and sharp bright spots, including one at the pole
    /// row and one straddling the u = 0/1 seam.
    fn synthetic_map(rotation_deg: f32) -> EnvironmentMap {
        let (w, h) = (160usize, 80usize);
        let mut px = Vec::with_capacity(w * h);
        for j in 0..h {
            for i in 0..w {
                let (u, v) = ((i as f32 + 0.5) / w as f32, (j as f32 + 0.5) / h as f32);
                let mut c = Rgb::new(0.2 + 1.5 * (1.0 - v), 0.3 + 0.5 * u, 0.4 + v);
                if (56..64).contains(&j) {
                    c = Rgb::ZERO;
                }
                match (i, j) {
                    (20, 10) => c = Rgb::new(800.0, 700.0, 600.0),
                    (100..=102, 45..=46) => c = Rgb::new(150.0, 200.0, 250.0),
                    (70, 1) => c = Rgb::splat(300.0),
                    (0, 30) | (159, 30) => c = Rgb::new(100.0, 50.0, 20.0),
                    _ => {}
                }
                px.push(c);
            }
        }
        EnvironmentMap::from_pixels(w as u32, h as u32, px, rotation_deg, 1.0).unwrap()
    }

    fn chi2_harness() -> SphereChi2 {
        SphereChi2 {
            pole: Vec3::Y,
            ..Default::default()
        }
    }

    /// Wraps a solid-angle pdf so that, evaluated at a sub-cell midpoint of `chi`, it returns
    /// the pdf's exact mean over that sub-cell.
    ///
    /// Why: the harness integrates the pdf with a midpoint rule, which cannot resolve the
    /// discontinuities of a texel-wise constant pdf around sharp, bright texels well enough for
    /// 10⁶ samples (it rejects a correct sampler). Here each sub-cell is split at the texel
    /// edges and `pdf` itself is evaluated at the centre of every piece, which is exact when
    /// pdf · sin θ is constant on texels — precisely the claim under test. A pdf shifted against
    /// the texel grid (pbrt-v3#62) is evaluated in the wrong texel on part of the pieces and
    /// fails.
    fn subcell_mean_pdf<'a>(
        chi: &SphereChi2,
        env: &'a EnvironmentMap,
        pdf: impl Fn(Vec3) -> f64 + 'a,
    ) -> impl Fn(Vec3) -> f64 + 'a {
        // The harness's cells are in this frame: local φ = 0 along +x, φ = π/2 along −z.
        let f = Frame::from_z(chi.pole);
        assert!(f.x.abs_diff_eq(Vec3::X, 1e-6) && f.y.abs_diff_eq(-Vec3::Z, 1e-6));
        let dc = 2.0 / (chi.res_cos * chi.sub) as f64;
        let dp = std::f64::consts::TAU / (chi.res_phi * chi.sub) as f64;
        let (w, h) = (env.width as f64, env.height as f64);
        let rot = env.rotation as f64;
        move |d: Vec3| {
            let l = f.to_local(d);
            let ic = ((l.z as f64 + 1.0) / dc).floor();
            let ip = ((l.y as f64)
                .atan2(l.x as f64)
                .rem_euclid(std::f64::consts::TAU)
                / dp)
                .floor();
            let (c0, p0) = (-1.0 + ic * dc, ip * dp);
            // Map azimuth is π/2 − local φ; u grows as local φ shrinks.
            let u_of =
                |p: f64| (std::f64::consts::FRAC_PI_2 - p + rot) / std::f64::consts::TAU + 0.5;
            let (ua, ub) = (u_of(p0 + dp), u_of(p0));
            let (va, vb) = (
                (c0 + dc).clamp(-1.0, 1.0).acos() / std::f64::consts::PI,
                c0.clamp(-1.0, 1.0).acos() / std::f64::consts::PI,
            );
            let cuts = |a: f64, b: f64, n: f64| {
                let mut xs = vec![a];
                let mut k = (a * n).floor() + 1.0;
                while k / n < b {
                    xs.push(k / n);
                    k += 1.0;
                }
                xs.push(b);
                xs
            };
            let (us, vs) = (cuts(ua, ub, w), cuts(va, vb, h));
            let mut integral = 0.0;
            for vv in vs.windows(2) {
                let vc = 0.5 * (vv[0] + vv[1]);
                let theta = vc * std::f64::consts::PI;
                for uu in us.windows(2) {
                    let uc = (0.5 * (uu[0] + uu[1])).rem_euclid(1.0);
                    let dir = map_direction(
                        (std::f64::consts::FRAC_PI_2 - theta) as f32,
                        ((uc - 0.5) * std::f64::consts::TAU - rot) as f32,
                    );
                    let jac = 2.0 * std::f64::consts::PI * std::f64::consts::PI * theta.sin();
                    integral += pdf(dir) * jac * (uu[1] - uu[0]) * (vv[1] - vv[0]);
                }
            }
            integral / (dc * dp)
        }
    }

    fn run_chi2(env: &EnvironmentMap, seed: u64) -> Chi2Outcome {
        let chi = chi2_harness();
        let (outcome, _, _) = chi.run(
            seed,
            |s| env.sample(s.next_2d()).map(|ls| ls.wi),
            subcell_mean_pdf(&chi, env, |d| env.pdf(d) as f64),
        );
        eprintln!("χ² {}x{} map: {outcome:?}", env.width, env.height);
        outcome
    }

    /// ∫ pdf(ω) sin^power θ dω by the midpoint rule on a grid with 3×3 points per texel (aligned
    /// with the texel edges, so the discontinuities of a correct pdf cost no accuracy).
    fn pdf_moment(env: &EnvironmentMap, power: i32) -> f64 {
        let (nt, np) = (3 * env.height, 3 * env.width);
        let (dt, dp) = (PI as f64 / nt as f64, TAU as f64 / np as f64);
        let mut sum = 0.0;
        for a in 0..nt {
            let theta = (a as f64 + 0.5) * dt;
            for b in 0..np {
                let phi = (b as f64 + 0.5) * dp - PI as f64 - env.rotation as f64;
                let d = map_direction((0.5 * PI as f64 - theta) as f32, phi as f32);
                sum += env.pdf(d) as f64 * theta.sin().powi(1 + power) * dt * dp;
            }
        }
        sum
    }

    fn assert_pdf_normalised(env: &EnvironmentMap) {
        let total = pdf_moment(env, 0);
        assert!((total - 1.0).abs() < 0.01, "∫ pdf dω = {total}");
    }

    #[test]
    fn chi2_synthetic_rotated_map() {
        let env = synthetic_map(37.5);
        let outcome = run_chi2(&env, 11);
        let alpha = sidak_alpha(0.01, CHI2_TESTS);
        assert!(outcome.p_value > alpha, "{outcome:?}");
    }

    #[test]
    fn chi2_rejects_pdf_without_sin_theta() {
        let env = synthetic_map(37.5);
        // pdf_uv / (2π²), renormalised over the sphere: the density of a sampler that forgot
        // the sin θ Jacobian.
        let weighted = pdf_moment(&env, 1);
        let wrong = |d: Vec3| {
            let sin_t = d.x.hypot(d.z) as f64;
            env.pdf(d) as f64 * sin_t / weighted
        };
        let chi = chi2_harness();
        let (outcome, _, _) = chi.run(
            11,
            |s| env.sample(s.next_2d()).map(|ls| ls.wi),
            subcell_mean_pdf(&chi, &env, wrong),
        );
        eprintln!("χ² with a pdf lacking sin θ: {outcome:?}");
        assert!(outcome.p_value < 1e-9, "{outcome:?}");
    }

    #[test]
    fn chi2_builtin_sky() {
        let env = EnvironmentMap::builtin_sky(-20.0, 1.0).unwrap();
        let outcome = run_chi2(&env, 5);
        assert!(
            outcome.p_value > sidak_alpha(0.01, CHI2_TESTS),
            "{outcome:?}"
        );
    }

    #[test]
    fn chi2_real_map() {
        if !Path::new(VENICE).exists() {
            eprintln!("skipping chi2_real_map: {VENICE} is absent");
            return;
        }
        let env = EnvironmentMap::from_file(VENICE, 120.0, 1.0).unwrap();
        assert_eq!(env.resolution(), (1024, 512));
        assert_pdf_normalised(&env);
        let outcome = run_chi2(&env, 3);
        assert!(
            outcome.p_value > sidak_alpha(0.01, CHI2_TESTS),
            "{outcome:?}"
        );
    }

    #[test]
    fn bilinear_radiance_interpolates_between_texel_centres() {
        let env = synthetic_map(0.0);
        let (w, h) = (160.0f32, 80.0f32);
        let dir = |u: f32, v: f32| map_direction(0.5 * PI - v * PI, (u - 0.5) * TAU);
        let texel = |i: usize, j: usize| env.cells[j * env.width + i].radiance;
        // At a texel centre: the texel.
        let at = env.radiance_bilinear(dir(30.5 / w, 20.5 / h));
        assert!((at - texel(30, 20)).length() < 1e-4 * texel(30, 20).length());
        // Halfway between two centres of a row: their mean; and across the u = 0/1 seam.
        for (i0, i1, u) in [(30, 31, 31.0 / w), (159, 0, 0.0)] {
            let mid = env.radiance_bilinear(dir(u, 20.5 / h));
            let want = 0.5 * (texel(i0, 20) + texel(i1, 20));
            assert!(
                (mid - want).length() < 1e-3 * want.length(),
                "{mid} vs {want}"
            );
        }
        // Lighting keeps the nearest texel.
        assert_eq!(env.radiance(dir(31.2 / w, 20.5 / h)), texel(31, 20));
    }

    /// The densities recomputed from a texel's radiance are the alias table's own, bit for
    /// bit, and each record's alias radiance is its alias's radiance.
    #[test]
    fn records_match_the_distribution() {
        let mut maps = vec![
            synthetic_map(37.5),
            EnvironmentMap::builtin_sky(0.0, 3.0).unwrap(),
            EnvironmentMap::from_pixels(4, 2, vec![Rgb::ZERO; 8], 0.0, 1.0).unwrap(),
        ];
        if Path::new(VENICE).exists() {
            maps.push(EnvironmentMap::from_file(VENICE, 120.0, 1.0).unwrap());
        }
        for env in &maps {
            let w = env.width;
            let func: Vec<f32> = (env.cells.iter().enumerate())
                .map(|(k, c)| luminance(c.radiance) * env.row_sin[k / w])
                .collect();
            let distribution = Distribution1D::new(&func);
            assert_eq!(distribution.integral(), env.integral);
            for (k, c) in env.cells.iter().enumerate() {
                assert_eq!(
                    env.pdf_uv(c.radiance, k / w),
                    distribution.pdf_cell(k),
                    "{k}"
                );
                assert_eq!((c.keep, c.alias), distribution.alias_entry(k));
                assert_eq!(c.alias_radiance, env.cells[c.alias as usize].radiance);
            }
        }
    }

    #[test]
    fn pdf_integrates_to_one() {
        assert_pdf_normalised(&synthetic_map(37.5));
        assert_pdf_normalised(&synthetic_map(-200.0));
        assert_pdf_normalised(&EnvironmentMap::builtin_sky(0.0, 3.0).unwrap());
    }

    #[test]
    fn sample_agrees_with_radiance_and_pdf() {
        for rotation in [37.5, 7000.0] {
            sample_agrees_on(&synthetic_map(rotation));
        }
        if Path::new(VENICE).exists() {
            sample_agrees_on(&EnvironmentMap::from_file(VENICE, 120.0, 1.0).unwrap());
        }
    }

    fn sample_agrees_on(env: &EnvironmentMap) {
        let mut s = Sampler::from_seed(2);
        let mut returned = 0;
        for _ in 0..200_000 {
            if let Some(ls) = env.sample(s.next_2d()) {
                returned += 1;
                assert_eq!(env.radiance(ls.wi), ls.radiance);
                assert_eq!(env.pdf(ls.wi), ls.pdf);
                assert_eq!(env.radiance_pdf(ls.wi), (ls.radiance, ls.pdf));
                let d = crate::sampling::sample_uniform_sphere(s.next_2d());
                assert_eq!(env.radiance_pdf(d), (env.radiance(d), env.pdf(d)));
                assert!(ls.pdf > 0.0 && ls.distance.is_infinite() && !ls.is_delta);
                assert!((ls.wi.length() - 1.0).abs() < 1e-5);
                // Sampling never lands where there is no light.
                assert!(ls.radiance.max_element() > 0.0, "{ls:?}");
            }
        }
        assert!(returned > 199_990, "{returned}");
    }

    /// A point as far inside its texel as `interior` allows (the worst case of
    /// `EnvironmentMap::sample`'s shortcut) maps to a direction that `uv_of` puts back in the
    /// same texel, for every texel of the real map, turned as scenes turn it and far beyond.
    #[test]
    fn points_inside_the_margins_stay_in_their_texel() {
        let maps: Vec<EnvironmentMap> = if Path::new(VENICE).exists() {
            [0.0, 120.0, -200.0, 7000.0]
                .iter()
                .map(|&r| EnvironmentMap::from_file(VENICE, r, 1.0).unwrap())
                .collect()
        } else {
            vec![synthetic_map(37.5), synthetic_map(7000.0)]
        };
        for env in &maps {
            let (w, h) = (env.width, env.height);
            let m = env.interior;
            assert!(m.x < 0.2 && m.y < 0.01, "{m}");
            for j in 0..h {
                for i in 0..w {
                    for (du, dv) in [(m.x, m.y), (1.0 - m.x, m.y), (m.x, 1.0 - m.y)]
                        .into_iter()
                        .chain([(1.0 - m.x, 1.0 - m.y)])
                    {
                        let uv = Vec2::new((i as f32 + du) / w as f32, (j as f32 + dv) / h as f32);
                        let found = env.texel_at(env.uv_of(env.direction_at(uv)).0);
                        assert_eq!(found, (j * w + i, j), "texel ({i}, {j}), ({du}, {dv})");
                    }
                }
            }
        }
    }

    /// pbrt-v3#62: the sampled texel must be the texel whose radiance the lookup returns,
    /// covered uniformly and not shifted by half a texel.
    #[test]
    fn single_texel_is_sampled_exactly_where_it_shines() {
        let (w, h, i0, j0) = (64usize, 32usize, 40usize, 9usize);
        let mut px = vec![Rgb::ZERO; w * h];
        let value = Rgb::new(5.0, 4.0, 3.0);
        px[j0 * w + i0] = value;
        let env = EnvironmentMap::from_pixels(w as u32, h as u32, px, 17.0, 2.0).unwrap();
        let mut s = Sampler::from_seed(4);
        let (mut umin, mut umax, mut vmin, mut vmax) = (1.0f32, 0.0f32, 1.0f32, 0.0f32);
        let n = 100_000;
        let mut estimate = 0.0f64;
        for _ in 0..n {
            let ls = env.sample(s.next_2d()).unwrap();
            assert_eq!(ls.radiance, 2.0 * value);
            let (uv, _) = env.uv_of(ls.wi);
            let (fu, fv) = (uv.x * w as f32 - i0 as f32, uv.y * h as f32 - j0 as f32);
            (umin, umax, vmin, vmax) = (umin.min(fu), umax.max(fu), vmin.min(fv), vmax.max(fv));
            estimate += (ls.radiance.x / ls.pdf) as f64 / n as f64;
        }
        assert!(
            (0.0..0.01).contains(&umin) && umax < 1.0 && umax > 0.99,
            "{umin} {umax}"
        );
        assert!(
            (0.0..0.01).contains(&vmin) && vmax < 1.0 && vmax > 0.99,
            "{vmin} {vmax}"
        );
        // ∫ L dω = L · texel solid angle.
        let (t0, t1) = (PI * j0 as f32 / h as f32, PI * (j0 + 1) as f32 / h as f32);
        let exact = 10.0 * (TAU / w as f32) * (t0.cos() - t1.cos());
        assert!(
            (estimate / exact as f64 - 1.0).abs() < 1e-3,
            "{estimate} vs {exact}"
        );
        // The pdf is zero half a texel outside the texel and positive inside.
        let at = |fu: f32, fv: f32| {
            let (u, v) = ((i0 as f32 + fu) / w as f32, (j0 as f32 + fv) / h as f32);
            env.pdf(map_direction(
                0.5 * PI - v * PI,
                (u - 0.5) * TAU - env.rotation,
            ))
        };
        assert!(at(0.5, 0.5) > 0.0);
        for (fu, fv) in [(-0.5, 0.5), (1.5, 0.5), (0.5, -0.5), (0.5, 1.5)] {
            assert_eq!(at(fu, fv), 0.0, "({fu}, {fv})");
        }
    }

    /// ∫ L(ω) max(0, ω·n) dω: importance-sampled estimate against a brute-force quadrature.
    #[test]
    fn irradiance_estimate_matches_quadrature() {
        let env = synthetic_map(37.5);
        let k = 8usize;
        for n in [Vec3::Y, -Vec3::Y, Vec3::new(1.0, 0.3, -0.5).normalize()] {
            let mut quad = [0.0f64; 3];
            let (w, h) = (env.width, env.height);
            let du_dv = 1.0 / (w * h * k * k) as f64;
            for j in 0..h * k {
                let v = (j as f32 + 0.5) / (h * k) as f32;
                let jac = 2.0 * (PI * PI) as f64 * (v * PI).sin() as f64 * du_dv;
                for i in 0..w * k {
                    let u = (i as f32 + 0.5) / (w * k) as f32;
                    let d = map_direction(0.5 * PI - v * PI, (u - 0.5) * TAU - env.rotation);
                    let l = env.radiance(d) * d.dot(n).max(0.0);
                    for c in 0..3 {
                        quad[c] += l[c] as f64 * jac;
                    }
                }
            }
            let mut s = Sampler::from_seed(8);
            let samples = 400_000;
            let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
            for _ in 0..samples {
                if let Some(ls) = env.sample(s.next_2d()) {
                    let f = ls.radiance * ls.wi.dot(n).max(0.0) / ls.pdf;
                    for c in 0..3 {
                        sum[c] += f[c] as f64;
                        sum2[c] += (f[c] as f64).powi(2);
                    }
                }
            }
            for c in 0..3 {
                let mean = sum[c] / samples as f64;
                let stderr = ((sum2[c] / samples as f64 - mean * mean) / samples as f64).sqrt();
                let rel = mean / quad[c] - 1.0;
                eprintln!(
                    "n = {n}, channel {c}: IS {mean:.5} ± {stderr:.5}, quadrature {:.5}, rel {rel:+.5}",
                    quad[c]
                );
                assert!(
                    rel.abs() < 0.01,
                    "n = {n}, channel {c}: {mean} vs {}",
                    quad[c]
                );
            }
        }
    }

    #[test]
    fn rotation_is_right_handed_about_y() {
        let (w, h) = (8u32, 4u32);
        let mut px = vec![Rgb::ZERO; 32];
        // Texel (4, 1) and (4, 2) border the centre column u = ½, which faces −z unrotated.
        px[(w + 4) as usize] = Rgb::ONE;
        px[(2 * w + 4) as usize] = Rgb::ONE;
        let probe = Vec3::new(0.05, 0.0, -1.0).normalize();
        let env = EnvironmentMap::from_pixels(w, h, px.clone(), 0.0, 1.0).unwrap();
        assert_eq!(env.radiance(probe), Rgb::ONE);
        let turned = EnvironmentMap::from_pixels(w, h, px, 90.0, 1.0).unwrap();
        assert_eq!(turned.radiance(probe), Rgb::ZERO);
        let probe_turned = Vec3::new(-1.0, 0.0, -0.05).normalize();
        assert_eq!(turned.radiance(probe_turned), Rgb::ONE);
    }

    #[test]
    fn builtin_sky_looks_like_a_sky() {
        let env = EnvironmentMap::builtin_sky(30.0, 1.0).unwrap();
        // The sun sits at elevation 35° and map azimuth 40°, seen at 40° − 30° after rotation.
        let sun = map_direction(35f32.to_radians(), 10f32.to_radians());
        assert!(
            env.radiance(sun).min_element() > 100.0,
            "{}",
            env.radiance(sun)
        );
        let zenith = env.radiance(Vec3::Y);
        let horizon = env.radiance(map_direction(0.02, 3.0));
        let ground = env.radiance(map_direction(-0.6, 3.0));
        assert!(
            zenith.z / zenith.x > horizon.z / horizon.x,
            "{zenith} {horizon}"
        );
        assert!(luminance(horizon) > luminance(zenith));
        assert!(
            luminance(ground) < 0.3 * luminance(horizon),
            "{ground} {horizon}"
        );
        // The sun carries a large share of the power, so sampling goes there often.
        let mut s = Sampler::from_seed(1);
        let hits = (0..10_000)
            .filter_map(|_| env.sample(s.next_2d()))
            .filter(|ls| ls.wi.dot(sun) > 3f32.to_radians().cos())
            .count();
        assert!(hits > 2_000, "{hits}");
        let scaled = EnvironmentMap::builtin_sky(30.0, 2.0).unwrap();
        assert_eq!(scaled.radiance(sun), 2.0 * env.radiance(sun));
    }

    #[test]
    fn invalid_inputs_are_errors() {
        let bad_len = EnvironmentMap::from_pixels(4, 2, vec![Rgb::ONE; 7], 0.0, 1.0);
        assert!(bad_len.unwrap_err().to_string().contains("4x2"));
        let empty = EnvironmentMap::from_pixels(0, 2, vec![], 0.0, 1.0);
        assert!(empty.is_err());
        let mut px = vec![Rgb::ONE; 8];
        px[5] = Rgb::new(1.0, f32::NAN, 0.0);
        let nan = EnvironmentMap::from_pixels(4, 2, px, 0.0, 1.0).unwrap_err();
        assert!(nan.to_string().contains("pixel (1, 1)"), "{nan}");
        for (rot, scale) in [(f32::NAN, 1.0), (0.0, -1.0), (0.0, f32::INFINITY)] {
            assert!(EnvironmentMap::from_pixels(4, 2, vec![Rgb::ONE; 8], rot, scale).is_err());
            assert!(EnvironmentMap::builtin_sky(rot, scale).is_err());
        }
        let missing = EnvironmentMap::from_file("/nonexistent/sky.hdr", 0.0, 1.0).unwrap_err();
        assert!(
            missing.to_string().contains("/nonexistent/sky.hdr"),
            "{missing}"
        );
        // Negative components are clamped, not kept as negative light.
        let mut px = vec![Rgb::ONE; 8];
        px[0] = Rgb::new(-1.0, 2.0, 0.5);
        let env = EnvironmentMap::from_pixels(4, 2, px, 0.0, 1.0).unwrap();
        assert!(env.cells[0].radiance == Rgb::new(0.0, 2.0, 0.5));
    }
}
