//! Helpers shared by the unit tests of several models.

use crate::pigment::{Pigment, NO_TINT};
use crate::{HairModel, ParamError};
use std::fmt::Debug;

/// An edit of a model's default parameters, and the field the model must name in refusing it.
pub(crate) type BadEdit<P> = (fn(&mut P), &'static str);

/// Asserts that `new` refuses the default parameters changed by each edit of `cases`, naming
/// the field given beside the edit.
pub(crate) fn assert_rejected<P: Default + Debug, M: Debug>(
    new: impl Fn(&P) -> Result<M, ParamError>,
    cases: &[BadEdit<P>],
) {
    for (edit, field) in cases {
        let mut p = P::default();
        edit(&mut p);
        assert_eq!(new(&p).unwrap_err().field, *field, "{p:?}");
    }
}

/// One preparation context shared by every test of the crate, so that the tests share each
/// build of a table (dual scattering's, the fur's).
pub(crate) fn shared_prep() -> &'static tress_core::prepare::Preparation {
    static PREP: std::sync::OnceLock<tress_core::prepare::Preparation> = std::sync::OnceLock::new();
    PREP.get_or_init(tress_core::prepare::Preparation::new)
}

/// Dual-scattering tables through [`shared_prep`].
pub(crate) fn shared_tables(
    b: &dyn tress_core::Bcsdf,
    s: &crate::dual_scattering::DualScatteringSettings,
) -> std::sync::Arc<crate::dual_scattering::DualScatteringTables> {
    use crate::dual_scattering::{fingerprint, DualScatteringTables};
    shared_prep()
        .get_or_build((fingerprint(b), s.clone()), || {
            DualScatteringTables::new(b, s, &tress_core::limits::Limits::default())
        })
        .unwrap()
}

/// A Chiang model with β_n 0.4 and `pigment`: the registry's and per-strand variation's tests
/// vary the pigment of one model.
pub(crate) fn chiang(pigment: Pigment) -> HairModel {
    HairModel::Chiang(crate::chiang::Params {
        beta_n: 0.4,
        pigment,
        ..Default::default()
    })
}

/// Brown hair: eumelanin 1.3, pheomelanin 0.2, no tint.
pub(crate) fn brown() -> Pigment {
    Pigment::Melanin {
        eumelanin: 1.3,
        pheomelanin: 0.2,
        tint: NO_TINT,
    }
}
