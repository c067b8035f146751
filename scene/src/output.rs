//! Writing outputs so that readers never see a partial file: through a temporary file beside
//! the target and a rename.

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
