//! The Chiang model against values computed independently of tress: `chiang_reference.py`
//! (beside this file) evaluates the model in 40-digit arithmetic with the exact Bessel I₀
//! (mpmath) on a grid of fibers (brown, white, narrow blond), offsets h, inclinations θ_o,
//! θ_i and azimuths Δφ, writing `data/chiang_reference.csv`. tress evaluates in f32 with an
//! approximated ln I₀ (Abramowitz & Stegun, |ε| < 2e-7), so it must agree to 1e-4 relative.

use tress_core::math::fiber_direction;
use tress_core::Bcsdf;
use tress_materials::chiang::{Chiang, Params};
use tress_materials::pigment::Pigment;

const DATA: &str = include_str!("data/chiang_reference.csv");

/// Relative tolerance, and the absolute floor below which values count as zero (f32 evaluation
/// of products of exponentials: the grid's smallest non-zero reference values are ~1e-12).
const REL: f64 = 1e-4;
const FLOOR: f64 = 1e-12;

#[test]
fn chiang_matches_the_independent_mpmath_reference() {
    let mut rows = 0;
    let mut worst = (0.0f64, String::new());
    for line in DATA.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
        let params = Params {
            beta_m: v[0] as f32,
            beta_n: v[1] as f32,
            alpha: v[2] as f32,
            eta: v[3] as f32,
            pigment: Pigment::SigmaA((v[4] as f32, v[5] as f32, v[6] as f32)),
        };
        let (theta_o, theta_i, phi, h) = (v[7] as f32, v[8] as f32, v[9] as f32, v[10] as f32);
        let c = Chiang::new(&params).unwrap();
        // φ_o = π/2, φ_i = π/2 + Δφ.
        let half_pi = std::f32::consts::FRAC_PI_2;
        let wo = fiber_direction(theta_o.sin(), theta_o.cos(), half_pi);
        let wi = fiber_direction(theta_i.sin(), theta_i.cos(), half_pi + phi);
        let (f, pdf) = c.eval_pdf(wo, wi, h);
        for (got, want) in f.to_array().into_iter().chain([pdf]).zip(&v[11..15]) {
            let err = (got as f64 - want).abs();
            assert!(
                err <= REL * want.abs() + FLOOR,
                "{line}: got {got:e}, want {want:e} (relative error {:.2e})",
                err / want.abs()
            );
            if want.abs() > 1e-6 && err / want.abs() > worst.0 {
                worst = (err / want.abs(), line.to_string());
            }
        }
        rows += 1;
    }
    assert_eq!(rows, 1200, "the reference grid");
    eprintln!(
        "{rows} reference points; worst relative error above 1e-6: {:.2e} at {}",
        worst.0, worst.1
    );
}
