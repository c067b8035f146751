//! Multiple scattering measured in a statistically homogeneous medium of parallel fibers, by
//! random walks that sample the BCSDF itself: the transport quantities dual scattering needs,
//! without the one-dimensional approximations of Zinke et al.'s closed forms.
//!
//! # Why
//! Zinke et al. model the hair around a shading point as a stack of fibers in which light either
//! continues forward (fraction ā_f) or reverses (ā_b), so light crossing n fibers arrives with
//! `ā_f^n` and back-scattering sums a few reversals (Ā_b). In a real fiber volume "forward"
//! light leaves a fiber anywhere on its forward half-cone, so after a few crossings it travels
//! sideways and back as well: transport is diffusive. Measured on blond Chiang fibers
//! (eumelanin 0.15) at normal incidence, the walk below transmits, through 16 fibers, 0.061 /
//! 0.038 / 0.018 (R/G/B) of the light where `ā_f^16` gives 0.025 / 0.0056 / 0.0001, and
//! reflects 0.20 / 0.13 / 0.058 after two or more scatterings where Ā_b gives 0.15 / 0.084 /
//! 0.029. Light hair under back or side lighting — where most of what reaches the camera has
//! crossed many fibers — is therefore far too dark and too grey with the closed forms.
//!
//! # The medium
//! Fibers run along the local x axis (the fiber frame of the tables), placed at random across it
//! (a Poisson process), with a density such that a line crosses on average `cos θ` fibers per
//! unit length, θ its inclination to the fibers (`sin θ = d.x`). Lengths are therefore measured
//! in expected crossings of a line perpendicular to the fibers. The medium fills `z < 0`; light
//! from the table direction `w = (sin θ, 0, cos θ)` enters it head-on in azimuth, so a straight
//! line from the surface to depth D crosses on average D fibers — the grid's n along a shadow
//! ray. At each crossing the light leaves the fiber as `Bcsdf::sample` directs it (h uniform,
//! the direction it came from in the `wo` slot as for the tables), weighted by `f/pdf`, times
//! `1/max(1, ā_f + ā_b)` so that a model that is not energy conserving (Marschner) cannot feed
//! an ever-growing walk.
//!
//! # What is tabulated, per light inclination θ
//! * **Back-scattering** (replaces Ā_b, Δ_b, σ_b²): light that meets a fiber x at the surface
//!   and leaves the medium after at least one more scattering below x — the energy Zinke's local
//!   term f_back returns around x. Stored as its energy and the mean and variance of
//!   `θ_h = (θ + θ_out)/2` (the tables' units), for the half-space and, as energy, for layers
//!   D deep (the light that never went below D): the shading point has only so much hair behind
//!   it, and a half-space behind every point of a thin layer would return light twice over.
//! * **Scattered transmittance** T_s(D): the scattered light that reaches depth D for the first
//!   time — what a layer D deep lets through after at least one scattering; the unscattered
//!   part `e^{−D}` is the shadow ray's business. (Counting every downward crossing instead, the
//!   half-space's light that came back up from below D, doubled a white furnace.)
//!
//! Both are tabulated for D on a geometric ladder ([`DEPTHS`]), interpolated geometrically in D,
//! growing linearly from nothing above the first node; beyond the last, transmittance keeps the
//! decay of the last step and back-scattering its value.
//!
//! # What it leaves out
//! The hair around a shading point is a homogeneous layer whose fibers are parallel and face
//! the light head-on: real grooms are neither. And each point is treated as the top of its
//! layer: light that the hair below returns and the fibers above reflect back down is missing,
//! so a white furnace returns 0.95 at a fiber on the surface of a half-space but 0.83 for the
//! fibers a camera sees a fiber or two deep (a slab), 0.62–0.92 on a ball of fibers over
//! β = 0.001…0.9 (path: 1). Against the path tracer (converged, mean over hair pixels,
//! docs/src/research/dual-scattering-accuracy.md#where-it-stands-now) light hair is up to 19 % dark in red (platinum
//! straight.hair; the blond head within 3 %); brown and dark hair within 3.4 %.
//!
//! Every θ node walks its own seeded stream, so the tables do not depend on the thread count.

use std::f32::consts::PI;
use tress_core::math::{Rgb, Vec3};
use tress_core::rng::{hash_words, Sampler};
use tress_core::{Bcsdf, FiberFrame};

/// Depths (expected fibers crossed along the light's line) at which T_s is tabulated.
pub const DEPTHS: [f32; 11] = [
    0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0,
];
/// Walks end below this depth: nothing from there reaches a tabulated depth or the surface in
/// measurable amounts.
const FLOOR: f32 = 320.0;
/// Scattering events after which a walk ends (white fibers wander for long).
const MAX_EVENTS: u32 = 4096;
/// Russian roulette below this throughput (the largest channel).
const ROULETTE_BELOW: f32 = 0.1;

