//! Curve bases: polyline → Embree control points, segment evaluation, and the capsule around
//! each segment that the self-intersection filter reasons with.

use embree3::GeometryKind;
use serde::{Deserialize, Serialize};
use tress_core::math::Vec3;

/// How a strand's polyline is turned into Embree flat (ray-facing ribbon) curves.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
pub enum CurveBasis {
    /// Straight segments between the input points (Embree flat linear curves). Exact, fastest.
    #[default]
    Linear,
    /// Cubic Catmull-Rom segments (Embree flat Catmull-Rom curves): passes through every input
    /// point, C1. End tangents come from mirrored phantom points.
    CatmullRom,
    /// Interpolating uniform cubic B-spline (Embree flat B-spline curves): the control points
    /// are solved per strand so the C2 curve passes through every input point (natural ends).
    BSpline,
}

/// The surface Embree draws a fiber as.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
pub enum CurveShape {
    /// Ribbons of the fiber's width that face every ray (Embree flat curves), hit at the depth
    /// of the axis. Fastest; what hair renderers built on Embree use, and enough for fiber
    /// models, which take only `h` from the hit.
    #[default]
    Flat,
    /// Tubes (Embree round curves: a sphere swept along the curve), hit on their surface: the
    /// geometry of pbrt-v4's cylinder curves, Mitsuba 3's and Cycles' thick curves. `h` is
    /// the same impact parameter as on a ribbon; the hit point lies up to a radius nearer the
    /// ray origin.
    Round,
}

/// What a ray that starts inside another fiber meets of it. The fibers of real grooms
/// interpenetrate, so a ray leaving one fiber often starts inside a second.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema,
)]
pub enum Overlaps {
    /// The ray scatters off the fiber where it leaves it, as if the overlap were that fiber's
    /// own material: tubes always; ribbons, which Embree meets at the depth of the axis, when
    /// the ray starts on the near side of the axis (from beyond it the ribbon lies behind the
    /// ray and is not met). It invents an interface inside the overlap and traps light there:
    /// lossless tubes that interpenetrate deeply reflect 0.43–0.45 in a white furnace. Kept
    /// for comparing with renders made before it stopped being the default.
    Scatter,
    /// The ray passes through the fiber it starts inside, and is stopped only by fibers it
    /// enters from outside (the default): inside one fiber there is no interface where a
    /// second fiber's wall crosses it, so light is neither trapped nor lost (a white furnace
    /// of interpenetrating lossless tubes reflects 1). Mitsuba 3's convention too (its Embree
    /// culls the back faces of round curves). The same image where fibers do not
    /// interpenetrate.
    #[default]
    PassThrough,
}

impl CurveBasis {
    pub(crate) fn geometry_kind(self, shape: CurveShape) -> GeometryKind {
        match (shape, self) {
            (CurveShape::Flat, CurveBasis::Linear) => GeometryKind::FLAT_LINEAR_CURVE,
            (CurveShape::Flat, CurveBasis::CatmullRom) => GeometryKind::FLAT_CATMULL_ROM_CURVE,
            (CurveShape::Flat, CurveBasis::BSpline) => GeometryKind::FLAT_BSPLINE_CURVE,
            (CurveShape::Round, CurveBasis::Linear) => GeometryKind::ROUND_LINEAR_CURVE,
            (CurveShape::Round, CurveBasis::CatmullRom) => GeometryKind::ROUND_CATMULL_ROM_CURVE,
            (CurveShape::Round, CurveBasis::BSpline) => GeometryKind::ROUND_BSPLINE_CURVE,
        }
    }

    /// Control points per segment.
    pub(crate) fn order(self) -> usize {
        match self {
            CurveBasis::Linear => 2,
            CurveBasis::CatmullRom | CurveBasis::BSpline => 4,
        }
    }

