//! Procedural hair: straight, wavy and curly strands growing from a sphere scalp, and a hair
//! ball. Deterministic for a seed; strand `i` depends only on (seed, i), so changing the strand
//! count keeps the other strands where they were.
//!
//! The scalp is a sphere (`center`, `sphere_radius`) with the face toward +z and +y up: roots
//! cover a 75° cap around an axis tilted 27° toward the back (hairline above the forehead,
//! lower at the nape). Each strand leaves the scalp almost tangentially, combed toward the back
//! and down, and bends under a gravity-like pull. Above the scalp's equator it lies on a sphere
//! slightly larger than the scalp (a different one per strand, so the hair has volume); below,
//! it hangs freely but is pushed out of that sphere. Wavy strands then get a sideways sinusoidal
//! offset whose phase follows the height (within 0.5 rad across strands, so neighbours wave
//! together), curly ones a helical one along the strand (random phase), both faded in over the
//! first 15% of the length so the roots stay on the scalp.
//!
//! ```ron
//! Procedural((style: Curly(amplitude: 0.04, frequency: 6.0), strands: 3000, points_per_strand: 48))
//! ```

use crate::error::{Error, Result};
use crate::geometry::HairGeometry;
use serde::{Deserialize, Serialize};
use std::f32::consts::PI;
use tress_core::limits::Limits;
use tress_core::math::{Frame, Vec2, Vec3};
use tress_core::rng::{mix64, Pcg32};
use tress_core::sampling::sample_uniform_sphere;

/// The shape of generated hair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum HairStyle {
    /// Smooth strands hanging from the scalp.
    Straight,
    /// Scalp strands with a sideways sinusoidal wave: `amplitude` in world units, `frequency`
    /// in waves per unit of height (the wave advances with height so neighbours wave together).
    Wavy {
        /// Wave amplitude, in world units (≥ 0).
        amplitude: f32,
        /// Waves per unit of height (≥ 0).
        frequency: f32,
    },
    /// Scalp strands with a helical curl: `amplitude` is the curl radius, `frequency` the turns
    /// per unit length (use several points per turn).
    Curly {
        /// Curl radius, in world units (≥ 0).
        amplitude: f32,
        /// Turns per unit of strand length (≥ 0).
        frequency: f32,
    },
    /// A ball of fibers: each strand is a circular arc on a random great circle of a random
    /// shell inside the sphere, shells spread so the fiber density is uniform in volume.
    Ball,
}

/// Parameters of generated hair (every field has a default).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ProceduralHair {
    /// Straight, wavy, curly or a ball (default straight).
    pub style: HairStyle,
    /// Seed of the random layout; strand `i` depends only on the seed and `i` (default 0).
    pub seed: u64,
    /// Number of strands, at least 1 (default 4000).
    pub strands: u32,
    /// Points per strand, at least 2 (default 24).
    pub points_per_strand: u32,
    /// Fiber radius.
    pub radius: f32,
    /// Mean strand length (scalp strands vary by ±15%).
    pub length: f32,
    /// Centre of the scalp sphere or of the ball.
    #[schemars(with = "[f32; 3]")]
    pub center: Vec3,
    /// Radius of the scalp sphere or of the ball.
    pub sphere_radius: f32,
}

impl Default for ProceduralHair {
    fn default() -> Self {
        ProceduralHair {
            style: HairStyle::Straight,
            seed: 0,
            strands: 4000,
            points_per_strand: 24,
            radius: 0.004,
            length: 1.6,
            center: Vec3::ZERO,
            sphere_radius: 1.0,
        }
    }
}

impl ProceduralHair {
    fn name(&self) -> String {
        format!(
            "procedural {} hair (seed {})",
            match self.style {
                HairStyle::Straight => "straight",
                HairStyle::Wavy { .. } => "wavy",
                HairStyle::Curly { .. } => "curly",
                HairStyle::Ball => "ball",
            },
            self.seed
        )
    }

