//! The workspace these tests check: its root folder and its members, read from the root
//! `Cargo.toml`, for the tests that read the sources and manifests (library_sources,
//! library_dependencies, test_files, docs_links).

use std::path::{Path, PathBuf};

/// The workspace's root folder (tests/ is one of its members).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ lies in the workspace")
        .to_path_buf()
}

/// The members the `Cargo.toml` at `root` lists in `members = [...]`, as paths (e.g.
/// `integrators/path`); comments in the list are skipped.
pub fn members(root: &Path) -> Result<Vec<String>, String> {
    let manifest = root.join("Cargo.toml");
    let text =
        std::fs::read_to_string(&manifest).map_err(|e| format!("{}: {e}", manifest.display()))?;
    let start = text
        .find("members")
        .and_then(|m| text[m..].find('[').map(|b| m + b + 1))
        .ok_or_else(|| format!("{}: no `members = [...]`", manifest.display()))?;
    let end = text[start..]
        .find(']')
        .map(|e| start + e)
        .ok_or_else(|| format!("{}: unterminated `members`", manifest.display()))?;
    let members: Vec<String> = text[start..end]
        .lines()
        .map(|l| l.split('#').next().unwrap_or(""))
        .flat_map(|l| l.split(','))
        .map(|m| m.trim().trim_matches('"').to_owned())
        .filter(|m| !m.is_empty())
        .collect();
    if members.is_empty() {
        return Err(format!("{}: `members` is empty", manifest.display()));
    }
    Ok(members)
}

/// The workspace members that are front ends (may read the environment, may use anyhow);
/// every other member is a library crate.
const FRONT_ENDS: [&str; 2] = ["cli", "python"];

/// The library members of the workspace at `root`: those its `Cargo.toml` lists, bar the
/// front ends.
pub fn library_members(root: &Path) -> Result<Vec<String>, String> {
    Ok(members(root)?
        .into_iter()
        .filter(|m| !FRONT_ENDS.contains(&m.as_str()))
        .collect())
}
