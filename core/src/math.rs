//! Small math types on top of glam.

pub use glam::{Mat3, Mat4, Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// `v` scaled to unit length, for every finite non-zero `v`: normalised in f64, where neither a
/// tiny length (1e-30, whose square is 0 in f32) nor a huge one (3e38, whose square overflows)
/// is lost. `None` for zero or non-finite vectors.
pub fn unit(v: Vec3) -> Option<Vec3> {
    if !v.is_finite() {
        return None;
    }
    v.as_dvec3().try_normalize().map(|d| d.as_vec3())
}

/// Linear RGB radiance or reflectance. Plain `Vec3` so all of glam's arithmetic applies.
pub type Rgb = Vec3;

/// Rec. 709 luminance of a linear RGB value.
#[inline]
pub fn luminance(c: Rgb) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// Identifies one primitive: an Embree geometry and a primitive (curve segment, triangle, sphere)
/// inside it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PrimId {
    /// Embree geometry id: one per hair object or mesh, one shared by all spheres.
    pub geom: u32,
    /// Primitive index within that geometry.
    pub prim: u32,
}

/// A ray with a parametric extent `(0, t_max)` and an optional primitive to ignore.
///
/// `exclude` names the primitive the ray leaves from: a ray leaving a convex primitive (a fiber
/// segment, a triangle, the outside of a sphere) can never hit it again, so accelerators skip it
/// instead of relying on an epsilon offset (see `tress-accel`).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    /// Start point, in world space.
    pub origin: Vec3,
    /// Unit direction.
    pub dir: Vec3,
    /// End of the parametric extent: infinite unless limited (shadow rays).
    pub t_max: f32,
    /// Primitive the ray leaves from, never reported as hit; `None` for camera rays.
    pub exclude: Option<PrimId>,
}

impl Ray {
    /// A ray of unlimited extent from `origin` along unit `dir`, excluding nothing.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Ray {
            origin,
            dir,
            t_max: f32::INFINITY,
            exclude: None,
        }
    }

    /// A ray leaving primitive `from`.
    pub fn leaving(origin: Vec3, dir: Vec3, from: PrimId) -> Self {
        Ray {
            origin,
            dir,
            t_max: f32::INFINITY,
            exclude: Some(from),
        }
    }

    /// The same ray limited to `(0, t_max)`, e.g. a shadow ray that stops at a light.
    pub fn with_t_max(mut self, t_max: f32) -> Self {
        self.t_max = t_max;
        self
    }

    /// The point at parameter `t`: `origin + t·dir`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }
}

/// An orthonormal frame; `to_local` maps world directions to (x, y, z) coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Unit x axis, in world coordinates.
    pub x: Vec3,
    /// Unit y axis, in world coordinates.
    pub y: Vec3,
    /// Unit z axis, in world coordinates (the normal, for [`Frame::from_z`]).
    pub z: Vec3,
}

impl Frame {
    /// Any frame whose z axis is the unit vector `n` (Duff et al. 2017 branchless basis).
    pub fn from_z(n: Vec3) -> Self {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let x = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let y = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { x, y, z: n }
    }

    /// World vector `v` in frame coordinates (its dot products with x, y and z).
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.x), v.dot(self.y), v.dot(self.z))
    }

    /// Frame coordinates `v` back to a world vector.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.x * v.x + self.y * v.y + self.z * v.z
    }
}

/// Axis-aligned bounding box.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
pub struct Aabb {
    /// Lower corner (componentwise minimum).
    #[schemars(with = "[f32; 3]")]
    pub min: Vec3,
    /// Upper corner (componentwise maximum).
    #[schemars(with = "[f32; 3]")]
    pub max: Vec3,
}

