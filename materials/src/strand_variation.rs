//! Per-strand variation of a hair object's material: its pigment from strand to strand and from
//! root to tip — random melanin (Cycles' *Random Color*), a root-to-tip gradient, darker roots
//! (PxrHairColor's *Darken Roots*), the colours a hair file stores — and its roughness from
//! strand to strand (Cycles' *Random Roughness*), quantised to a few variants of the object's
//! material.

use crate::pigment::Pigment;
use crate::{HairModel, ParamError};
use serde::{Deserialize, Serialize};
use tress_core::math::Rgb;
use tress_core::rng::hash_words;

/// Per-strand variation of a hair object's material (the `variation` of a `Hair` object):
/// random melanin, a root-to-tip gradient, darker roots, the colours stored in the hair file,
/// random roughness.
///
/// ```ron
/// (random: 0.3, seed: 7, gradient: Some(tip: Scale(0.4), start: 0.5))
/// (file_colors: true, variants: 32)
/// (gradient: Some(tip: Pigment(Melanin(eumelanin: 0.2, pheomelanin: 0.4)), start: 0.7))
/// (random_roughness: 0.3, darken_roots: Some(amount: 1.0, length: 0.2))
/// ```
///
/// Each curve segment gets the absorption σ_a = f·d·((1 − w)·σ_root + w·σ_tip), where σ_root is
/// the material's pigment (or the file's colour there, through Chiang's colour fit), σ_tip the
/// gradient's tip pigment, w = clamp((v − start) / (1 − start), 0, 1) at the middle of the
/// segment (v = 0 at the root, 1 at the tip; w = 0 without a gradient), f = 1 + random·(2ξ −
/// 1), ξ uniform in [0, 1) per strand from `seed` and the strand's index, and d = 1 +
/// amount·max(1 − v/length, 0) the darkening of the roots (1 without). σ_a is linear in the
/// melanin concentrations, so f and d multiply them (as Cycles' *Random Color* does) and the
/// gradient interpolates them. Each strand's roughness is scaled by g = 1 +
/// random_roughness·(2ζ − 1), ζ uniform in [0, 1) per strand, drawn independently of ξ. The
/// segments' (σ_a, g) pairs are then quantised to at most `variants` values, each a copy of the
/// material with that absorption and roughness: the distinct values themselves when there are
/// no more, else the means of groups found by variance-minimising splits in (√σ_a, ln g / 6)
/// (equal steps there are about equal ratios of colour, and of roughness), so the mean
/// absorption and roughness scale are kept.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct StrandVariation {
    /// Random melanin (Cycles' *Random Color*): each strand's absorption — its melanin
    /// concentrations, and a `tint`'s absorption with them — is multiplied by
    /// 1 + random·(2ξ − 1), ξ uniform in [0, 1) per strand; in [0, 1] (default 0: none).
    pub random: f32,
    /// Seed of the per-strand random numbers (default 0).
    pub seed: u64,
    /// Root-to-tip change of pigment (default none).
    pub gradient: Option<Gradient>,
    /// Darker roots (PxrHairColor's *Darken Roots*; default none).
    pub darken_roots: Option<DarkenRoots>,
    /// Random roughness (Cycles' *Random Roughness*): each strand's roughness — Chiang's β_m
    /// and β_n, d'Eon's longitudinal and azimuthal roughness, Marschner's β_R — is multiplied by
    /// 1 + random_roughness·(2ζ − 1), ζ uniform in [0, 1) per strand, then clamped to the
    /// model's range; in [0, 1) (default 0: none). The absorption does not change with it: a
    /// `Color` pigment is converted at the material's own β_n.
    pub random_roughness: f32,
    /// Take the root pigment from the colours the hair file stores per strand or per point
    /// (HAIR colour arrays, PLY vertex colours, TressFX vertex colours), each a `Color` target
    /// (channels in (0, 1]), instead of the material's pigment (default false).
    pub file_colors: bool,
    /// At most this many distinct pigments, each a copy of the material, in [1, 256] (default
    /// 16). Free for path tracing; the dual-scattering integrators build tables for each
    /// (about as long as for one material, each), so fewer set them up faster.
    pub variants: u32,
}

impl Default for StrandVariation {
    fn default() -> Self {
        StrandVariation {
            random: 0.0,
            seed: 0,
            gradient: None,
            darken_roots: None,
            random_roughness: 0.0,
            file_colors: false,
            variants: 16,
        }
    }
}

/// Darker roots: the absorption (the melanin concentrations) is multiplied by 1 + `amount` at
/// the root, falling linearly to 1 at `length` along the strand and staying 1 beyond.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DarkenRoots {
    /// How much darker the root is: its absorption is 1 + amount times the rest's; finite and
    /// in [0, 100].
    pub amount: f32,
    /// Where the darkening ends, as a fraction of the strand from the root, in (0, 1] (default
    /// 0.2).
    #[serde(default = "a_fifth")]
    pub length: f32,
}