    fn validate(&self, limits: &Limits) -> Result<()> {
        let bad = |field: &'static str, reason: String| {
            Error::InvalidOption(crate::InvalidOption {
                object: self.name(),
                field,
                reason,
            })
        };
        let positive = |field: &'static str, v: f32| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(bad(field, format!("must be finite and positive, got {v}")))
            }
        };
        if self.strands == 0 {
            return Err(bad("strands", "must be at least 1".into()));
        }
        if self.points_per_strand < 2 {
            return Err(bad(
                "points_per_strand",
                format!("must be at least 2, got {}", self.points_per_strand),
            ));
        }
        // Keeps the point count inside u32 (strand offsets) and memory sane.
        if self.strands as u64 * self.points_per_strand as u64 > 1 << 30 {
            return Err(bad(
                "strands",
                "strands × points_per_strand exceeds 2^30 points".into(),
            ));
        }
        crate::geometry::check_point_memory(
            &self.name(),
            "strands",
            "strands × points_per_strand",
            self.strands as f64 * self.points_per_strand as f64,
            limits,
        )?;
        positive("radius", self.radius)?;
        positive("length", self.length)?;
        positive("sphere_radius", self.sphere_radius)?;
        if !self.center.is_finite() {
            return Err(bad(
                "center",
                format!("must be finite, got {:?}", self.center),
            ));
        }
        if let HairStyle::Wavy {
            amplitude,
            frequency,
        }
        | HairStyle::Curly {
            amplitude,
            frequency,
        } = self.style
        {
            for (field, v) in [("amplitude", amplitude), ("frequency", frequency)] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(bad(field, format!("must be finite and ≥ 0, got {v}")));
                }
            }
        }
        Ok(())
    }

    /// Generates the hair, refusing more points than the memory limit of `limits` allows.
    pub fn generate(&self, limits: &Limits) -> Result<HairGeometry> {
        self.validate(limits)?;
        let m = self.points_per_strand as usize;
        let n = self.strands as usize;
        let mut points = Vec::with_capacity(n * m);
        let key = mix64(self.seed);
        for i in 0..n {
            let mut rng = Pcg32::new(key, i as u64);
            match self.style {
                HairStyle::Ball => self.ball_strand(&mut rng, &mut points),
                _ => self.scalp_strand(&mut rng, &mut points),
            }
        }
        let hair = HairGeometry {
            name: self.name(),
            radii: vec![self.radius; points.len()],
            points,
            strand_offsets: (0..=n).map(|i| (i * m) as u32).collect(),
            colors: None,
            transparency: None,
            orientations: None,
        };
        hair.validate()?;
        Ok(hair)
    }

    fn ball_strand(&self, rng: &mut Pcg32, out: &mut Vec<Vec3>) {
        let r = self.sphere_radius;
        // Shells no smaller than length/π, so no arc exceeds half a great circle.
        let r_min = (self.length / PI).min(r);
        let (lo, hi) = (r_min.powi(3), r.powi(3));
        let rho = (lo + rng.next_f32() * (hi - lo)).cbrt();
        let axis = sample_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32()));
        let f = Frame::from_z(axis);
        let phi0 = 2.0 * PI * rng.next_f32();
        let sweep = self.length / rho;
        let m = self.points_per_strand as usize;
        for k in 0..m {
            let phi = phi0 + sweep * k as f32 / (m - 1) as f32;
            out.push(self.center + rho * (phi.cos() * f.x + phi.sin() * f.y));
        }
    }

    fn scalp_strand(&self, rng: &mut Pcg32, out: &mut Vec<Vec3>) {
        let (c, r) = (self.center, self.sphere_radius);
        let m = self.points_per_strand as usize;
        // Root on the cap.
        let cap = Frame::from_z(Vec3::new(0.0, 1.0, -0.5).normalize());
        let cos_max = 75f32.to_radians().cos();
        let cos_t = 1.0 - rng.next_f32() * (1.0 - cos_max);
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let phi = 2.0 * PI * rng.next_f32();
        let n = cap.to_world(Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t));
        // Each strand rests on its own layer so the hair has volume.
        let layer = r * (1.003 + 0.06 * rng.next_f32());
        let len = self.length * (0.85 + 0.3 * rng.next_f32());
        let ds = len / (m - 1) as f32;
        // Comb toward the back and down, tangent to the scalp.
        let flow = Vec3::new(0.0, -0.5, -1.0).normalize();
        let comb = (flow - n * flow.dot(n))
            .try_normalize()
            .unwrap_or(Frame::from_z(n).x);
        let jitter = sample_uniform_sphere(Vec2::new(rng.next_f32(), rng.next_f32())) * 0.1;
        let mut d = (0.15 * n + comb + jitter).normalize();
        let gravity = Vec3::new(0.0, -5.0 / self.length, 0.0);

        let start = out.len();
        let mut p = c + r * n;
        out.push(p);
        for _ in 1..m {
            d = (d + gravity * ds).normalize();
            let mut next = p + d * ds;
            let q = next - c;
            // Inside the layer, or above the scalp's equator (where gravity presses the hair
            // onto the head): lie on the layer.
            if q.length() < layer || q.y > 0.0 {
                next = c + q.normalize() * layer;
                d = (next - p).try_normalize().unwrap_or(d);
            }
            out.push(next);
            p = next;
        }

        let (amp, freq, helix) = match self.style {
            HairStyle::Wavy {
                amplitude,
                frequency,
            } => (amplitude, frequency, false),
            HairStyle::Curly {
                amplitude,
                frequency,
            } => (amplitude, frequency, true),
            HairStyle::Straight | HairStyle::Ball => return,
        };
        let amp = amp * (0.8 + 0.4 * rng.next_f32());
        // Neighbouring wavy strands wave together (else the hair looks woven); curls do not.
        let (freq, phase) = if helix {
            (
                freq * (0.9 + 0.2 * rng.next_f32()),
                2.0 * PI * rng.next_f32(),
            )
        } else {
            (freq * (0.95 + 0.1 * rng.next_f32()), 0.5 * rng.next_f32())
        };
        // Offsets in a frame parallel-transported along the base path.
        let base: Vec<Vec3> = out[start..].to_vec();
        let mut e1 = (base[1] - base[0])
            .cross(n)
            .try_normalize()
            .unwrap_or(cap.x);
        let mut s = 0.0;
        for k in 1..m {
            s += base[k].distance(base[k - 1]);
            let t = (base[(k + 1).min(m - 1)] - base[k - 1]).normalize_or_zero();
            e1 = (e1 - t * e1.dot(t)).try_normalize().unwrap_or(e1);
            let e2 = t.cross(e1);
            let x = s / (0.15 * len);
            let ramp = if x >= 1.0 {
                1.0
            } else {
                x * x * (3.0 - 2.0 * x)
            };
            // Waves advance with height so that neighbouring strands, rooted at different
            // heights, still wave together; curls advance along the strand.
            let along = if helix { s } else { c.y + r - base[k].y };
            let angle = 2.0 * PI * freq * along + phase;
            let offset = if helix {
                angle.cos() * e1 + angle.sin() * e2
            } else {
                angle.sin() * e1
            };
            let mut q = base[k] + ramp * amp * offset - c;
            if q.length() < r * 1.003 {
                q = q.normalize() * r * 1.003;
            }
            out[start + k] = c + q;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn styles() -> [HairStyle; 4] {
        [
            HairStyle::Straight,
            HairStyle::Wavy {
                amplitude: 0.05,
                frequency: 3.0,
            },
            HairStyle::Curly {
                amplitude: 0.04,
                frequency: 5.0,
            },
            HairStyle::Ball,
        ]
    }

    #[test]
    fn deterministic_for_a_seed() {
        for style in styles() {
            let p = ProceduralHair {
                style: style.clone(),
                seed: 11,
                strands: 300,
                points_per_strand: 20,
                ..Default::default()
            };
            let a = p.generate(&Limits::default()).unwrap();
            assert_eq!(a, p.generate(&Limits::default()).unwrap(), "{style:?}");
            assert_eq!(a.strand_count(), 300);
            assert_eq!(a.point_count(), 6000);
            let other = ProceduralHair {
                seed: 12,
                ..p.clone()
            }
            .generate(&Limits::default())
            .unwrap();
            assert_ne!(a.points, other.points);
            // Strand i depends only on (seed, i).
            let fewer = ProceduralHair { strands: 100, ..p }
                .generate(&Limits::default())
                .unwrap();
            assert_eq!(fewer.points[..], a.points[..2000]);
        }
    }

    #[test]
    fn scalp_hair_stays_on_and_outside_the_scalp() {
        let center = Vec3::new(1.0, 2.0, 3.0);
        for style in &styles()[..3] {
            let p = ProceduralHair {
                style: style.clone(),
                strands: 500,
                center,
                sphere_radius: 2.0,
                length: 3.0,
                ..Default::default()
            };
            let g = p.generate(&Limits::default()).unwrap();
            for i in 0..g.strand_count() {
                let pts = &g.points[g.strand(i)];
                assert!(
                    (pts[0].distance(center) - 2.0).abs() < 1e-4,
                    "root on the scalp"
                );
                assert!(pts.iter().all(|q| q.distance(center) > 2.0 - 1e-4));
                // Roots on the upper cap, never on the face (front, below the eyes).
                let n = (pts[0] - center) / 2.0;
                assert!(n.y > -0.25 && !(n.z > 0.6 && n.y < 0.5), "root at {n}");
                let len: f32 = pts.windows(2).map(|w| w[0].distance(w[1])).sum();
                assert!(
                    len > 0.5 * 3.0 && len < 2.5 * 3.0,
                    "{style:?}: length {len}"
                );
            }
            // The hair hangs: tips are on average well below the roots.
            let drop: f32 = (0..g.strand_count())
                .map(|i| g.points[g.strand(i).start].y - g.points[g.strand(i).end - 1].y)
                .sum::<f32>()
                / g.strand_count() as f32;
            assert!(drop > 1.0, "{style:?}: mean drop {drop}");
        }
    }

    #[test]
    fn ball_fills_the_sphere() {
        let p = ProceduralHair {
            style: HairStyle::Ball,
            strands: 2000,
            length: 1.0,
            ..Default::default()
        };
        let g = p.generate(&Limits::default()).unwrap();
        assert!(g.points.iter().all(|q| q.length() <= 1.0 + 1e-5));
        // Uniform volume density over shells from 1/π (the smallest allowed for length 1) to 1.
        let outer = g.points.iter().filter(|q| q.length() > 0.5).count() as f32;
        let frac = outer / g.point_count() as f32;
        let want = (1.0 - 0.125) / (1.0 - (1.0 / PI).powi(3));
        assert!((frac - want).abs() < 0.03, "{frac} vs {want}");
    }

    #[test]
    fn bad_parameters_are_errors_naming_the_field() {
        let cases = [
            ProceduralHair {
                strands: 0,
                ..Default::default()
            },
            ProceduralHair {
                points_per_strand: 1,
                ..Default::default()
            },
            ProceduralHair {
                radius: -1.0,
                ..Default::default()
            },
            ProceduralHair {
                length: f32::NAN,
                ..Default::default()
            },
            ProceduralHair {
                style: HairStyle::Wavy {
                    amplitude: -1.0,
                    frequency: 1.0,
                },
                ..Default::default()
            },
        ];
        for (p, field) in cases.iter().zip([
            "strands",
            "points_per_strand",
            "radius",
            "length",
            "amplitude",
        ]) {
            let e = p.generate(&Limits::default()).unwrap_err().to_string();
            assert!(e.contains(field) && e.contains("procedural"), "{e}");
        }
    }
}
