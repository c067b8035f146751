//! Lean `f32x4` versions of the transcendental functions that dominated [`crate::chiang`]'s cost,
//! each specialised to the arguments Chiang passes it.
//!
//! `wide`'s own `exp`, `ln` and `sin_cos` handle every input (NaN, ±∞, overflow, subnormal
//! results) with a dozen selects and an early-out branch each, and round with a slow SSE2
//! emulation of `roundps`, which showed in Chiang's profile (the measurements are in
//! docs/src/research/performance.md). Here each function accepts a stated domain only, reduces
//! its argument with integer bit arithmetic and the 1.5·2²³ rounding trick, and evaluates one
//! short polynomial. The polynomial coefficients were fitted for this module (weighted minimax fits by
//! Lawson's iteratively reweighted least squares on dense grids in f64, weight = the relative
//! error, or absolute where stated, of the final result), then rounded to f32; the errors quoted
//! are measured on the f32 results against f64 `std` by the tests below, which fail if a bound is
//! exceeded. Outside its domain a function returns an unspecified finite or non-finite value.

// The fitted coefficients are written with 10 significant digits, as the fit printed them; each
// is the f32 the fit was re-measured with.
#![allow(clippy::excessive_precision)]

use std::f32::consts::LOG2_E;
use wide::bytemuck::cast;
use wide::{f32x4, i32x4};

/// Adding 1.5·2²³ to an f32 of magnitude < 2²² rounds it to an integer (ties to even), and the
/// low bits of the sum's encoding are that integer's two's complement.
const ROUND_MAGIC: f32 = 12_582_912.0;

/// ln 2 in two parts: the first with 9 significant bits, so that `n · LN2_HI` is exact for
/// |n| < 2¹⁵, the second the f32 nearest to the rest.
const LN2_HI: f32 = 0.693_359_375;
const LN2_LO: f32 = -2.121_944_4e-4;

/// Rounds to the nearest integer: (that integer as f32, its two's complement as i32).
#[inline(always)]
fn round_to_int(x: f32x4) -> (f32x4, i32x4) {
    let magic = f32x4::splat(ROUND_MAGIC);
    let shifted = x + magic;
    (
        shifted - magic,
        cast::<f32x4, i32x4>(shifted) - i32x4::splat(ROUND_MAGIC.to_bits() as i32),
    )
}

/// `e^x` for x ≤ 88 (finite or −∞).
///
/// Results below 2⁻¹²⁶ ≈ 1.2·10⁻³⁸ (x < −87.3) are 0 or a subnormal: x is clamped to −88, where
/// the power of two `2^n` has the exponent field 0, which encodes 0. Method: `x = n ln 2 + r`
/// with `n = round(x / ln 2)` and |r| ≤ ln 2 / 2 (Cody–Waite, two-part ln 2), then
/// `e^r = 1 + r + r² Q(r)` with Q of degree 4 (fit: 3.8·10⁻⁹ relative), and `2^n` built in the
/// exponent field. Measured: relative error 8.2·10⁻⁸ (1.4 ulp) over [−87.3, 88].
#[inline(always)]
pub fn exp(x: f32x4) -> f32x4 {
    let c = f32x4::splat;
    let x = x.max(c(-88.0));
    let (n, n_int) = round_to_int(x * c(LOG2_E));
    let r = (x - n * c(LN2_HI)) - n * c(LN2_LO);
    let r2 = r * r;
    // Estrin's scheme: independent pairs rather than one long Horner chain.
    let q = (c(4.999_999_404e-1) + r * c(1.666_652_113e-1))
        + r2 * ((c(4.166_838_899e-2) + r * c(8.368_710_056e-3)) + r2 * c(1.381_460_461e-3));
    let two_n = cast::<i32x4, f32x4>((n_int + i32x4::splat(127)) << 23u32);
    (c(1.0) + (r + r2 * q)) * two_n
}

