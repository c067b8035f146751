//! Helpers shared by the unit tests of several models.

use crate::ParamError;
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
