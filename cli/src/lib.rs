//! The `tress` binary as a library: scene files, their objects and the integrator registry,
//! and [`run_study`]. The binary uses it as is, so fuzz targets (`cli/fuzz`), tests and the
//! Python bindings (`python/`) reach exactly the parser, validation and commands the binary runs.

#![warn(missing_docs)]

pub mod geometry;
pub mod integrators;
pub mod reference;
pub mod scene_desc;

// The commands. `main.rs` parses the command line and calls into these; they are the binary's
// internals, not an API, so they stay out of the documentation.
#[doc(hidden)]
pub mod bcsdf_cmd;
#[doc(hidden)]
pub mod bench;
#[doc(hidden)]
pub mod calibrate;
mod cost;
#[doc(hidden)]
pub mod diff;
#[doc(hidden)]
pub mod farm;
#[doc(hidden)]
pub mod interrupt;
#[doc(hidden)]
pub mod logging;
#[doc(hidden)]
pub mod merge;
mod plot;
#[doc(hidden)]
pub mod render_cmd;
mod render_file;
#[doc(hidden)]
pub mod study;

pub use study::{StudyArgs, StudyOutputs};

/// RON options for everything tress parses: newtype variants may omit their inner parentheses,
/// so `Chiang(beta_m: 0.3)` and `Path(max_depth: 8)` read naturally.
pub fn ron_options() -> ron::Options {
    ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES)
}

/// The run's limits as the environment sets them (`TRESS_MEMORY_LIMIT_GIB`,
/// `TRESS_ALLOW_SLOW_TABLES`): the front ends read them here and hand them to the libraries.
pub fn limits_from_env() -> tress_core::limits::Limits {
    use tress_core::limits::{Limits, ALLOW_SLOW_TABLES_VAR, MEMORY_LIMIT_VAR};
    Limits::from_environment_values(
        std::env::var(MEMORY_LIMIT_VAR).ok().as_deref(),
        std::env::var_os(ALLOW_SLOW_TABLES_VAR).is_some(),
    )
}

/// `threads` if this machine can use that many worker threads (0: one per core). More than
/// eight per core (or 64) only add overhead: `--threads 10000` on a 16² image crawled,
/// starting and switching threads.
pub fn check_threads(threads: usize) -> Result<usize, String> {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let max = (8 * cores).max(64);
    if threads > max {
        return Err(format!(
            "{threads} worker threads: at most {max} on this machine ({cores} cores); \
             0 or none uses one per core"
        ));
    }
    Ok(threads)
}

/// [`check_threads`] as a command-line value parser.
#[doc(hidden)]
pub fn parse_threads(s: &str) -> Result<usize, String> {
    check_threads(s.parse().map_err(|e| format!("{e}"))?)
}

/// A writer of one output, given the path to write (a temporary file beside the target).
pub type OutputWriter<'a> = Box<dyn FnOnce(&std::path::Path) -> anyhow::Result<()> + 'a>;