/// Natural logarithm for positive normal x (≥ 2⁻¹²⁶); +∞ gives 128 ln 2 ≈ 88.7.
///
/// Method: `x = 2^k m` with m in [√½, √2) taken from the encoding, then with `f = m − 1` (exact)
/// and `s = f / (2 + f)`, `ln m = 2 atanh s = f − s (f − s² P(s²))` with P of degree 2 (fit:
/// 8.7·10⁻¹⁰ relative; the exact f carries the leading term), and `ln x = k ln 2 + ln m` with the
/// two-part ln 2. Measured: relative error 8.6·10⁻⁸ (1.4 ulp) over all positive normal x, also
/// near x = 1, where ln x → 0.
#[inline(always)]
pub fn ln(x: f32x4) -> f32x4 {
    let c = f32x4::splat;
    let bits = cast::<f32x4, i32x4>(x);
    // k such that x / 2^k lies in [√½, √2): the exponent of x / √½, read from the encodings.
    let k = (bits - i32x4::splat(std::f32::consts::FRAC_1_SQRT_2.to_bits() as i32)) >> 23u32;
    let m = cast::<i32x4, f32x4>(bits - (k << 23u32));
    let k = k.round_float();
    let f = m - c(1.0);
    let s = f / (c(2.0) + f);
    let s2 = s * s;
    let p = c(6.666_677_594e-1) + s2 * (c(3.997_754_157e-1) + s2 * c(2.987_170_219e-1));
    let ln_m = f - s * (f - s2 * p);
    k * c(LN2_HI) + (ln_m + k * c(LN2_LO))
}