impl Aabb {
    /// The empty box (min +∞, max −∞), from which [`Aabb::grow`] and [`Aabb::union`] start.
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// Whether the box contains no point (some min above its max).
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// Enlarges the box to contain `p`.
    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// The smallest box containing both boxes.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    /// Side lengths, `max − min`.
    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    /// Midpoint of the box.
    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Entry and exit distances of a ray through the box, if it crosses it within `[0, t_max]`.
    pub fn intersect(&self, ray: &Ray) -> Option<(f32, f32)> {
        let inv = ray.dir.recip();
        let t0 = (self.min - ray.origin) * inv;
        let t1 = (self.max - ray.origin) * inv;
        let tmin = t0.min(t1).max_element().max(0.0);
        let tmax = t0.max(t1).min_element().min(ray.t_max);
        (tmin <= tmax).then_some((tmin, tmax))
    }
}

/// Spherical direction from (sin θ, cos θ, φ) in a frame whose x axis is the pole; used by the
/// fiber frame where x is the tangent.
#[inline]
pub fn fiber_direction(sin_theta: f32, cos_theta: f32, phi: f32) -> Vec3 {
    let (s, c) = phi.sin_cos();
    Vec3::new(sin_theta, cos_theta * c, cos_theta * s)
}

/// erfc(x) with relative error below 1.2e-7 everywhere, deep tails included (the Chebyshev fit
/// of e^{x²} erfc(x) in Numerical Recipes, §6.2): the hair models' truncated normals need the
/// tails relatively accurate.
pub fn erfc(x: f64) -> f64 {
    const C: [f64; 10] = [
        -1.265_512_23,
        1.000_023_68,
        0.374_091_96,
        0.096_784_18,
        -0.186_288_06,
        0.278_868_07,
        -1.135_203_98,
        1.488_515_87,
        -0.822_152_23,
        0.170_872_77,
    ];
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = C.iter().rev().fold(0.0, |acc, c| acc * t + c);
    let r = t * (-z * z + poly).exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// erf(x) = 1 − erfc(x) (see [`erfc`]).
pub fn erf(x: f64) -> f64 {
    1.0 - erfc(x)
}

/// √x with a slightly negative `x` (from rounding) taken as 0.
#[inline]
pub fn safe_sqrt(x: f32) -> f32 {
    x.max(0.0).sqrt()
}

/// asin with the argument clamped to [−1, 1], so rounding never yields NaN.
#[inline]
pub fn safe_asin(x: f32) -> f32 {
    x.clamp(-1.0, 1.0).asin()
}

/// acos with the argument clamped to [−1, 1], so rounding never yields NaN.
#[inline]
pub fn safe_acos(x: f32) -> f32 {
    x.clamp(-1.0, 1.0).acos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfc_is_relatively_accurate_in_both_tails() {
        // Reference values (mpmath, 30 digits).
        for (x, want) in [
            (0.0, 1.0),
            (0.5, 0.479_500_122_186_953_5),
            (1.0, 0.157_299_207_050_285_13),
            (3.0, 2.209_049_699_858_544e-5),
            (6.0, 2.151_973_671_249_891_3e-17),
            (10.0, 2.088_487_583_762_545e-45),
            (-1.0, 1.842_700_792_949_715),
            (-4.0, 1.999_999_984_582_742),
        ] {
            let got = erfc(x);
            assert!(
                ((got - want) / want).abs() < 1.2e-7,
                "erfc({x}) = {got}, want {want}"
            );
        }
        assert!((erf(0.3) + erf(-0.3)).abs() < 1e-12);
    }

    #[test]
    fn frame_from_z_is_orthonormal() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.3, -0.5, 0.8).normalize(),
        ] {
            let f = Frame::from_z(n);
            assert!((f.x.length() - 1.0).abs() < 1e-5);
            assert!((f.y.length() - 1.0).abs() < 1e-5);
            assert!(
                f.x.dot(f.y).abs() < 1e-5 && f.x.dot(f.z).abs() < 1e-5 && f.y.dot(f.z).abs() < 1e-5
            );
            let v = Vec3::new(0.2, 0.7, -0.1);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }

    #[test]
    fn aabb_ray_intersection() {
        let b = Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let r = Ray::new(Vec3::new(0.0, 0.0, -5.0), Vec3::Z);
        assert_eq!(b.intersect(&r), Some((4.0, 6.0)));
        let miss = Ray::new(Vec3::new(3.0, 0.0, -5.0), Vec3::Z);
        assert_eq!(b.intersect(&miss), None);
    }
}