/// Writes outputs that belong together (an EXR and its PNG, a plot's PNG and SVG) all or
/// nothing: each is written to a temporary file beside its target, and only once all are
/// complete are they renamed into place. A failure before then leaves nothing; a rename failing
/// part way removes the outputs already renamed.
pub fn write_together(outputs: Vec<(&std::path::Path, OutputWriter<'_>)>) -> anyhow::Result<()> {
    use anyhow::Context;
    let mut staged = Vec::new();
    for (target, write) in outputs {
        let dir = target
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(std::path::Path::new("."));
        // The target's extension, which writers check.
        let suffix = target
            .extension()
            .map_or(String::new(), |e| format!(".{}", e.to_string_lossy()));
        let tmp = tress_core::image_io::output_temp_file(dir, &suffix)
            .with_context(|| format!("cannot write in {}", dir.display()))?;
        // The writer's message names the temporary file: say which output it was.
        write(tmp.path()).with_context(|| format!("writing {}", target.display()))?;
        staged.push((target, tmp.into_temp_path()));
    }
    let mut placed = Vec::new();
    for (target, tmp) in staged {
        if let Err(e) = tmp.persist(target) {
            for p in placed {
                let _ = std::fs::remove_file(p);
            }
            // The bare io::Error: the PathPersistError would keep the temporary file alive.
            return Err(e.error).with_context(|| format!("cannot create {}", target.display()));
        }
        placed.push(target);
    }
    Ok(())
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, so readers
/// never see a partial file.
pub fn atomic_write(path: &std::path::Path, bytes: &[u8]) -> anyhow::Result<()> {
    use anyhow::Context;
    use std::io::Write;
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(std::path::Path::new("."));
    let mut tmp = tress_core::image_io::output_temp_file(dir, ".tmp")
        .with_context(|| format!("cannot write in {}", dir.display()))?;
    tmp.write_all(bytes)
        .with_context(|| format!("writing {}", path.display()))?;
    // The bare io::Error: a kept PersistError would hold (and so leave behind) the temporary
    // file until the error is dropped, and would print the io error twice.
    tmp.persist(path)
        .map_err(|e| e.error)
        .with_context(|| format!("cannot create {}", path.display()))?;
    Ok(())
}

/// Runs a comparative study exactly as `tress study` does (`args` are its command-line
/// options) and says where it wrote its results.
pub fn run_study(args: StudyArgs) -> anyhow::Result<StudyOutputs> {
    study::run(args)
}

#[cfg(test)]
mod tests {
    use serde::de::DeserializeOwned;

    /// The ```` ```ron ```` blocks of a source file's doc comments.
    fn ron_blocks(source: &str) -> Vec<Vec<String>> {
        let mut blocks = Vec::new();
        let mut current: Option<Vec<String>> = None;
        for line in source.lines() {
            let Some(doc) = line.trim_start().strip_prefix("///") else {
                continue;
            };
            let doc = doc.strip_prefix(' ').unwrap_or(doc);
            match (&mut current, doc.trim()) {
                (None, "```ron") => current = Some(Vec::new()),
                (Some(_), "```") => blocks.extend(current.take()),
                (Some(block), _) => block.push(doc.split("//").next().unwrap().to_owned()),
                (None, _) => {}
            }
        }
        blocks
    }

    #[test]
    fn the_documented_hair_source_and_option_forms_parse_as_scene_files_write_them() {
        let blocks = ron_blocks(include_str!("../../accel/src/source.rs"));
        assert_eq!(blocks.len(), 2, "{blocks:?}");
        for line in blocks[0].iter().filter(|l| !l.trim().is_empty()) {
            crate::ron_options()
                .from_str::<tress_accel::HairSource>(line)
                .unwrap_or_else(|e| panic!("{line}: {e}"));
        }
        let options = blocks[1].join("\n");
        let parsed: tress_accel::HairOptions = crate::ron_options()
            .from_str(&options)
            .unwrap_or_else(|e| panic!("{options}: {e}"));
        assert_eq!(parsed.curve, tress_accel::CurveShape::Round);
    }

    /// The variant names of `T`, from the error a variant that does not exist gives.
    fn variants<T: DeserializeOwned + std::fmt::Debug>() -> Vec<String> {
        let err = crate::ron_options()
            .from_str::<T>("NoSuchVariant()")
            .unwrap_err()
            .to_string();
        let expected = err.rsplit("expected").next().unwrap_or_default();
        let names: Vec<String> = expected
            .split('`')
            .skip(1)
            .step_by(2)
            .filter(|n| *n != "NoSuchVariant" && n.chars().next().is_some_and(char::is_uppercase))
            .map(str::to_string)
            .collect();
        assert!(names.len() >= 2, "cannot read the variants from: {err}");
        names
    }

    /// Every variant of every enum a scene is written with refuses a misspelt field (the list of
    /// variants comes from serde, so a new variant is covered automatically).
    fn refuses_typos<T: DeserializeOwned + std::fmt::Debug>(what: &str) {
        for v in variants::<T>() {
            let text = format!("{v}(zz_typo: 1)");
            match crate::ron_options().from_str::<T>(&text) {
                Ok(parsed) => panic!("{what}: `{text}` was accepted as {parsed:?}"),
                // Struct variants name the field; tuple variants refuse the syntax. A missing-field
                // error would mean the misspelt field was skipped silently.
                Err(e) => assert!(
                    e.to_string().contains("zz_typo") || !e.to_string().contains("field"),
                    "{what}: `{text}` failed without naming the field: {e}"
                ),
            }
        }
    }

    #[test]
    fn misspelt_fields_are_refused_in_every_variant() {
        refuses_typos::<crate::scene_desc::MaterialDesc>("material");
        refuses_typos::<crate::scene_desc::LightDesc>("light");
        refuses_typos::<crate::geometry::ObjectDesc>("object");
        refuses_typos::<crate::integrators::IntegratorDesc>("integrator");
        refuses_typos::<tress_materials::HairModel>("hair model");
        refuses_typos::<tress_materials::pigment::Pigment>("pigment");
        refuses_typos::<tress_accel::HairSource>("hair source");
        refuses_typos::<tress_accel::HairStyle>("hair style");
    }
}
