//! How many worker threads a run may ask for.

/// `threads` if this machine can use that many worker threads (0: one per core). More than
/// eight per core (or 64) only add overhead: `--threads 10000` on a 16² image crawled,
/// starting and switching threads.
pub fn check_threads(threads: usize) -> Result<usize, String> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let max = (8 * cores).max(64);
    if threads > max {
        return Err(format!(
            "{threads} worker threads: at most {max} on this machine ({cores} cores); \
             0 or none uses one per core"
        ));
    }
    Ok(threads)
}
