//! Film settings, what a render records per pixel (radiance, alpha, AOVs) and the image buffer
//! the render loop fills.

use crate::limits::{Limits, MEMORY_LIMIT_VAR};
use crate::math::Rgb;
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::fmt;
use std::str::FromStr;

/// Film description: resolution, samples, seed and an optional crop window.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FilmSettings {
    /// Film width in pixels, 1 to 65 536.
    pub width: u32,
    /// Film height in pixels, 1 to 65 536.
    pub height: u32,
    /// Samples per pixel, at least 1 (default 16).
    #[serde(default = "default_spp")]
    pub spp: u32,
    /// Seed of every pixel sample's random stream; the same seed gives the same image (default 0).
    #[serde(default)]
    pub seed: u64,
    /// Pixel window `[x0, y0, x1, y1)` to render; `None` renders the whole film.
    #[serde(default)]
    pub crop: Option<[u32; 4]>,
}

fn default_spp() -> u32 {
    16
}

/// Largest film side, in pixels.
pub const MAX_FILM_SIDE: u32 = 1 << 16;

/// Why film settings cannot be rendered.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FilmError {
    /// A side is zero.
    #[error("film size {width}x{height} is empty")]
    Empty {
        /// Film width, in pixels.
        width: u32,
        /// Film height, in pixels.
        height: u32,
    },
    /// A side exceeds [`MAX_FILM_SIDE`].
    #[error("film size {width}x{height} exceeds {MAX_FILM_SIDE} pixels per side")]
    TooLarge {
        /// Film width, in pixels.
        width: u32,
        /// Film height, in pixels.
        height: u32,
    },
    /// Zero samples per pixel.
    #[error("spp must be at least 1")]
    NoSamples,
    /// The crop window is empty or reaches outside the film.
    #[error(
        "crop window [{}, {}, {}, {}) is empty or outside the {width}x{height} film",
        crop[0], crop[1], crop[2], crop[3]
    )]
    Crop {
        /// The window `[x0, y0, x1, y1)`.
        crop: [u32; 4],
        /// Film width, in pixels.
        width: u32,
        /// Film height, in pixels.
        height: u32,
    },
    /// The render's sums and image would exceed the memory limit.
    #[error(
        "a {width}x{height} window at {spp} spp needs about {need_gib:.1} GiB for its sample \
         sums and image, over the {limit_gib} GiB limit: render it in tiles (`tress farm`) or \
         set {MEMORY_LIMIT_VAR} to a larger number of GiB"
    )]
    Memory {
        /// Window width, in pixels.
        width: u32,
        /// Window height, in pixels.
        height: u32,
        /// Samples per pixel.
        spp: u32,
        /// Estimated need, in GiB.
        need_gib: f64,
        /// The limit, in GiB.
        limit_gib: f64,
    },
}

impl FilmSettings {
    /// The pixel window actually rendered, `[x0, y0, x1, y1)`.
    pub fn window(&self) -> [u32; 4] {
        self.crop.unwrap_or([0, 0, self.width, self.height])
    }

    /// Checks sizes and the crop window, describing the first problem found.
    pub fn validate(&self) -> Result<(), FilmError> {
        let (width, height) = (self.width, self.height);
        if width == 0 || height == 0 {
            return Err(FilmError::Empty { width, height });
        }
        if width > MAX_FILM_SIDE || height > MAX_FILM_SIDE {
            return Err(FilmError::TooLarge { width, height });
        }
        if self.spp == 0 {
            return Err(FilmError::NoSamples);
        }
        if let Some(crop @ [x0, y0, x1, y1]) = self.crop {
            if x0 >= x1 || y0 >= y1 || x1 > width || y1 > height {
                return Err(FilmError::Crop {
                    crop,
                    width,
                    height,
                });
            }
        }
        Ok(())
    }

    /// [`Self::validate`], and that a render of radiance alone fits the memory limit of
    /// `limits`.
    pub fn validate_for_render(&self, limits: &Limits) -> Result<(), FilmError> {
        self.validate_for_outputs(&Outputs::default(), limits)
    }

