//! The rules of the library crates' sources that clippy cannot say, checked by parsing them
//! with `syn`, so that a change breaking one fails here, naming file and line. (clippy.toml says
//! the others: no environment or command line read outside the front ends, no file written
//! outside `tress_core::output_file`, no `thread_local!` or `lazy_static!`. Clippy has no lint
//! against declaring a `static`, and forbidding the interior-mutable types would forbid them in
//! locals and fields too.)
//!
//! 1. **No import cycles between files.** Within a crate, file A depends on file B when A's code
//!    names something of B's module: a `use` of it, a path through it (`crate::b::f`,
//!    `super::f`, `self::b::X`, `b::X` for a child module `b`), or a glob import of it
//!    (`use super::*`). A path is charged to the deepest module file it reaches; a name a
//!    module re-exports with `pub use` is followed to where it comes from, so `crate::Image`
//!    counts as a use of `film.rs` when the crate root says `pub use film::Image`. `mod`
//!    declarations are structure, not use. A macro body that is not a list of items stays
//!    tokens to syn: it is read for paths of two or more segments, `$crate::b::X` included,
//!    metavariables (`$m::X`) not. Files that name each other, directly or round a longer
//!    loop, fail with the loop and the line of each step.
//! 2. **No process-wide mutable state.** No `static mut` and no `static` of an interior-mutable
//!    type (atomics, `Cell`s, locks, `OnceLock`, `LazyLock`, …), in code or in a macro body:
//!    state lives in values their owners pass in, never beside them. A type is judged by the
//!    names it is written with, so an alias hides an interior-mutable one.
//!
//! The library crates are the workspace members named in the root `Cargo.toml` except the
//! front ends `cli` and `python`; their modules are found by following `mod` declarations
//! (and `#[path]`) from `src/lib.rs`, and a file under `src/` that is no module fails the
//! check (the rules would not see it). Test code — items, statements and modules under
//! `#[cfg(test)]`, and the files of `#[cfg(test)] mod x;` — is skipped by both rules.

use crate::workspace;
use proc_macro2::{Span, TokenStream, TokenTree};
use quote::ToTokens;
use std::collections::{BTreeMap, HashMap, VecDeque};
use std::path::{Path, PathBuf};
use syn::visit::{self, Visit};

/// Type names that make a `static` mutable, besides `Atomic*`.
const INTERIOR_MUTABLE: &str =
    "Cell RefCell UnsafeCell SyncUnsafeCell OnceCell OnceLock LazyCell LazyLock Lazy Mutex RwLock";

/// A path a file names: its segments as written, the inline modules it is written in (below
/// the file's module), its line, and whether it is a glob import (it names the module itself).
#[derive(Clone, Debug)]
struct PathRef(Vec<String>, Vec<String>, usize, bool);

/// What one file says outside its test code (its `mod` declarations also inside it).
#[derive(Debug, Default)]
struct FileScan {
    paths: Vec<PathRef>,
    /// `pub use`s: other files naming `this_module::name` depend on where the path leads.
    reexports: Vec<(String, PathRef)>,
    /// `mod x;`: name, `#[path]`, inline modules it sits in, and whether it is test code.
    mods: Vec<(String, Option<String>, Vec<String>, bool)>,
    /// Process-wide mutable state: (line, what).
    state: Vec<(usize, String)>,
    context: Vec<String>,
    in_test: bool,
}

fn line(span: Span) -> usize {
    span.start().line
}

/// What makes a `static` process-wide mutable state, if anything: `mut`, or an interior-mutable
/// type among the names its type is written with (`ty`, read up to a `=` or `;`).
fn mutable_static(mutable: bool, name: &str, ty: &[TokenTree]) -> Option<String> {
    if mutable {
        return Some("`static mut`".into());
    }
    let mut names = ty
        .iter()
        .map(|t| t.to_string())
        .take_while(|t| t != "=" && t != ";");
    let interior = |n: &String| INTERIOR_MUTABLE.split(' ').any(|m| m == n);
    let ty = names.find(|n| n.starts_with("Atomic") || interior(n))?;
    Some(format!("`static {name}` of type {ty}"))
}

