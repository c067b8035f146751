//! Lights: environment maps (importance sampled), a constant environment, distant (sun) lights
//! with an angular radius, and point lights.
//!
//! World directions map to environment-map texels with +y up: θ = acos(d.y) from the zenith,
//! φ = atan2(d.x, −d.z), u = φ/2π + ½ wrapped, v = θ/π (so the map's centre column faces −z),
//! then rotated about +y by `rotation_deg`, right-handed: a map feature at azimuth φ appears at
//! φ − rotation (rotating by 90° turns the centre column from −z to −x), so lookups use
//! u = (φ + rotation)/2π + ½.

use crate::math::Frame;
use crate::math::{Rgb, Vec2, Vec3};
use crate::sampling::{sample_uniform_cone, sample_uniform_sphere, uniform_cone_pdf, INV_4PI};

pub use crate::envmap::EnvironmentMap;
pub use crate::light_sample::{LightSample, MAX_LIGHT};

/// A light source.
#[derive(Clone, Debug)]
pub enum Light {
    /// Image-based environment, importance sampled.
    Environment(EnvironmentMap),
    /// Uniform radiance from every direction.
    Constant {
        /// Radiance per channel, the same from every direction.
        radiance: Rgb,
    },
    /// A distant light (the sun): radiance `radiance` within a cone of half-angle
    /// `half_angle_rad` around `-direction`; a delta light when the angle is 0, in which case
    /// `radiance` is the irradiance it delivers perpendicular to its direction.
    Distant {
        /// Direction the light travels, from the sun into the scene (normalised on use).
        direction: Vec3,
        /// Radiance within the disc, or the perpendicular irradiance of a delta light.
        radiance: Rgb,
        /// Angular radius of the sun's disc, in radians; 0 makes a delta light.
        half_angle_rad: f32,
    },
    /// A point light of intensity `intensity` (W/sr).
    Point {
        /// Position of the light, in world space.
        position: Vec3,
        /// Radiant intensity per channel, in W/sr.
        intensity: Rgb,
    },
}

/// Why light parameters cannot make a light.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LightError {
    /// A radiance, irradiance or intensity with a negative or non-finite channel.
    #[error("{name} {value} must be finite and non-negative")]
    Negative {
        /// Which quantity.
        name: &'static str,
        /// Its value.
        value: Rgb,
    },
    /// A direction that is zero or not finite.
    #[error("direction {0} must be finite and non-zero")]
    Direction(Vec3),
    /// A sun disc outside [0, 90) degrees.
    #[error("angular_radius = {0} must lie in [0, 90) degrees")]
    AngularRadius(f32),
    /// A finite irradiance spread over so small a disc that its radiance overflows f32 or
    /// exceeds [`MAX_LIGHT`].
    #[error(
        "irradiance {irradiance} from a disc of {angular_radius_deg}° is a radiance of \
         {radiance}, beyond {max:e}: lower the irradiance or widen the disc",
        max = MAX_LIGHT
    )]
    Overflow {
        /// The irradiance asked for.
        irradiance: Rgb,
        /// The disc's angular radius, in degrees.
        angular_radius_deg: f32,
        /// The radiance it would take.
        radiance: Rgb,
    },
    /// A radiance, irradiance or intensity beyond [`MAX_LIGHT`].
    #[error(
        "{name} {value} is beyond {max:e}: a path's throughput times it overflows f32 (the \
         samples were dropped and the image came out biased dark); scale the lights down",
        max = MAX_LIGHT
    )]
    TooBright {
        /// Which quantity.
        name: &'static str,
        /// Its value.
        value: Rgb,
    },
    /// A point light position that is not finite.
    #[error("position {0} must be finite")]
    Position(Vec3),
}

fn non_negative(name: &'static str, value: Rgb) -> Result<Rgb, LightError> {
    if !(value.is_finite() && value.min_element() >= 0.0) {
        return Err(LightError::Negative { name, value });
    }
    if value.max_element() > MAX_LIGHT {
        return Err(LightError::TooBright { name, value });
    }
    Ok(value)
}

