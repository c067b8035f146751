//! What a run may spend: memory for films, hair, density grids and the text of included files,
//! and the build time of precomputed tables. Each is checked before the allocation or build
//! that would exceed it, so a typo in a scene fails at once with the size it asked for instead
//! of exhausting the machine.
//!
//! Library code is handed its [`Limits`]; only the front ends (the `tress` command, the Python
//! package) read them from the environment ([`MEMORY_LIMIT_VAR`], [`ALLOW_SLOW_TABLES_VAR`],
//! through [`Limits::from_environment_values`]), which is why error messages name the
//! variables.

/// Environment variable the front ends read to override [`DEFAULT_MEMORY_LIMIT_GIB`].
pub const MEMORY_LIMIT_VAR: &str = "TRESS_MEMORY_LIMIT_GIB";
/// The memory limit, in GiB, when [`MEMORY_LIMIT_VAR`] does not set one.
pub const DEFAULT_MEMORY_LIMIT_GIB: f64 = 16.0;
/// Environment variable the front ends read: when set (to anything), tables beyond their work
/// limit are built anyway ([`Limits::slow_tables`]).
pub const ALLOW_SLOW_TABLES_VAR: &str = "TRESS_ALLOW_SLOW_TABLES";

/// The limits of a run (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Memory a render may plan for, in GiB (positive): films, hair points, density grids and
    /// the text of included files are checked against it before they are allocated.
    pub memory_gib: f64,
    /// Build precomputed tables whatever their cost (dual scattering's tables beyond
    /// `MAX_TABLE_WORK` times the default tables' work are refused otherwise).
    pub slow_tables: bool,
}

impl Default for Limits {
    /// [`DEFAULT_MEMORY_LIMIT_GIB`], and no slow tables.
    fn default() -> Self {
        Limits {
            memory_gib: DEFAULT_MEMORY_LIMIT_GIB,
            slow_tables: false,
        }
    }
}

impl Limits {
    /// The limits the environment sets, given what the front end read: `memory_limit_gib`,
    /// the value of [`MEMORY_LIMIT_VAR`], when it is a positive number (else the default), and
    /// slow tables when [`ALLOW_SLOW_TABLES_VAR`] is set at all.
    pub fn from_environment_values(
        memory_limit_gib: Option<&str>,
        allow_slow_tables: bool,
    ) -> Self {
        let memory_gib = memory_limit_gib
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|g| *g > 0.0)
            .unwrap_or(DEFAULT_MEMORY_LIMIT_GIB);
        Limits {
            memory_gib,
            slow_tables: allow_slow_tables,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_a_positive_number_overrides_the_memory_limit() {
        let memory = |v| Limits::from_environment_values(v, false).memory_gib;
        assert_eq!(memory(Some("0.5")), 0.5);
        assert_eq!(memory(Some("64")), 64.0);
        for ignored in [
            None,
            Some(""),
            Some("0"),
            Some("-2"),
            Some("lots"),
            Some("NaN"),
        ] {
            assert_eq!(memory(ignored), DEFAULT_MEMORY_LIMIT_GIB, "{ignored:?}");
        }
        assert!(Limits::from_environment_values(None, true).slow_tables);
        assert_eq!(
            Limits::from_environment_values(None, false),
            Limits::default()
        );
    }
}