    /// [`Self::validate`], and that a render recording `outputs` fits the memory limit of
    /// `limits`.
    pub fn validate_for_outputs(
        &self,
        outputs: &Outputs,
        limits: &Limits,
    ) -> Result<(), FilmError> {
        self.validate()?;
        let limit_gib = limits.memory_gib;
        let need_gib = self.memory_bytes_for(outputs) as f64 / (1u64 << 30) as f64;
        if need_gib > limit_gib {
            let [x0, y0, x1, y1] = self.window();
            return Err(FilmError::Memory {
                width: x1 - x0,
                height: y1 - y0,
                spp: self.spp,
                need_gib,
                limit_gib,
            });
        }
        Ok(())
    }

    /// Memory a render of radiance alone needs at the least ([`Self::memory_bytes_for`]).
    pub fn memory_bytes(&self) -> u64 {
        self.memory_bytes_for(&Outputs::default())
    }

    /// Memory the render of the window recording `outputs` needs at the least: per pixel an
    /// f64 sum of every recorded quantity ([`quantities`]: RGB, and what alpha and the
    /// AOVs need) for each aligned block of its samples (at most ⌊log2 spp⌋ + 1 of them;
    /// `render::dyadic_cover`) and the f32 output channels, twice over while waves are merged.
    pub fn memory_bytes_for(&self, outputs: &Outputs) -> u64 {
        let [x0, y0, x1, y1] = self.window();
        let pixels = (x1 - x0) as u64 * (y1 - y0) as u64;
        let blocks = 64 - (self.spp.max(1) as u64).leading_zeros() as u64;
        let quantities = quantity_count(outputs) as u64;
        let channels = outputs.channel_names().len() as u64;
        2 * pixels * (8 * quantities * blocks + 4 * channels)
    }
}

/// An extra per-pixel output a render can write beside its radiance (an "AOV", arbitrary
/// output variable), learnt from the first hit of each camera ray.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Aov {
    /// Distance along the camera ray to the first hit, averaged over the pixel's samples that
    /// hit something; +∞ where none did. Channel `depth.Z`.
    Depth,
    /// Unit fiber tangent (world space, root → tip) at the first hit, averaged over the
    /// pixel's samples whose first hit is a fiber, and not renormalised: shorter than 1 where
    /// the pixel's fibers point different ways, 0 where no sample saw a fiber. Channels
    /// `tangent.X`, `tangent.Y`, `tangent.Z`.
    Tangent,
    /// Directional albedo of the first hit's material toward the camera, averaged over the
    /// pixel's samples that hit something; 0 where none did. Each sample estimates it from
    /// one direction drawn by the material's own sampling (f·cos θ / pdf): exact for diffuse
    /// surfaces, unbiased and nearly noise-free for fiber models that sample their lobes
    /// exactly. Channels `albedo.R`, `albedo.G`, `albedo.B`.
    Albedo,
    /// Variance of the pixel value (the mean of its n samples), from the sums of the samples
    /// and of their squares: (Σx² − (Σx)²/n) / (n(n − 1)) per channel; +∞ below two samples.
    /// Channels `variance.R`, `variance.G`, `variance.B`.
    Variance,
}

impl Aov {
    /// Every AOV, in the order channels are listed.
    pub const ALL: [Aov; 4] = [Aov::Depth, Aov::Tangent, Aov::Albedo, Aov::Variance];

    /// The name on the command line and the layer name in the EXR.
    pub fn name(self) -> &'static str {
        match self {
            Aov::Depth => "depth",
            Aov::Tangent => "tangent",
            Aov::Albedo => "albedo",
            Aov::Variance => "variance",
        }
    }

    /// The EXR channels it is written to, `layer.channel` as OpenEXR names layers.
    pub fn channels(self) -> &'static [&'static str] {
        match self {
            Aov::Depth => &["depth.Z"],
            Aov::Tangent => &["tangent.X", "tangent.Y", "tangent.Z"],
            Aov::Albedo => &["albedo.R", "albedo.G", "albedo.B"],
            Aov::Variance => &["variance.R", "variance.G", "variance.B"],
        }
    }
}