/// Light returned toward the surface around a fiber, per RGB channel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BackScattering {
    /// Energy per unit of energy meeting the surface fiber.
    pub energy: Rgb,
    /// Mean of θ_h (rad).
    pub mean: Rgb,
    /// Variance of θ_h (rad²).
    pub variance: Rgb,
}

impl BackScattering {
    fn lerp(&self, o: &Self, t: f32) -> Self {
        BackScattering {
            energy: self.energy.lerp(o.energy, t),
            mean: self.mean.lerp(o.mean, t),
            variance: self.variance.lerp(o.variance, t),
        }
    }
}

/// The random-walk tables of one BCSDF at the dual-scattering tables' θ nodes.
#[derive(Clone, Debug)]
pub struct FiberMedium {
    back: Vec<BackScattering>,
    /// Back-scattered energy of layers `DEPTHS` deep: `θ nodes × DEPTHS`, node-major.
    reflect: Vec<Rgb>,
    /// `θ nodes × DEPTHS`, node-major.
    transmit: Vec<Rgb>,
}

impl FiberMedium {
    /// Walks `walks` light paths per θ node for each quantity. `albedo[k]` is the fiber's
    /// albedo ā_f + ā_b at node k, as the quadrature tables measure it (for the energy
    /// normalisation); `theta_of(k)` is node k's inclination.
    pub fn build(
        bcsdf: &dyn Bcsdf,
        albedo: &[Rgb],
        theta_of: impl Fn(usize) -> f32 + Sync,
        walks: u32,
    ) -> Self {
        let n = albedo.len();
        let normalisation = |theta: f32| {
            // Nearest node: the scale only guards models that exceed 1, where it varies slowly.
            let k = (((theta + 0.5 * PI) / PI * n as f32) as usize).min(n - 1);
            Rgb::ONE / albedo[k].max(Rgb::ONE)
        };
        type Node = ((BackScattering, [Rgb; DEPTHS.len()]), [Rgb; DEPTHS.len()]);
        let per_node: Vec<Node> = crate::parallel_map(n, |k| {
            let walker = Walker {
                bcsdf,
                normalisation: &normalisation,
                theta: theta_of(k),
            };
            (
                walker.back_scattering(walks, hash_words(&[k as u64, 1])),
                walker.transmittance(walks, hash_words(&[k as u64, 2])),
            )
        });
        FiberMedium {
            back: per_node.iter().map(|((b, _), _)| *b).collect(),
            reflect: per_node.iter().flat_map(|((_, r), _)| *r).collect(),
            transmit: per_node.iter().flat_map(|(_, t)| *t).collect(),
        }
    }

    /// Back-scattering for light meeting the fiber at node `i` + fraction `t` (see
    /// `DualScatteringTables::locate`).
    /// with `behind` fibers (expected) behind the fiber, away from the light.
    pub(crate) fn back_scattering(&self, i: usize, t: f32, behind: f32) -> BackScattering {
        let mut b = self.back[i].lerp(&self.back[i + 1], t);
        if behind < DEPTHS[DEPTHS.len() - 1] {
            let at = |k: usize| {
                self.reflect[i * DEPTHS.len() + k].lerp(self.reflect[(i + 1) * DEPTHS.len() + k], t)
            };
            b.energy = layer_value(behind, at, Beyond::Saturates);
        }
        b
    }

    /// The depth past which [`Self::scattered_transmittance`] stays at or below `negligible`
    /// in every channel at every inclination (infinite if it never does, or if the
    /// extrapolation past the deepest node could climb back above it).
    pub(crate) fn transmittance_negligible_past(&self, negligible: f32) -> f32 {
        let last = DEPTHS.len() - 1;
        self.transmit
            .chunks_exact(DEPTHS.len())
            .map(|row| {
                let (deepest, before) = (row[last].max_element(), row[last - 1].max_element());
                if deepest > negligible || (deepest > 0.0 && deepest > before) {
                    return f32::INFINITY;
                }
                // Between two nodes at or below `negligible` the interpolation stays there.
                let first_small = row
                    .iter()
                    .rposition(|t| t.max_element() > negligible)
                    .map_or(0, |k| k + 1);
                DEPTHS[first_small]
            })
            .fold(0.0, f32::max)
    }