/// The tokens of a stream with its groups opened.
fn flatten(stream: TokenStream) -> Vec<TokenTree> {
    let open = |tree| match tree {
        TokenTree::Group(g) => flatten(g.stream()),
        other => vec![other],
    };
    stream.into_iter().flat_map(open).collect()
}

impl FileScan {
    fn path(&mut self, segments: Vec<String>, line: usize, glob: bool) {
        let context = self.context.clone();
        self.paths.push(PathRef(segments, context, line, glob));
    }

    /// The leaves of a use tree below `prefix`; a public one's name is a re-export.
    fn use_tree(&mut self, tree: &syn::UseTree, mut prefix: Vec<String>, public: bool) {
        let (name, leaf) = match tree {
            syn::UseTree::Path(p) => {
                prefix.push(p.ident.to_string());
                return self.use_tree(&p.tree, prefix, public);
            }
            syn::UseTree::Group(g) => {
                let trees = g.items.iter();
                return trees.for_each(|t| self.use_tree(t, prefix.clone(), public));
            }
            syn::UseTree::Glob(g) => return self.path(prefix, line(g.star_token.span), true),
            syn::UseTree::Name(n) => (&n.ident, &n.ident),
            syn::UseTree::Rename(r) => (&r.rename, &r.ident),
        };
        if leaf != "self" {
            prefix.push(leaf.to_string());
        }
        self.path(prefix, line(leaf.span()), false);
        if public {
            let target = self.paths.last().cloned().unwrap();
            self.reexports.push((name.to_string(), target));
        }
    }

    /// The paths and statics in a macro body left as tokens (a `macro_rules!` template, a
    /// `format!`). A path is an identifier followed by `::` and more, not after `::` (a tail) or
    /// `.` (a method), and after `$` only as `$crate`.
    fn macro_tokens(&mut self, tokens: TokenStream) {
        let t = flatten(tokens);
        let punct = |k, c| matches!(t.get(k), Some(TokenTree::Punct(p)) if p.as_char() == c);
        let ident = |k| match t.get(k) {
            Some(TokenTree::Ident(i)) => Some(i.to_string()),
            _ => None,
        };
        let path_sep = |k| punct(k, ':') && punct(k + 1, ':');
        for (i, tree) in t.iter().enumerate() {
            let TokenTree::Ident(first) = tree else {
                continue;
            };
            let after = |c| i > 0 && punct(i - 1, c);
            if (i > 1 && path_sep(i - 2)) || after('.') || (after('$') && first != "crate") {
                continue;
            }
            if first == "static" && !after('\'') {
                let mutable = ident(i + 1).is_some_and(|m| m == "mut");
                let ty = t.get(i + 2..).unwrap_or_default();
                if let Some(what) = ident(i + 1).and_then(|n| mutable_static(mutable, &n, ty)) {
                    self.state.push((line(tree.span()), what));
                }
            }
            let mut segments = vec![first.to_string()];
            let next = |n: usize| ident(i + 3 * n).filter(|_| path_sep(i + 3 * n - 2));
            while let Some(next) = next(segments.len()) {
                segments.push(next);
            }
            if segments.len() > 1 {
                self.path(segments, line(tree.span()), false);
            }
        }
    }
}

/// Visitors of nodes that attributes can mark as test code: the mark lasts to the node's end.
macro_rules! test_scoped {
    ($($visit:ident: $node:ty),*) => {$(
        fn $visit(&mut self, node: &'ast $node) {
            let outer = self.in_test;
            visit::$visit(self, node);
            self.in_test = outer;
        }
    )*};
}

impl<'ast> Visit<'ast> for FileScan {
    test_scoped!(visit_item: syn::Item, visit_impl_item: syn::ImplItem,
        visit_trait_item: syn::TraitItem, visit_stmt: syn::Stmt, visit_field: syn::Field,
        visit_variant: syn::Variant, visit_arm: syn::Arm);

    // A node's attributes are visited before the rest of it.
    fn visit_attribute(&mut self, attr: &'ast syn::Attribute) {
        let tokens = attr.meta.require_list().map(|l| l.tokens.to_string());
        self.in_test |= attr.path().is_ident("cfg") && tokens.is_ok_and(|t| t == "test");
        visit::visit_attribute(self, attr);
    }

