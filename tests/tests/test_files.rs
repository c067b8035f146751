//! Every test file is compiled. A crate whose `Cargo.toml` sets `autotests = false` builds its
//! integration tests as one binary from `tests/main.rs`, and Cargo then ignores every file of
//! `tests/` that main.rs does not declare as a module: its tests would silently never run.

use crate::workspace;
use std::path::Path;

/// The modules of `tests/` that `tests/main.rs` of `member` fails to declare, as paths; empty
/// when the member's tests are Cargo's usual one binary per file.
fn undeclared_test_files(root: &Path, member: &str) -> Vec<String> {
    let dir = root.join(member);
    let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
    if !manifest.lines().any(|l| l.trim() == "autotests = false") {
        return Vec::new();
    }
    let tests = dir.join("tests");
    let main = std::fs::read_to_string(tests.join("main.rs"))
        .unwrap_or_else(|e| panic!("{member}/tests/main.rs: {e}"));
    let declared: Vec<&str> = main
        .lines()
        .filter_map(|l| l.trim().strip_prefix("mod ")?.strip_suffix(';'))
        .collect();
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(&tests).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        // A file `x.rs`, or a folder `x/` with a `mod.rs` (other folders hold data).
        let module = match name.strip_suffix(".rs") {
            Some(stem) if stem != "main" => stem,
            Some(_) => continue,
            None if path.join("mod.rs").is_file() => name.as_str(),
            None => continue,
        };
        if !declared.contains(&module) {
            missing.push(format!("{member}/tests/{name}"));
        }
    }
    missing.sort();
    missing
}

#[test]
fn test_files_are_modules() {
    let root = workspace::root();
    let missing: Vec<String> = workspace::members(&root)
        .unwrap()
        .iter()
        .flat_map(|m| undeclared_test_files(&root, m))
        .collect();
    assert!(
        missing.is_empty(),
        "not declared in their crate's tests/main.rs (`mod name;`), so never compiled: {missing:?}"
    );
}

#[test]
fn an_undeclared_test_file_or_folder_is_found() {
    let root = tempfile::tempdir().unwrap();
    let write = |path: &str, text: &str| {
        let path = root.path().join(path);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    };
    write("Cargo.toml", "[workspace]\nmembers = [\"one\", \"two\"]\n");
    write("one/Cargo.toml", "[package]\nautotests = false\n");
    write("one/tests/main.rs", "//! Tests.\n\nmod a;\nmod common;\n");
    for file in [
        "a.rs",
        "b.rs",
        "common/mod.rs",
        "helpers/mod.rs",
        "data/x.rs",
    ] {
        write(&format!("one/tests/{file}"), "");
    }
    // Cargo's default: every file is its own binary.
    write("two/Cargo.toml", "[package]\n");
    write("two/tests/c.rs", "");
    let missing: Vec<String> = workspace::members(root.path())
        .unwrap()
        .iter()
        .flat_map(|m| undeclared_test_files(root.path(), m))
        .collect();
    assert_eq!(missing, ["one/tests/b.rs", "one/tests/helpers"]);
}
