//! Perspective camera with an optional thin lens.

use crate::math::{Mat4, Ray, Vec2, Vec3};
use crate::sampling::sample_uniform_disk_concentric;
use glam::Vec4;

/// A pinhole or thin-lens perspective camera.
#[derive(Clone, Debug)]
pub struct Camera {
    origin: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    /// tan(fov_y / 2).
    tan_half_fov: f32,
    lens_radius: f32,
    focus_distance: f32,
}

/// Largest coordinate a camera (or anything else that starts rays) may have: Embree aborts
/// on ray origins beyond about 1.8e18.
pub const MAX_COORDINATE: f32 = 1e16;

/// Why camera parameters cannot make a camera.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// The field of view is not in (0, 180) degrees.
    #[error("camera.fov = {0} must lie in (0, 180) degrees")]
    Fov(f32),
    /// A position is not finite or too far out, or `up` is not finite.
    #[error("camera positions must be finite and within ±{MAX_COORDINATE:e}")]
    Position,
    /// `look_at` equals `look_from`.
    #[error("camera.look_at must differ from look_from")]
    Coincident,
    /// `up` is zero or parallel to the view direction.
    #[error("camera.up must be non-zero and not parallel to the view direction")]
    Up,
    /// The lens radius is negative, NaN or too large.
    #[error("camera.lens_radius = {0} must lie in [0, {MAX_COORDINATE:e}]")]
    LensRadius(f32),
    /// The focus distance is not positive and finite.
    #[error("camera.focus_distance = Some({0}) must lie in (0, {MAX_COORDINATE:e}]")]
    FocusDistance(f32),
}

impl Camera {
    /// [`Camera::perspective`] after checking every ray-producing quantity: a camera from it
    /// only makes finite rays Embree accepts.
    pub fn new(
        look_from: Vec3,
        look_at: Vec3,
        up: Vec3,
        fov_y_deg: f32,
        lens_radius: f32,
        focus_distance: Option<f32>,
    ) -> Result<Self, CameraError> {
        if !(fov_y_deg > 0.0 && fov_y_deg < 180.0) {
            return Err(CameraError::Fov(fov_y_deg));
        }
        let placeable = |v: Vec3| v.is_finite() && v.abs().max_element() <= MAX_COORDINATE;
        if !placeable(look_from) || !placeable(look_at) || !up.is_finite() {
            return Err(CameraError::Position);
        }
        // Relative tests, in f64: a view direction of length 1e-30 is as good as any (its
        // square underflows f32).
        let view = look_at.as_dvec3() - look_from.as_dvec3();
        if view.length() == 0.0 {
            return Err(CameraError::Coincident);
        }
        let up64 = up.as_dvec3();
        if up64.length() == 0.0 || view.normalize().cross(up64.normalize()).length() < 1e-6 {
            return Err(CameraError::Up);
        }
        if !(0.0..=MAX_COORDINATE).contains(&lens_radius) {
            return Err(CameraError::LensRadius(lens_radius));
        }
        if let Some(f) = focus_distance.filter(|f| !(*f > 0.0 && *f <= MAX_COORDINATE)) {
            return Err(CameraError::FocusDistance(f));
        }
        Ok(Self::perspective(
            look_from,
            look_at,
            up,
            fov_y_deg,
            lens_radius,
            focus_distance,
        ))
    }

    /// `fov_y_deg`: vertical field of view in degrees, in (0, 180). `lens_radius` 0 is a pinhole.
    pub fn perspective(
        look_from: Vec3,
        look_at: Vec3,
        up: Vec3,
        fov_y_deg: f32,
        lens_radius: f32,
        focus_distance: Option<f32>,
    ) -> Self {
        // In f64: the view vector may be tiny (1e-30), and its square underflows f32.
        let view = look_at.as_dvec3() - look_from.as_dvec3();
        let forward = view.normalize().as_vec3();
        let right = forward.cross(up.normalize()).normalize();
        let true_up = right.cross(forward);
        Camera {
            origin: look_from,
            forward,
            right,
            up: true_up,
            tan_half_fov: (fov_y_deg.to_radians() * 0.5).tan(),
            lens_radius,
            focus_distance: focus_distance.unwrap_or(view.length() as f32),
        }
    }

    /// The ray through film position (`px`, `py`) in pixels (y down) of a `width`×`height` film.
    pub fn generate_ray(&self, px: f32, py: f32, width: u32, height: u32, lens_u: Vec2) -> Ray {
        let aspect = width as f32 / height as f32;
        let sx = (2.0 * px / width as f32 - 1.0) * self.tan_half_fov * aspect;
        let sy = (1.0 - 2.0 * py / height as f32) * self.tan_half_fov;
        let dir = (self.forward + self.right * sx + self.up * sy).normalize();
        if self.lens_radius <= 0.0 {
            return Ray::new(self.origin, dir);
        }
        // Thin lens: all rays through the lens meet on the plane of focus.
        let focus_t = self.focus_distance / dir.dot(self.forward);
        let focus_point = self.origin + dir * focus_t;
        let lens = sample_uniform_disk_concentric(lens_u) * self.lens_radius;
        let origin = self.origin + self.right * lens.x + self.up * lens.y;
        Ray::new(origin, (focus_point - origin).normalize())
    }

