//! Paths in scene files.

use std::path::{Path, PathBuf};

/// Resolves `p` against the folder holding the scene file.
pub fn resolve(scene_path: &Path, p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        scene_path.parent().unwrap_or(Path::new(".")).join(p)
    }
}
