//! The orientation of fibers about their axes — an elliptical fiber's major axis — from the
//! groom where it stores one (USD `normals`) and otherwise from a stated default: a
//! minimum-twist frame along each strand, started at the root from the direction away from the
//! centre of the object's roots (an estimate of the scalp normal), or a fixed world direction.
//! Only hair models that use the orientation ([`tress_core::Bcsdf::uses_orientation`]) see it.

use tress_core::math::{Frame, Vec3};

/// Where a hair object's fibers take their orientation about their axes (the major axis of an
/// elliptical fiber).
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema,
)]
pub enum FiberOrientation {
    /// The groom's own (USD `normals`, per point or per strand) where it has one, otherwise
    /// `ScalpNormal` (the default).
    #[default]
    Groom,
    /// A minimum-twist (rotation-minimising) frame along each strand whose major axis starts at
    /// the root pointing away from the centre of the object's roots, an estimate of the scalp
    /// normal; the groom's own orientation is ignored.
    ScalpNormal,
    /// The major axis toward this world direction everywhere (made orthogonal to the fiber);
    /// where a fiber runs along it, the minimum-twist frame's.
    Fixed((f32, f32, f32)),
}

impl FiberOrientation {
    /// A reason the option is unusable, if it is.
    pub(crate) fn invalid(&self) -> Option<String> {
        match *self {
            FiberOrientation::Fixed((x, y, z)) => {
                let v = Vec3::new(x, y, z);
                (!(v.is_finite() && v.length_squared() > 0.0))
                    .then(|| format!("Fixed({x}, {y}, {z}) must be a finite, non-zero direction"))
            }
            _ => None,
        }
    }
}

/// Per point of one strand through `pts` (world space, at least two), the orientation: the
/// file's (`file`, per point, world space) when the option takes it, the fixed direction, or
/// the minimum-twist frame started from `outward` (the root's direction away from the roots'
/// centre). Each vector is orthogonal to a segment at that point, unit; models project it onto
/// the plane across the tangent at the hit.
pub(crate) fn strand_orientations(
    option: &FiberOrientation,
    pts: &[Vec3],
    file: Option<&[Vec3]>,
    outward: Vec3,
) -> Vec<Vec3> {
    let dirs: Vec<Vec3> = pts
        .windows(2)
        .map(|w| (w[1] - w[0]).try_normalize().unwrap_or(Vec3::Y))
        .collect();
    let transported = || minimum_twist(&dirs, outward);
    match (option, file) {
        (FiberOrientation::Groom, Some(file)) => {
            let fallback = transported();
            file.iter()
                .zip(&fallback)
                .zip(point_tangents(&dirs))
                .map(|((&n, &f), t)| across(n, t).unwrap_or(f))
                .collect()
        }
        (FiberOrientation::Fixed((x, y, z)), _) => {
            let d = Vec3::new(*x, *y, *z);
            let fallback = transported();
            point_tangents(&dirs)
                .zip(&fallback)
                .map(|(t, &f)| across(d, t).unwrap_or(f))
                .collect()
        }
        _ => transported(),
    }
}

/// `v` made orthogonal to unit `t` and normalised, unless it (nearly) runs along `t`.
fn across(v: Vec3, t: Vec3) -> Option<Vec3> {
    (v - t * v.dot(t))
        .try_normalize()
        .filter(|u| u.dot(v.normalize_or_zero()).abs() > 1e-3)
}

/// The tangent at each point: the mean of its segments' directions.
fn point_tangents(dirs: &[Vec3]) -> impl Iterator<Item = Vec3> + '_ {
    (0..=dirs.len()).map(move |i| {
        let a = dirs[i.saturating_sub(1)];
        let b = dirs[i.min(dirs.len() - 1)];
        (a + b).try_normalize().unwrap_or(b)
    })
}

