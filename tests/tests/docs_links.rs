//! The documentation's links stay valid: in `README.md` and the book (`docs/src`), every relative
//! link names a file that exists and every `#anchor` a heading of its target; links in the book
//! stay inside `docs/src` (mdBook copies nothing else into the built book); every chapter is in
//! `SUMMARY.md`; and every `docs/src/….md#anchor` that a Rust source or a scene file cites
//! resolves too.
//!
//! Heading anchors follow mdBook's rule (GitHub's is the same for what the docs use): the
//! heading's text, lower-cased, each whitespace character replaced by `-`, every character that
//! is not alphanumeric, `-` or `_` dropped; a repeated id gets `-1`, `-2`, … `{{#include FILE}}`
//! is expanded as mdBook expands it, so anchors into included text resolve in the including
//! chapter. External links (`http:`, `https:`, `mailto:`) are not fetched.

use crate::workspace;
use std::collections::{BTreeMap, BTreeSet, HashSet};
use std::path::{Component, Path, PathBuf};

/// The book's source folder, relative to the repository.
const BOOK_SRC: &str = "docs/src";

/// This file, whose tests cite made-up chapters on purpose.
const THIS_FILE: &str = "tests/tests/docs_links.rs";

/// Where the documents come from: the repository on disk, or a few files a test makes up.
trait Files {
    /// The text of a file (a repository-relative path), if it is a readable file.
    fn read(&self, path: &Path) -> Option<String>;
    /// Whether a file or folder exists there.
    fn exists(&self, path: &Path) -> bool;
    /// Every file under `dir` whose name ends in `.{ext}`, repository-relative, sorted; hidden
    /// and `target*` folders and symbolic links to folders are not entered.
    fn files_under(&self, dir: &Path, ext: &str) -> Vec<PathBuf>;
}

struct Repository(PathBuf);

impl Files for Repository {
    fn read(&self, path: &Path) -> Option<String> {
        std::fs::read_to_string(self.0.join(path)).ok()
    }

    fn exists(&self, path: &Path) -> bool {
        self.0.join(path).exists()
    }

    fn files_under(&self, dir: &Path, ext: &str) -> Vec<PathBuf> {
        fn walk(root: &Path, dir: &Path, ext: &str, out: &mut Vec<PathBuf>) {
            let Ok(entries) = std::fs::read_dir(root.join(dir)) else {
                return;
            };
            for entry in entries.flatten() {
                let name = entry.file_name().to_string_lossy().into_owned();
                let rel = dir.join(&name);
                let Ok(kind) = entry.file_type() else {
                    continue;
                };
                if kind.is_dir() {
                    if !name.starts_with('.')
                        && !name.starts_with("target")
                        && rel != Path::new("docs/book")
                    {
                        walk(root, &rel, ext, out);
                    }
                } else if kind.is_file() && name.ends_with(&format!(".{ext}")) {
                    out.push(rel);
                }
            }
        }
        let mut out = Vec::new();
        walk(&self.0, dir, ext, &mut out);
        out.sort();
        out
    }
}

/// A path made of its normal components only (`a/./b/../c` → `a/c`); `None` when it climbs out
/// of the repository or is absolute.
fn normalize(path: &Path) -> Option<PathBuf> {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::Normal(part) => out.push(part),
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    return None;
                }
            }
            Component::RootDir | Component::Prefix(_) => return None,
        }
    }
    Some(out)
}

/// mdBook's heading id: lower case, whitespace → `-`, only alphanumerics, `-` and `_` kept.
fn heading_id(text: &str) -> String {
    text.trim()
        .to_lowercase()
        .chars()
        .filter_map(|c| {
            if c.is_alphanumeric() || c == '-' || c == '_' {
                Some(c)
            } else if c.is_whitespace() {
                Some('-')
            } else {
                None
            }
        })
        .collect()
}

/// The text of a document outside fenced code blocks, line by line (1-based line numbers);
/// fenced lines are blanked so that line numbers stay right.
fn outside_fences(text: &str) -> Vec<(usize, String)> {
    let mut fence: Option<String> = None;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        let marker: String = trimmed
            .chars()
            .take_while(|&c| c == '`' || c == '~')
            .collect();
        let is_marker =
            marker.len() >= 3 && marker.chars().all(|c| c == marker.as_bytes()[0] as char);
        match &fence {
            Some(open) => {
                if is_marker
                    && marker.starts_with(open.as_str())
                    && trimmed[marker.len()..].trim().is_empty()
                {
                    fence = None;
                }
                out.push((i + 1, String::new()));
            }
            None if is_marker => {
                fence = Some(marker);
                out.push((i + 1, String::new()));
            }
            None => out.push((i + 1, line.to_string())),
        }
    }
    out
}

