//! 8-bit sRGB pictures: crops of renders for a study's sheets, and the sRGB encoding they use.

use crate::metrics::Rect;
use tress_core::Image;

/// An 8-bit sRGB picture (a crop of a render) for an image sheet.
#[derive(Clone, Debug)]
pub struct Picture {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major RGB bytes.
    pub rgb: Vec<u8>,
}

impl Picture {
    /// The pixels `r` (film coordinates, inside the rendered window) of `img`, scaled by `gain`
    /// and sRGB-encoded.
    pub fn crop(img: &Image, r: Rect, gain: f32) -> Picture {
        let mut rgb = Vec::with_capacity(r.w as usize * r.h as usize * 3);
        for y in r.y..r.y + r.h {
            for x in r.x..r.x + r.w {
                let p = img.get(x - img.x0, y - img.y0);
                rgb.extend([p.x, p.y, p.z].map(|c| srgb8(c, gain)));
            }
        }
        Picture {
            width: r.w,
            height: r.h,
            rgb,
        }
    }

    /// Nearest-neighbour resampling to `w × h` (pixelated, so single-pixel noise stays visible).
    pub fn resized(&self, w: u32, h: u32) -> Picture {
        let mut rgb = Vec::with_capacity(w as usize * h as usize * 3);
        for y in 0..h {
            let sy = (y as u64 * self.height as u64 / h as u64) as usize;
            for x in 0..w {
                let sx = (x as u64 * self.width as u64 / w as u64) as usize;
                let i = (sy * self.width as usize + sx) * 3;
                rgb.extend_from_slice(&self.rgb[i..i + 3]);
            }
        }
        Picture {
            width: w,
            height: h,
            rgb,
        }
    }
}

/// The sRGB encoding of a display-linear value, clamped to [0, 1] (NaN → 0).
pub fn srgb(c: f32) -> f32 {
    let v = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    if v <= 0.003_130_8 {
        12.92 * v
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Linear radiance to an 8-bit sRGB byte: scaled by `gain`, clamped to [0, 1] (NaN → 0).
pub fn srgb8(c: f32, gain: f32) -> u8 {
    (srgb(c * gain) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_are_clamped_and_nan_is_black() {
        assert_eq!(srgb8(1.0, 1.0), 255);
        assert_eq!(srgb8(f32::NAN, 1.0), 0);
        assert_eq!(srgb8(0.5, 2.0), 255);
    }
}