    /// The depth past which [`Self::back_scattering`]'s energy is within `tolerance` of the
    /// half-space's (relative, every channel, every inclination); at most the deepest node,
    /// past which it is the half-space's.
    pub(crate) fn back_scattering_settled_past(&self, tolerance: f32) -> f32 {
        self.reflect
            .chunks_exact(DEPTHS.len())
            .zip(&self.back)
            .map(|(row, half_space)| {
                let settled = |r: &Rgb| {
                    (*r - half_space.energy)
                        .abs()
                        .cmple(half_space.energy * tolerance)
                        .all()
                };
                // Between two settled nodes the interpolation stays between them.
                let first_settled = row
                    .iter()
                    .rposition(|r| !settled(r))
                    .map_or(0, |k| k + 1)
                    .min(DEPTHS.len() - 1);
                DEPTHS[first_settled]
            })
            .fold(0.0, f32::max)
    }

    /// T_s after crossing `depth` fibers (expected), at node `i` + fraction `t`.
    pub(crate) fn scattered_transmittance(&self, i: usize, t: f32, depth: f32) -> Rgb {
        let at = |k: usize| {
            self.transmit[i * DEPTHS.len() + k].lerp(self.transmit[(i + 1) * DEPTHS.len() + k], t)
        };
        layer_value(depth, at, Beyond::Decays)
    }
}

/// How a tabulated quantity continues past the deepest node.
#[derive(Clone, Copy)]
enum Beyond {
    /// Transmittance: keeps the decay of the last step (diffusion decays exponentially).
    Decays,
    /// Back-scattering: a deeper layer returns no less, and nothing measurable more.
    Saturates,
}

/// The value of a layer `depth` fibers deep from the tabulated values `at(k)` at `DEPTHS[k]`.
fn layer_value(depth: f32, at: impl Fn(usize) -> Rgb, beyond: Beyond) -> Rgb {
    if depth.is_nan() || depth <= 0.0 {
        return Rgb::ZERO;
    }
    let last = DEPTHS.len() - 1;
    // Both grow linearly from nothing in a layer of no depth.
    if depth <= DEPTHS[0] {
        return at(0) * (depth / DEPTHS[0]);
    }
    let (k, x) = match DEPTHS.iter().position(|&d| d >= depth) {
        Some(k) => (k - 1, (depth / DEPTHS[k - 1]).log2()),
        None => match beyond {
            Beyond::Decays => (
                last - 1,
                1.0 + (depth - DEPTHS[last]) / (DEPTHS[last] - DEPTHS[last - 1]),
            ),
            Beyond::Saturates => return at(last),
        },
    };
    let (a, b) = (at(k), at(k + 1));
    // Geometric in depth between nodes (DEPTHS doubles), exponential beyond; linear where a
    // node saw no light.
    Rgb::from_array(std::array::from_fn(|c| {
        if a[c] > 0.0 && b[c] > 0.0 {
            a[c] * (b[c] / a[c]).powf(x)
        } else {
            (a[c] + (b[c] - a[c]) * x.min(1.0)).max(0.0)
        }
    }))
}

struct Walker<'a, N: Fn(f32) -> Rgb> {
    bcsdf: &'a dyn Bcsdf,
    normalisation: &'a N,
    theta: f32,
}