    fn visit_item_mod(&mut self, m: &'ast syn::ItemMod) {
        m.attrs.iter().for_each(|a| self.visit_attribute(a));
        let name = m.ident.to_string();
        let Some((_, items)) = &m.content else {
            let path = m.attrs.iter().find(|a| a.path().is_ident("path"));
            let path = path.and_then(|a| a.meta.require_name_value().ok());
            let path =
                path.and_then(|p| syn::parse2::<syn::LitStr>(p.value.to_token_stream()).ok());
            let (context, test) = (self.context.clone(), self.in_test);
            return self
                .mods
                .push((name, path.map(|p| p.value()), context, test));
        };
        self.context.push(name);
        items.iter().for_each(|item| self.visit_item(item));
        self.context.pop();
    }

    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        visit::visit_item_use(self, u);
        if !self.in_test {
            let public = !matches!(u.vis, syn::Visibility::Inherited) && self.context.is_empty();
            self.use_tree(&u.tree, Vec::new(), public);
        }
    }

    fn visit_path(&mut self, p: &'ast syn::Path) {
        visit::visit_path(self, p);
        if !self.in_test && p.segments.len() > 1 {
            let segments = p.segments.iter().map(|s| s.ident.to_string()).collect();
            self.path(segments, line(p.segments[0].ident.span()), false);
        }
    }

    fn visit_item_static(&mut self, s: &'ast syn::ItemStatic) {
        visit::visit_item_static(self, s);
        let mutable = matches!(s.mutability, syn::StaticMutability::Mut(_));
        let ty = flatten(s.ty.to_token_stream());
        let what = mutable_static(mutable, &s.ident.to_string(), &ty);
        if let Some(what) = what.filter(|_| !self.in_test) {
            self.state.push((line(s.static_token.span), what));
        }
    }

    // A body that parses as items (`thread_local!`'s) is read as code, any other as tokens.
    fn visit_macro(&mut self, mac: &'ast syn::Macro) {
        visit::visit_macro(self, mac);
        match syn::parse2::<syn::File>(mac.tokens.clone()) {
            Ok(items) => self.visit_file(&items),
            Err(_) if !self.in_test => self.macro_tokens(mac.tokens.clone()),
            Err(_) => {}
        }
    }
}

/// A module file of a crate: its path in the crate's folder (`src/film.rs`), its module path,
/// whether it is test code, and what it says.
#[derive(Debug)]
struct ModuleFile(String, Vec<String>, bool, FileScan);

#[derive(Debug)]
struct Crate {
    /// The member's path in the workspace, e.g. `integrators/path`.
    member: String,
    files: Vec<ModuleFile>,
    index: HashMap<Vec<String>, usize>,
}

