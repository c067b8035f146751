//! Creating an Embree device turns on flush-to-zero and denormals-are-zero (MXCSR FTZ/DAZ) on
//! the calling thread and leaves them on. Only that thread then computes with denormals
//! flushed, so the same pixel could give different bits depending on which worker rendered it
//! (seen with dual scattering, whose `ā_f^n` reaches denormals in dark hair). Every tress
//! thread instead keeps the default floating-point environment — the one the compiler assumes —
//! by restoring the control word around the Embree call that changes it.

/// Runs `f` and restores the calling thread's floating-point control word afterwards.
pub(crate) fn preserving_fp_mode<T>(f: impl FnOnce() -> T) -> T {
    let saved = imp::control_word();
    let result = f();
    imp::set_control_word(saved);
    result
}

#[cfg(target_arch = "x86_64")]
mod imp {
    // `_mm_getcsr`/`_mm_setcsr` are deprecated because changing the FP environment under the
    // compiler is unsound in general; here they only put back the state the compiler assumes.
    #[allow(deprecated)]
    pub(super) fn control_word() -> u32 {
        // SAFETY: reading MXCSR has no side effect; SSE is part of the x86_64 baseline.
        unsafe { std::arch::x86_64::_mm_getcsr() }
    }

    #[allow(deprecated)]
    pub(super) fn set_control_word(word: u32) {
        // SAFETY: restores a value read from this thread's MXCSR by `control_word`.
        unsafe { std::arch::x86_64::_mm_setcsr(word) }
    }
}

#[cfg(not(target_arch = "x86_64"))]
mod imp {
    // Embree's FTZ/DAZ handling is an x86 (MXCSR) matter; elsewhere there is nothing to keep.
    pub(super) fn control_word() -> u32 {
        0
    }

    pub(super) fn set_control_word(_: u32) {}
}

#[cfg(test)]
mod tests {
    use super::*;
    use tress_core::math::Vec3;
    use tress_groom::test_util::{hair, line};

    #[test]
    fn building_a_scene_leaves_the_floating_point_mode_as_it_was() {
        let before = imp::control_word();
        let strands: Vec<_> = (0..4)
            .map(|i| {
                line(
                    Vec3::new(i as f32, 0.0, 0.0),
                    Vec3::new(i as f32, 5.0, 0.0),
                    6,
                )
            })
            .collect();
        let _accel = crate::SceneBuilder::new()
            .and_then(|b| b.add_hair(&hair(&strands, 0.1), &Default::default(), 0))
            .and_then(|b| b.build())
            .unwrap();
        // Compare the control bits only: the low six bits are sticky exception flags.
        assert_eq!(imp::control_word() & !0x3f, before & !0x3f);
    }
}