impl<N: Fn(f32) -> Rgb> Walker<'_, N> {
    /// Direction the light travels when it enters.
    fn entering(&self) -> Vec3 {
        -Vec3::new(self.theta.sin(), 0.0, self.theta.cos())
    }

    /// Scatters light travelling along `d` at a fiber: the new direction and its weight.
    fn scatter(&self, d: Vec3, rng: &mut Sampler) -> Option<(Vec3, Rgb)> {
        let wo = -d;
        let frame = FiberFrame::new(Vec3::X, wo);
        let h = 2.0 * rng.next_1d() - 1.0;
        let s = self.bcsdf.sample(frame.to_local(wo), h, rng.next_4d())?;
        if s.pdf.is_nan() || s.pdf <= 0.0 {
            return None;
        }
        let weight = s.f / s.pdf * (self.normalisation)(wo.x.clamp(-1.0, 1.0).asin());
        weight.is_finite().then(|| (frame.to_world(s.wi), weight))
    }

    /// Distance to the next fiber along `d` (infinite along the fibers).
    fn flight(d: Vec3, rng: &mut Sampler) -> f32 {
        let rate = (d.y * d.y + d.z * d.z).sqrt();
        -(1.0 - rng.next_1d()).ln() / rate
    }

    /// Russian roulette; false ends the walk.
    fn survives(throughput: &mut Rgb, rng: &mut Sampler) -> bool {
        let m = throughput.max_element();
        if m >= ROULETTE_BELOW {
            return true;
        }
        if m <= 0.0 || rng.next_1d() * ROULETTE_BELOW >= m {
            return false;
        }
        *throughput *= ROULETTE_BELOW / m;
        true
    }

    /// The back-scattering of half-spaces (`.0`) and of layers [`DEPTHS`] deep (`.1`).
    fn back_scattering(&self, walks: u32, seed: u64) -> (BackScattering, [Rgb; DEPTHS.len()]) {
        let mut rng = Sampler::from_seed(seed);
        let (mut energy, mut m1, mut m2) = (Rgb::ZERO, Rgb::ZERO, Rgb::ZERO);
        let mut layers = [Rgb::ZERO; DEPTHS.len()];
        for _ in 0..walks {
            let (mut d, mut depth, mut throughput) = (self.entering(), 0.0f32, Rgb::ONE);
            let mut deepest = 0.0f32;
            for event in 1..=MAX_EVENTS {
                let Some((next, w)) = self.scatter(d, &mut rng) else {
                    break;
                };
                d = next;
                throughput *= w;
                depth += d.z * Self::flight(d, &mut rng);
                if depth > 0.0 {
                    // The first event's own exits are single scattering (f_s), not this term.
                    if event > 1 {
                        let theta_h = 0.5 * (self.theta + d.x.clamp(-1.0, 1.0).asin());
                        energy += throughput;
                        m1 += throughput * theta_h;
                        m2 += throughput * (theta_h * theta_h);
                        // A layer returns the light that never went below it.
                        for (k, &dk) in DEPTHS.iter().enumerate() {
                            if -deepest < dk {
                                layers[k] += throughput;
                            }
                        }
                    }
                    break;
                }
                deepest = deepest.min(depth);
                if depth.is_nan() || depth < -FLOOR || !Self::survives(&mut throughput, &mut rng) {
                    break;
                }
            }
        }
        let safe = energy.max(Rgb::splat(1e-30));
        let mean = m1 / safe;
        let back = BackScattering {
            energy: energy / walks as f32,
            mean,
            variance: (m2 / safe - mean * mean).max(Rgb::ZERO),
        };
        (back, layers.map(|r| r / walks as f32))
    }

    fn transmittance(&self, walks: u32, seed: u64) -> [Rgb; DEPTHS.len()] {
        let mut rng = Sampler::from_seed(seed);
        let mut flux = [Rgb::ZERO; DEPTHS.len()];
        for _ in 0..walks {
            let mut d = self.entering();
            let mut depth = d.z * Self::flight(d, &mut rng);
            // Depths already passed, unscattered or not, are not passed for the first time again.
            let mut deepest = depth;
            let mut throughput = Rgb::ONE;
            for _ in 0..MAX_EVENTS {
                if depth > 0.0 || depth.is_nan() || depth < -FLOOR {
                    break;
                }
                let Some((next, w)) = self.scatter(d, &mut rng) else {
                    break;
                };
                d = next;
                throughput *= w;
                if !Self::survives(&mut throughput, &mut rng) {
                    break;
                }
                depth += d.z * Self::flight(d, &mut rng);
                // Scattered light reaching the tabulated depths for the first time: what a slab
                // that deep lets through (light that came back up from below it is not its own).
                if depth < deepest {
                    for (k, &dk) in DEPTHS.iter().enumerate() {
                        if depth < -dk && -dk < deepest {
                            flux[k] += throughput;
                        }
                    }
                    deepest = depth;
                }
            }
        }
        flux.map(|f| f / walks as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_is_geometric_between_nodes_and_continues_the_last_decay() {
        let at = |k: usize| Rgb::splat(0.5f32.powi(k as i32));
        assert_eq!(layer_value(0.0, at, Beyond::Decays), Rgb::ZERO);
        assert!((layer_value(DEPTHS[0] / 2.0, at, Beyond::Decays).x - 0.5).abs() < 1e-6);
        for (k, &d) in DEPTHS.iter().enumerate() {
            assert!(
                (layer_value(d, at, Beyond::Decays).x - at(k).x).abs() < 1e-6,
                "node {k}"
            );
        }
        // Halfway (geometrically) between nodes 3 and 4: the geometric mean.
        let mid = (DEPTHS[3] * DEPTHS[4]).sqrt();
        assert!((layer_value(mid, at, Beyond::Decays).x - (at(3).x * at(4).x).sqrt()).abs() < 1e-6);
        // One ladder step past the end: one more halving.
        let past = 2.0 * DEPTHS[DEPTHS.len() - 1] - DEPTHS[DEPTHS.len() - 2];
        let expected = at(DEPTHS.len() - 1).x / 2.0;
        assert!(
            (layer_value(past, at, Beyond::Decays).x - expected).abs() < 1e-6 * expected.max(1e-6)
        );
        assert_eq!(
            layer_value(past, at, Beyond::Saturates),
            at(DEPTHS.len() - 1)
        );
    }
}