/// `lines` with every inline code span blanked out (a run of n backticks up to the next run of
/// exactly n, within a paragraph); an unclosed run stays as literal text.
fn without_code_spans(lines: &[(usize, String)]) -> Vec<(usize, String)> {
    let mut out: Vec<(usize, Vec<char>)> = lines
        .iter()
        .map(|(n, l)| (*n, l.chars().collect()))
        .collect();
    // Paragraphs: runs of non-blank lines.
    let mut start = 0;
    while start < out.len() {
        let mut end = start;
        while end < out.len() && !out[end].1.iter().all(|c| c.is_whitespace()) {
            end += 1;
        }
        // Positions (line, column) of the paragraph's characters, joined by newlines.
        let mut chars: Vec<(usize, usize, char)> = Vec::new();
        for (li, (_, line)) in out.iter().enumerate().take(end).skip(start) {
            for (ci, &c) in line.iter().enumerate() {
                chars.push((li, ci, c));
            }
            chars.push((li, usize::MAX, '\n'));
        }
        let mut i = 0;
        while i < chars.len() {
            if chars[i].2 != '`' {
                i += 1;
                continue;
            }
            let run = chars[i..].iter().take_while(|c| c.2 == '`').count();
            let mut j = i + run;
            let mut close = None;
            while j < chars.len() {
                if chars[j].2 == '`' {
                    let n = chars[j..].iter().take_while(|c| c.2 == '`').count();
                    if n == run {
                        close = Some(j + n);
                        break;
                    }
                    j += n;
                } else {
                    j += 1;
                }
            }
            match close {
                Some(after) => {
                    for &(li, ci, _) in &chars[i..after] {
                        if ci != usize::MAX {
                            out[li].1[ci] = ' ';
                        }
                    }
                    i = after;
                }
                None => i += run,
            }
        }
        start = end + 1;
    }
    out.into_iter()
        .map(|(n, l)| (n, l.into_iter().collect()))
        .collect()
}

/// The link targets of a line: inline links and images `[text](target "title")`, and reference
/// definitions `[label]: target`.
fn link_targets(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let trimmed = line.trim_start();
    if let Some(rest) = trimmed.strip_prefix('[') {
        if let Some(close) = rest.find("]:") {
            if let Some(target) = rest[close + 2..].split_whitespace().next() {
                out.push(target.trim_matches(|c| c == '<' || c == '>').to_string());
            }
        }
    }
    let mut from = 0;
    while let Some(k) = line[from..].find("](") {
        let start = from + k + 2;
        let mut depth = 0;
        let mut end = line.len();
        for (i, c) in line[start..].char_indices() {
            match c {
                '(' => depth += 1,
                ')' if depth == 0 => {
                    end = start + i;
                    break;
                }
                ')' => depth -= 1,
                _ => {}
            }
        }
        let inner = line[start..end].trim();
        let target = inner.split_whitespace().next().unwrap_or("");
        out.push(target.trim_matches(|c| c == '<' || c == '>').to_string());
        from = end.min(line.len());
        if from == line.len() {
            break;
        }
    }
    out
}

/// The plain text of a heading: code spans unwrapped, links and images reduced to their text,
/// emphasis markers and HTML tags dropped.
fn heading_text(raw: &str) -> String {
    let mut text = String::new();
    let mut chars = raw.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '`' | '*' => {}
            '!' if chars.peek() == Some(&'[') => {}
            '[' => {}
            ']' if chars.peek() == Some(&'(') => {
                // Skip the link's target.
                let mut depth = 0;
                for d in chars.by_ref() {
                    match d {
                        '(' => depth += 1,
                        ')' => {
                            depth -= 1;
                            if depth == 0 {
                                break;
                            }
                        }
                        _ => {}
                    }
                }
            }
            ']' => {}
            '<' => {
                for d in chars.by_ref() {
                    if d == '>' {
                        break;
                    }
                }
            }
            _ => text.push(c),
        }
    }
    text
}

