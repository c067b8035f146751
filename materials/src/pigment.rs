//! Fiber absorption σ_a (per unit fiber *radius*), given directly, from melanin concentrations,
//! or from a target colour (Chiang et al. 2016 §4.2), with the parameter names of pbrt, Mitsuba 3
//! and Cycles.
//!
//! RON (tress parses with `unwrap_variant_newtypes`, so a tuple variant takes its values
//! directly): `SigmaA(0.06, 0.10, 0.20)`, `Melanin(eumelanin: 1.3, pheomelanin: 0.2)`,
//! `Color(0.8, 0.6, 0.4)`.
//!
//! [`crate::strand_variation`] varies a hair object's pigment from strand to strand and from
//! root to tip.

use crate::ParamError;
use serde::{Deserialize, Serialize};
use tress_core::math::Rgb;

/// Eumelanin absorption per unit concentration (RGB), as in pbrt-v3/v4 and Mitsuba 3.
const EUMELANIN_SIGMA_A: [f32; 3] = [0.419, 0.697, 1.37];
/// Pheomelanin absorption per unit concentration (RGB).
const PHEOMELANIN_SIGMA_A: [f32; 3] = [0.187, 0.4, 1.05];

/// How a fiber's absorption is specified.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum Pigment {
    /// Absorption coefficient per unit radius, RGB.
    SigmaA((f32, f32, f32)),
    /// Melanin concentrations (≈0 blond … ≈8 black for eumelanin; pheomelanin adds red), and
    /// an optional dye.
    Melanin {
        /// Eumelanin concentration, ≥ 0 (default 0).
        #[serde(default)]
        eumelanin: f32,
        /// Pheomelanin concentration, ≥ 0 (default 0).
        #[serde(default)]
        pheomelanin: f32,
        /// A dye over the melanin (Cycles' Tint): its absorption is that of `Color(tint)`,
        /// added to the melanin's; each channel in (0, 1], default (1, 1, 1): none.
        #[serde(default = "no_tint")]
        tint: (f32, f32, f32),
    },
    /// Target multiple-scattering colour of a hair volume, each channel in (0, 1]; mapped to σ_a
    /// through Chiang et al.'s fit, which depends on the azimuthal roughness β_n.
    Color((f32, f32, f32)),
}

/// The tint that adds no absorption.
pub const NO_TINT: (f32, f32, f32) = (1.0, 1.0, 1.0);

fn no_tint() -> (f32, f32, f32) {
    NO_TINT
}

impl Default for Pigment {
    /// pbrt's default: eumelanin 1.3 (brown).
    fn default() -> Self {
        Pigment::Melanin {
            eumelanin: 1.3,
            pheomelanin: 0.0,
            tint: NO_TINT,
        }
    }
}

impl Pigment {
    /// σ_a per unit radius. `beta_n` is the azimuthal roughness in [0, 1] used by the colour fit.
    pub fn sigma_a(&self, beta_n: f32) -> Result<Rgb, ParamError> {
        match *self {
            Pigment::SigmaA((r, g, b)) => {
                for v in [r, g, b] {
                    if !(v.is_finite() && v >= 0.0) {
                        return Err(ParamError::new(
                            "sigma_a",
                            v,
                            "must be finite and non-negative",
                        ));
                    }
                }
                Ok(Rgb::new(r, g, b))
            }
            Pigment::Melanin {
                eumelanin,
                pheomelanin,
                tint,
            } => {
                for (field, v) in [("eumelanin", eumelanin), ("pheomelanin", pheomelanin)] {
                    if !(v.is_finite() && v >= 0.0) {
                        return Err(ParamError::new(field, v, "must be finite and non-negative"));
                    }
                }
                let melanin = Rgb::from_array(std::array::from_fn(|i| {
                    eumelanin * EUMELANIN_SIGMA_A[i] + pheomelanin * PHEOMELANIN_SIGMA_A[i]
                }));
                // Without a tint the melanin's absorption is returned as it is (no `+ 0`).
                if tint == NO_TINT {
                    return Ok(melanin);
                }
                Ok(melanin + colour_sigma_a("tint", tint, beta_n)?)
            }
            Pigment::Color(c) => colour_sigma_a("color", c, beta_n),
        }
    }
}