    /// The camera's position (the lens centre), in world space.
    pub fn position(&self) -> Vec3 {
        self.origin
    }

    /// World to camera space as OpenEXR's `worldToCamera` attribute (and RenderMan) define it:
    /// the camera at the origin, +x right, +y up and +z the viewing direction (left-handed).
    /// Column-vector convention (`m * p`); OpenEXR stores it transposed, which is glam's
    /// column-major array.
    pub fn world_to_camera(&self) -> Mat4 {
        let rows = Mat4::from_cols(
            self.right.extend(0.0),
            self.up.extend(0.0),
            self.forward.extend(0.0),
            Vec4::W,
        )
        .transpose();
        rows * Mat4::from_translation(-self.origin)
    }

    /// World to normalised device coordinates of a `width`×`height` film, as OpenEXR's
    /// `worldToNDC` attribute defines them: after the perspective divide, (0, 0) is the film's
    /// upper-left corner and (1, 1) its lower-right, x right and y down; z becomes 1 / (depth
    /// along the view axis). The projection through the lens centre (a thin lens brings the
    /// plane of focus to the same place). Column-vector convention, as [`Self::world_to_camera`].
    pub fn world_to_ndc(&self, width: u32, height: u32) -> Mat4 {
        let aspect = width as f32 / height as f32;
        let kx = 0.5 / (self.tan_half_fov * aspect);
        let ky = 0.5 / self.tan_half_fov;
        // x = (kx·cx + cz/2) / cz, y = (cz/2 − ky·cy) / cz, z = 1 / cz, w = cz.
        let projection = Mat4::from_cols(
            Vec4::new(kx, 0.0, 0.0, 0.0),
            Vec4::new(0.0, -ky, 0.0, 0.0),
            Vec4::new(0.5, 0.5, 0.0, 1.0),
            Vec4::new(0.0, 0.0, 1.0, 0.0),
        );
        projection * self.world_to_camera()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn center_ray_looks_at_target() {
        let c = Camera::perspective(
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::ZERO,
            Vec3::Y,
            40.0,
            0.0,
            None,
        );
        let r = c.generate_ray(50.0, 50.0, 100, 100, Vec2::ZERO);
        assert!((r.dir - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        // Top edge of the film is fov/2 above the axis.
        let top = c.generate_ray(50.0, 0.0, 100, 100, Vec2::ZERO);
        assert!((top.dir.y.atan2(-top.dir.z).to_degrees() - 20.0).abs() < 1e-3);
    }

    /// The matrices put a point seen through film position (px, py) at (px / w, py / h) in NDC
    /// and at positive camera z, the camera at the origin.
    #[test]
    fn world_to_ndc_projects_onto_the_film_position_of_the_ray() {
        let c = Camera::perspective(
            Vec3::new(1.0, 2.0, 5.0),
            Vec3::new(-0.5, 0.3, -1.0),
            Vec3::new(0.1, 1.0, 0.0),
            50.0,
            0.0,
            None,
        );
        let (w, h) = (64, 48);
        let to_camera = c.world_to_camera();
        let to_ndc = c.world_to_ndc(w, h);
        assert!(to_camera.transform_point3(c.position()).length() < 1e-5);
        assert!(to_camera.determinant() < 0.0, "camera space is left-handed");
        for (px, py, d) in [
            (0.0, 0.0, 1.0),
            (64.0, 48.0, 7.5),
            (10.5, 40.25, 0.3),
            (32.0, 24.0, 3.0),
        ] {
            let r = c.generate_ray(px, py, w, h, Vec2::ZERO);
            let p = r.at(d);
            let cam = to_camera.transform_point3(p);
            assert!((cam.length() - d).abs() < 1e-4 && cam.z > 0.0, "{cam}");
            // Right of centre is +x, above is +y.
            assert_eq!(cam.x > 1e-4, px > 32.0);
            assert_eq!(cam.y > 1e-4, py < 24.0);
            let ndc = to_ndc.project_point3(p);
            assert!(
                (ndc.x - px / w as f32).abs() < 1e-5,
                "{ndc} for ({px}, {py})"
            );
            assert!(
                (ndc.y - py / h as f32).abs() < 1e-5,
                "{ndc} for ({px}, {py})"
            );
            assert!((ndc.z - 1.0 / cam.z).abs() < 1e-4 * ndc.z);
        }
    }

    #[test]
    fn thin_lens_rays_focus() {
        let c = Camera::perspective(
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::ZERO,
            Vec3::Y,
            40.0,
            0.5,
            None,
        );
        for u in [Vec2::new(0.1, 0.9), Vec2::new(0.7, 0.3)] {
            let r = c.generate_ray(30.0, 60.0, 100, 100, u);
            let p = c.generate_ray(30.0, 60.0, 100, 100, Vec2::splat(0.5));
            let t = (0.0 - r.origin.z) / r.dir.z;
            let tp = (0.0 - p.origin.z) / p.dir.z;
            assert!((r.at(t) - p.at(tp)).length() < 1e-4);
        }
    }
}