/// (sin x, cos x) for |x| ≤ 8π (Chiang passes angles in [−2π, 6π]).
///
/// Method: `x = k π/2 + r` with `k = round(2x/π)` and |r| ≤ π/4 (Cody–Waite, π/2 in three parts:
/// exact products for |k| < 2¹²), then `sin r = r + r³ S(r²)` (S of degree 2, fit 6.1·10⁻⁹
/// relative) and `cos r = 1 − r²/2 + r⁴ C(r²)` (C of degree 2, fit 5.1·10⁻¹⁰ absolute), swapped
/// and negated by the quadrant k mod 4. Measured: absolute error 9.1·10⁻⁸ on [−8π, 8π], and
/// relative error of sin 6.9·10⁻⁸ on [−π/4, π/4].
#[inline(always)]
pub fn sin_cos(x: f32x4) -> (f32x4, f32x4) {
    let c = f32x4::splat;
    let (k, k_int) = round_to_int(x * c(std::f32::consts::FRAC_2_PI));
    let r = ((x - k * c(1.570_312_5)) - k * c(4.837_513e-4)) - k * c(7.549_79e-8);
    let r2 = r * r;
    let sin_r = r
        + (r * r2)
            * (c(-1.666_665_524e-1) + r2 * (c(8.332_177_997e-3) + r2 * c(-1.951_730_519e-4)));
    let cos_r = (c(1.0) - c(0.5) * r2)
        + (r2 * r2)
            * (c(4.166_664_556e-2) + r2 * (c(-1.388_736_768e-3) + r2 * c(2.443_845_551e-5)));
    // Quadrant k mod 4: odd k swaps sine and cosine; sin is negated for k mod 4 in {2, 3}, cos
    // for {1, 2}. Bit 1 of k (resp. k + 1) moved to the sign bit.
    let swap = cast::<i32x4, f32x4>((k_int & i32x4::splat(1)).simd_eq(i32x4::splat(1)));
    let sin_sign = cast::<i32x4, f32x4>((k_int & i32x4::splat(2)) << 30u32);
    let cos_sign = cast::<i32x4, f32x4>(((k_int + i32x4::splat(1)) & i32x4::splat(2)) << 30u32);
    (
        swap.select(cos_r, sin_r) ^ sin_sign,
        swap.select(sin_r, cos_r) ^ cos_sign,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::{FRAC_PI_2, PI};

    /// Runs `f` on `xs` four at a time and returns its lane results.
    fn lanes(xs: &[f32], f: impl Fn(f32x4) -> f32x4) -> Vec<f32> {
        xs.chunks(4)
            .flat_map(|ch| {
                let mut a = [ch[0]; 4];
                a[..ch.len()].copy_from_slice(ch);
                f(f32x4::new(a)).to_array()[..ch.len()].to_vec()
            })
            .collect()
    }

    /// `n + 1` points evenly spaced on [a, b], both ends included.
    fn grid(a: f64, b: f64, n: usize) -> Vec<f32> {
        (0..=n)
            .map(|i| (a + (b - a) * i as f64 / n as f64) as f32)
            .collect()
    }

    /// Largest relative and absolute errors of `f` against the f64 `reference` on `xs`.
    fn errors(
        xs: &[f32],
        f: impl Fn(f32x4) -> f32x4,
        reference: impl Fn(f64) -> f64,
    ) -> (f64, f64) {
        lanes(xs, f)
            .iter()
            .zip(xs)
            .fold((0.0f64, 0.0f64), |(rel, abs), (&got, &x)| {
                let want = reference(x as f64);
                let err = (got as f64 - want).abs();
                assert!(got.is_finite(), "{x}: {got}");
                (
                    rel.max(if want == 0.0 { err } else { err / want.abs() }),
                    abs.max(err),
                )
            })
    }

    fn check(name: &str, (rel, abs): (f64, f64), max_rel: f64, max_abs: f64) {
        println!("{name}: max relative error {rel:.3e}, absolute {abs:.3e}");
        assert!(
            rel <= max_rel,
            "{name}: relative error {rel:e} > {max_rel:e}"
        );
        assert!(
            abs <= max_abs,
            "{name}: absolute error {abs:e} > {max_abs:e}"
        );
    }

    #[test]
    fn exp_matches_std() {
        // The normal range, the reduction's interval ends (±ln 2 / 2 around every n) included.
        let xs = grid(-87.3, 88.0, 2_000_000);
        check("exp", errors(&xs, exp, f64::exp), 1e-7, f64::INFINITY);
        let xs = grid(-1.0, 1.0, 200_000);
        check(
            "exp near 0",
            errors(&xs, exp, f64::exp),
            1e-7,
            f64::INFINITY,
        );
        // Underflow: 0 or a subnormal below 2⁻¹²⁶, never anything larger.
        let tiny = [-87.4f32, -88.0, -100.0, -1e4, f32::MIN, f32::NEG_INFINITY];
        for (x, y) in tiny.iter().zip(lanes(&tiny, exp)) {
            assert!((0.0..f32::MIN_POSITIVE).contains(&y), "exp({x}) = {y}");
        }
        assert_eq!(lanes(&[0.0, -0.0], exp), [1.0, 1.0]);
    }

    #[test]
    fn ln_matches_std() {
        let near_one = grid(
            std::f64::consts::FRAC_1_SQRT_2,
            std::f64::consts::SQRT_2,
            2_000_000,
        );
        check("ln near 1", errors(&near_one, ln, f64::ln), 1e-7, 5e-8);
        // Chiang's range: (2⁻²⁴, 1] for the vMF and positive ratios for the logistic; every
        // mantissa pattern class across all exponents by a geometric grid.
        let wide: Vec<f32> = (0..=2_000_000)
            .map(|i| {
                (f32::MIN_POSITIVE as f64
                    * (f32::MAX as f64 / f32::MIN_POSITIVE as f64).powf(i as f64 / 2e6))
                    as f32
            })
            .filter(|x| x.is_finite())
            .collect();
        check("ln", errors(&wide, ln, f64::ln), 1e-7, f64::INFINITY);
        assert_eq!(lanes(&[1.0], ln), [0.0]);
        let ends = [f32::MIN_POSITIVE, 1.0 / (1u32 << 24) as f32, f32::MAX];
        for (x, y) in ends.iter().zip(lanes(&ends, ln)) {
            assert!(
                ((y as f64) / (*x as f64).ln() - 1.0).abs() < 1e-7,
                "ln({x}) = {y}"
            );
        }
        assert!((lanes(&[f32::INFINITY], ln)[0] - 128.0 * std::f32::consts::LN_2).abs() < 1e-4);
    }

    #[test]
    fn sin_cos_match_std() {
        let bound = 8.0 * std::f64::consts::PI;
        let xs = grid(-bound, bound, 2_000_000);
        check(
            "sin",
            errors(&xs, |x| sin_cos(x).0, f64::sin),
            f64::INFINITY,
            1e-7,
        );
        check(
            "cos",
            errors(&xs, |x| sin_cos(x).1, f64::cos),
            f64::INFINITY,
            1e-7,
        );
        let small = grid(
            -std::f64::consts::FRAC_PI_4,
            std::f64::consts::FRAC_PI_4,
            200_000,
        );
        check(
            "sin near 0",
            errors(&small, |x| sin_cos(x).0, f64::sin),
            1e-7,
            1e-7,
        );
        let (s, c) = sin_cos(f32x4::new([0.0, -0.0, FRAC_PI_2, PI]));
        assert_eq!(s.to_array()[..2], [0.0, 0.0]);
        assert_eq!(c.to_array()[..2], [1.0, 1.0]);
        assert!((s.to_array()[2] - 1.0).abs() < 1e-7 && c.to_array()[3] == -1.0);
    }
}
