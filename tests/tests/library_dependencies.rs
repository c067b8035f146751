//! Library crates report typed errors (thiserror) that keep their causes as sources; `anyhow`,
//! which erases the type, is for the binaries (the command line, tests, examples). This checks
//! that no library crate depends on it outside its dev-dependencies.

use crate::workspace;

/// Library crates allowed to depend on anyhow, and why.
const ALLOWED: [(&str, &str); 1] = [(
    "groom",
    "openusd's API returns anyhow errors, which the USD reader turns into tress_groom::Error",
)];

/// The crates named in the `[dependencies]` tables of `manifest` (target-specific ones too),
/// not in `[dev-dependencies]`: what the library itself links.
fn normal_dependencies(manifest: &str) -> Vec<String> {
    let mut names = Vec::new();
    let mut in_dependencies = false;
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            let table = line.trim_matches(|c| c == '[' || c == ']');
            in_dependencies = table == "dependencies" || table.ends_with(".dependencies");
            // `[dependencies.anyhow]` names the crate in the header.
            if let Some(name) = table.strip_prefix("dependencies.") {
                names.push(name.to_owned());
                in_dependencies = false;
            }
            continue;
        }
        if in_dependencies && !line.starts_with('#') {
            if let Some(key) = line.split(['=', '.']).next().map(str::trim) {
                if !key.is_empty() {
                    names.push(key.to_owned());
                }
            }
        }
    }
    names
}

#[test]
fn library_crates_do_not_depend_on_anyhow() {
    let root = workspace::root();
    let mut offenders = Vec::new();
    for member in workspace::library_members(&root).unwrap() {
        let path = root.join(&member).join("Cargo.toml");
        let manifest =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let allowed = ALLOWED.iter().any(|(crate_dir, _)| *crate_dir == member);
        if normal_dependencies(&manifest).iter().any(|d| d == "anyhow") && !allowed {
            offenders.push(member);
        }
    }
    assert!(
        offenders.is_empty(),
        "library crates depending on anyhow (give them thiserror errors that keep their \
         sources): {offenders:?}"
    );
}

#[test]
fn the_dependency_reader_finds_anyhow_where_the_library_links_it() {
    let manifest = r#"
[package]
name = "x"

[dependencies]
thiserror.workspace = true
anyhow = "1"

[dev-dependencies]
tempfile.workspace = true
"#;
    assert_eq!(normal_dependencies(manifest), ["thiserror", "anyhow"]);
    let dev_only = "[dependencies]\nthiserror = \"2\"\n\n[dev-dependencies]\nanyhow = \"1\"\n";
    assert_eq!(normal_dependencies(dev_only), ["thiserror"]);
    let by_table = "[target.'cfg(unix)'.dependencies]\nlibc = \"0.2\"\n[dependencies.anyhow]\nversion = \"1\"\n";
    assert_eq!(normal_dependencies(by_table), ["libc", "anyhow"]);
}