fn a_fifth() -> f32 {
    0.2
}

/// A root-to-tip change of pigment: the root pigment up to `start`, then a linear change of
/// absorption (of melanin concentrations) to the `tip` pigment at the tip.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Gradient {
    /// The pigment at the tip.
    pub tip: TipPigment,
    /// Where the change begins, as a fraction of the strand from the root, in [0, 1) (default
    /// 0.5).
    #[serde(default = "half")]
    pub start: f32,
}

fn half() -> f32 {
    0.5
}

/// The pigment at the tips of a [`Gradient`].
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum TipPigment {
    /// The root's absorption (its melanin concentrations) times this factor, finite and ≥ 0:
    /// below 1 lighter tips (sun-bleached), above 1 darker ones.
    Scale(f32),
    /// This pigment, whatever the root's (dyed or ombré ends).
    Pigment(Pigment),
}

impl StrandVariation {
    /// The largest `variants`: every variant is a material of its own, for which the
    /// dual-scattering integrators build tables.
    pub const MAX_VARIANTS: u32 = 256;

    /// Checks the values and applies the variation to `model`'s pigment. Errors name the field
    /// (`variation.random`, …); a model without a pigment is an error too.
    pub fn for_model(&self, model: &HairModel) -> Result<PigmentVariation, ParamError> {
        let Some((pigment, beta_n)) = model.pigment() else {
            // The variant's name: its `Debug` text up to the parameters.
            let debug = format!("{model:?}");
            let name = debug.split('(').next().unwrap_or(&debug);
            return Err(ParamError::new(
                "variation",
                "Some(…)",
                format!(
                    "{name} has no pigment to vary: use one of {}",
                    HairModel::names_with_pigment().join(", ")
                ),
            ));
        };
        crate::check_range("variation.random", self.random, 0.0, 1.0)?;
        if !(self.random_roughness.is_finite() && (0.0..1.0).contains(&self.random_roughness)) {
            return Err(ParamError::new(
                "variation.random_roughness",
                self.random_roughness,
                "must lie in [0, 1)",
            ));
        }
        if let Some(d) = &self.darken_roots {
            crate::check_range("variation.darken_roots.amount", d.amount, 0.0, 100.0)?;
            if !(d.length.is_finite() && d.length > 0.0 && d.length <= 1.0) {
                return Err(ParamError::new(
                    "variation.darken_roots.length",
                    d.length,
                    "must lie in (0, 1]",
                ));
            }
        }
        if !(1..=Self::MAX_VARIANTS).contains(&self.variants) {
            return Err(ParamError::new(
                "variation.variants",
                self.variants,
                format!("must lie in [1, {}]", Self::MAX_VARIANTS),
            ));
        }
        let tip = match &self.gradient {
            None => None,
            Some(g) => {
                if !(g.start.is_finite() && (0.0..1.0).contains(&g.start)) {
                    return Err(ParamError::new(
                        "variation.gradient.start",
                        g.start,
                        "must lie in [0, 1)",
                    ));
                }
                let tip = match &g.tip {
                    TipPigment::Scale(s) => {
                        if !(s.is_finite() && *s >= 0.0) {
                            return Err(ParamError::new(
                                "variation.gradient.tip",
                                s,
                                "a scale must be finite and non-negative",
                            ));
                        }
                        TipAbsorption::Scale(*s)
                    }
                    TipPigment::Pigment(p) => {
                        TipAbsorption::Fixed(p.sigma_a(beta_n).map_err(|e| {
                            ParamError::new(
                                "variation.gradient.tip",
                                format!("{p:?}"),
                                e.to_string(),
                            )
                        })?)
                    }
                };
                Some((tip, g.start))
            }
        };
        Ok(PigmentVariation {
            random: self.random,
            seed: self.seed,
            root: pigment.sigma_a(beta_n)?,
            beta_n,
            tip,
            darken_roots: self.darken_roots.as_ref().map(|d| (d.amount, d.length)),
            random_roughness: self.random_roughness,
            file_colors: self.file_colors,
            variants: self.variants,
        })
    }
}

/// The tip's absorption of a [`Gradient`], resolved.
#[derive(Clone, Copy, Debug, PartialEq)]
enum TipAbsorption {
    Scale(f32),
    Fixed(Rgb),
}

/// A [`StrandVariation`] applied to a model's pigment ([`StrandVariation::for_model`]):
/// computes the absorption of every segment.
#[derive(Clone, Debug, PartialEq)]
pub struct PigmentVariation {
    random: f32,
    seed: u64,
    /// σ_a of the model's own pigment.
    root: Rgb,
    /// The β_n of the model's colour fit.
    beta_n: f32,
    /// The tip's absorption and where the gradient starts.
    tip: Option<(TipAbsorption, f32)>,
    /// The roots' darkening: amount and length.
    darken_roots: Option<(f32, f32)>,
    random_roughness: f32,
    file_colors: bool,
    variants: u32,
}

