//! Warps from the unit square, MIS heuristics and piecewise-constant distributions.

use crate::math::{Vec2, Vec3};
use std::f32::consts::{FRAC_PI_4, PI};

pub const INV_4PI: f32 = 1.0 / (4.0 * PI);

/// Uniform direction on the unit sphere; pdf 1/(4π).
#[inline]
pub fn sample_uniform_sphere(u: Vec2) -> Vec3 {
    let z = 1.0 - 2.0 * u.x;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.y).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// Uniform point on the unit disk (Shirley–Chiu concentric map).
#[inline]
pub fn sample_uniform_disk_concentric(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, FRAC_PI_4 * (o.y / o.x))
    } else {
        (o.y, std::f32::consts::FRAC_PI_2 - FRAC_PI_4 * (o.x / o.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// Cosine-weighted direction on the +z hemisphere; pdf cos θ / π.
#[inline]
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = sample_uniform_disk_concentric(u);
    Vec3::new(d.x, d.y, (1.0 - d.length_squared()).max(0.0).sqrt())
}

/// Uniform direction in the cone of half-angle acos(`cos_max`) around +z; pdf 1/(2π(1−cos_max)).
#[inline]
pub fn sample_uniform_cone(u: Vec2, cos_max: f32) -> Vec3 {
    let cos_t = 1.0 - u.x * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let (s, c) = (2.0 * PI * u.y).sin_cos();
    Vec3::new(sin_t * c, sin_t * s, cos_t)
}

#[inline]
pub fn uniform_cone_pdf(cos_max: f32) -> f32 {
    1.0 / (2.0 * PI * (1.0 - cos_max))
}

/// Power heuristic (β = 2) weight of strategy `f` against `g`, one sample each.
#[inline]
pub fn power_heuristic(pdf_f: f32, pdf_g: f32) -> f32 {
    let f2 = pdf_f * pdf_f;
    let g2 = pdf_g * pdf_g;
    if f2.is_infinite() {
        return 1.0;
    }
    if f2 + g2 == 0.0 {
        0.0
    } else {
        f2 / (f2 + g2)
    }
}

/// A piecewise-constant density on [0, 1) with `n` equal cells.
#[derive(Clone, Debug)]
pub struct Distribution1D {
    func: Vec<f32>,
    cdf: Vec<f32>,
    integral: f32,
}

impl Distribution1D {
    /// From non-negative cell values. An all-zero function becomes uniform so sampling never fails.
    pub fn new(func: &[f32]) -> Self {
        let n = func.len().max(1);
        let mut func: Vec<f32> = func
            .iter()
            .map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 })
            .collect();
        if func.is_empty() {
            func.push(1.0);
        }
        let mut cdf = vec![0.0f64; n + 1];
        for i in 0..n {
            cdf[i + 1] = cdf[i] + func[i] as f64 / n as f64;
        }
        let mut integral = cdf[n];
        if integral == 0.0 {
            func.iter_mut().for_each(|v| *v = 1.0);
            for (i, c) in cdf.iter_mut().enumerate() {
                *c = i as f64 / n as f64;
            }
            integral = 0.0;
        } else {
            cdf.iter_mut().for_each(|c| *c /= integral);
        }
        Distribution1D {
            func,
            cdf: cdf.into_iter().map(|c| c as f32).collect(),
            integral: integral as f32,
        }
    }

    pub fn len(&self) -> usize {
        self.func.len()
    }

    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// ∫ func over [0, 1) (0 if the input was all zero).
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// Returns (x ∈ [0,1), density at x, cell index).
    pub fn sample_continuous(&self, u: f32) -> (f32, f32, usize) {
        let n = self.func.len();
        // Largest i with cdf[i] <= u.
        let i = self
            .cdf
            .partition_point(|&c| c <= u)
            .saturating_sub(1)
            .min(n - 1);
        let width = self.cdf[i + 1] - self.cdf[i];
        let du = if width > 0.0 {
            ((u - self.cdf[i]) / width).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let x = ((i as f32 + du) / n as f32).min(1.0 - f32::EPSILON);
        (x, self.pdf_cell(i), i)
    }

    /// Density (w.r.t. x ∈ [0,1)) of cell `i`.
    pub fn pdf_cell(&self, i: usize) -> f32 {
        if self.integral > 0.0 {
            self.func[i] / self.integral
        } else {
            1.0
        }
    }

    /// Density at x ∈ [0, 1).
    pub fn pdf(&self, x: f32) -> f32 {
        let i = ((x * self.func.len() as f32) as usize).min(self.func.len() - 1);
        self.pdf_cell(i)
    }
}

/// A piecewise-constant density on [0,1)² (rows are v, columns u): marginal in v, conditional in u.
#[derive(Clone, Debug)]
pub struct Distribution2D {
    conditional: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// `func[v * nu + u]`.
    pub fn new(func: &[f32], nu: usize, nv: usize) -> Self {
        assert_eq!(func.len(), nu * nv, "Distribution2D: size mismatch");
        let conditional: Vec<Distribution1D> = (0..nv)
            .map(|v| Distribution1D::new(&func[v * nu..(v + 1) * nu]))
            .collect();
        let marginal =
            Distribution1D::new(&conditional.iter().map(|c| c.integral()).collect::<Vec<_>>());
        Distribution2D {
            conditional,
            marginal,
        }
    }

    /// Returns ((u, v) ∈ [0,1)², density w.r.t. area in [0,1)²).
    pub fn sample_continuous(&self, u: Vec2) -> (Vec2, f32) {
        let (v, pdf_v, iv) = self.marginal.sample_continuous(u.y);
        let (x, pdf_u, _) = self.conditional[iv].sample_continuous(u.x);
        (Vec2::new(x, v), pdf_v * pdf_u)
    }

    pub fn pdf(&self, p: Vec2) -> f32 {
        let nv = self.conditional.len();
        let iv = ((p.y * nv as f32) as usize).min(nv - 1);
        self.marginal.pdf_cell(iv) * self.conditional[iv].pdf(p.x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Sampler;

    #[test]
    fn distribution1d_samples_proportionally() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0]);
        let mut s = Sampler::from_seed(1);
        let mut counts = [0u32; 3];
        let n = 100_000;
        for _ in 0..n {
            let (x, pdf, i) = d.sample_continuous(s.next_1d());
            assert!((d.pdf(x) - pdf).abs() < 1e-6);
            counts[i] += 1;
        }
        assert_eq!(counts[1], 0);
        assert!((counts[2] as f64 / n as f64 - 0.75).abs() < 0.01);
    }

    #[test]
    fn distribution2d_pdf_integrates_to_one() {
        let f: Vec<f32> = (0..12).map(|i| (i % 5) as f32 + 0.5).collect();
        let d = Distribution2D::new(&f, 4, 3);
        let n = 64;
        let mut sum = 0.0;
        for j in 0..n {
            for i in 0..n {
                sum += d.pdf(Vec2::new(
                    (i as f32 + 0.5) / n as f32,
                    (j as f32 + 0.5) / n as f32,
                ));
            }
        }
        assert!((sum / (n * n) as f32 - 1.0).abs() < 1e-4);
    }

    #[test]
    fn power_heuristic_limits() {
        assert_eq!(power_heuristic(1.0, 0.0), 1.0);
        assert_eq!(power_heuristic(0.0, 0.0), 0.0);
        assert_eq!(power_heuristic(f32::INFINITY, 1.0), 1.0);
        assert!((power_heuristic(1.0, 1.0) - 0.5).abs() < 1e-7);
    }
}
