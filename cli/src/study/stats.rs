//! Statistics over repetitions: means, confidence intervals, convergence curves and verdicts.

use super::*;

/// Mean and the half-width of its 95 % confidence interval (Student t; none for one value).
#[derive(Clone, Copy, Debug)]
pub(super) struct Stat {
    pub(super) mean: f64,
    pub(super) ci: Option<f64>,
}

/// The 97.5 % quantile of Student's t with `df` degrees of freedom.
pub(super) fn t975(df: usize) -> f64 {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    StudentsT::new(0.0, 1.0, df.max(1) as f64)
        .map(|t| t.inverse_cdf(0.975))
        .unwrap_or(f64::NAN)
}

pub(super) fn stat(v: &[f64]) -> Stat {
    let n = v.len();
    let mean = v.iter().sum::<f64>() / n.max(1) as f64;
    let ci = (n > 1).then(|| {
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        t975(n - 1) * (var / n as f64).sqrt()
    });
    Stat { mean, ci }
}

/// Averages over the repetitions of one (integrator, spp) setting.
#[derive(Clone, Copy, Debug)]
pub(super) struct Point {
    pub(super) spp: u32,
    pub(super) mse: Stat,
    pub(super) relmse: Stat,
    pub(super) time_s: f64,
    /// Mean squared bias over the pixels and channels, (K·MSE(mean image) − mean MSE)/(K − 1)
    /// for K ≥ 2 repetitions: unbiased, since the mean of K independent renders has the same
    /// bias and 1/K of the variance. It includes the reference's own squared error.
    pub(super) bias2: Option<f64>,
}

/// The convergence curve of one integrator in one scene, against one reference, over the whole
/// image (`region` None) or a region.
pub(super) fn curve(
    res: &Results,
    plan: &Plan,
    scene: usize,
    integrator: usize,
    kind: RefKind,
    region: Option<usize>,
) -> Vec<Point> {
    plan.spp
        .iter()
        .filter_map(|&spp| {
            let rows: Vec<&Row> = res
                .rows
                .iter()
                .filter(|r| {
                    r.scene == scene
                        && r.integrator == integrator
                        && r.reference == kind
                        && r.spp == spp
                })
                .collect();
            if rows.is_empty() {
                return None;
            }
            let err = |r: &Row| match region {
                None => r.whole,
                Some(g) => r.regions[g],
            };
            let mse: Vec<f64> = rows.iter().map(|r| err(r).mse).collect();
            let rel: Vec<f64> = rows.iter().map(|r| err(r).relmse).collect();
            let time: Vec<f64> = rows.iter().map(|r| r.time_s).collect();
            let mse = stat(&mse);
            let k = rows.len() as f64;
            let bias2 = match region {
                None => res
                    .mean_mse
                    .get(&(scene, integrator, spp, kind))
                    .map(|m| (k * m - mse.mean) / (k - 1.0)),
                Some(_) => None,
            };
            Some(Point {
                spp,
                mse,
                relmse: stat(&rel),
                time_s: stat(&time).mean,
                bias2,
            })
        })
        .collect()
}

/// Piecewise-linear interpolation of `y(x)` in log-log space; `None` outside the sampled range
/// (no extrapolation). `pts` need not be sorted.
pub(super) fn loglog_at(pts: &[(f64, f64)], x: f64) -> Option<f64> {
    let mut p: Vec<(f64, f64)> = pts
        .iter()
        .copied()
        .filter(|(a, b)| *a > 0.0 && *b > 0.0 && a.is_finite() && b.is_finite())
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    if p.is_empty() || x < p[0].0 || x > p[p.len() - 1].0 {
        return None;
    }
    if p.len() == 1 {
        return Some(p[0].1);
    }
    let i = p.partition_point(|q| q.0 < x).clamp(1, p.len() - 1);
    let ((x0, y0), (x1, y1)) = (p[i - 1], p[i]);
    if x == x1 {
        return Some(y1);
    }
    if x1 == x0 {
        return Some(y0);
    }
    let f = (x.ln() - x0.ln()) / (x1.ln() - x0.ln());
    Some((y0.ln() + f * (y1.ln() - y0.ln())).exp())
}

/// Where a curve first reaches relMSE ≤ `target`: (spp, seconds), interpolated in log-log
/// between the settings around the crossing.
pub(super) enum Reach {
    /// Already at the smallest spp.
    AtOnce(u32, f64),
    At(f64, f64),
    Never(f64),
}