/// Parallel transport of the root's normal along the polyline's segment directions: at every
/// joint the normal turns by the smallest rotation taking one segment's direction to the next,
/// so the frame does not twist about the strand. Per point; the last point takes its segment's.
fn minimum_twist(dirs: &[Vec3], outward: Vec3) -> Vec<Vec3> {
    let mut n = across(outward, dirs[0]).unwrap_or_else(|| Frame::from_z(dirs[0]).x);
    let mut out = Vec::with_capacity(dirs.len() + 1);
    out.push(n);
    for w in dirs.windows(2) {
        let (a, b) = (w[0], w[1]);
        let c = a.dot(b);
        if c > -0.999 {
            // Rodrigues' rotation about a × b by the angle between a and b.
            let k = a.cross(b);
            n = n * c + k.cross(n) + k * (k.dot(n) / (1.0 + c));
        }
        n = across(n, b).unwrap_or_else(|| Frame::from_z(b).x);
        out.push(n);
    }
    out.push(n);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_minimum_twist_frame_follows_a_planar_bend_without_turning() {
        // A strand bending in the xy plane: a normal starting along z stays along z.
        let pts: Vec<Vec3> = (0..10)
            .map(|i| {
                let a = i as f32 * 0.2;
                Vec3::new(a.sin(), 1.0 - a.cos(), 0.0)
            })
            .collect();
        let n = strand_orientations(&FiberOrientation::ScalpNormal, &pts, None, Vec3::Z);
        assert_eq!(n.len(), pts.len());
        for v in &n {
            assert!((*v - Vec3::Z).length() < 1e-5, "{v}");
        }
        // Starting in the bending plane, it stays in the plane, orthogonal to the strand.
        let n = strand_orientations(&FiberOrientation::ScalpNormal, &pts, None, Vec3::Y);
        for (i, v) in n.iter().enumerate().take(pts.len() - 1) {
            let t = (pts[i + 1] - pts[i]).normalize();
            assert!(v.z.abs() < 1e-5 && v.dot(t).abs() < 0.11, "{i}: {v}");
        }
    }

    #[test]
    fn a_helix_frame_does_not_spin_faster_than_the_curve_turns() {
        // Along a helix the transported normal stays orthogonal to the strand and unit.
        let pts: Vec<Vec3> = (0..200)
            .map(|i| {
                let a = i as f32 * 0.1;
                Vec3::new(a.cos(), 0.05 * i as f32, a.sin())
            })
            .collect();
        let n = strand_orientations(&FiberOrientation::ScalpNormal, &pts, None, Vec3::X);
        for (i, v) in n.iter().enumerate().take(pts.len() - 1) {
            let t = (pts[i + 1] - pts[i]).normalize();
            assert!(
                (v.length() - 1.0).abs() < 1e-4 && v.dot(t).abs() < 1e-4,
                "{i}: {v}"
            );
        }
    }

    #[test]
    fn file_and_fixed_orientations_are_made_orthogonal_to_the_strand() {
        let pts = [Vec3::ZERO, Vec3::Y, 2.0 * Vec3::Y];
        let file = [Vec3::new(1.0, 1.0, 0.0), Vec3::Z, Vec3::Y];
        let n = strand_orientations(&FiberOrientation::Groom, &pts, Some(&file), Vec3::X);
        assert!((n[0] - Vec3::X).length() < 1e-6);
        assert!((n[1] - Vec3::Z).length() < 1e-6);
        // Along the strand: the minimum-twist frame's instead.
        assert!((n[2] - Vec3::X).length() < 1e-6, "{}", n[2]);
        let fixed = FiberOrientation::Fixed((0.0, 0.5, 2.0));
        for v in strand_orientations(&fixed, &pts, Some(&file), Vec3::X) {
            assert!((v - Vec3::Z).length() < 1e-6, "{v}");
        }
        let ignored =
            strand_orientations(&FiberOrientation::ScalpNormal, &pts, Some(&file), Vec3::X);
        assert!(ignored.iter().all(|v| (*v - Vec3::X).length() < 1e-6));
        assert!(FiberOrientation::Fixed((0.0, 0.0, 0.0)).invalid().is_some());
        assert!(FiberOrientation::Fixed((f32::NAN, 1.0, 0.0))
            .invalid()
            .is_some());
    }
}