impl PigmentVariation {
    /// Whether the root pigment comes from the file's colours.
    pub fn uses_file_colors(&self) -> bool {
        self.file_colors
    }

    /// The most variants the object may use.
    pub fn variants(&self) -> u32 {
        self.variants
    }

    /// Strand `strand`'s melanin factor 1 + random·(2ξ − 1), in [1 − random, 1 + random]: ξ
    /// comes from a hash of the seed and the strand's index (24 bits, as `Pcg32::next_f32`).
    pub fn strand_factor(&self, strand: u32) -> f32 {
        let xi =
            (hash_words(&[self.seed, strand as u64]) >> 40) as f32 * (1.0 / (1u32 << 24) as f32);
        1.0 + self.random * (2.0 * xi - 1.0)
    }

    /// Strand `strand`'s roughness factor 1 + random_roughness·(2ζ − 1), in [1 −
    /// random_roughness, 1 + random_roughness]: ζ comes from a hash of the seed, the strand's
    /// index and a third word, so it is independent of the melanin factor's ξ.
    pub fn roughness_scale(&self, strand: u32) -> f32 {
        let zeta =
            (hash_words(&[self.seed, strand as u64, 1]) >> 40) as f32 * (1.0 / (1u32 << 24) as f32);
        1.0 + self.random_roughness * (2.0 * zeta - 1.0)
    }

    /// The roots' darkening factor at `v`: 1 + amount at the root, 1 from `length` on.
    fn root_darkening(&self, v: f32) -> f32 {
        self.darken_roots.map_or(1.0, |(amount, length)| {
            1.0 + amount * (1.0 - v / length).max(0.0)
        })
    }

    /// The gradient's weight of the tip pigment at `v` (0 at the root … 1 at the tip).
    fn tip_weight(&self, v: f32) -> f32 {
        self.tip.map_or(0.0, |(_, start)| {
            ((v - start) / (1.0 - start)).clamp(0.0, 1.0)
        })
    }

    /// σ_a (per unit radius) of strand `strand` at `v` along it (0 root, 1 tip), `file_color`
    /// being the file's colour there (needed with `file_colors`, ignored without).
    pub fn sigma_a(&self, strand: u32, v: f32, file_color: Option<Rgb>) -> Result<Rgb, ParamError> {
        let root = if self.file_colors {
            let c = file_color.ok_or_else(|| {
                ParamError::new(
                    "variation.file_colors",
                    true,
                    "the hair file stores no colours",
                )
            })?;
            Pigment::Color((c.x, c.y, c.z)).sigma_a(self.beta_n)?
        } else {
            self.root
        };
        let w = self.tip_weight(v);
        // Forms exact at w = 0 and, for a scale of 1, everywhere: roots, and strands that do
        // not change, keep the root's absorption to the bit (one variant, not several that
        // differ by rounding).
        let mixed = match self.tip {
            None => root,
            Some((TipAbsorption::Scale(s), _)) => root * (1.0 + (s - 1.0) * w),
            Some((TipAbsorption::Fixed(tip), _)) => root + (tip - root) * w,
        };
        Ok(self.strand_factor(strand) * self.root_darkening(v) * mixed)
    }

    /// What segment `strand`, at `v` along it, is made of: its absorption ([`Self::sigma_a`])
    /// and its strand's roughness scale.
    pub fn variant(
        &self,
        strand: u32,
        v: f32,
        file_color: Option<Rgb>,
    ) -> Result<Variant, ParamError> {
        Ok(Variant {
            sigma_a: self.sigma_a(strand, v, file_color)?,
            roughness: self.roughness_scale(strand),
        })
    }
}

/// A material variant of a hair object: an absorption σ_a (per unit radius, non-negative) and
/// a roughness scale (positive) for the model's roughness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Variant {
    /// σ_a per unit radius.
    pub sigma_a: Rgb,
    /// The factor on the model's roughness ([`HairModel::with_roughness_scale`]).
    pub roughness: f32,
}

/// Weight of ln(roughness scale) beside √σ_a when grouping variants: by Chiang's fit √σ_a ≈
/// −ln(colour)/6 (for β_n about 0.3), so a ratio of roughness weighs as the same ratio of colour.
const ROUGHNESS_WEIGHT: f64 = 1.0 / 6.0;

