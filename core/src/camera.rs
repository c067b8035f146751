//! Perspective camera with an optional thin lens.

use crate::math::{Ray, Vec2, Vec3};
use crate::sampling::sample_uniform_disk_concentric;

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

impl Camera {
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
