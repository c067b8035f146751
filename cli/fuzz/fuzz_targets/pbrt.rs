//! The pbrt curve reader on arbitrary text: an error or valid geometry, never a panic, and no
//! allocation beyond what the file's size justifies (a curve is refined into at most 2^10
//! pieces a segment). `Include`s resolve beside the scratch file.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tress_groom::PbrtFile;

fuzz_target!(|data: &[u8]| {
    let path = tress_fuzz::scratch_file("pbrt", data);
    if let Ok(hair) = PbrtFile::new(&path).read(&Default::default()) {
        assert!(hair.validate().is_ok());
        assert!(hair.points.iter().all(|p| p.is_finite()));
        assert!(hair.radii.iter().all(|r| r.is_finite() && *r > 0.0));
        assert!(!hair.bounds().is_empty());
    }
});
