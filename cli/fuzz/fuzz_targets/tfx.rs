//! The AMD TressFX reader on arbitrary bytes: an error or valid geometry, never a panic, and no
//! allocation beyond what the file's size justifies.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tress_groom::TfxFile;

fuzz_target!(|data: &[u8]| {
    let path = tress_fuzz::scratch_file("tfx", data);
    if let Ok(hair) = TfxFile::new(&path).read() {
        assert!(hair.validate().is_ok());
        assert!(hair.points.iter().all(|p| p.is_finite()));
        assert!(hair.radii.iter().all(|r| r.is_finite() && *r > 0.0));
        assert!(!hair.bounds().is_empty());
    }
});
