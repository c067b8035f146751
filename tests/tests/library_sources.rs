//! The rules of the library crates' sources that clippy cannot say, checked by reading them as
//! text, so that a change breaking one fails here, naming file and line. (The others are in
//! clippy.toml: no environment or command line read outside the front ends, no file written
//! outside `tress_core::output_file`, no `thread_local!`.)
//!
//! 1. **No import cycles between files.** Within a crate, file A depends on file B when A's code
//!    names something of B's module: a `use` of it, a path through it (`crate::b::f`,
//!    `super::f`, `self::b::X`, `b::X` for a child module `b`, `$crate::b` in macros), or a
//!    glob import of it (`use super::*`). A path is charged to the deepest module file it
//!    reaches; a name a module re-exports with `pub use` is followed to where it comes from, so
//!    `crate::Image` counts as a use of `film.rs` when the crate root says `pub use
//!    film::Image`. `mod` declarations are structure, not use. Files that name each other,
//!    directly or round a longer loop, fail with the loop and the line of each step.
//! 2. **No process-wide mutable state.** No `static mut`, no `static` of an interior-mutable
//!    type (atomics, `Cell`s, locks, `OnceLock`, `LazyLock`, …) and no `thread_local!`: state
//!    lives in values their owners pass in, never beside them. Constant statics are fine.
//!
//! The library crates are the workspace members named in the root `Cargo.toml` except the
//! front ends `cli` and `python`; their modules are found by following `mod` declarations
//! (and `#[path]`) from `src/lib.rs`, and a file under `src/` that is no module fails the
//! check (the rules would not see it). Test code — `#[cfg(test)]` items and modules, and the
//! files of `#[cfg(test)] mod x;` — is not library code and is skipped by both rules.

use crate::workspace;
use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------------------------
// Lexing: identifiers, `::` and punctuation with their lines; comments, literals and
// lifetimes cannot be mistaken for paths.

#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Ident(String),
    /// `::`
    PathSep,
    Punct(char),
    /// A string literal's text (escapes not interpreted): `#[path = "…"]` is read from it.
    Str(String),
    /// Any other literal, or a lifetime.
    Other,
}

#[derive(Clone, Debug)]
struct Token {
    tok: Tok,
    line: u32,
}

impl Token {
    fn is_ident(&self, s: &str) -> bool {
        matches!(&self.tok, Tok::Ident(i) if i == s)
    }
    fn is_punct(&self, c: char) -> bool {
        self.tok == Tok::Punct(c)
    }
    fn ident(&self) -> Option<&str> {
        match &self.tok {
            Tok::Ident(i) => Some(i),
            _ => None,
        }
    }
}

