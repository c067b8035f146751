//! Statistics over repetitions: means, confidence intervals, convergence curves and verdicts.

use crate::plan::Plan;
use crate::results::{RefKind, Results, Row};

/// Mean and the half-width of its 95 % confidence interval (Student t; none for one value).
#[derive(Clone, Copy, Debug)]
pub struct Stat {
    /// The mean.
    pub mean: f64,
    /// Half-width of the 95 % confidence interval of the mean; none for a single value.
    pub ci: Option<f64>,
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
pub struct Point {
    /// Samples per pixel.
    pub spp: u32,
    /// Mean squared error.
    pub mse: Stat,
    /// Relative mean squared error.
    pub relmse: Stat,
    /// Mean CPU seconds of a render.
    pub time_s: f64,
    /// Mean squared bias over the pixels and channels, (K·MSE(mean image) − mean MSE)/(K − 1)
    /// for K ≥ 2 repetitions: unbiased, since the mean of K independent renders has the same
    /// bias and 1/K of the variance. It includes the reference's own squared error.
    pub bias2: Option<f64>,
}

/// The convergence curve of one integrator in one scene, against one reference, over the whole
/// image (`region` None) or a region.
pub fn curve(
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn student_t_quantiles() {
        // Tabulated values (to the table's three decimals).
        for (df, want) in [
            (1, 12.706),
            (2, 4.303),
            (30, 2.042),
            (40, 2.021),
            (120, 1.980),
        ] {
            assert!((t975(df) - want).abs() < 1e-3, "t975({df}) = {}", t975(df));
        }
        let s = stat(&[1.0, 2.0, 3.0]);
        assert_eq!(s.mean, 2.0);
        assert!((s.ci.unwrap() - 4.303 / 3f64.sqrt()).abs() < 1e-3);
        assert!(stat(&[5.0]).ci.is_none());
    }

    #[test]
    fn log_log_interpolation() {
        let pts = [(1.0, 1.0), (100.0, 1e-2), (10.0, 1e-1)];
        assert!(
            (loglog_at(&pts, 31.622_776_601_683_793).unwrap() - 10f64.powf(-1.5)).abs() < 1e-12
        );
        assert_eq!(loglog_at(&pts, 0.5), None);
        assert_eq!(loglog_at(&pts, 100.0), Some(1e-2));
    }

    fn pt(spp: u32, mse: f64, time_s: f64) -> Point {
        let s = Stat {
            mean: mse,
            ci: None,
        };
        Point {
            spp,
            mse: s,
            relmse: s,
            time_s,
            bias2: None,
        }
    }

    #[test]
    fn verdicts_and_time_to_target() {
        let unbiased: Vec<Point> = [1, 4, 16, 64]
            .iter()
            .map(|&n| pt(n, 1.0 / n as f64, n as f64))
            .collect();
        assert!(verdict(&unbiased, None).starts_with("flat"));
        let biased: Vec<Point> = [1, 4, 16, 64]
            .iter()
            .map(|&n| pt(n, 1.0 / n as f64 + 0.1, n as f64))
            .collect();
        assert!(verdict(&biased, None).contains("error floor"));
        // Reference noise alone is not taken for bias once subtracted.
        let noisy: Vec<Point> = [1, 4, 16, 64]
            .iter()
            .map(|&n| pt(n, 1.0 / n as f64 + 0.02, n as f64))
            .collect();
        assert!(verdict(&noisy, None).contains("error floor"));
        assert!(verdict(&noisy, Some(0.02)).starts_with("flat"));
        // With a bias estimate the floor is attributed: to bias when bias² dominates the MSE…
        let mut split = biased.clone();
        split[3].bias2 = Some(0.1);
        assert!(verdict(&split, None).starts_with("**bias**"));
        // …and to heavy-tailed variance when the mean image is as close as 1/K predicts.
        split[3].bias2 = Some(0.001);
        assert!(verdict(&split, None).starts_with("**excess variance**"));
        // A bias that dominates at the highest spp is reported even before MSE·spp rises.
        let mut early = unbiased.clone();
        early[3].bias2 = Some(0.6 / 64.0);
        assert!(verdict(&early, None).starts_with("**bias**"));
        early[3].bias2 = Some(0.3 / 64.0);
        assert!(verdict(&early, None).starts_with("flat"));
        // relMSE 1/N reaches 0.1 at 10 spp and 10 s.
        match reach(&unbiased, 0.1) {
            Reach::At(spp, t) => {
                assert!((spp - 10.0).abs() < 1e-9 && (t - 10.0).abs() < 1e-9);
            }
            _ => panic!("target not found"),
        }
        assert!(matches!(reach(&unbiased, 2.0), Reach::AtOnce(1, _)));
        assert!(matches!(reach(&unbiased, 1e-3), Reach::Never(_)));
        // Short of it, 1/N from the last setting (relMSE 1/64 at 64 spp and 64 s) gets there at
        // 1000 spp and 1000 s; a reached target is not extrapolated.
        let (spp, t) = extrapolated_reach(&unbiased, 1e-3).unwrap();
        assert!(
            (spp - 1000.0).abs() < 1e-6 && (t - 1000.0).abs() < 1e-6,
            "{spp} {t}"
        );
        assert!(extrapolated_reach(&unbiased, 0.1).is_none());
    }
}