/// The ids of a document's headings, as mdBook assigns them.
fn heading_ids(text: &str) -> HashSet<String> {
    let mut ids = HashSet::new();
    for (_, line) in outside_fences(text) {
        let trimmed = line.trim_start();
        let level = trimmed.chars().take_while(|&c| c == '#').count();
        if level == 0 || level > 6 || line.len() - trimmed.len() > 3 {
            continue;
        }
        let rest = &trimmed[level..];
        if !(rest.is_empty() || rest.starts_with(' ') || rest.starts_with('\t')) {
            continue;
        }
        let mut content = rest.trim().trim_end_matches('#').trim_end().to_string();
        let id = match content.rfind("{#") {
            Some(k) if content.ends_with('}') => {
                let id = content[k + 2..content.len() - 1]
                    .split_whitespace()
                    .next()
                    .unwrap_or("")
                    .to_string();
                content.truncate(k);
                id
            }
            _ => heading_id(&heading_text(&content)),
        };
        let mut unique = id.clone();
        let mut n = 1;
        while !ids.insert(unique.clone()) {
            unique = format!("{id}-{n}");
            n += 1;
        }
    }
    ids
}

/// A book chapter with its `{{#include FILE}}` directives replaced by the files' text, as
/// mdBook does before rendering (paths relative to the including file). Other `{{#…}}`
/// directives are reported, so that the check never passes text it does not understand.
fn expand_includes(
    files: &dyn Files,
    path: &Path,
    text: &str,
    depth: usize,
    problems: &mut Vec<String>,
) -> String {
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        let Some(k) = line.find("{{#") else {
            out.push_str(line);
            out.push('\n');
            continue;
        };
        let Some(end) = line[k..].find("}}") else {
            problems.push(format!("{}:{}: unclosed {{{{#", path.display(), i + 1));
            continue;
        };
        let directive = line[k + 3..k + end].trim();
        let included = directive
            .strip_prefix("include ")
            .map(str::trim)
            .filter(|p| !p.contains(':'));
        let Some(included) = included else {
            problems.push(format!(
                "{}:{}: {{{{#{directive}}}}}: only whole-file includes are checked",
                path.display(),
                i + 1
            ));
            continue;
        };
        let target = path.parent().map(|d| d.join(included));
        let text = target
            .as_deref()
            .and_then(normalize)
            .and_then(|t| files.read(&t).map(|s| (t, s)));
        match text {
            Some((target, text)) if depth < 8 => {
                out.push_str(&line[..k]);
                out.push_str(&expand_includes(files, &target, &text, depth + 1, problems));
                out.push_str(&line[k + end + 2..]);
                out.push('\n');
            }
            _ => problems.push(format!(
                "{}:{}: {{{{#include {included}}}}}: no such file (or includes nested too deep)",
                path.display(),
                i + 1
            )),
        }
    }
    out
}

fn is_external(target: &str) -> bool {
    ["http://", "https://", "mailto:"]
        .iter()
        .any(|scheme| target.starts_with(scheme))
}

/// Checks one link of `from` (line `line`; `shown` names the place in messages): the file
/// exists, stays in the book when `from` is a chapter, and the anchor names a heading of the
/// target.
fn check_link(
    files: &dyn Files,
    from: &Path,
    shown: &Path,
    line: usize,
    target: &str,
    own_ids: &HashSet<String>,
    problems: &mut Vec<String>,
) {
    if target.is_empty() {
        problems.push(format!("{}:{line}: empty link target", shown.display()));
        return;
    }
    if is_external(target) {
        return;
    }
    let (file, anchor) = match target.split_once('#') {
        Some((f, a)) => (f, Some(a)),
        None => (target, None),
    };
    let here = format!("{}:{line}: link '{target}'", shown.display());
    let resolved = if file.is_empty() {
        Some(from.to_path_buf())
    } else {
        from.parent().and_then(|d| normalize(&d.join(file)))
    };
    let Some(resolved) = resolved else {
        problems.push(format!("{here}: leaves the repository"));
        return;
    };
    if !files.exists(&resolved) {
        problems.push(format!("{here}: no such file {}", resolved.display()));
        return;
    }
    if from.starts_with(BOOK_SRC) && !resolved.starts_with(BOOK_SRC) {
        problems.push(format!(
            "{here}: points outside {BOOK_SRC}, which the built book does not contain"
        ));
    }
    let Some(anchor) = anchor else {
        return;
    };
    let ids = if file.is_empty() {
        own_ids.clone()
    } else if resolved.extension().is_some_and(|e| e == "md") {
        let text = files.read(&resolved).unwrap_or_default();
        let text = if resolved.starts_with(BOOK_SRC) {
            expand_includes(files, &resolved, &text, 0, &mut Vec::new())
        } else {
            text
        };
        heading_ids(&text)
    } else {
        problems.push(format!(
            "{here}: an anchor into a file that is not Markdown"
        ));
        return;
    };
    if !ids.contains(anchor) {
        problems.push(format!("{here}: no heading with the id '{anchor}'"));
    }
}