/// The `.rs` files in `dir` and its subfolders.
fn rs_files(dir: &Path) -> Vec<PathBuf> {
    let mut files = Vec::new();
    let entries = std::fs::read_dir(dir).into_iter().flatten().flatten();
    for path in entries.map(|e| e.path()) {
        if path.is_dir() {
            files.extend(rs_files(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            files.push(path);
        }
    }
    files
}

/// Reads the crate at `root/member` by following its `mod` declarations from `src/lib.rs`.
fn read_crate(root: &Path, member: &str) -> Result<Crate, String> {
    let dir = root.join(member);
    let rel = |p: &Path| p.strip_prefix(&dir).unwrap().display().to_string();
    let (mut files, mut index, mut problems) = (Vec::new(), HashMap::new(), Vec::new());
    // (file, module, test only, whether its children live beside it: lib.rs, mod.rs, #[path])
    let mut queue = VecDeque::from([(dir.join("src/lib.rs"), Vec::new(), false, true)]);
    while let Some((path, module, test, owns_dir)) = queue.pop_front() {
        let fail = |e: &dyn std::fmt::Display| format!("{member}/{}: {e}", rel(&path));
        let text = std::fs::read_to_string(&path).map_err(|e| fail(&e))?;
        let parse_error =
            |e: syn::Error| format!("{member}/{}:{}: {e}", rel(&path), line(e.span()));
        let file = syn::parse_file(&text).map_err(parse_error)?;
        let mut scan = FileScan::default();
        scan.visit_file(&file);
        let here = path.parent().unwrap_or(&dir).to_path_buf();
        for (name, path_attr, inline, test_mod) in &scan.mods {
            let mut base = here.clone();
            if !owns_dir {
                base.push(path.file_stem().unwrap_or_default());
            }
            base.extend(inline);
            // `#[path]` is relative to the declaring file's folder, unless in an inline module.
            let candidates = match path_attr {
                Some(p) => vec![if inline.is_empty() { &here } else { &base }.join(p)],
                None => vec![
                    base.join(format!("{name}.rs")),
                    base.join(name).join("mod.rs"),
                ],
            };
            let Some(file) = candidates.into_iter().find(|c| c.is_file()) else {
                problems.push(fail(&format!("no file for `mod {name}`")));
                continue;
            };
            let owns = path_attr.is_some() || file.ends_with("mod.rs");
            let child = [&module[..], inline, std::slice::from_ref(name)].concat();
            queue.push_back((file, child, test || *test_mod, owns));
        }
        index.insert(module.clone(), files.len());
        files.push(ModuleFile(rel(&path), module, test, scan));
    }
    for path in rs_files(&dir.join("src"))
        .into_iter()
        .filter(|p| files.iter().all(|f| f.0 != rel(p)))
    {
        problems.push(format!(
            "{member}/{}: not a module reached from src/lib.rs by `mod` declarations, so these \
             checks cannot read it",
            rel(&path)
        ));
    }
    if !problems.is_empty() {
        return Err(problems.join("\n"));
    }
    Ok(Crate {
        member: member.to_owned(),
        files,
        index,
    })
}

impl Crate {
    /// The absolute module path `path` names, written in `file` (see the module docs); `None`
    /// for paths outside the crate (std, other crates, local names).
    fn absolutize(
        &self,
        file: &ModuleFile,
        PathRef(seg, inline, _, glob): &PathRef,
    ) -> Option<Vec<String>> {
        let context = [&file.1[..], inline].concat();
        let mut abs = match seg.first()?.as_str() {
            "crate" => seg[1..].to_vec(),
            "self" => [&context[..], &seg[1..]].concat(),
            "super" => {
                let ups = seg.iter().take_while(|s| *s == "super").count();
                [&context[..context.len().checked_sub(ups)?], &seg[ups..]].concat()
            }
            // A child module of the current module (or of the file's, from an inline one).
            _ => [&context, &file.1]
                .into_iter()
                .map(|m| [&m[..], seg].concat())
                .find(|m| self.index.contains_key(&m[..m.len() - seg.len() + 1]))?,
        };
        if *glob {
            abs.push("*".into());
        }
        Some(abs)
    }

    /// The file that the absolute path `abs` leads to, following `pub use`s.
    fn resolve(&self, abs: &[String], depth: u32) -> Option<usize> {
        (0..=abs.len()).rev().find_map(|k| {
            let &f = self.index.get(&abs[..k])?;
            let reexport = self.files[f]
                .3
                .reexports
                .iter()
                .find(|(n, _)| abs.get(k) == Some(n));
            let through = reexport.filter(|_| depth < 16).and_then(|(_, target)| {
                let target = self.absolutize(&self.files[f], target)?;
                self.resolve(&[&target[..], &abs[k + 1..]].concat(), depth + 1)
            });
            Some(through.unwrap_or(f))
        })
    }

    /// The dependencies between files: for each (from, to), the first line and path.
    fn edges(&self) -> BTreeMap<(usize, usize), (usize, String)> {
        let mut edges = BTreeMap::new();
        for (from, file) in self.files.iter().enumerate().filter(|(_, f)| !f.2) {
            for path in &file.3.paths {
                let to = self
                    .absolutize(file, path)
                    .and_then(|abs| self.resolve(&abs, 0));
                if let Some(to) = to.filter(|&to| to != from) {
                    let text = path.0.join("::") + if path.3 { "::*" } else { "" };
                    edges.entry((from, to)).or_insert((path.2, text));
                }
            }
        }
        edges
    }

    /// Every cycle of file dependencies, step by step: for each file on a loop no cycle found
    /// so far goes through, the shortest loop through it.
    fn cycles(&self) -> Vec<String> {
        let (edges, n) = (self.edges(), self.files.len());
        let name = |f: usize| self.files[f].0.as_str();
        let (mut shown, mut out) = (vec![false; n], Vec::new());
        for start in 0..n {
            if shown[start] {
                continue;
            }
            // Breadth first from `start` until a step leads back to it.
            let (mut parent, mut queue) = (vec![None; n], VecDeque::from([start]));
            while let Some(a) = queue.pop_front().filter(|_| parent[start].is_none()) {
                for &(_, b) in edges.range((a, 0)..(a + 1, 0)).map(|(k, _)| k) {
                    if parent[b].is_none() {
                        parent[b] = Some(a);
                        queue.push_back(b);
                    }
                }
            }
            let mut cycle = vec![start];
            while let Some(p) = parent[cycle[0]].filter(|_| cycle.len() == 1 || cycle[0] != start) {
                cycle.insert(0, p);
            }
            if cycle.len() == 1 {
                continue;
            }
            cycle.iter().for_each(|&f| shown[f] = true);
            let names: Vec<&str> = cycle.iter().map(|&f| name(f)).collect();
            let steps = cycle.windows(2).map(|step| {
                let (line, path) = &edges[&(step[0], step[1])];
                format!("\n    {}:{line} names {path}", name(step[0]))
            });
            let steps: String = steps.collect();
            out.push(format!(
                "{}: import cycle {}{steps}",
                self.member,
                names.join(" -> ")
            ));
        }
        out
    }

    fn mutable_statics(&self) -> Vec<String> {
        let files = self.files.iter().filter(|f| !f.2);
        let state =
            files.flat_map(|f| f.3.state.iter().map(move |(line, what)| (&f.0, line, what)));
        let message = |(rel, line, what)| {
            format!(
                "{}/{rel}:{line}: {what} is process-wide mutable state in library code: keep it \
                 in a value the caller owns and passes in",
                self.member
            )
        };
        state.map(message).collect()
    }
}

/// Runs `rule` over every library crate of the workspace at `root`; the problems found.
fn check_workspace(root: &Path, rule: impl Fn(&Crate) -> Vec<String>) -> Vec<String> {
    let members = match workspace::library_members(root) {
        Ok(members) => members,
        Err(e) => return vec![e],
    };
    let check = |m: String| read_crate(root, &m).map_or_else(|e| vec![e], |k| rule(&k));
    members.into_iter().flat_map(check).collect()
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

// The checks themselves, on small made-up workspaces: each must be able to fail.

/// A workspace in a temporary folder with `members` and `files`, each file given by a line
/// `== path` followed by its text.
fn workspace(members: &[&str], files: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let manifest = format!("[workspace]\nmembers = [\"{}\"]\n", members.join("\", \""));
    std::fs::write(dir.path().join("Cargo.toml"), manifest).unwrap();
    for file in files.split("== ").skip(1) {
        let (path, text) = file.split_once('\n').unwrap();
        let path = dir.path().join(path);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }
    dir
}

fn cycles_in(files: &str) -> Vec<String> {
    check_workspace(workspace(&["lib"], files).path(), Crate::cycles)
}

#[test]
fn cycles_are_named_with_the_line_of_each_step() {
    // film ↔ render; a → b through a use tree, b → c through `super::`, c → a through the
    // root's re-export; m/child.rs uses its parent by a glob.
    let found = cycles_in(
        "== lib/src/lib.rs\npub mod film;\npub mod render;\nmod a;\nmod b;\nmod c;\nmod m;
pub use a::Thing;
== lib/src/film.rs\npub struct Film;\npub fn n() -> usize {\n    crate::render::count()\n}
== lib/src/render.rs\nuse crate::film::Film;
== lib/src/a.rs\nuse crate::{b::{self, B}};
== lib/src/b.rs\npub struct B;\nfn f() {\n    super::c::g();\n}
== lib/src/c.rs\npub fn g() -> crate::Thing {}
== lib/src/m.rs\nmod child;\nuse child::helper;
== lib/src/m/child.rs\nuse super::*;
",
    );
    let expected = [
        "lib: import cycle src/film.rs -> src/render.rs -> src/film.rs
    src/film.rs:3 names crate::render::count
    src/render.rs:1 names crate::film::Film",
        "lib: import cycle src/a.rs -> src/b.rs -> src/c.rs -> src/a.rs
    src/a.rs:1 names crate::b
    src/b.rs:3 names super::c::g
    src/c.rs:1 names crate::Thing",
        "lib: import cycle src/m.rs -> src/m/child.rs -> src/m.rs
    src/m.rs:2 names child::helper
    src/m/child.rs:1 names super::*",
    ];
    assert_eq!(found, expected);
}

#[test]
fn paths_in_macro_bodies_count_but_metavariables_do_not() {
    let found = cycles_in(
        "== lib/src/lib.rs\nmod a;\nmod b;\nmod c;\nmacro_rules! m { ($c:ident) => { $c::Y }; }
== lib/src/a.rs\nmacro_rules! m { ($b:ident) => { $crate::b::X + $b::Y }; }
== lib/src/b.rs\npub fn f() -> usize { format!(\"{}\", crate::a::Z).len() }
== lib/src/c.rs\npub const Y: u32 = crate::X;
",
    );
    let expected = "lib: import cycle src/a.rs -> src/b.rs -> src/a.rs
    src/a.rs:1 names crate::b::X
    src/b.rs:1 names crate::a::Z";
    assert_eq!(found, [expected]);
}

#[test]
fn what_is_not_a_use_makes_no_cycle() {
    // Comments, strings and lifetimes name b; test code uses it; std is no file of the crate.
    assert_none(cycles_in(
        "== lib/src/lib.rs\n//! See [`crate::b::f`].\npub mod a;\npub mod b;
#[cfg(test)]\nmod util;
== lib/src/a.rs\n// crate::b::f()\npub fn f(x: &'static str) -> &str { let _ = \"crate::b::f\"; x }
pub use std::fmt::Debug;\n#[cfg(test)]\nmod tests {\n    use crate::b;\n    fn t() { b::f(); }\n}
== lib/src/b.rs\npub fn f() { crate::a::f(\"\"); }
== lib/src/util.rs\npub fn x() { crate::b::f(); }
",
    ));
}

#[test]
fn every_library_member_and_file_is_read() {
    // The front ends are no library; a member whose sources cannot be read fails.
    let ws = workspace(&["core", "scene", "cli", "python"], "");
    let found = check_workspace(ws.path(), Crate::cycles);
    let members: Vec<&str> = found.iter().map(|f| &f[..f.find('/').unwrap()]).collect();
    assert_eq!(members, ["core", "scene"], "{found:?}");
    let found = cycles_in(
        "== lib/src/lib.rs\n#[path = \"elsewhere.rs\"]\nmod a;
== lib/src/elsewhere.rs\n== lib/src/stray.rs\n",
    );
    let stray = "lib/src/stray.rs: not a module reached from src/lib.rs by `mod` declarations, so \
                 these checks cannot read it";
    assert_eq!(found, [stray]);
}

#[test]
fn mutable_statics_are_found_and_constant_ones_pass() {
    let ws = workspace(
        &["core"],
        "== core/src/lib.rs
use std::sync::atomic::AtomicU64;
static NAMES: [&str; 2] = [\"a\", \"b\"];
static mut COUNT: u32 = 0;
pub fn id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    0
}
static CACHE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
thread_local! { static RAYS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) }; }
macro_rules! counter { () => { static HITS: AtomicU64 = AtomicU64::new(0); }; }
pub fn f(x: &'static str) -> &'static str { x }
#[cfg(test)]
mod tests {
    static SHARED: std::sync::Mutex<u32> = std::sync::Mutex::new(0);
}
",
    );
    let found = check_workspace(ws.path(), Crate::mutable_statics);
    let found: Vec<&str> = found
        .iter()
        .map(|f| f.split(" is ").next().unwrap())
        .collect();
    let expected = [
        "core/src/lib.rs:3: `static mut`",
        "core/src/lib.rs:5: `static NEXT` of type AtomicU64",
        "core/src/lib.rs:8: `static CACHE` of type OnceLock",
        "core/src/lib.rs:9: `static RAYS` of type Cell",
        "core/src/lib.rs:10: `static HITS` of type AtomicU64",
    ];
    assert_eq!(found, expected);
}
