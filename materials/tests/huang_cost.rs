//! Huang's cost per call against Chiang's (not an assertion), as docs/src/research/performance.md
//! ("Huang's cost") measures it: `tress bench`'s inputs ([`CostInputs`]), each model timed over passes of 40,000 calls in the
//! thread's CPU time, the models alternating pass by pass, `HUANG_COST_ROUNDS` rounds (default
//! 11) in one process; prints the median ns per call and the median of the rounds' ratios to
//! Chiang. Run:
//! `cargo test --release -p tress-materials --test integration -- --ignored --nocapture huang_cost`.

use std::hint::black_box;
use tress_core::math::Vec2;
use tress_core::prepare::Preparation;
use tress_core::rng::Pcg32;
use tress_core::sampling::sample_uniform_sphere;
use tress_core::Bcsdf;
use tress_materials::{CostInputs, HairModel};

/// CPU time of the calling thread, in ns (other processes on the machine do not count).
fn thread_ns() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: a valid clock id and a valid pointer to a timespec.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    assert_eq!(rc, 0, "clock_gettime");
    t.tv_sec as f64 * 1e9 + t.tv_nsec as f64
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
#[ignore]
fn huang_cost() {
    const CALLS: usize = 40_000;
    let rounds: usize = std::env::var("HUANG_COST_ROUNDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(11);
    let CostInputs { dirs, hs, us } = CostInputs::new();
    let names = ["Chiang/brown", "Huang/brown", "Huang/rough_far_field"];
    let all = HairModel::test_instances();
    let models: Vec<std::sync::Arc<dyn Bcsdf>> = names
        .iter()
        .map(|n| {
            let t = all.iter().find(|t| t.name == *n).unwrap();
            t.params.build(&Preparation::new()).unwrap()
        })
        .collect();
    let metrics = ["eval", "pdf", "sample", "eval_pdf"];
    let call = |b: &dyn Bcsdf, metric: usize, i: usize| -> f32 {
        let (wo, wi) = dirs[i];
        match metric {
            0 => b.eval(wo, wi, hs[i]).x,
            1 => b.pdf(wo, wi, hs[i]),
            2 => b.sample(wo, hs[i], us[i]).map_or(0.0, |s| s.pdf),
            _ => {
                let (f, pdf) = b.eval_pdf(wo, wi, hs[i]);
                f.x + pdf
            }
        }
    };
    // ns[metric][model][round]
    let mut ns = vec![vec![Vec::new(); models.len()]; metrics.len()];
    for _ in 0..rounds {
        for (m, per_model) in ns.iter_mut().enumerate() {
            for (b, times) in models.iter().zip(per_model.iter_mut()) {
                let start = thread_ns();
                let mut acc = 0.0f32;
                for i in 0..CALLS {
                    acc += call(b.as_ref(), m, black_box(i % CostInputs::LEN));
                }
                black_box(acc);
                times.push((thread_ns() - start) / CALLS as f64);
            }
        }
    }
    println!("\n{rounds} rounds of {CALLS} calls; ns per call (median), × Chiang (median of the rounds' ratios)");
    println!(
        "{:<24}{:>18}{:>18}{:>18}{:>18}",
        "", "eval", "pdf", "sample", "eval+pdf"
    );
    for (k, name) in names.iter().enumerate() {
        let mut line = format!("{name:<24}");
        for per_model in &ns {
            let ratio = median(
                per_model[k]
                    .iter()
                    .zip(&per_model[0])
                    .map(|(a, c)| a / c)
                    .collect(),
            );
            line += &format!(
                "{:>18}",
                format!("{:.0} ({ratio:.2}×)", median(per_model[k].clone()))
            );
        }
        println!("{line}");
    }
}

/// Prints a digest of every Huang test instance's `eval_pdf` and `sample` bits at 20,000 random
/// points: two builds printing the same digests compute the same values (how the commits that
/// rearrange Huang's code check that they change no bit).
#[test]
#[ignore]
fn huang_digest() {
    use std::hash::{Hash, Hasher};
    let mut rng = Pcg32::new(99, 0);
    let mut r = || rng.next_f32();
    let all = HairModel::test_instances();
    for t in all.iter().filter(|t| t.name.starts_with("Huang/")) {
        let b = t.params.build(&Preparation::new()).unwrap();
        let mut hs = std::collections::hash_map::DefaultHasher::new();
        for _ in 0..20_000 {
            let wo = sample_uniform_sphere(Vec2::new(r(), r()));
            let wi = sample_uniform_sphere(Vec2::new(r(), r()));
            let h = 2.0 * r() - 1.0;
            let u = [r(), r(), r(), r()];
            let (f, pdf) = b.eval_pdf(wo, wi, h);
            (f.to_array().map(f32::to_bits), pdf.to_bits()).hash(&mut hs);
            if let Some(s) = b.sample(wo, h, u) {
                (
                    s.wi.to_array().map(f32::to_bits),
                    s.f.to_array().map(f32::to_bits),
                    s.pdf.to_bits(),
                )
                    .hash(&mut hs);
            }
        }
        println!("{} {:016x}", t.name, hs.finish());
    }
}