/// Every problem with the documentation in `files`, one line each.
fn check(files: &dyn Files) -> Vec<String> {
    let mut problems = Vec::new();
    let chapters = files.files_under(Path::new(BOOK_SRC), "md");
    let mut documents = vec![PathBuf::from("README.md")];
    documents.extend(chapters.iter().cloned());
    for doc in &documents {
        let Some(text) = files.read(doc) else {
            problems.push(format!("{}: cannot read it", doc.display()));
            continue;
        };
        let text = if doc.starts_with(BOOK_SRC) {
            expand_includes(files, doc, &text, 0, &mut problems)
        } else {
            text
        };
        let own_ids = heading_ids(&text);
        for (line, prose) in without_code_spans(&outside_fences(&text)) {
            for target in link_targets(&prose) {
                check_link(files, doc, doc, line, &target, &own_ids, &mut problems);
            }
        }
    }

    // Every chapter is in the summary (mdBook renders only what SUMMARY.md lists).
    let summary = Path::new(BOOK_SRC).join("SUMMARY.md");
    let listed: BTreeSet<PathBuf> = files
        .read(&summary)
        .map(|text| {
            without_code_spans(&outside_fences(&text))
                .iter()
                .flat_map(|(_, line)| link_targets(line))
                .filter_map(|t| normalize(&Path::new(BOOK_SRC).join(t.split('#').next()?)))
                .collect()
        })
        .unwrap_or_default();
    if listed.is_empty() {
        problems.push(format!(
            "{}: missing, or lists no chapter",
            summary.display()
        ));
    }
    for chapter in &chapters {
        if *chapter != summary && !listed.contains(chapter) {
            problems.push(format!(
                "{}: a chapter that {} does not list",
                chapter.display(),
                summary.display()
            ));
        }
    }

    // Code and scenes that cite the book (`docs/src/….md#anchor`) cite something that exists.
    let sources = ["rs", "ron"]
        .iter()
        .flat_map(|ext| files.files_under(Path::new(""), ext));
    for source in sources {
        if source == Path::new(THIS_FILE) {
            continue;
        }
        let Some(text) = files.read(&source) else {
            continue;
        };
        for (i, line) in text.lines().enumerate() {
            let mut from = 0;
            while let Some(k) = line[from..].find("docs/src/") {
                let start = from + k;
                let cited: String = line[start..]
                    .chars()
                    .take_while(|&c| c.is_alphanumeric() || "/._-#".contains(c))
                    .collect();
                from = start + cited.len();
                let cited = cited.trim_end_matches(['.', '-']);
                if !cited.split('#').next().is_some_and(|f| f.ends_with(".md")) {
                    continue;
                }
                // Resolved as a link from a file at the repository's root.
                check_link(
                    files,
                    Path::new("citation"),
                    &source,
                    i + 1,
                    cited,
                    &HashSet::new(),
                    &mut problems,
                );
            }
        }
    }
    problems
}

#[test]
fn the_readme_and_the_book_have_no_broken_links() {
    let problems = check(&Repository(workspace::root()));
    assert!(
        problems.is_empty(),
        "{} broken links in the documentation:\n{}",
        problems.len(),
        problems.join("\n")
    );
}

/// A few files, for the tests of the checker itself.
struct Memory(BTreeMap<PathBuf, String>);

impl Memory {
    fn new(files: &[(&str, &str)]) -> Self {
        Memory(
            files
                .iter()
                .map(|(p, t)| (PathBuf::from(p), t.to_string()))
                .collect(),
        )
    }
}

impl Files for Memory {
    fn read(&self, path: &Path) -> Option<String> {
        self.0.get(path).cloned()
    }

    fn exists(&self, path: &Path) -> bool {
        self.0.keys().any(|p| p.starts_with(path))
    }

    fn files_under(&self, dir: &Path, ext: &str) -> Vec<PathBuf> {
        self.0
            .keys()
            .filter(|p| p.starts_with(dir) && p.extension().is_some_and(|e| e == ext))
            .cloned()
            .collect()
    }
}

/// A README and a two-chapter book whose links all resolve.
fn sound_docs() -> Vec<(&'static str, &'static str)> {
    vec![
        (
            "README.md",
            "# tress\n\nSee [the guide](docs/src/guide.md#placing-a-camera) and ![a picture](scenes/a.png).\n",
        ),
        ("scenes/a.png", ""),
        ("scenes/REF.md", "## CameraDesc\n\nSee [the film](#filmsettings).\n\n## FilmSettings\n"),
        (
            "docs/src/SUMMARY.md",
            "# Summary\n\n- [Guide](guide.md)\n- [Reference](reference.md)\n",
        ),
        (
            "docs/src/guide.md",
            "# Guide\n\n## Placing a camera\n\n## Placing a camera\n\nBack to [the top](#guide), the [second](#placing-a-camera-1), the [reference](reference.md#cameradesc).\n\n```sh\n# not a heading; [not](a-link.md)\n```\n\nCode: `[not](a-link.md)`.\n",
        ),
        ("docs/src/reference.md", "{{#include ../../scenes/REF.md}}\n"),
        (
            "core/src/lib.rs",
            "//! The camera (docs/src/guide.md#placing-a-camera).\n",
        ),
    ]
}