impl Light {
    /// Uniform radiance from every direction.
    pub fn constant(radiance: Rgb) -> Result<Self, LightError> {
        Ok(Light::Constant {
            radiance: non_negative("radiance", radiance)?,
        })
    }

    /// A sun shining along `direction` that delivers `irradiance` perpendicular to it, from a
    /// disc of angular radius `angular_radius_deg` (0: a delta light). A disc narrower than f32
    /// can tell from its axis (1 − cos below 1e-6, about 0.08°) is a point: sampled as a cone,
    /// its cos_max rounds to 1 and it rendered black (or, at 1e-30°, with infinite radiance).
    pub fn distant(
        direction: Vec3,
        irradiance: Rgb,
        angular_radius_deg: f32,
    ) -> Result<Self, LightError> {
        let irradiance = non_negative("irradiance", irradiance)?;
        let direction = crate::math::unit(direction).ok_or(LightError::Direction(direction))?;
        if !(0.0..90.0).contains(&angular_radius_deg) {
            return Err(LightError::AngularRadius(angular_radius_deg));
        }
        let half = angular_radius_deg.to_radians();
        let half = if 1.0 - f64::from(half).cos() < 1e-6 {
            0.0
        } else {
            half
        };
        // Uniform disc radiance delivering `irradiance` at normal incidence:
        // E = L · π sin²(half) (the cosine-weighted solid angle of the disc).
        let radiance = if half > 0.0 {
            irradiance / (std::f32::consts::PI * half.sin().powi(2))
        } else {
            irradiance
        };
        if !(radiance.is_finite() && radiance.max_element() <= MAX_LIGHT) {
            return Err(LightError::Overflow {
                irradiance,
                angular_radius_deg,
                radiance,
            });
        }
        Ok(Light::Distant {
            direction,
            radiance,
            half_angle_rad: half,
        })
    }

    /// A point light of radiant intensity `intensity` (W/sr) at `position`.
    pub fn point(position: Vec3, intensity: Rgb) -> Result<Self, LightError> {
        if !position.is_finite() {
            return Err(LightError::Position(position));
        }
        Ok(Light::Point {
            position,
            intensity: non_negative("intensity", intensity)?,
        })
    }

    /// A direction toward the light from `p`, from two uniform numbers.
    pub fn sample_li(&self, p: Vec3, u: Vec2) -> Option<LightSample> {
        match self {
            Light::Environment(env) => env.sample(u),
            Light::Constant { radiance } => {
                let wi = sample_uniform_sphere(u);
                Some(LightSample {
                    wi,
                    radiance: *radiance,
                    pdf: INV_4PI,
                    distance: f32::INFINITY,
                    is_delta: false,
                })
            }
            Light::Distant {
                direction,
                radiance,
                half_angle_rad,
            } => {
                let to_light = -direction.normalize();
                if *half_angle_rad <= 0.0 {
                    return Some(LightSample {
                        wi: to_light,
                        radiance: *radiance,
                        pdf: 1.0,
                        distance: f32::INFINITY,
                        is_delta: true,
                    });
                }
                let cos_max = half_angle_rad.cos();
                let wi = Frame::from_z(to_light).to_world(sample_uniform_cone(u, cos_max));
                Some(LightSample {
                    wi,
                    radiance: *radiance,
                    pdf: uniform_cone_pdf(cos_max),
                    distance: f32::INFINITY,
                    is_delta: false,
                })
            }
            Light::Point {
                position,
                intensity,
            } => {
                let d = *position - p;
                let dist2 = d.length_squared();
                if dist2 == 0.0 {
                    return None;
                }
                let dist = dist2.sqrt();
                Some(LightSample {
                    wi: d / dist,
                    radiance: *intensity / dist2,
                    pdf: 1.0,
                    distance: dist,
                    is_delta: true,
                })
            }
        }
    }