fn is_ident_char(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

fn lex(src: &str) -> Vec<Token> {
    let c: Vec<char> = src.chars().collect();
    let at = |i: usize| c.get(i).copied().unwrap_or('\0');
    let mut out = Vec::new();
    let mut line = 1u32;
    let mut i = 0;
    // Skips a quoted literal whose opening quote is at `i`, ending with `close` followed by
    // `hashes` '#'s; returns the index past it and the text inside.
    let skip_quoted =
        |mut i: usize, hashes: usize, escapes: bool, line: &mut u32| -> (usize, String) {
            let start = i + 1;
            i += 1;
            while i < c.len() {
                match c[i] {
                    '\\' if escapes => i += 1,
                    '\n' => *line += 1,
                    '"' if (1..=hashes).all(|k| at(i + k) == '#') => {
                        let text = c[start..i].iter().collect();
                        return (i + 1 + hashes, text);
                    }
                    _ => {}
                }
                i += 1;
            }
            (i, c[start.min(c.len())..].iter().collect())
        };
    while i < c.len() {
        let ch = c[i];
        if ch == '\n' {
            line += 1;
            i += 1;
        } else if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && at(i + 1) == '/' {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && at(i + 1) == '*' {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && at(i + 1) == '*' {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && at(i + 1) == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    if c[i] == '\n' {
                        line += 1;
                    }
                    i += 1;
                }
            }
        } else if ch == '"' {
            let l = line;
            let (next, text) = skip_quoted(i, 0, true, &mut line);
            out.push(Token {
                tok: Tok::Str(text),
                line: l,
            });
            i = next;
        } else if ch == '\'' {
            // A char literal ('a', '\n', '\u{..}') or a lifetime ('a, 'static).
            let l = line;
            if at(i + 1) == '\\' {
                i += 2;
                while i < c.len() && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if at(i + 2) == '\'' {
                i += 3;
            } else {
                i += 1;
                while i < c.len() && is_ident_char(c[i]) {
                    i += 1;
                }
            }
            out.push(Token {
                tok: Tok::Other,
                line: l,
            });
        } else if is_ident_char(ch) && !ch.is_ascii_digit() {
            // Prefixed literals (b"", r#""#, br"", c"", b'') and raw identifiers (r#type).
            let prefix_len = match (ch, at(i + 1), at(i + 2)) {
                ('b' | 'c', 'r', '"' | '#') => Some(2),
                ('r', '"' | '#', _) => Some(1),
                ('b' | 'c', '"', _) => Some(1),
                _ => None,
            };
            let l = line;
            if let Some(p) = prefix_len {
                let raw = c[i..i + p].contains(&'r');
                let mut j = i + p;
                let mut hashes = 0;
                while at(j) == '#' {
                    hashes += 1;
                    j += 1;
                }
                if at(j) == '"' {
                    let (next, text) = skip_quoted(j, hashes, !raw, &mut line);
                    out.push(Token {
                        tok: Tok::Str(text),
                        line: l,
                    });
                    i = next;
                    continue;
                }
                if ch == 'r' && hashes == 1 && is_ident_char(at(j)) {
                    i = j; // r#ident: the identifier follows
                }
            } else if ch == 'b' && at(i + 1) == '\'' {
                i += 2;
                while i < c.len() && c[i] != '\'' {
                    if c[i] == '\\' {
                        i += 1;
                    }
                    i += 1;
                }
                out.push(Token {
                    tok: Tok::Other,
                    line: l,
                });
                i += 1;
                continue;
            }
            let start = i;
            while i < c.len() && is_ident_char(c[i]) {
                i += 1;
            }
            out.push(Token {
                tok: Tok::Ident(c[start..i].iter().collect()),
                line: l,
            });
        } else if ch.is_ascii_digit() {
            while i < c.len()
                && (is_ident_char(c[i]) || (c[i] == '.' && at(i + 1).is_ascii_digit()))
            {
                i += 1;
            }
            out.push(Token {
                tok: Tok::Other,
                line,
            });
        } else if ch == ':' && at(i + 1) == ':' {
            out.push(Token {
                tok: Tok::PathSep,
                line,
            });
            i += 2;
        } else {
            out.push(Token {
                tok: Tok::Punct(ch),
                line,
            });
            i += 1;
        }
    }
    out
}

// ---------------------------------------------------------------------------------------------
// What one file says: its uses, paths, file-module declarations, statics and environment
// reads, each outside test code.

/// A path a file names, made absolute where it can be (see [`absolutize`]).
#[derive(Clone, Debug)]
struct PathRef {
    /// Segments as written (`crate`, `super`, … included).
    segments: Vec<String>,
    /// The module (file module, then inline modules) the path is written in.
    context: Vec<String>,
    line: u32,
    /// A glob import (`use x::*`): the path names the module itself.
    glob: bool,
}

/// A `pub use` of a name: other files naming `module::name` depend on `target`.
#[derive(Clone, Debug)]
struct Reexport {
    name: String,
    target: PathRef,
}

#[derive(Clone, Debug)]
struct ModDecl {
    name: String,
    /// `#[path = "…"]`, if given.
    path_attr: Option<String>,
    /// Inline modules the declaration sits in, below the file's module.
    inline: Vec<String>,
    /// Declared under `#[cfg(test)]`.
    test: bool,
}

#[derive(Debug, Default)]
struct FileScan {
    paths: Vec<PathRef>,
    reexports: Vec<Reexport>,
    mods: Vec<ModDecl>,
    /// Mutable process-wide state: (line, what).
    state: Vec<(u32, String)>,
}

/// Interior-mutable types: a `static` of one is process-wide mutable state.
fn is_interior_mutable(ty: &str) -> bool {
    ty.starts_with("Atomic")
        || [
            "Cell",
            "RefCell",
            "UnsafeCell",
            "SyncUnsafeCell",
            "OnceCell",
            "OnceLock",
            "LazyCell",
            "LazyLock",
            "Lazy",
            "Mutex",
            "RwLock",
            "Condvar",
        ]
        .contains(&ty)
}

/// For each opening bracket, the index of its closing one (and the reverse).
fn brackets(t: &[Token]) -> HashMap<usize, usize> {
    let mut pairs = HashMap::new();
    let mut stack = Vec::new();
    for (i, tok) in t.iter().enumerate() {
        match tok.tok {
            Tok::Punct('(' | '[' | '{') => stack.push(i),
            Tok::Punct(')' | ']' | '}') => {
                if let Some(open) = stack.pop() {
                    pairs.insert(open, i);
                    pairs.insert(i, open);
                }
            }
            _ => {}
        }
    }
    pairs
}

/// The last token of the item starting at `k`: its `;`, or the `}` closing its first block.
fn item_end(t: &[Token], pairs: &HashMap<usize, usize>, mut k: usize) -> usize {
    while k < t.len() {
        match t[k].tok {
            Tok::Punct(';') => return k,
            Tok::Punct('{') => return pairs.get(&k).copied().unwrap_or(t.len() - 1),
            Tok::Punct('(' | '[') => k = pairs.get(&k).copied().unwrap_or(t.len()) + 1,
            _ => k += 1,
        }
    }
    t.len().saturating_sub(1)
}

/// Whether attribute tokens `open..=close` (`[` … `]`) are `[cfg(test)]`.
fn is_cfg_test(t: &[Token], open: usize, close: usize) -> bool {
    let inner: Vec<&Tok> = t[open + 1..close].iter().map(|x| &x.tok).collect();
    inner
        == [
            &Tok::Ident("cfg".into()),
            &Tok::Punct('('),
            &Tok::Ident("test".into()),
            &Tok::Punct(')'),
        ]
}

/// Parses the use tree starting at `i` into `(segments, alias, glob)` leaves; returns the
/// index past it.
fn use_tree(
    t: &[Token],
    mut i: usize,
    prefix: &mut Vec<String>,
    out: &mut Vec<(Vec<String>, Option<String>, bool, u32)>,
) -> usize {
    let pushed = prefix.len();
    if i < t.len() && t[i].tok == Tok::PathSep {
        i += 1; // `::std::…`
    }
    while i < t.len() {
        match &t[i].tok {
            Tok::Ident(name) => {
                let line = t[i].line;
                if t.get(i + 1).map(|x| &x.tok) == Some(&Tok::PathSep) {
                    prefix.push(name.clone());
                    i += 2;
                    continue;
                }
                let alias = (t.get(i + 1).is_some_and(|x| x.is_ident("as")))
                    .then(|| t.get(i + 2).and_then(Token::ident).map(str::to_owned))
                    .flatten();
                let mut leaf = prefix.clone();
                if name != "self" {
                    leaf.push(name.clone());
                }
                out.push((leaf, alias.clone(), false, line));
                i += if alias.is_some() { 3 } else { 1 };
                break;
            }
            Tok::Punct('*') => {
                out.push((prefix.clone(), None, true, t[i].line));
                i += 1;
                break;
            }
            Tok::Punct('{') => {
                i += 1;
                loop {
                    if i >= t.len() || t[i].is_punct('}') {
                        i += 1;
                        break;
                    }
                    i = use_tree(t, i, prefix, out);
                    if i < t.len() && t[i].is_punct(',') {
                        i += 1;
                    }
                }
                break;
            }
            _ => break,
        }
    }
    prefix.truncate(pushed);
    i
}

fn scan(src: &str) -> FileScan {
    let t = lex(src);
    let pairs = brackets(&t);
    let n = t.len();

    // Test code: every token of a `#[cfg(test)]` item.
    let mut test = vec![false; n];
    // Inline modules: the module path below the file's module, per token.
    let mut inline: Vec<Vec<String>> = vec![Vec::new(); n];
    let mut stack: Vec<(usize, String)> = Vec::new();
    for i in 0..n {
        while stack.last().is_some_and(|&(close, _)| close < i) {
            stack.pop();
        }
        inline[i] = stack.iter().map(|(_, m)| m.clone()).collect();
        if t[i].is_ident("mod") {
            if let (Some(name), Some(brace)) = (t.get(i + 1).and_then(Token::ident), t.get(i + 2)) {
                if brace.is_punct('{') {
                    if let Some(&close) = pairs.get(&(i + 2)) {
                        stack.push((close, name.to_owned()));
                    }
                }
            }
        }
        if t[i].is_punct('#') && t.get(i + 1).is_some_and(|x| x.is_punct('[')) {
            let Some(&close) = pairs.get(&(i + 1)) else {
                continue;
            };
            if is_cfg_test(&t, i + 1, close) {
                let end = item_end(&t, &pairs, close + 1);
                test[i..=end].iter_mut().for_each(|x| *x = true);
            }
        }
    }

    let mut s = FileScan::default();
    let mut i = 0;
    while i < n {
        if test[i] {
            // `#[cfg(test)] mod x;` declares a test-only file; other test code is skipped.
            if t[i].is_ident("mod") && t.get(i + 2).is_some_and(|x| x.is_punct(';')) {
                if let Some(name) = t.get(i + 1).and_then(Token::ident) {
                    s.mods.push(ModDecl {
                        name: name.to_owned(),
                        path_attr: path_attribute(&t, &pairs, i),
                        inline: inline[i].clone(),
                        test: true,
                    });
                }
            }
            i += 1;
            continue;
        }
        let context = inline[i].clone();
        match &t[i].tok {
            Tok::Ident(word) if word == "use" => {
                let is_pub = visibility_before(&t, &pairs, i);
                let mut leaves = Vec::new();
                let end = use_tree(&t, i + 1, &mut Vec::new(), &mut leaves);
                for (segments, alias, glob, line) in leaves {
                    let path = PathRef {
                        segments: segments.clone(),
                        context: context.clone(),
                        line,
                        glob,
                    };
                    if is_pub && !glob && context.is_empty() {
                        if let Some(name) = alias.or_else(|| segments.last().cloned()) {
                            s.reexports.push(Reexport {
                                name,
                                target: path.clone(),
                            });
                        }
                    }
                    s.paths.push(path);
                }
                i = end.max(i + 1);
            }
            Tok::Ident(word) if word == "mod" && t.get(i + 2).is_some_and(|x| x.is_punct(';')) => {
                if let Some(name) = t.get(i + 1).and_then(Token::ident) {
                    s.mods.push(ModDecl {
                        name: name.to_owned(),
                        path_attr: path_attribute(&t, &pairs, i),
                        inline: context,
                        test: false,
                    });
                }
                i += 3;
            }
            Tok::Ident(word) if word == "static" => {
                let line = t[i].line;
                if t.get(i + 1).is_some_and(|x| x.is_ident("mut")) {
                    s.state.push((line, "`static mut`".into()));
                } else if let Some(name) = t.get(i + 1).and_then(Token::ident) {
                    // The type: the tokens between `:` and `=` (or `;`).
                    let interior: Vec<&str> = t[i + 2..]
                        .iter()
                        .take_while(|x| !x.is_punct('=') && !x.is_punct(';'))
                        .filter_map(Token::ident)
                        .filter(|ty| is_interior_mutable(ty))
                        .collect();
                    if let Some(ty) = interior.first() {
                        s.state
                            .push((line, format!("`static {name}` of type {ty}")));
                    }
                }
                i += 1;
            }
            Tok::Ident(word)
                if word == "thread_local" && t.get(i + 1).is_some_and(|x| x.is_punct('!')) =>
            {
                s.state.push((t[i].line, "`thread_local!`".into()));
                i += 1;
            }
            Tok::Ident(first) => {
                // A path in code: `a::b::c`, not the tail of a longer path or a method name,
                // and not a macro's metavariable (`$module::Params`), but `$crate::…`.
                let prev = i.checked_sub(1).map(|p| &t[p]);
                let after_dollar = prev.is_some_and(|p| p.is_punct('$'));
                let tail = prev.is_some_and(|p| p.tok == Tok::PathSep || p.is_punct('.'));
                let mut segments = vec![first.clone()];
                let mut j = i + 1;
                while j + 1 < n && t[j].tok == Tok::PathSep {
                    match t[j + 1].ident() {
                        Some(next) => segments.push(next.to_owned()),
                        None => break,
                    }
                    j += 2;
                }
                if segments.len() > 1 && !tail && (!after_dollar || first == "crate") {
                    s.paths.push(PathRef {
                        segments,
                        context,
                        line: t[i].line,
                        glob: false,
                    });
                }
                i = j;
            }
            _ => i += 1,
        }
    }
    s
}

/// Whether the item whose keyword is at `i` is `pub` or `pub(…)`.
fn visibility_before(t: &[Token], pairs: &HashMap<usize, usize>, i: usize) -> bool {
    match i.checked_sub(1).map(|p| &t[p]) {
        Some(p) if p.is_ident("pub") => true,
        Some(p) if p.is_punct(')') => pairs
            .get(&(i - 1))
            .and_then(|&open| open.checked_sub(1))
            .is_some_and(|k| t[k].is_ident("pub")),
        _ => false,
    }
}

/// The `#[path = "…"]` among the attributes before the `mod` at `i`.
fn path_attribute(t: &[Token], pairs: &HashMap<usize, usize>, i: usize) -> Option<String> {
    let mut k = i;
    // Past the visibility.
    if k > 0 && t[k - 1].is_ident("pub") {
        k -= 1;
    } else if k > 0 && t[k - 1].is_punct(')') {
        k = pairs.get(&(k - 1))?.checked_sub(1)?;
    }
    while k > 0 && t[k - 1].is_punct(']') {
        let open = *pairs.get(&(k - 1))?;
        if t.get(open + 1).is_some_and(|x| x.is_ident("path"))
            && t.get(open + 2).is_some_and(|x| x.is_punct('='))
        {
            if let Some(Tok::Str(p)) = t.get(open + 3).map(|x| &x.tok) {
                return Some(p.clone());
            }
        }
        k = open.checked_sub(1)?; // the `#`
    }
    None
}

// ---------------------------------------------------------------------------------------------
// Crates: the module files and the dependencies between them.

#[derive(Debug)]
struct ModuleFile {
    /// Path relative to the crate's folder, e.g. `src/film.rs`.
    rel: String,
    module: Vec<String>,
    test: bool,
    scan: FileScan,
}

#[derive(Debug)]
struct Crate {
    /// The member's path in the workspace, e.g. `integrators/path`.
    member: String,
    files: Vec<ModuleFile>,
    index: HashMap<Vec<String>, usize>,
}

fn rs_files(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for entry in entries {
        let path = entry.map_err(|e| format!("{}: {e}", dir.display()))?.path();
        if path.is_dir() {
            rs_files(&path, out)?;
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    Ok(())
}

/// Reads the crate at `root/member` by following its `mod` declarations from `src/lib.rs`.
fn read_crate(root: &Path, member: &str) -> Result<Crate, String> {
    let dir = root.join(member);
    let rel = |p: &Path| {
        p.strip_prefix(&dir)
            .unwrap_or(p)
            .to_string_lossy()
            .replace('\\', "/")
    };
    let mut krate = Crate {
        member: member.to_owned(),
        files: Vec::new(),
        index: HashMap::new(),
    };
    // (file, module, test only, whether its children live beside it: lib.rs, mod.rs, #[path])
    let mut queue = VecDeque::from([(dir.join("src/lib.rs"), Vec::new(), false, true)]);
    let mut problems = Vec::new();
    while let Some((path, module, test, owns_dir)) = queue.pop_front() {
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{member}/{}: {e}", rel(&path)))?;
        let scan = scan(&text);
        let here = path.parent().unwrap_or(&dir).to_path_buf();
        for m in &scan.mods {
            let mut base = if owns_dir {
                here.clone()
            } else {
                here.join(path.file_stem().unwrap_or_default())
            };
            base.extend(&m.inline);
            let candidates = match &m.path_attr {
                Some(p) if m.inline.is_empty() => vec![here.join(p)],
                Some(p) => vec![base.join(p)],
                None => vec![
                    base.join(format!("{}.rs", m.name)),
                    base.join(&m.name).join("mod.rs"),
                ],
            };
            let Some(file) = candidates.into_iter().find(|c| c.is_file()) else {
                problems.push(format!(
                    "{member}/{}: no file for `mod {}`",
                    rel(&path),
                    m.name
                ));
                continue;
            };
            let owns = m.path_attr.is_some() || file.ends_with("mod.rs");
            let mut child = module.clone();
            child.extend(m.inline.iter().cloned());
            child.push(m.name.clone());
            queue.push_back((file, child, test || m.test, owns));
        }
        krate.index.insert(module.clone(), krate.files.len());
        krate.files.push(ModuleFile {
            rel: rel(&path),
            module,
            test,
            scan,
        });
    }
    let mut all = Vec::new();
    rs_files(&dir.join("src"), &mut all)?;
    let known: BTreeSet<String> = krate.files.iter().map(|f| f.rel.clone()).collect();
    for f in all {
        if !known.contains(&rel(&f)) {
            problems.push(format!(
                "{member}/{}: not a module reached from src/lib.rs by `mod` declarations, so \
                 these checks cannot read it",
                rel(&f)
            ));
        }
    }
    if problems.is_empty() {
        Ok(krate)
    } else {
        Err(problems.join("\n"))
    }
}

impl Crate {
    /// The absolute module path `path` names, written in `file` (see the module docs);
    /// `None` for paths outside the crate (std, other crates, local names).
    fn absolutize(&self, file: &ModuleFile, path: &PathRef) -> Option<Vec<String>> {
        let mut context = file.module.clone();
        context.extend(path.context.iter().cloned());
        let seg = &path.segments;
        let first = seg.first()?;
        let mut abs = match first.as_str() {
            "crate" => seg[1..].to_vec(),
            "self" => [context, seg[1..].to_vec()].concat(),
            "super" => {
                let ups = seg.iter().take_while(|s| *s == "super").count();
                let base = context.len().checked_sub(ups)?;
                [context[..base].to_vec(), seg[ups..].to_vec()].concat()
            }
            _ => {
                // A child module of the current module (or of the file's, from an inline one).
                let mut own = file.module.clone();
                own.push(first.clone());
                let mut inner = context.clone();
                inner.push(first.clone());
                let base = [inner, own]
                    .into_iter()
                    .find(|m| self.index.contains_key(m))?;
                [base, seg[1..].to_vec()].concat()
            }
        };
        if path.glob {
            abs.push("*".into());
        }
        Some(abs)
    }

    /// The file that the absolute path `abs` leads to, following `pub use`s.
    fn resolve(&self, abs: &[String], depth: u32) -> Option<usize> {
        (0..=abs.len()).rev().find_map(|k| {
            let &f = self.index.get(&abs[..k])?;
            let through = (k < abs.len() && depth < 16)
                .then(|| {
                    let file = &self.files[f];
                    let r = file.scan.reexports.iter().find(|r| r.name == abs[k])?;
                    let target = self.absolutize(file, &r.target)?;
                    self.resolve(&[target, abs[k + 1..].to_vec()].concat(), depth + 1)
                })
                .flatten();
            Some(through.unwrap_or(f))
        })
    }

    /// The dependencies between files: for each (from, to), the first line and path.
    fn edges(&self) -> BTreeMap<(usize, usize), (u32, String)> {
        let mut edges = BTreeMap::new();
        for (from, file) in self.files.iter().enumerate() {
            if file.test {
                continue;
            }
            for path in &file.scan.paths {
                let Some(abs) = self.absolutize(file, path) else {
                    continue;
                };
                match self.resolve(&abs, 0) {
                    Some(to) if to != from => {
                        let text = path.segments.join("::") + if path.glob { "::*" } else { "" };
                        edges.entry((from, to)).or_insert((path.line, text));
                    }
                    _ => {}
                }
            }
        }
        edges
    }

    /// Every cycle of file dependencies, one (shortest) loop per strongly connected group,
    /// described step by step.
    fn cycles(&self) -> Vec<String> {
        let edges = self.edges();
        let n = self.files.len();
        let mut next = vec![Vec::new(); n];
        for &(a, b) in edges.keys() {
            next[a].push(b);
        }
        let mut reported: BTreeSet<usize> = BTreeSet::new();
        let mut out = Vec::new();
        for start in 0..n {
            if reported.contains(&start) {
                continue;
            }
            // The shortest way back to `start`, by breadth-first search.
            let mut parent: Vec<Option<usize>> = vec![None; n];
            let mut queue = VecDeque::from([start]);
            let mut seen = vec![false; n];
            let mut back = None;
            'search: while let Some(a) = queue.pop_front() {
                for &b in &next[a] {
                    if b == start {
                        back = Some(a);
                        break 'search;
                    }
                    if !seen[b] {
                        seen[b] = true;
                        parent[b] = Some(a);
                        queue.push_back(b);
                    }
                }
            }
            let Some(mut last) = back else {
                continue;
            };
            let mut cycle = vec![start];
            let mut tail = vec![last];
            while let Some(p) = parent[last] {
                tail.push(p);
                last = p;
            }
            tail.pop(); // `start` itself
            cycle.extend(tail.into_iter().rev());
            // Report each group of files once: everything reachable both ways from `start`.
            let group: Vec<usize> = (0..n)
                .filter(|&f| self.reaches(&next, start, f) && self.reaches(&next, f, start))
                .collect();
            reported.extend(&group);
            let name = |f: usize| self.files[f].rel.as_str();
            let mut text = format!(
                "{}: import cycle {} -> {}",
                self.member,
                cycle
                    .iter()
                    .map(|&f| name(f))
                    .collect::<Vec<_>>()
                    .join(" -> "),
                name(start)
            );
            for (k, &a) in cycle.iter().enumerate() {
                let b = cycle[(k + 1) % cycle.len()];
                let (line, path) = &edges[&(a, b)];
                text += &format!("\n    {}:{line} names {path}", name(a));
            }
            if group.len() > cycle.len() {
                let names: Vec<&str> = group.iter().map(|&f| name(f)).collect();
                text += &format!(
                    "\n    (files caught in the same knot: {})",
                    names.join(", ")
                );
            }
            out.push(text);
        }
        out
    }

    fn reaches(&self, next: &[Vec<usize>], from: usize, to: usize) -> bool {
        let mut seen = vec![false; next.len()];
        let mut stack = vec![from];
        while let Some(a) = stack.pop() {
            if a == to {
                return true;
            }
            if !std::mem::replace(&mut seen[a], true) {
                stack.extend(&next[a]);
            }
        }
        false
    }

    /// Process-wide mutable state.
    fn mutable_statics(&self) -> Vec<String> {
        let mut out = Vec::new();
        for file in self.files.iter().filter(|f| !f.test) {
            for (line, what) in &file.scan.state {
                out.push(format!(
                    "{}/{}:{line}: {what} is process-wide mutable state in library code: \
                     keep it in a value the caller owns and passes in",
                    self.member, file.rel
                ));
            }
        }
        out
    }
}

/// Runs `rule` over every library crate of the workspace at `root`; the problems found.
fn check_workspace(root: &Path, rule: impl Fn(&Crate) -> Vec<String>) -> Vec<String> {
    let members = match workspace::library_members(root) {
        Ok(m) => m,
        Err(e) => return vec![e],
    };
    let mut problems = Vec::new();
    for member in members {
        match read_crate(root, &member) {
            Ok(krate) => problems.extend(rule(&krate)),
            Err(e) => problems.push(e),
        }
    }
    problems
}

fn assert_none(problems: Vec<String>) {
    assert!(problems.is_empty(), "\n{}\n", problems.join("\n"));
}

#[test]
fn library_files_import_each_other_without_cycles() {
    assert_none(check_workspace(&workspace::root(), Crate::cycles));
}

#[test]
fn library_crates_keep_no_process_wide_mutable_state() {
    assert_none(check_workspace(&workspace::root(), Crate::mutable_statics));
}

// ---------------------------------------------------------------------------------------------
// The checks themselves, on small made-up workspaces: each must be able to fail.

/// A workspace in a temporary folder: `members` in its manifest, `files` as (path, text).
fn workspace(members: &[&str], files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let list: Vec<String> = members.iter().map(|m| format!("    \"{m}\",")).collect();
    std::fs::write(
        dir.path().join("Cargo.toml"),
        format!("[workspace]\nmembers = [\n{}\n]\n", list.join("\n")),
    )
    .unwrap();
    for (path, text) in files {
        let path = dir.path().join(path);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    dir
}

fn cycles_in(files: &[(&str, &str)]) -> Vec<String> {
    let ws = workspace(&["lib"], files);
    check_workspace(ws.path(), Crate::cycles)
}

#[test]
fn a_two_file_cycle_is_named_with_its_lines() {
    let found = cycles_in(&[
        ("lib/src/lib.rs", "pub mod film;\npub mod render;\n"),
        (
            "lib/src/film.rs",
            "pub struct Film;\npub fn n() -> usize {\n    crate::render::count()\n}\n",
        ),
        (
            "lib/src/render.rs",
            "use crate::film::Film;\npub fn count() -> usize { 3 }\n",
        ),
    ]);
    assert_eq!(found.len(), 1, "{found:?}");
    let report = &found[0];
    assert!(
        report.contains("lib: import cycle src/film.rs -> src/render.rs -> src/film.rs"),
        "{report}"
    );
    assert!(
        report.contains("src/film.rs:3 names crate::render::count"),
        "{report}"
    );
    assert!(
        report.contains("src/render.rs:1 names crate::film::Film"),
        "{report}"
    );
}

#[test]
fn longer_cycles_and_every_kind_of_path_are_found() {
    // a → b through a use tree, b → c through `super::`, c → a through the root's re-export.
    let found = cycles_in(&[
        (
            "lib/src/lib.rs",
            "mod a;\nmod b;\npub mod c;\npub use a::Thing;\n",
        ),
        (
            "lib/src/a.rs",
            "use crate::{b::{self, B}};\npub struct Thing;\n",
        ),
        (
            "lib/src/b.rs",
            "pub struct B;\nfn f() {\n    super::c::g();\n}\n",
        ),
        (
            "lib/src/c.rs",
            "pub fn g() -> crate::Thing {\n    crate::Thing\n}\n",
        ),
    ]);
    assert_eq!(found.len(), 1, "{found:?}");
    let report = &found[0];
    assert!(
        report.contains("import cycle src/a.rs -> src/b.rs -> src/c.rs -> src/a.rs"),
        "{report}"
    );
    assert!(report.contains("src/a.rs:1 names crate::b"), "{report}");
    assert!(report.contains("src/b.rs:3 names super::c::g"), "{report}");
    assert!(report.contains("src/c.rs:1 names crate::Thing"), "{report}");

    // A child file using its parent and the parent using the child.
    let found = cycles_in(&[
        ("lib/src/lib.rs", "mod m;\n"),
        (
            "lib/src/m.rs",
            "mod child;\nuse child::helper;\npub struct P;\n",
        ),
        ("lib/src/m/child.rs", "use super::*;\npub fn helper() {}\n"),
    ]);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(
        found[0].contains("src/m/child.rs:1 names super::*"),
        "{}",
        found[0]
    );

    // A macro's `$crate::` path counts, its metavariables do not.
    let found = cycles_in(&[
        ("lib/src/lib.rs", "mod a;\nmod b;\n"),
        (
            "lib/src/a.rs",
            "macro_rules! m { ($b:ident) => { $crate::b::X + $b::Y }; }\n",
        ),
        ("lib/src/b.rs", "pub const X: u32 = crate::a::Z;\n"),
    ]);
    assert_eq!(found.len(), 1, "{found:?}");
    // … and `$a::Y` in the root is no use of its child `a`.
    let found = cycles_in(&[
        (
            "lib/src/lib.rs",
            "mod a;\npub const X: u32 = 1;\nmacro_rules! m { ($a:ident) => { $a::Y }; }\n",
        ),
        ("lib/src/a.rs", "pub const Y: u32 = crate::X;\n"),
    ]);
    assert!(found.is_empty(), "{found:?}");
}

#[test]
fn what_is_not_a_use_makes_no_cycle() {
    let found = cycles_in(&[
        (
            "lib/src/lib.rs",
            "//! See [`crate::b::f`].\npub mod a;\npub mod b;\n#[cfg(test)]\nmod test_util;\n",
        ),
        (
            "lib/src/a.rs",
            // Comments, strings, chars and lifetimes mention b; the tests use it; a
            // re-export from another crate and `std` paths are not files of this crate.
            "// crate::b::f()\npub fn f(x: &'static str) -> char {\n    let _ = \"crate::b::f\";\n    \
             let _ = r#\"b::f \"quoted\"\"#;\n    'b'\n}\npub use std::fmt::Debug;\n\
             #[cfg(test)]\nmod tests {\n    use crate::b;\n    #[test]\n    fn t() { b::f(); }\n}\n",
        ),
        ("lib/src/b.rs", "pub fn f() { crate::a::f(\"\"); crate::test_util::x(); }\n"),
        ("lib/src/test_util.rs", "pub fn x() { crate::b::f(); }\n"),
    ]);
    assert!(found.is_empty(), "{found:?}");
}

#[test]
fn files_the_module_tree_does_not_reach_are_refused() {
    let found = cycles_in(&[
        ("lib/src/lib.rs", "#[path = \"elsewhere.rs\"]\nmod a;\n"),
        ("lib/src/elsewhere.rs", "pub fn f() {}\n"),
        ("lib/src/stray.rs", "pub fn g() {}\n"),
    ]);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(
        found[0].contains("lib/src/stray.rs: not a module"),
        "{}",
        found[0]
    );
}

#[test]
fn mutable_statics_are_found_and_constant_ones_pass() {
    let ws = workspace(
        &["core"],
        &[(
            "core/src/lib.rs",
            "use std::sync::atomic::AtomicU64;\n\
             static NAMES: [&str; 2] = [\"a\", \"b\"];\n\
             static mut COUNT: u32 = 0;\n\
             pub fn id() -> u64 {\n    static NEXT: AtomicU64 = AtomicU64::new(0);\n    0\n}\n\
             static CACHE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();\n\
             thread_local! { static RAYS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) }; }\n\
             pub fn f(x: &'static str) -> &'static str { x }\n\
             #[cfg(test)]\nmod tests {\n    static SHARED: std::sync::Mutex<u32> = std::sync::Mutex::new(0);\n}\n",
        )],
    );
    let found = check_workspace(ws.path(), Crate::mutable_statics);
    let what: Vec<&str> = found
        .iter()
        .map(|f| f.split(" is process-wide").next().unwrap())
        .collect();
    assert_eq!(
        what,
        [
            "core/src/lib.rs:3: `static mut`",
            "core/src/lib.rs:5: `static NEXT` of type AtomicU64",
            "core/src/lib.rs:8: `static CACHE` of type OnceLock",
            "core/src/lib.rs:9: `thread_local!`",
            "core/src/lib.rs:9: `static RAYS` of type Cell",
        ],
        "{found:#?}"
    );
}

#[test]
fn the_library_members_come_from_the_root_manifest() {
    let ws = workspace(&["core", "scene", "cli", "python"], &[]);
    assert_eq!(
        workspace::library_members(ws.path()).unwrap(),
        ["core", "scene"]
    );
    // A member whose sources cannot be read is a failure, not a pass.
    let found = check_workspace(ws.path(), Crate::cycles);
    assert_eq!(found.len(), 2, "{found:?}");
}
