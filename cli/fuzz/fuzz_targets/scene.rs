//! The scene loader on arbitrary text: `scene_desc::parse` (RON with tress's options, and the
//! error message that quotes the offending line), then the checks that need no files — film
//! validation and building every hair model's parameters.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tress_loader::materials::MaterialDesc;
use tress_loader::scene_desc;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match scene_desc::parse(text) {
        Ok(desc) => {
            let _ = desc.film.validate();
            for material in desc.materials.values() {
                if let MaterialDesc::Hair(model) = material {
                    let _ = model.build(&Default::default());
                }
            }
        }
        Err(error) => assert!(!error.to_string().is_empty()),
    }
});