    /// Solid-angle pdf with which [`Light::sample_li`] returns `wi` (0 for delta lights).
    pub fn pdf_li(&self, wi: Vec3) -> f32 {
        match self {
            Light::Environment(env) => env.pdf(wi),
            Light::Constant { .. } => INV_4PI,
            Light::Distant {
                direction,
                half_angle_rad,
                ..
            } => {
                if *half_angle_rad <= 0.0 {
                    return 0.0;
                }
                let cos_max = half_angle_rad.cos();
                if wi.dot(-direction.normalize()) >= cos_max {
                    uniform_cone_pdf(cos_max)
                } else {
                    0.0
                }
            }
            Light::Point { .. } => 0.0,
        }
    }

    /// [`Self::le`] as seen directly by the camera: environment maps interpolated between texel
    /// centres rather than blocky; every other light as `le`.
    pub fn le_seen(&self, dir: Vec3) -> Rgb {
        match self {
            Light::Environment(env) => env.radiance_bilinear(dir),
            _ => self.le(dir),
        }
    }

    /// Asks for what [`Light::sample_li`] reads first for `u` to be brought into the cache,
    /// where it reads a table (environment maps): a hint for integrators with other work to
    /// do before they sample, which changes no result.
    pub fn prefetch_sample(&self, u: Vec2) {
        if let Light::Environment(env) = self {
            env.prefetch_sample(u);
        }
    }

    /// Whether [`Light::sample_li`] reads a table ([`Light::prefetch_sample`] fetches ahead).
    pub fn sampling_reads_table(&self) -> bool {
        matches!(self, Light::Environment(_))
    }

    /// As [`Light::prefetch_sample`], for what [`Light::le_pdf`] reads for `dir`.
    pub fn prefetch_le(&self, dir: Vec3) {
        if let Light::Environment(env) = self {
            env.prefetch_radiance(dir);
        }
    }

    /// `(le(dir), pdf_li(dir))` in one call (the environment map locates its texel once).
    pub fn le_pdf(&self, dir: Vec3) -> (Rgb, f32) {
        match self {
            Light::Environment(env) => env.radiance_pdf(dir),
            _ => (self.le(dir), self.pdf_li(dir)),
        }
    }

    /// Radiance arriving from direction `dir` (the way an escaping ray travels); zero for delta
    /// lights, which only sampling reaches.
    pub fn le(&self, dir: Vec3) -> Rgb {
        match self {
            Light::Environment(env) => env.radiance(dir),
            Light::Constant { radiance } => *radiance,
            Light::Distant {
                direction,
                radiance,
                half_angle_rad,
            } => {
                if *half_angle_rad > 0.0 && dir.dot(-direction.normalize()) >= half_angle_rad.cos()
                {
                    *radiance
                } else {
                    Rgb::ZERO
                }
            }
            Light::Point { .. } => Rgb::ZERO,
        }
    }

    /// Whether the light is a delta distribution in direction (a point, or a distant light
    /// without a disc): it can only be reached by sampling it.
    pub fn is_delta(&self) -> bool {
        match self {
            Light::Point { .. } => true,
            Light::Distant { half_angle_rad, .. } => *half_angle_rad <= 0.0,
            _ => false,
        }
    }

    /// Whether next-event estimation samples the light. A constant sky is left to the
    /// scattering sample: its own sample is uniform over the sphere, while the scattering
    /// sample already follows the product it weights, so in a multiple-importance-sampled sum
    /// its shadow ray adds a ray and a BCSDF evaluation per vertex and takes next to no
    /// variance away (measured in the book's performance notes).
    pub fn is_sampled_directly(&self) -> bool {
        !matches!(self, Light::Constant { .. })
    }

    /// Whether the light is at infinity (seen by escaping rays, no distance).
    pub fn is_infinite(&self) -> bool {
        !matches!(self, Light::Point { .. })
    }
}
