//! The Cem Yuksel HAIR reader on arbitrary bytes: an error or valid geometry, never a panic, and
//! no allocation beyond what the file's size justifies (libFuzzer's -rss_limit_mb catches that).
#![no_main]

use libfuzzer_sys::fuzz_target;
use tress_groom::HairFile;

fuzz_target!(|data: &[u8]| {
    let path = tress_fuzz::scratch_file("hair", data);
    for z_up in [true, false] {
        if let Ok(hair) = (HairFile {
            path: path.clone(),
            z_up,
        })
        .read()
        {
            // What the reader returns has passed validation: check it holds.
            assert!(hair.validate().is_ok());
            assert!(hair.points.iter().all(|p| p.is_finite()));
            assert!(hair.radii.iter().all(|r| r.is_finite() && *r > 0.0));
            assert!(!hair.bounds().is_empty());
        }
    }
});
