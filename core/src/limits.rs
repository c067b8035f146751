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
    /// Memory the scene's objects added so far take, in GiB: the memory limit holds for the
    /// whole scene, so what an object adds is checked with this counted in (four objects of
    /// 0.7 GiB each passed a 1 GiB limit when each was checked alone).
    pub scene_gib: f64,
    /// Build precomputed tables whatever their cost (dual scattering's tables beyond
    /// `MAX_TABLE_WORK` times the default tables' work are refused otherwise).
    pub slow_tables: bool,
}

impl Default for Limits {
    /// [`DEFAULT_MEMORY_LIMIT_GIB`], and no slow tables.
    fn default() -> Self {
        Limits {
            memory_gib: DEFAULT_MEMORY_LIMIT_GIB,
            scene_gib: 0.0,
            slow_tables: false,
        }
    }
}

impl Limits {
    /// Refuses `need_gib` more for the scene when, with [`Limits::scene_gib`], it would pass
    /// the memory limit; the reason says how much the scene already takes.
    pub fn check_scene_memory(&self, need_gib: f64) -> Result<(), String> {
        let (scene, limit) = (self.scene_gib, self.memory_gib);
        if scene + need_gib <= limit {
            return Ok(());
        }
        let before = if scene > 0.0 {
            format!(
                ", {:.3} GiB with the {scene:.3} GiB of the objects before it",
                scene + need_gib
            )
        } else {
            String::new()
        };
        Err(format!(
            "about {need_gib:.3} GiB{before}, over the {limit} GiB limit for the whole scene: \
             use fewer, or set {MEMORY_LIMIT_VAR} to more GiB"
        ))
    }

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
            scene_gib: 0.0,
            slow_tables: allow_slow_tables,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scene_memory_check_counts_what_the_scene_holds() {
        let mut limits = Limits {
            memory_gib: 1.0,
            ..Limits::default()
        };
        assert!(limits.check_scene_memory(0.7).is_ok());
        let e = limits.check_scene_memory(1.5).unwrap_err();
        assert!(e.contains("1.500 GiB") && !e.contains("before it"), "{e}");
        limits.scene_gib = 0.7;
        let e = limits.check_scene_memory(0.7).unwrap_err();
        assert!(
            e.contains("1.400 GiB with the 0.700 GiB of the objects before it"),
            "{e}"
        );
        assert!(
            e.contains("1 GiB limit") && e.contains(MEMORY_LIMIT_VAR),
            "{e}"
        );
    }

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
            Limits::from_environment_values(Some("8"), false).scene_gib,
            0.0
        );
        assert_eq!(
            Limits::from_environment_values(None, false),
            Limits::default()
        );
    }
}
