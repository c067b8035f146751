//! The USD reader on arbitrary bytes, as `.usdc` when they start with the binary format's magic
//! and as `.usda` otherwise: an error or valid geometry, never a panic (a panic inside the USD
//! library is a failure here even though the reader contains it), a stack overflow or an
//! allocation beyond what the file's size justifies. References and sublayers resolve beside
//! the scratch file. The memory limit is half a GiB, so that what it allows stays under
//! libFuzzer's -rss_limit_mb (2 GB by default) and anything beyond it is a finding.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tress_groom::UsdFile;
use tress_core::limits::Limits;

fuzz_target!(|data: &[u8]| {
    let ext = if data.starts_with(b"PXR-USDC") {
        "usdc"
    } else {
        "usda"
    };
    let path = tress_fuzz::scratch_file(ext, data);
    let limits = Limits {
        memory_gib: 0.5,
        ..Limits::default()
    };
    if let Ok(hair) = UsdFile::new(&path).read(&limits) {
        assert!(hair.validate().is_ok());
        assert!(hair.points.iter().all(|p| p.is_finite()));
        assert!(hair.radii.iter().all(|r| r.is_finite() && *r > 0.0));
        assert!(!hair.bounds().is_empty());
    }
});