fn problems_with(changes: &[(&'static str, &'static str)]) -> Vec<String> {
    let mut files: BTreeMap<&str, &str> = sound_docs().into_iter().collect();
    for &(path, text) in changes {
        files.insert(path, text);
    }
    let files: Vec<(&str, &str)> = files.into_iter().collect();
    check(&Memory::new(&files))
}

#[test]
fn sound_docs_pass() {
    assert_eq!(problems_with(&[]), Vec::<String>::new());
}

#[test]
fn a_missing_file_is_reported() {
    let problems = problems_with(&[(
        "README.md",
        "# tress\n\nSee [the guide](docs/src/gide.md).\n",
    )]);
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(
        problems[0].starts_with("README.md:3: link 'docs/src/gide.md': no such file"),
        "{problems:?}"
    );
}

#[test]
fn a_missing_anchor_is_reported() {
    let problems = problems_with(&[(
        "README.md",
        "# tress\n\n[camera](docs/src/guide.md#placing-the-camera), [top](#tres).\n",
    )]);
    assert_eq!(problems.len(), 2, "{problems:?}");
    assert!(problems[0].contains("no heading with the id 'placing-the-camera'"));
    assert!(problems[1].contains("no heading with the id 'tres'"));
}

#[test]
fn anchors_into_included_text_resolve_in_the_including_chapter() {
    let problems = problems_with(&[(
        "docs/src/guide.md",
        "# Guide\n\n## Placing a camera\n\n[film](reference.md#filmsettings), [lens](reference.md#lens).\n",
    )]);
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(
        problems[0].starts_with("docs/src/guide.md:5: link 'reference.md#lens': no heading"),
        "{problems:?}"
    );
}

#[test]
fn a_chapter_left_out_of_the_summary_is_reported() {
    let problems = problems_with(&[("docs/src/orphan.md", "# Orphan\n")]);
    assert_eq!(
        problems,
        vec!["docs/src/orphan.md: a chapter that docs/src/SUMMARY.md does not list".to_string()]
    );
}

#[test]
fn book_links_must_stay_in_the_book() {
    let problems = problems_with(&[(
        "docs/src/guide.md",
        "# Guide\n\n## Placing a camera\n\n![a picture](../../scenes/a.png)\n",
    )]);
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(
        problems[0].contains("points outside docs/src"),
        "{problems:?}"
    );
}

#[test]
fn broken_citations_in_code_are_reported() {
    let problems = problems_with(&[(
        "core/src/lib.rs",
        "//! See docs/src/guide.md#placing-a-lens and docs/src/gone.md.\n",
    )]);
    assert_eq!(problems.len(), 2, "{problems:?}");
    assert!(problems[0].starts_with("core/src/lib.rs:1: link 'docs/src/guide.md#placing-a-lens'"));
    assert!(problems[1].starts_with("core/src/lib.rs:1: link 'docs/src/gone.md'"));
}

#[test]
fn unsupported_directives_are_reported() {
    let problems = problems_with(&[(
        "docs/src/reference.md",
        "{{#include ../../scenes/REF.md:5:9}}\n",
    )]);
    assert!(
        problems
            .iter()
            .any(|p| p.contains("only whole-file includes are checked")),
        "{problems:?}"
    );
}

#[test]
fn heading_ids_follow_mdbook() {
    assert_eq!(heading_id("Marschner's energy"), "marschners-energy");
    assert_eq!(
        heading_id("Under a directional light: 45–970× faster on light hair"),
        "under-a-directional-light-45970-faster-on-light-hair"
    );
    assert_eq!(
        heading_id("`--passes`: add more passes"),
        "--passes-add-more-passes"
    );
    assert_eq!(heading_id("Über_Größe 2"), "über_größe-2");
    assert_eq!(
        heading_text("Comparing two renders: `tress diff`"),
        "Comparing two renders: tress diff"
    );
    assert_eq!(heading_text("See [the *guide*](x.md#y)"), "See the guide");
    let ids = heading_ids("# A\n\n## A\n\n### B {#custom}\n\n```\n# C\n```\n");
    let want: HashSet<String> = ["a", "a-1", "custom"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert_eq!(ids, want);
}
