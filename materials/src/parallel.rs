//! Deterministic parallel loops for table builds.

/// `f(0), …, f(n − 1)` on all cores: thread j computes j, j + threads, … (interleaving balances
/// cheap and expensive items), so the result does not depend on the thread count.
pub(crate) fn parallel_map<T: Send>(n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let threads = std::thread::available_parallelism()
        .map_or(1, |c| c.get())
        .min(n)
        .max(1);
    let mut out: Vec<Option<T>> = (0..n).map(|_| None).collect();
    std::thread::scope(|s| {
        let f = &f;
        let handles: Vec<_> = (0..threads)
            .map(|j| {
                s.spawn(move || {
                    (j..n)
                        .step_by(threads)
                        .map(|k| (k, f(k)))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        for h in handles {
            for (k, v) in h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)) {
                out[k] = Some(v);
            }
        }
    });
    out.into_iter().flatten().collect()
}
