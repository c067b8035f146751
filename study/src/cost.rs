//! What a piece of work cost: wall time and, from the kernel's per-thread scheduler statistics,
//! the CPU time of the process's threads and their time spent waiting for a core. CPU time is
//! the cost measure that survives other processes' load on a shared machine.

use std::time::Instant;

/// Wall time, and where the kernel's scheduler statistics are available, the CPU time of all
/// the process's threads and the time they were runnable but waiting for a core (other
/// processes' load), in seconds.
#[derive(Clone, Copy, Debug)]
pub struct Cost {
    /// Wall seconds.
    pub wall: f64,
    /// CPU seconds of all the process's threads.
    pub cpu: Option<f64>,
    /// Seconds the process's threads were runnable but waiting for a core.
    pub wait: Option<f64>,
}

impl Cost {
    /// Share of the runnable time spent waiting for a core.
    pub fn waiting(&self) -> Option<f64> {
        let (cpu, wait) = (self.cpu?, self.wait?);
        (cpu + wait > 0.0).then(|| wait / (cpu + wait))
    }
}

/// Run and wait nanoseconds summed over the process's threads (/proc/self/task/*/schedstat).
fn schedstat() -> Option<(u64, u64)> {
    let (mut run, mut wait) = (0, 0);
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let text = std::fs::read_to_string(task.ok()?.path().join("schedstat")).ok()?;
        let mut fields = text.split_whitespace().map(str::parse::<u64>);
        run += fields.next()?.ok()?;
        wait += fields.next()?.ok()?;
    }
    Some((run, wait))
}

/// Runs `f` and says what it cost.
pub fn timed<R>(f: impl FnOnce() -> R) -> (R, Cost) {
    let before = schedstat();
    let start = Instant::now();
    let r = f();
    let wall = start.elapsed().as_secs_f64();
    let after = schedstat();
    let delta = before.zip(after).map(|(b, a)| {
        (
            a.0.saturating_sub(b.0) as f64 * 1e-9,
            a.1.saturating_sub(b.1) as f64 * 1e-9,
        )
    });
    (
        r,
        Cost {
            wall,
            cpu: delta.map(|d| d.0),
            wait: delta.map(|d| d.1),
        },
    )
}