impl fmt::Display for Aov {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Aov {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        Aov::ALL
            .into_iter()
            .find(|a| a.name() == s.trim())
            .ok_or_else(|| {
                let names: Vec<&str> = Aov::ALL.iter().map(|a| a.name()).collect();
                format!("unknown AOV '{s}' (expected {})", names.join(", "))
            })
    }
}

/// What a render records per pixel besides radiance.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Outputs {
    /// Alpha: the fraction of the pixel's camera samples whose camera ray hit geometry, hair or
    /// surface (channel `A`).
    pub alpha: bool,
    /// The AOVs.
    pub aovs: BTreeSet<Aov>,
}

impl Outputs {
    /// Whether `aov` is recorded.
    pub fn has(&self, aov: Aov) -> bool {
        self.aovs.contains(&aov)
    }

    /// The output channels in the order they are listed: `R`, `G`, `B`, `A` with alpha, then
    /// the AOVs' channels (`depth.Z`, `tangent.X`, …).
    pub fn channel_names(&self) -> Vec<&'static str> {
        let mut names = vec!["R", "G", "B"];
        if self.alpha {
            names.push("A");
        }
        for aov in &self.aovs {
            names.extend_from_slice(aov.channels());
        }
        names
    }
}

/// A linear RGB image covering the pixel window `[x0, y0, x0 + width, y0 + height)` of a
/// `full_width` × `full_height` film (the window is the whole film unless cropped).
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Window width in pixels.
    pub width: u32,
    /// Window height in pixels.
    pub height: u32,
    /// Left column of the window within the full film.
    pub x0: u32,
    /// Top row of the window within the full film (rows run downwards).
    pub y0: u32,
    /// Width of the whole film in pixels.
    pub full_width: u32,
    /// Height of the whole film in pixels.
    pub full_height: u32,
    /// Row-major, `width * height` pixels.
    pub pixels: Vec<Rgb>,
}

impl Image {
    /// An image of the whole `width`×`height` film with pixel (x, y) set to `f(x, y)`, called
    /// row by row.
    pub fn from_fn(width: u32, height: u32, mut f: impl FnMut(u32, u32) -> Rgb) -> Self {
        let mut image = Image::new(width, height);
        let coordinates = (0..height).flat_map(|y| (0..width).map(move |x| (x, y)));
        for (pixel, (x, y)) in image.pixels.iter_mut().zip(coordinates) {
            *pixel = f(x, y);
        }
        image
    }

    /// A black image of the whole `width`×`height` film.
    pub fn new(width: u32, height: u32) -> Self {
        Image {
            width,
            height,
            x0: 0,
            y0: 0,
            full_width: width,
            full_height: height,
            pixels: vec![Rgb::ZERO; width as usize * height as usize],
        }
    }

    /// A black image of `window` within a `full_width`×`full_height` film.
    pub fn window(window: [u32; 4], full_width: u32, full_height: u32) -> Self {
        let [x0, y0, x1, y1] = window;
        Image {
            width: x1 - x0,
            height: y1 - y0,
            x0,
            y0,
            full_width,
            full_height,
            pixels: vec![Rgb::ZERO; (x1 - x0) as usize * (y1 - y0) as usize],
        }
    }

