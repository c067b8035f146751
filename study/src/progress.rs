//! Where a running study reports to.

/// Where a running study reports: how many samples it has done, for a progress bar, and lines
/// for people. Warnings (samples dropped as NaN) are noted whatever
/// [`StudySettings::verbose`](super::StudySettings::verbose) says; the rest (renders redone,
/// tables built, the closing summary) only when it is set.
pub trait Progress: Sync {
    /// Rendering starts; it will take `samples` samples in all (pixels × spp over every render,
    /// counting the ones read back from an earlier run).
    fn start(&self, samples: u64);
    /// `samples` more are done (rendered, or read back).
    fn advance(&self, samples: u64);
    /// A line for people.
    fn note(&self, line: &str);
    /// Rendering is over; the tables and the report are written next.
    fn finish(&self);
}

/// Notes on stderr, and no progress bar: for callers without a terminal of their own (the
/// Python bindings).
pub struct NotesOnStderr;

impl Progress for NotesOnStderr {
    fn start(&self, _samples: u64) {}
    fn advance(&self, _samples: u64) {}
    fn note(&self, line: &str) {
        eprintln!("{line}");
    }
    fn finish(&self) {}
}