/// At most `k` (≥ 1) representative variants for `values` (absorptions per unit radius,
/// non-negative, and roughness scales, positive) and the index of each value's
/// representative, deterministically (the same input gives the same result on any machine and
/// thread count).
///
/// Values equal to 16 significant bits (about 5 digits: far below what a render shows) count
/// as one, so values that differ by rounding do not make variants of their own (bar a pair
/// on either side of a rounding boundary). When there are at most `k` distinct values, they
/// are the representatives (each the mean of the values it stands for: exact when they are
/// equal). Otherwise the distinct values are grouped by variance-minimising splits in (√σ_a,
/// ln(roughness)/6) — by Chiang et al.'s colour fit, √σ_a is proportional to −ln of the
/// colour, so equal steps are equal ratios of colour, about equally visible, and the roughness
/// coordinate makes a ratio of roughness weigh as the same ratio of colour: the group of
/// largest squared error (weighted by how many values share each point) is cut, across its
/// axis of largest variance, where the two halves' summed squared error is least, until there
/// are `k` groups. A group's representative is the mean σ_a and mean roughness scale of its
/// values, so the means over all values are kept. The representatives are ordered by total
/// absorption, lightest first, then by roughness.
pub fn quantise_variants(values: &[Variant], k: usize) -> (Vec<Variant>, Vec<u32>) {
    let k = k.max(1);
    let array = |v: &Variant| {
        let [r, g, b] = v.sigma_a.to_array();
        [r, g, b, v.roughness]
    };
    // Distinct values, by their bits rounded to 16 significant bits (for non-negative floats
    // the bit patterns order like the values; with the index, a total order, so the sort is
    // deterministic).
    let key = |v: &Variant| array(v).map(|x| (x.to_bits() + 0x40) & !0x7f);
    let mut order: Vec<u32> = (0..values.len() as u32).collect();
    order.sort_unstable_by_key(|&i| (key(&values[i as usize]), i));
    // Per distinct value: the sum of the values it stands for and their number.
    let mut sums: Vec<[f64; 4]> = Vec::new();
    let mut weight: Vec<f64> = Vec::new();
    let mut of = vec![0u32; values.len()];
    let mut last_key = None;
    for &i in &order {
        let v = &values[i as usize];
        if last_key != Some(key(v)) {
            last_key = Some(key(v));
            sums.push([0.0; 4]);
            weight.push(0.0);
        }
        let d = sums.len() - 1;
        for (s, x) in sums[d].iter_mut().zip(array(v)) {
            *s += x as f64;
        }
        weight[d] += 1.0;
        of[i as usize] = d as u32;
    }
    drop(order);

    let groups: Vec<Vec<u32>> = if sums.len() <= k {
        (0..sums.len() as u32).map(|d| vec![d]).collect()
    } else {
        let x: Vec<[f64; 4]> = sums
            .iter()
            .zip(&weight)
            .map(|(s, &w)| {
                let [r, g, b, rough] = s.map(|v| v / w);
                [
                    r.max(0.0).sqrt(),
                    g.max(0.0).sqrt(),
                    b.max(0.0).sqrt(),
                    rough.ln() * ROUGHNESS_WEIGHT,
                ]
            })
            .collect();
        split_by_variance(&x, &weight, k)
    };
    // Representatives: the mean of each group's values.
    let mut reps: Vec<(Variant, Vec<u32>)> = groups
        .into_iter()
        .map(|g| {
            let (mut sum, mut n) = ([0.0f64; 4], 0.0);
            for &d in &g {
                for (s, v) in sum.iter_mut().zip(sums[d as usize]) {
                    *s += v;
                }
                n += weight[d as usize];
            }
            let [r, g_, b, rough] = sum.map(|s| (s / n) as f32);
            let variant = Variant {
                sigma_a: Rgb::new(r, g_, b),
                roughness: rough,
            };
            (variant, g)
        })
        .collect();
    reps.sort_by(|a, b| {
        let total = |v: &Variant| v.sigma_a.x as f64 + v.sigma_a.y as f64 + v.sigma_a.z as f64;
        total(&a.0).total_cmp(&total(&b.0)).then(
            array(&a.0)
                .map(f32::to_bits)
                .cmp(&array(&b.0).map(f32::to_bits)),
        )
    });
    let mut group_of = vec![0u32; sums.len()];
    for (r, (_, g)) in reps.iter().enumerate() {
        for &d in g {
            group_of[d as usize] = r as u32;
        }
    }
    let index = of.iter().map(|&d| group_of[d as usize]).collect();
    (reps.into_iter().map(|(v, _)| v).collect(), index)
}