    /// Control points (xyz, radius in w) of one strand of `pts` (at least two points). Segment
    /// `j` of the strand, from `pts[j]` to `pts[j + 1]`, uses control points `j..j + order()`.
    pub(crate) fn control_points(self, pts: &[glam::Vec4]) -> Vec<glam::Vec4> {
        let n = pts.len();
        debug_assert!(n >= 2);
        match self {
            CurveBasis::Linear => pts.to_vec(),
            CurveBasis::CatmullRom => {
                // Mirror the end points for the phantom tangents, keeping the end radii (a
                // mirrored radius could go negative).
                let first = (2.0 * pts[0] - pts[1]).truncate().extend(pts[0].w);
                let last = (2.0 * pts[n - 1] - pts[n - 2])
                    .truncate()
                    .extend(pts[n - 1].w);
                let mut cps = Vec::with_capacity(n + 2);
                cps.push(first);
                cps.extend_from_slice(pts);
                cps.push(last);
                cps
            }
            CurveBasis::BSpline => {
                // Unknowns c_0..c_{n+1}. Interpolation: (c_i + 4c_{i+1} + c_{i+2})/6 = p_i for
                // i = 0..n-1; natural ends c_0 - 2c_1 + c_2 = 0 (and at the tip) give c_1 = p_0,
                // c_n = p_{n-1}, leaving a diagonally dominant tridiagonal system (Thomas).
                let mut c = vec![glam::Vec4::ZERO; n + 2];
                c[1] = pts[0];
                c[n] = pts[n - 1];
                let m = n - 2;
                if m > 0 {
                    let mut cp = vec![0.0f32; m];
                    let mut dp = vec![glam::Vec4::ZERO; m];
                    for k in 0..m {
                        let i = k + 1;
                        let mut d = 6.0 * pts[i];
                        if k == 0 {
                            d -= c[1];
                        }
                        if k == m - 1 {
                            d -= c[n];
                        }
                        let (w, prev) = if k == 0 {
                            (4.0, glam::Vec4::ZERO)
                        } else {
                            (4.0 - cp[k - 1], dp[k - 1])
                        };
                        cp[k] = 1.0 / w;
                        dp[k] = (d - prev) / w;
                    }
                    c[m + 1] = dp[m - 1];
                    for k in (0..m - 1).rev() {
                        c[k + 2] = dp[k] - cp[k] * c[k + 3];
                    }
                }
                c[0] = 2.0 * c[1] - c[2];
                c[n + 1] = 2.0 * c[n] - c[n - 1];
                // Embree needs non-negative radii; overshoot only happens for rough radius data.
                for p in &mut c {
                    p.w = p.w.max(0.0);
                }
                c
            }
        }
    }

    /// Position+radius and its derivative with respect to `u` on a segment with control
    /// points `cps` (`order()` of them).
    pub(crate) fn eval(self, cps: &[glam::Vec4], u: f32) -> (glam::Vec4, glam::Vec4) {
        let (w, dw) = match self {
            CurveBasis::Linear => {
                return (cps[0].lerp(cps[1], u), cps[1] - cps[0]);
            }
            CurveBasis::CatmullRom => {
                let (u2, u3) = (u * u, u * u * u);
                (
                    [
                        0.5 * (-u3 + 2.0 * u2 - u),
                        0.5 * (3.0 * u3 - 5.0 * u2 + 2.0),
                        0.5 * (-3.0 * u3 + 4.0 * u2 + u),
                        0.5 * (u3 - u2),
                    ],
                    [
                        0.5 * (-3.0 * u2 + 4.0 * u - 1.0),
                        0.5 * (9.0 * u2 - 10.0 * u),
                        0.5 * (-9.0 * u2 + 8.0 * u + 1.0),
                        0.5 * (3.0 * u2 - 2.0 * u),
                    ],
                )
            }
            CurveBasis::BSpline => {
                let (s, u2, u3) = (1.0 - u, u * u, u * u * u);
                (
                    [
                        s * s * s / 6.0,
                        (3.0 * u3 - 6.0 * u2 + 4.0) / 6.0,
                        (-3.0 * u3 + 3.0 * u2 + 3.0 * u + 1.0) / 6.0,
                        u3 / 6.0,
                    ],
                    [
                        -0.5 * s * s,
                        0.5 * (3.0 * u2 - 4.0 * u),
                        0.5 * (-3.0 * u2 + 2.0 * u + 1.0),
                        0.5 * u2,
                    ],
                )
            }
        };
        let mut p = glam::Vec4::ZERO;
        let mut d = glam::Vec4::ZERO;
        for k in 0..4 {
            p += w[k] * cps[k];
            d += dw[k] * cps[k];
        }
        (p, d)
    }