    /// Pixel at window-relative coordinates.
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> Rgb {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Sets the pixel at window-relative coordinates.
    #[inline]
    pub fn set(&mut self, x: u32, y: u32, c: Rgb) {
        self.pixels[(y * self.width + x) as usize] = c;
    }

    /// Mean over all pixels and channels.
    pub fn mean(&self) -> f64 {
        let s: f64 = self.pixels.iter().map(|p| (p.x + p.y + p.z) as f64).sum();
        s / (3 * self.pixels.len()).max(1) as f64
    }

    /// Per-channel mean.
    pub fn mean_rgb(&self) -> [f64; 3] {
        let mut s = [0.0f64; 3];
        for p in &self.pixels {
            s[0] += p.x as f64;
            s[1] += p.y as f64;
            s[2] += p.z as f64;
        }
        let n = self.pixels.len().max(1) as f64;
        s.map(|v| v / n)
    }
}

/// A per-sample quantity the render loop sums exactly. Every camera sample adds one value of
/// each quantity its render records ([`quantities`]); the output channels are computed from
/// the pixel's totals ([`crate::render::SampleSums::channels`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Quantity {
    /// Radiance, red: 0 for a NaN or infinite sample.
    R,
    /// Radiance, green.
    G,
    /// Radiance, blue.
    B,
    /// 1 when the camera ray hit geometry (hair or surface), else 0.
    Hits,
    /// Distance along the camera ray to its first hit; 0 on a miss.
    Distance,
    /// 1 when the camera ray's first hit is a fiber, else 0.
    FiberHits,
    /// Fiber tangent at the first hit, x (0 unless a fiber was hit).
    TangentX,
    /// Fiber tangent, y.
    TangentY,
    /// Fiber tangent, z.
    TangentZ,
    /// Albedo estimate of the first hit's material, red (0 on a miss).
    AlbedoR,
    /// Albedo estimate, green.
    AlbedoG,
    /// Albedo estimate, blue.
    AlbedoB,
    /// Squared radiance, red (0 for a NaN or infinite sample).
    R2,
    /// Squared radiance, green.
    G2,
    /// Squared radiance, blue.
    B2,
}

impl Quantity {
    /// Every quantity, in the order a render lists those it records.
    pub const ALL: [Quantity; 15] = [
        Quantity::R,
        Quantity::G,
        Quantity::B,
        Quantity::Hits,
        Quantity::Distance,
        Quantity::FiberHits,
        Quantity::TangentX,
        Quantity::TangentY,
        Quantity::TangentZ,
        Quantity::AlbedoR,
        Quantity::AlbedoG,
        Quantity::AlbedoB,
        Quantity::R2,
        Quantity::G2,
        Quantity::B2,
    ];

    /// Short name, as the sum channels of a render EXR spell it.
    pub fn name(self) -> &'static str {
        match self {
            Quantity::R => "R",
            Quantity::G => "G",
            Quantity::B => "B",
            Quantity::Hits => "hits",
            Quantity::Distance => "distance",
            Quantity::FiberHits => "fiberHits",
            Quantity::TangentX => "tangentX",
            Quantity::TangentY => "tangentY",
            Quantity::TangentZ => "tangentZ",
            Quantity::AlbedoR => "albedoR",
            Quantity::AlbedoG => "albedoG",
            Quantity::AlbedoB => "albedoB",
            Quantity::R2 => "R2",
            Quantity::G2 => "G2",
            Quantity::B2 => "B2",
        }
    }
}

/// Whether `outputs` need the count of camera rays that hit something (alpha, and the
/// averages over hits).
pub(crate) fn counts_hits(outputs: &Outputs) -> bool {
    outputs.alpha || outputs.has(Aov::Depth) || outputs.has(Aov::Albedo)
}

/// The quantities a render recording `outputs` sums, in the order each sample adds them
/// (the render loop's per-sample record follows the same order).
pub fn quantities(outputs: &Outputs) -> Vec<Quantity> {
    use Quantity::*;
    let mut q = vec![R, G, B];
    if counts_hits(outputs) {
        q.push(Hits);
    }
    if outputs.has(Aov::Depth) {
        q.push(Distance);
    }
    if outputs.has(Aov::Tangent) {
        q.extend([FiberHits, TangentX, TangentY, TangentZ]);
    }
    if outputs.has(Aov::Albedo) {
        q.extend([AlbedoR, AlbedoG, AlbedoB]);
    }
    if outputs.has(Aov::Variance) {
        q.extend([R2, G2, B2]);
    }
    q
}

/// `quantities(outputs).len()`, without building the list.
pub fn quantity_count(outputs: &Outputs) -> usize {
    let on = |b: bool, n: usize| if b { n } else { 0 };
    3 + on(counts_hits(outputs), 1)
        + on(outputs.has(Aov::Depth), 1)
        + on(outputs.has(Aov::Tangent), 4)
        + on(outputs.has(Aov::Albedo), 3)
        + on(outputs.has(Aov::Variance), 3)
}