pub(super) fn reach(points: &[Point], target: f64) -> Reach {
    let k = match points.iter().position(|p| p.relmse.mean <= target) {
        None => {
            let best = points
                .iter()
                .map(|p| p.relmse.mean)
                .fold(f64::INFINITY, f64::min);
            return Reach::Never(best);
        }
        Some(k) => k,
    };
    if k == 0 {
        return Reach::AtOnce(points[0].spp, points[0].time_s);
    }
    let (a, b) = (&points[k - 1], &points[k]);
    let f = (target.ln() - a.relmse.mean.ln()) / (b.relmse.mean.ln() - a.relmse.mean.ln());
    let lerp = |u: f64, v: f64| (u.ln() + f * (v.ln() - u.ln())).exp();
    Reach::At(
        lerp(a.spp as f64, b.spp as f64),
        lerp(a.time_s.max(1e-9), b.time_s.max(1e-9)),
    )
}

/// Where a curve that never reaches relMSE ≤ `target` would, if it went on converging as 1/N
/// from its highest spp (relMSE ∝ 1/spp, time ∝ spp): (spp, seconds). Meaningful only for an
/// unbiased estimator against its own reference; `None` if the target was reached.
pub(super) fn extrapolated_reach(points: &[Point], target: f64) -> Option<(f64, f64)> {
    let last = points.last()?;
    let factor = last.relmse.mean / target;
    (factor > 1.0 && factor.is_finite()).then_some((last.spp as f64 * factor, last.time_s * factor))
}

/// One line on how MSE·spp evolves: flat for unbiased 1/N convergence, rising for an error
/// floor, which the bias estimate then attributes to bias or to heavy-tailed variance. `noise`
/// is the reference's own noise (an spp-independent additive term of every MSE and bias², the
/// test seeds being independent of the reference's), subtracted first when known.
pub(super) fn verdict(points: &[Point], noise: Option<f64>) -> String {
    let (Some(first), Some(last)) = (points.first(), points.last()) else {
        return "no data".into();
    };
    if points.len() < 2 {
        return "a single spp setting: no convergence trend".into();
    }
    let n = noise.unwrap_or(0.0);
    let p0 = (first.mse.mean - n) * first.spp as f64;
    let p1 = (last.mse.mean - n) * last.spp as f64;
    let span = format!("{} to {} spp", first.spp, last.spp);
    if p0.is_nan() || p0 <= 0.0 {
        return format!(
            "MSE at {} spp is at the reference noise: cannot judge",
            first.spp
        );
    }
    let rise = p1 / p0;
    // Split the MSE at the highest spp into bias² and variance.
    let split = last.bias2.map(|b| {
        let b2 = (b - n).max(0.0);
        (b2, (last.mse.mean - n - b2).max(0.0))
    });
    let at = last.spp;
    if rise > 2.0 {
        match split {
            Some((b2, var)) if b2 > var => format!(
                "**bias**: MSE·spp rises ×{rise:.2} from {span} and at {at} spp bias² ≈ \
                 {b2:.3e} (RMS {:.3e}) exceeds the variance {var:.3e}: the estimator converges \
                 to a different image than this reference",
                b2.sqrt()
            ),
            Some((b2, var)) => format!(
                "**excess variance**: MSE·spp rises ×{rise:.2} from {span}, but at {at} spp the \
                 mean of the repetitions is as close as independent noise predicts (bias² ≈ \
                 {b2:.3e} < variance {var:.3e}): heavy-tailed samples (rare and very bright) \
                 that low spp rarely draw"
            ),
            None => format!(
                "**error floor**: MSE·spp rises ×{rise:.2} from {span} (one repetition: bias \
                 and heavy-tailed variance cannot be told apart)"
            ),
        }
    } else {
        let trend = if rise < 0.5 {
            format!(
                "MSE·spp falls ×{:.2} from {span}: faster than 1/N",
                1.0 / rise
            )
        } else {
            format!("flat (×{rise:.2} from {span}): consistent with unbiased 1/N convergence")
        };
        match split {
            // An error floor that MSE·spp does not show yet at these spp (the variance still
            // dominates at the low end) but that the repetitions' mean already does.
            Some((b2, var)) if b2 > var => format!(
                "**bias**: at {at} spp bias² ≈ {b2:.3e} (RMS {:.3e}) exceeds the variance \
                 {var:.3e}, though MSE·spp only changes ×{rise:.2} from {span}: the estimator \
                 converges to a different image than this reference",
                b2.sqrt()
            ),
            Some((b2, var)) => {
                format!("{trend}; at {at} spp bias² ≈ {b2:.3e}, variance ≈ {var:.3e}")
            }
            None => trend,
        }
    }
}