    /// A capsule containing the swept fiber of a segment: the chord between its end points,
    /// with the largest radius plus the curve's largest distance from the chord, sampled at 33
    /// points and grown by 2% of that distance (a cubic strays about 0.1% of it between the
    /// samples).
    pub(crate) fn capsule(self, cps: &[glam::Vec4]) -> Capsule {
        if self == CurveBasis::Linear {
            return Capsule {
                a: cps[0].truncate(),
                b: cps[1].truncate(),
                r: cps[0].w.max(cps[1].w),
            };
        }
        let a = self.eval(cps, 0.0).0.truncate();
        let b = self.eval(cps, 1.0).0.truncate();
        let mut r = 0.0f32;
        let mut deviation = 0.0f32;
        for k in 0..=32 {
            let (p, _) = self.eval(cps, k as f32 / 32.0);
            let d = point_segment_distance(p.truncate(), a, b);
            deviation = deviation.max(d);
            r = r.max(p.w + d);
        }
        Capsule {
            a,
            b,
            r: r + 0.02 * deviation,
        }
    }
}

/// The set of points within `r` of the segment `a`–`b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Capsule {
    pub a: Vec3,
    pub b: Vec3,
    pub r: f32,
}

impl Capsule {
    /// The parameter interval `[t_in, t_out]` where the line `org + t·dir` (any t) lies inside
    /// the capsule, with the radius grown by `pad`.
    pub(crate) fn line_interval(&self, org: Vec3, dir: Vec3, pad: f32) -> Option<(f32, f32)> {
        let r = self.r + pad;
        let r2 = r * r;
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        let mut add = |iv: Option<(f32, f32)>| {
            if let Some((a, b)) = iv {
                lo = lo.min(a);
                hi = hi.max(b);
            }
        };
        // A capsule is the union of its two end balls and the finite cylinder between them; it
        // is convex, so the union of the three intervals is one interval.
        add(sphere_interval(org - self.a, dir, r2));
        add(sphere_interval(org - self.b, dir, r2));
        let axis = self.b - self.a;
        let len = axis.length();
        if len > 0.0 {
            let w = axis / len;
            let oc = org - self.a;
            let (ow, dw) = (oc.dot(w), dir.dot(w));
            let o_perp = oc - w * ow;
            let d_perp = dir - w * dw;
            let qa = d_perp.length_squared();
            let qb = o_perp.dot(d_perp);
            let qc = o_perp.length_squared() - r2;
            let cyl = if qa > 0.0 {
                let disc = qb * qb - qa * qc;
                (disc >= 0.0).then(|| {
                    let s = disc.sqrt();
                    ((-qb - s) / qa, (-qb + s) / qa)
                })
            } else if qc <= 0.0 {
                Some((f32::NEG_INFINITY, f32::INFINITY))
            } else {
                None
            };
            // Clip to the slab 0 ≤ (p − a)·w ≤ len.
            let slab = if dw != 0.0 {
                let (t0, t1) = (-ow / dw, (len - ow) / dw);
                Some((t0.min(t1), t0.max(t1)))
            } else if (0.0..=len).contains(&ow) {
                Some((f32::NEG_INFINITY, f32::INFINITY))
            } else {
                None
            };
            if let (Some(c), Some(s)) = (cyl, slab) {
                let (a, b) = (c.0.max(s.0), c.1.min(s.1));
                if a <= b {
                    add(Some((a, b)));
                }
            }
        }
        (lo <= hi).then_some((lo, hi))
    }
}

/// Interval of the line `oc + t·dir` (relative to the centre) inside the ball of radius² `r2`.
fn sphere_interval(oc: Vec3, dir: Vec3, r2: f32) -> Option<(f32, f32)> {
    let a = dir.length_squared();
    if a == 0.0 {
        return None;
    }
    let b = oc.dot(dir);
    // Discriminant in the form that avoids cancellation for rays starting near the ball.
    let perp = oc - dir * (b / a);
    let disc = a * (r2 - perp.length_squared());
    if disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    Some(((-b - s) / a, (-b + s) / a))
}

