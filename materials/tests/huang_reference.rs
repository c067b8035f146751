//! Huang's lanes implementation against the scalar one it replaced. `data/huang_reference.csv`
//! holds `eval_pdf` of the model as of commit c628613 (one quadrature node at a time, `std`'s
//! `exp`, every direction normalised) at 400 random (wo, wi, h) per test instance (uniform
//! directions and offsets from `Pcg32::new(2022, 0)`). The lanes compute the same model with the
//! arithmetic rearranged (cosines scaled by |H| instead of normalised half vectors, Fresnel and
//! the microfacet terms over one division, the lean `exp` of `simd_math`), so values move by f32
//! rounding, which the exit's Fresnel amplifies near total internal reflection. Measured worst:
//! f 1.4·10⁻⁴ of the row's largest channel (median 5·10⁻⁷), pdf 4.3·10⁻⁵ relative.

use tress_core::math::Vec3;
use tress_core::Bcsdf;
use tress_materials::huang::{test_instances, Huang};

const DATA: &str = include_str!("data/huang_reference.csv");

/// Largest error accepted, relative to the row's largest channel of f and to the pdf: seven
/// times the measured worst.
const TOL: f64 = 1e-3;

#[test]
fn huang_matches_the_scalar_implementation() {
    let models: Vec<(String, Huang)> = test_instances()
        .into_iter()
        .map(|t| (t.name, Huang::new(&t.params).unwrap()))
        .collect();
    let (mut rows, mut worst_f, mut worst_pdf) = (0, 0.0f64, 0.0f64);
    for line in DATA.lines().skip(1) {
        let (name, numbers) = line.split_once(',').unwrap();
        let v: Vec<f32> = numbers.split(',').map(|x| x.parse().unwrap()).collect();
        let b = &models.iter().find(|(n, _)| n == name).unwrap().1;
        let (wo, wi) = (Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]));
        let (f, pdf) = b.eval_pdf(wo, wi, v[6]);
        let want = Vec3::new(v[7], v[8], v[9]);
        let scale = want.abs().max_element().max(1e-12) as f64;
        let err_f = (f - want).abs().max_element() as f64 / scale;
        let err_pdf = ((pdf - v[10]) / v[10]).abs() as f64;
        assert!(
            err_f <= TOL && err_pdf <= TOL,
            "{line}: f {f}, pdf {pdf} (errors {err_f:.2e}, {err_pdf:.2e})"
        );
        worst_f = worst_f.max(err_f);
        worst_pdf = worst_pdf.max(err_pdf);
        rows += 1;
    }
    assert_eq!(rows, 400 * models.len(), "the reference rows");
    eprintln!("{rows} rows; worst error of f {worst_f:.2e}, of pdf {worst_pdf:.2e}");
}
