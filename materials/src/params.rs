//! Model parameters: the error that names a bad one, the range check every model uses, and the
//! parameter sets each model hands the statistical tests.

/// An invalid model parameter.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
#[error("{field} = {value}: {reason}")]
pub struct ParamError {
    /// Name of the parameter, as written in scene files.
    pub field: &'static str,
    /// The rejected value, as text.
    pub value: String,
    /// What the value must be, e.g. `must lie in [0, 1]`.
    pub reason: String,
}

impl ParamError {
    /// An error saying that `field` = `value` breaks `reason`.
    pub fn new(
        field: &'static str,
        value: impl std::fmt::Display,
        reason: impl Into<String>,
    ) -> Self {
        ParamError {
            field,
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}

/// Checks that `value` lies in `[lo, hi]` (and is finite).
pub fn check_range(field: &'static str, value: f32, lo: f32, hi: f32) -> Result<(), ParamError> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(ParamError::new(
            field,
            value,
            format!("must lie in [{lo}, {hi}]"),
        ))
    }
}

/// A named parameter set used by the statistical tests of every model.
#[derive(Clone, Debug)]
pub struct TestInstance<P> {
    /// Short name of the instance, used in test messages.
    pub name: String,
    /// The model's parameters.
    pub params: P,
    /// Non-absorbing and energy conserving: the white-furnace oracle applies.
    pub white_furnace: bool,
}