/// σ_a of a target colour through Chiang's fit; `field` names it in errors.
fn colour_sigma_a(
    field: &'static str,
    (r, g, b): (f32, f32, f32),
    beta_n: f32,
) -> Result<Rgb, ParamError> {
    let mut out = [0.0; 3];
    for (o, c) in out.iter_mut().zip([r, g, b]) {
        if !(c.is_finite() && c > 0.0 && c <= 1.0) {
            return Err(ParamError::new(field, c, "each channel must lie in (0, 1]"));
        }
        *o = sigma_a_from_reflectance(c, beta_n);
    }
    Ok(Rgb::from_array(out))
}

/// Chiang et al. 2016 eq. 9: σ_a giving multiple-scattering colour `c` at azimuthal roughness β_n.
pub fn sigma_a_from_reflectance(c: f32, beta_n: f32) -> f32 {
    let b = beta_n;
    let denom = 5.969 - 0.215 * b + 2.532 * b * b - 10.73 * b.powi(3)
        + 5.574 * b.powi(4)
        + 0.245 * b.powi(5);
    let l = c.max(1e-4).ln() / denom;
    l * l
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn melanin_is_linear_in_concentrations() {
        let s = Pigment::Melanin {
            eumelanin: 2.0,
            pheomelanin: 1.0,
            tint: NO_TINT,
        }
        .sigma_a(0.3)
        .unwrap();
        assert!(
            (s - Rgb::new(2.0 * 0.419 + 0.187, 2.0 * 0.697 + 0.4, 2.0 * 1.37 + 1.05)).length()
                < 1e-6
        );
    }

    #[test]
    fn a_tint_adds_the_absorption_of_its_colour_to_the_melanin() {
        let melanin = |tint| Pigment::Melanin {
            eumelanin: 0.3,
            pheomelanin: 0.1,
            tint,
        };
        let plain = melanin(NO_TINT).sigma_a(0.3).unwrap();
        let red = (0.9, 0.4, 0.3);
        let dyed = melanin(red).sigma_a(0.3).unwrap();
        let dye = Pigment::Color(red).sigma_a(0.3).unwrap();
        assert!((dyed - plain - dye).abs().max_element() < 1e-6);
        // Red dye absorbs green and blue more than red.
        assert!(dye.y > dye.x && dye.z > dye.x && dye.x > 0.0);
        // RON: the tint is optional and defaults to none.
        let parsed: Pigment =
            ron::from_str("Melanin(eumelanin: 0.3, pheomelanin: 0.1, tint: (0.9, 0.4, 0.3))")
                .unwrap();
        assert_eq!(parsed, melanin(red));
        let parsed: Pigment = ron::from_str("Melanin(eumelanin: 0.3, pheomelanin: 0.1)").unwrap();
        assert_eq!(parsed, melanin(NO_TINT));
        let e = melanin((0.0, 0.5, 0.5))
            .sigma_a(0.3)
            .unwrap_err()
            .to_string();
        assert!(e.contains("tint"), "{e}");
    }

    #[test]
    fn white_colour_means_no_absorption_and_darker_means_more() {
        let white = Pigment::Color((1.0, 1.0, 1.0)).sigma_a(0.3).unwrap();
        assert_eq!(white, Rgb::ZERO);
        let s = Pigment::Color((0.8, 0.5, 0.2)).sigma_a(0.3).unwrap();
        assert!(s.x < s.y && s.y < s.z);
    }

    #[test]
    fn invalid_values_are_rejected() {
        assert!(Pigment::SigmaA((-1.0, 0.0, 0.0)).sigma_a(0.3).is_err());
        assert!(Pigment::Melanin {
            eumelanin: f32::NAN,
            pheomelanin: 0.0,
            tint: NO_TINT,
        }
        .sigma_a(0.3)
        .is_err());
        assert!(Pigment::Color((0.0, 0.5, 0.5)).sigma_a(0.3).is_err());
    }
}