fn point_segment_distance(p: Vec3, a: Vec3, b: Vec3) -> f32 {
    let ab = b - a;
    let l2 = ab.length_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.distance(a + ab * t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec4;

    fn wiggly() -> Vec<Vec4> {
        (0..7)
            .map(|i| {
                let x = i as f32;
                Vec4::new(x, (x * 1.3).sin(), (x * 0.7).cos() * 0.5, 0.1 + 0.01 * x)
            })
            .collect()
    }

    #[test]
    fn cubic_bases_interpolate_the_input_points() {
        for basis in [CurveBasis::CatmullRom, CurveBasis::BSpline] {
            for n in 2..=7 {
                let pts = &wiggly()[..n];
                let cps = basis.control_points(pts);
                assert_eq!(cps.len(), n + 2);
                for j in 0..n - 1 {
                    let seg = &cps[j..j + 4];
                    let (p0, d0) = basis.eval(seg, 0.0);
                    let (p1, d1) = basis.eval(seg, 1.0);
                    assert!((p0 - pts[j]).length() < 1e-4, "{basis:?} n={n} j={j}");
                    assert!((p1 - pts[j + 1]).length() < 1e-4, "{basis:?} n={n} j={j}");
                    // C1 across the joint.
                    if j + 1 < n - 1 {
                        let (_, dn) = basis.eval(&cps[j + 1..j + 5], 0.0);
                        assert!((d1 - dn).length() < 1e-4);
                    }
                    // Derivative matches a finite difference.
                    let h = 1e-3;
                    let fd = (basis.eval(seg, 0.5 + h).0 - basis.eval(seg, 0.5 - h).0) / (2.0 * h);
                    assert!((fd - basis.eval(seg, 0.5).1).length() < 1e-2);
                    assert!(d0.truncate().length() > 0.0);
                }
            }
        }
    }

    #[test]
    fn bspline_reproduces_straight_lines_exactly() {
        let pts: Vec<Vec4> = (0..6)
            .map(|i| Vec4::new(i as f32, 2.0 * i as f32, 0.0, 0.1 - 0.01 * i as f32))
            .collect();
        let cps = CurveBasis::BSpline.control_points(&pts);
        for j in 0..5 {
            let (p, _) = CurveBasis::BSpline.eval(&cps[j..j + 4], 0.5);
            let want = pts[j].lerp(pts[j + 1], 0.5);
            assert!((p - want).length() < 1e-5, "{p} vs {want}");
        }
    }

    #[test]
    fn capsule_intervals() {
        let c = Capsule {
            a: Vec3::ZERO,
            b: Vec3::new(2.0, 0.0, 0.0),
            r: 0.5,
        };
        // Straight through the middle of the cylinder.
        let (a, b) = c
            .line_interval(Vec3::new(1.0, -3.0, 0.0), Vec3::Y, 0.0)
            .unwrap();
        assert!((a - 2.5).abs() < 1e-5 && (b - 3.5).abs() < 1e-5);
        // Along the axis: through both caps.
        let (a, b) = c
            .line_interval(Vec3::new(-5.0, 0.0, 0.0), Vec3::X, 0.0)
            .unwrap();
        assert!((a - 4.5).abs() < 1e-5 && (b - 7.5).abs() < 1e-5);
        // Parallel to the axis but outside.
        assert!(c
            .line_interval(Vec3::new(-5.0, 0.6, 0.0), Vec3::X, 0.0)
            .is_none());
        // Through an end cap only.
        let (a, b) = c
            .line_interval(Vec3::new(-0.3, -3.0, 0.0), Vec3::Y, 0.0)
            .unwrap();
        let half = (0.25f32 - 0.09).sqrt();
        assert!((a - (3.0 - half)).abs() < 1e-5 && (b - (3.0 + half)).abs() < 1e-5);
        // Padding grows the radius.
        assert!(c
            .line_interval(Vec3::new(-5.0, 0.6, 0.0), Vec3::X, 0.2)
            .is_some());
    }

    #[test]
    fn cubic_capsules_contain_the_curve() {
        for basis in [CurveBasis::CatmullRom, CurveBasis::BSpline] {
            let cps = basis.control_points(&wiggly());
            for j in 0..6 {
                let seg = &cps[j..j + 4];
                let cap = basis.capsule(seg);
                for k in 0..=1000 {
                    let (p, _) = basis.eval(seg, k as f32 / 1000.0);
                    let d = point_segment_distance(p.truncate(), cap.a, cap.b) + p.w;
                    assert!(d <= cap.r + 1e-6, "{basis:?} seg {j}: {d} > {}", cap.r);
                }
            }
        }
    }
}
