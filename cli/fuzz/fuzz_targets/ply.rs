//! The PLY strand reader on arbitrary bytes, with and without `points_per_strand`: an error or
//! valid geometry, never a panic, and no allocation beyond what the file's size justifies.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tress_groom::PlyFile;

fuzz_target!(|data: &[u8]| {
    let path = tress_fuzz::scratch_file("ply", data);
    for points_per_strand in [None, Some(3)] {
        let file = PlyFile {
            points_per_strand,
            ..PlyFile::new(&path)
        };
        if let Ok(hair) = file.read() {
            assert!(hair.validate().is_ok());
            assert!(hair.points.iter().all(|p| p.is_finite()));
            assert!(hair.radii.iter().all(|r| r.is_finite() && *r > 0.0));
            assert!(!hair.bounds().is_empty());
        }
    }
});
