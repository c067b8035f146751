//! Shared by the fuzz targets: the readers take file paths, so each input is written to a
//! scratch file first.

use std::path::PathBuf;

/// Writes `data` to this process's scratch file with extension `ext` (in memory when /dev/shm
/// exists) and returns its path.
pub fn scratch_file(ext: &str, data: &[u8]) -> PathBuf {
    let dir = PathBuf::from("/dev/shm");
    let dir = if dir.is_dir() {
        dir
    } else {
        std::env::temp_dir()
    };
    let path = dir.join(format!("tress-fuzz-{}.{ext}", std::process::id()));
    std::fs::write(&path, data).expect("write the scratch file");
    path
}