/// Groups the points `x` (with weights `w`) into at most `k` groups by variance-minimising
/// splits (see [`quantise_variants`]).
fn split_by_variance(x: &[[f64; 4]], w: &[f64], k: usize) -> Vec<Vec<u32>> {
    /// Weighted sums of a set of points: Σw, Σw·x, Σw·|x|².
    #[derive(Clone, Copy, Default)]
    struct Moments {
        w: f64,
        wx: [f64; 4],
        wxx: f64,
    }
    impl Moments {
        fn add(&mut self, x: &[f64; 4], w: f64) {
            self.w += w;
            for (s, v) in self.wx.iter_mut().zip(x) {
                *s += w * v;
            }
            self.wxx += w * x.iter().map(|v| v * v).sum::<f64>();
        }
        /// Σw·|x − mean|².
        fn squared_error(&self) -> f64 {
            if self.w <= 0.0 {
                return 0.0;
            }
            let m2: f64 = self.wx.iter().map(|s| s * s).sum::<f64>() / self.w;
            (self.wxx - m2).max(0.0)
        }
    }
    let moments = |g: &[u32]| {
        let mut m = Moments::default();
        g.iter().for_each(|&i| m.add(&x[i as usize], w[i as usize]));
        m
    };
    let all: Vec<u32> = (0..x.len() as u32).collect();
    let mut groups = vec![(moments(&all).squared_error(), all)];
    while groups.len() < k {
        let (worst, _) = groups
            .iter()
            .enumerate()
            .max_by(|(i, a), (j, b)| a.0.total_cmp(&b.0).then(j.cmp(i)))
            .expect("at least one group");
        if groups[worst].0 <= 0.0 || groups[worst].1.len() < 2 {
            break;
        }
        let (_, mut g) = groups.swap_remove(worst);
        // The axis of largest variance.
        let m = moments(&g);
        let axis = (0..4)
            .map(|a| {
                let mean = m.wx[a] / m.w;
                let var: f64 = g
                    .iter()
                    .map(|&i| w[i as usize] * (x[i as usize][a] - mean).powi(2))
                    .sum();
                (a, var)
            })
            .max_by(|p, q| p.1.total_cmp(&q.1).then(q.0.cmp(&p.0)))
            .map_or(0, |(a, _)| a);
        g.sort_unstable_by(|&i, &j| {
            x[i as usize][axis]
                .total_cmp(&x[j as usize][axis])
                .then(i.cmp(&j))
        });
        // The cut with the least summed squared error, from prefix moments.
        let mut left = Moments::default();
        let mut best = (f64::INFINITY, 1);
        for cut in 1..g.len() {
            let i = g[cut - 1] as usize;
            left.add(&x[i], w[i]);
            let right = Moments {
                w: m.w - left.w,
                wx: std::array::from_fn(|a| m.wx[a] - left.wx[a]),
                wxx: m.wxx - left.wxx,
            };
            let error = left.squared_error() + right.squared_error();
            if error < best.0 {
                best = (error, cut);
            }
        }
        let high = g.split_off(best.1);
        groups.push((moments(&g).squared_error(), g));
        groups.push((moments(&high).squared_error(), high));
    }
    groups.into_iter().map(|(_, g)| g).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::{brown, chiang};

    /// [`quantise_variants`] of absorptions alone (roughness scale 1).
    fn quantise_absorption(sigma: &[Rgb], k: usize) -> (Vec<Rgb>, Vec<u32>) {
        let values: Vec<Variant> = sigma
            .iter()
            .map(|&sigma_a| Variant {
                sigma_a,
                roughness: 1.0,
            })
            .collect();
        let (palette, index) = quantise_variants(&values, k);
        assert!(palette.iter().all(|v| v.roughness == 1.0));
        (palette.into_iter().map(|v| v.sigma_a).collect(), index)
    }

    #[test]
    fn variation_errors_name_the_field() {
        let m = chiang(brown());
        let check = |v: StrandVariation, field: &str| {
            let e = v.for_model(&m).unwrap_err();
            assert_eq!(e.field, field, "{e}");
        };
        let v = StrandVariation::default;
        check(
            StrandVariation {
                random: f32::NAN,
                ..v()
            },
            "variation.random",
        );
        check(StrandVariation { random: 1.5, ..v() }, "variation.random");
        for random_roughness in [1.0, -0.1, f32::NAN, f32::INFINITY] {
            check(
                StrandVariation {
                    random_roughness,
                    ..v()
                },
                "variation.random_roughness",
            );
        }
        let darken = |amount, length| StrandVariation {
            darken_roots: Some(DarkenRoots { amount, length }),
            ..v()
        };
        for amount in [-0.5, 101.0, f32::NAN] {
            check(darken(amount, 0.2), "variation.darken_roots.amount");
        }
        for length in [0.0, -0.1, 1.5, f32::NAN] {
            check(darken(1.0, length), "variation.darken_roots.length");
        }
        darken(0.0, 1.0).for_model(&m).unwrap();
        for variants in [0, 257, u32::MAX] {
            check(StrandVariation { variants, ..v() }, "variation.variants");
        }
        let gradient = |tip, start| StrandVariation {
            gradient: Some(Gradient { tip, start }),
            ..v()
        };
        check(
            gradient(TipPigment::Scale(0.5), 1.0),
            "variation.gradient.start",
        );
        check(
            gradient(TipPigment::Scale(0.5), f32::NAN),
            "variation.gradient.start",
        );
        check(
            gradient(TipPigment::Scale(-0.1), 0.5),
            "variation.gradient.tip",
        );
        let e = gradient(TipPigment::Pigment(Pigment::Color((0.0, 0.5, 0.5))), 0.5)
            .for_model(&m)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("variation.gradient.tip = Color((0.0, 0.5, 0.5)): color = 0"),
            "{e}"
        );
        let e = v()
            .for_model(&HairModel::LambertianFiber(Default::default()))
            .unwrap_err()
            .to_string();
        assert!(e.contains("no pigment"), "{e}");
        // The material's own pigment is checked too.
        let bad = chiang(Pigment::SigmaA((-1.0, 0.0, 0.0)));
        assert_eq!(v().for_model(&bad).unwrap_err().field, "sigma_a");
        v().for_model(&m).unwrap();
    }

    #[test]
    fn random_roughness_varies_per_strand_within_its_bounds() {
        let m = chiang(brown());
        let r = 0.4;
        let varied = |seed| {
            StrandVariation {
                random_roughness: r,
                seed,
                ..Default::default()
            }
            .for_model(&m)
            .unwrap()
        };
        let v = varied(5);
        let scales: Vec<f32> = (0..20_000).map(|s| v.roughness_scale(s)).collect();
        assert!(scales.iter().all(|&g| (1.0 - r..=1.0 + r).contains(&g)));
        assert!(scales.iter().any(|&g| g < 1.0 - 0.9 * r));
        assert!(scales.iter().any(|&g| g > 1.0 + 0.9 * r));
        // Independent of the melanin factor drawn from the same seed and strand: uncorrelated.
        let melanin = StrandVariation {
            random: 1.0,
            seed: 5,
            ..Default::default()
        }
        .for_model(&m)
        .unwrap();
        let n = scales.len() as f64;
        let covariance = scales
            .iter()
            .enumerate()
            .map(|(s, &g)| (g as f64 - 1.0) * (melanin.strand_factor(s as u32) as f64 - 1.0))
            .sum::<f64>()
            / n;
        // Each factor has standard deviation r/√3 and 1/√3; 4 standard errors of their mean
        // product.
        assert!(
            covariance.abs() < 4.0 * (r as f64 / 3.0) / n.sqrt(),
            "{covariance}"
        );
        // Deterministic per seed; another seed draws others.
        assert_eq!(varied(5).roughness_scale(9), v.roughness_scale(9));
        assert_ne!(varied(6).roughness_scale(9), v.roughness_scale(9));
        // The absorption does not change with it, and without it the scale is exactly 1.
        let base = brown().sigma_a(0.4).unwrap();
        let variant = v.variant(3, 0.5, None).unwrap();
        assert_eq!(variant.sigma_a, base);
        assert_eq!(variant.roughness, v.roughness_scale(3));
        let plain = StrandVariation::default().for_model(&m).unwrap();
        assert_eq!(plain.roughness_scale(3), 1.0);
    }

    #[test]
    fn darker_roots_fade_to_the_pigment_over_their_length() {
        let m = chiang(brown());
        let base = brown().sigma_a(0.4).unwrap();
        let v = StrandVariation {
            darken_roots: Some(DarkenRoots {
                amount: 2.0,
                length: 0.25,
            }),
            ..Default::default()
        }
        .for_model(&m)
        .unwrap();
        let at = |x: f32| v.sigma_a(7, x, None).unwrap();
        assert_eq!(at(0.0), 3.0 * base);
        assert_eq!(at(0.125), 2.0 * base);
        // From `length` on, the pigment itself, to the bit.
        for x in [0.25, 0.5, 1.0] {
            assert_eq!(at(x), base, "{x}");
        }
        // Darker all the way from the root to `length`.
        let steps: Vec<f32> = (0..=25).map(|i| at(i as f32 / 100.0).x).collect();
        assert!(steps.windows(2).all(|w| w[0] > w[1]), "{steps:?}");
        // With random melanin and a gradient, the darkening multiplies the rest.
        let all = StrandVariation {
            random: 0.5,
            gradient: Some(Gradient {
                tip: TipPigment::Scale(0.5),
                start: 0.0,
            }),
            darken_roots: Some(DarkenRoots {
                amount: 1.0,
                length: 0.5,
            }),
            ..Default::default()
        }
        .for_model(&m)
        .unwrap();
        let without = StrandVariation {
            darken_roots: None,
            ..StrandVariation {
                random: 0.5,
                gradient: Some(Gradient {
                    tip: TipPigment::Scale(0.5),
                    start: 0.0,
                }),
                ..Default::default()
            }
        }
        .for_model(&m)
        .unwrap();
        let ratio = all.sigma_a(4, 0.1, None).unwrap() / without.sigma_a(4, 0.1, None).unwrap();
        assert!(
            (ratio - Rgb::splat(1.8)).abs().max_element() < 1e-6,
            "{ratio}"
        );
    }

    #[test]
    fn quantisation_groups_roughness_too_and_keeps_its_mean() {
        let m = chiang(brown());
        let r = 0.5;
        let v = StrandVariation {
            random_roughness: r,
            seed: 2,
            ..Default::default()
        }
        .for_model(&m)
        .unwrap();
        let values: Vec<Variant> = (0..3000)
            .map(|s| v.variant(s, 0.5, None).unwrap())
            .collect();
        let (palette, index) = quantise_variants(&values, 8);
        // Only the roughness varies: 8 variants of one absorption, 8 distinct roughness scales
        // within the bounds.
        assert_eq!(palette.len(), 8);
        assert!(palette.iter().all(|p| p.sigma_a == values[0].sigma_a));
        let mut scales: Vec<f32> = palette.iter().map(|p| p.roughness).collect();
        assert!(
            scales.iter().all(|&g| (1.0 - r..=1.0 + r).contains(&g)),
            "{scales:?}"
        );
        scales.sort_by(f32::total_cmp);
        scales.dedup();
        assert_eq!(scales.len(), 8);
        assert!(
            scales[0] < 1.0 - 0.7 * r && scales[7] > 1.0 + 0.7 * r,
            "{scales:?}"
        );
        let mean = |g: &mut dyn Iterator<Item = f32>| g.map(f64::from).sum::<f64>() / 3000.0;
        let exact = mean(&mut values.iter().map(|v| v.roughness));
        let quantised = mean(&mut index.iter().map(|&i| palette[i as usize].roughness));
        assert!((exact - quantised).abs() < 1e-5, "{exact} vs {quantised}");
        // Each value's representative is near it.
        assert!(values
            .iter()
            .zip(&index)
            .all(|(v, &i)| (v.roughness - palette[i as usize].roughness).abs() < 0.1));
    }

    #[test]
    fn random_melanin_stays_in_bounds_and_averages_to_the_base() {
        let m = chiang(brown());
        let base = brown().sigma_a(0.4).unwrap();
        let random = 0.6;
        let v = StrandVariation {
            random,
            seed: 11,
            ..Default::default()
        }
        .for_model(&m)
        .unwrap();
        let n = 20_000;
        let factors: Vec<f32> = (0..n).map(|s| v.strand_factor(s)).collect();
        assert!(factors
            .iter()
            .all(|&f| (1.0 - random..=1.0 + random).contains(&f)));
        // The factor is uniform on [1 − r, 1 + r]: mean 1, standard deviation r/√3, so the
        // mean of n strands has standard error r/√(3n) ≈ 0.0024; allow 4 of them.
        let mean = factors.iter().map(|&f| f as f64).sum::<f64>() / n as f64;
        let tolerance = 4.0 * random as f64 / (3.0 * n as f64).sqrt();
        assert!((mean - 1.0).abs() < tolerance, "mean {mean}");
        // And it covers its range: both ends' tenths are visited.
        assert!(factors.iter().any(|&f| f < 1.0 - 0.9 * random));
        assert!(factors.iter().any(|&f| f > 1.0 + 0.9 * random));
        // σ_a is the base times the factor, whatever v without a gradient.
        let s = v.sigma_a(17, 0.9, None).unwrap();
        assert!((s - v.strand_factor(17) * base).abs().max_element() < 1e-6);
        // Another seed, other factors; the same seed, the same.
        let other = StrandVariation {
            random,
            seed: 12,
            ..Default::default()
        }
        .for_model(&m)
        .unwrap();
        assert_ne!(other.strand_factor(5), v.strand_factor(5));
        assert_eq!(v.clone().strand_factor(5), v.strand_factor(5));
    }

    #[test]
    fn gradient_runs_from_the_root_pigment_to_the_tip_pigment() {
        let m = chiang(brown());
        let base = brown().sigma_a(0.4).unwrap();
        let blond = Pigment::Melanin {
            eumelanin: 0.2,
            pheomelanin: 0.1,
            tint: crate::pigment::NO_TINT,
        };
        let tip = blond.sigma_a(0.4).unwrap();
        let graded = |tip, start| {
            StrandVariation {
                gradient: Some(Gradient { tip, start }),
                ..Default::default()
            }
            .for_model(&m)
            .unwrap()
        };
        let v = graded(TipPigment::Pigment(blond), 0.25);
        let at = |x| v.sigma_a(3, x, None).unwrap();
        assert_eq!(at(0.0), base);
        assert_eq!(at(0.25), base);
        assert!((at(1.0) - tip).abs().max_element() < 1e-6);
        // Halfway through the change, halfway in absorption (linear in melanin).
        assert!((at(0.625) - 0.5 * (base + tip)).abs().max_element() < 1e-6);
        // A scale of 1 and no randomness change nothing, to the bit.
        let v1 = graded(TipPigment::Scale(1.0), 0.1);
        for x in [0.0, 0.3, 0.77, 1.0] {
            assert_eq!(v1.sigma_a(9, x, None).unwrap(), base);
        }
        // A scale multiplies the root's absorption at the tip.
        let v = graded(TipPigment::Scale(0.3), 0.0);
        assert_eq!(v.sigma_a(0, 0.0, None).unwrap(), base);
        assert!(
            (v.sigma_a(0, 1.0, None).unwrap() - 0.3 * base)
                .abs()
                .max_element()
                < 1e-6
        );
    }

    #[test]
    fn file_colours_replace_the_root_pigment() {
        let m = chiang(brown());
        let v = StrandVariation {
            file_colors: true,
            gradient: Some(Gradient {
                tip: TipPigment::Scale(0.5),
                start: 0.5,
            }),
            ..Default::default()
        }
        .for_model(&m)
        .unwrap();
        let c = Rgb::new(0.7, 0.5, 0.3);
        let want = Pigment::Color((0.7, 0.5, 0.3)).sigma_a(0.4).unwrap();
        assert_eq!(v.sigma_a(0, 0.1, Some(c)).unwrap(), want);
        assert!(
            (v.sigma_a(0, 1.0, Some(c)).unwrap() - 0.5 * want)
                .abs()
                .max_element()
                < 1e-6
        );
        let e = v.sigma_a(0, 0.1, None).unwrap_err().to_string();
        assert!(
            e.contains("variation.file_colors") && e.contains("no colours"),
            "{e}"
        );
        let e = v
            .sigma_a(0, 0.1, Some(Rgb::new(1.5, 0.5, 0.5)))
            .unwrap_err();
        assert_eq!(e.field, "color");
    }

    #[test]
    fn few_distinct_absorptions_are_kept_exactly() {
        let a = Rgb::new(0.5, 0.7, 1.2);
        let b = Rgb::new(0.1, 0.2, 0.3);
        let sigma = [a, b, a, a, b];
        let (palette, index) = quantise_absorption(&sigma, 4);
        // Lightest first.
        assert_eq!(palette, vec![b, a]);
        assert_eq!(index, vec![1, 0, 1, 1, 0]);
        let (palette, index) = quantise_absorption(&sigma, 1);
        assert_eq!(index, vec![0; 5]);
        // Values one rounding step apart are one variant.
        let next = |c: Rgb| Rgb::from_array(c.to_array().map(|v| f32::from_bits(v.to_bits() + 1)));
        let (nearly, index_nearly) = quantise_absorption(&[a, next(a), b, next(next(b))], 8);
        assert_eq!(nearly.len(), 2);
        assert_eq!(index_nearly, vec![1, 1, 0, 0]);
        // One group: the mean absorption.
        assert!((palette[0] - (3.0 * a + 2.0 * b) / 5.0).abs().max_element() < 1e-6);
    }

    #[test]
    fn quantisation_is_deterministic_keeps_the_mean_and_follows_the_data() {
        // Random melanin and a gradient: every segment's absorption is different.
        let m = chiang(brown());
        let v = StrandVariation {
            random: 0.5,
            seed: 3,
            gradient: Some(Gradient {
                tip: TipPigment::Scale(0.2),
                start: 0.3,
            }),
            ..Default::default()
        }
        .for_model(&m)
        .unwrap();
        let sigma: Vec<Rgb> = (0..2000u32)
            .flat_map(|s| (0..10).map(move |j| (s, (j as f32 + 0.5) / 10.0)))
            .map(|(s, x)| v.sigma_a(s, x, None).unwrap())
            .collect();
        let (palette, index) = quantise_absorption(&sigma, 16);
        assert_eq!(palette.len(), 16);
        assert!(index.iter().all(|&i| (i as usize) < palette.len()));
        // Every group is used, and ordered lightest first.
        let mut used = [0usize; 16];
        index.iter().for_each(|&i| used[i as usize] += 1);
        assert!(used.iter().all(|&n| n > 0), "{used:?}");
        assert!(palette
            .windows(2)
            .all(|w| w[0].element_sum() <= w[1].element_sum()));
        // The mean absorption is kept.
        let mean = |c: &mut dyn Iterator<Item = Rgb>| {
            let (sum, n) = c.fold((glam::DVec3::ZERO, 0.0), |(s, n), c| {
                (s + c.as_dvec3(), n + 1.0)
            });
            sum / n
        };
        let exact = mean(&mut sigma.iter().copied());
        let quantised = mean(&mut index.iter().map(|&i| palette[i as usize]));
        assert!((exact - quantised).abs().max_element() < 1e-5 * exact.max_element());
        // Each value's representative is near it: far nearer than the spread of the values.
        let error = sigma
            .iter()
            .zip(&index)
            .map(|(c, &i)| (*c - palette[i as usize]).length() as f64)
            .sum::<f64>()
            / sigma.len() as f64;
        let spread = sigma
            .iter()
            .map(|c| (c.as_dvec3() - exact).length())
            .sum::<f64>()
            / sigma.len() as f64;
        assert!(error < 0.1 * spread, "error {error}, spread {spread}");
        // The same values in another order: the same palette, the same representatives.
        let reversed: Vec<Rgb> = sigma.iter().rev().copied().collect();
        let (palette_r, index_r) = quantise_absorption(&reversed, 16);
        assert_eq!(palette_r, palette);
        assert!(index_r.iter().rev().eq(index.iter()));
    }
}
