//! The import graph between the modules of a crate (or between the submodules of one of its
//! modules), read from its source files, and a cycle finder. Shared by `tests/layers.rs` and
//! the `module_cycles` tests of `tools/sim` and `tools/cli`, which include this file by path.
//!
//! A module is a file `src/NAME.rs` together with everything under `src/NAME/`; the crate root
//! (`lib.rs` or `main.rs`) is not a node. [`ModuleGraph::from_module`] reads one module's folder
//! the same way, its `mod.rs` being the root and `crate::MODULE::` its path. A module imports another when its code (comments
//! removed, so doc links do not count) names `crate::OTHER` (in a `use` line, a
//! `use crate::{a, b::C}` group, or a path in an expression) or reaches `OTHER` through enough
//! `super::` to climb to the crate root (`super::super::OTHER` from `src/a/b.rs`). Names that
//! are not modules (items of the crate root) are ignored; so are references inside the same
//! module (`super::` from `src/a/b.rs` or from a `mod tests` block).

#![allow(dead_code)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Where a module names another one: the file (relative to `src/`) and the line.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct Site {
    pub file: String,
    pub line: usize,
}

/// Top-level modules and, for each, the modules it names with where it names them first.
#[derive(Debug, Default)]
pub struct ModuleGraph {
    pub edges: BTreeMap<String, BTreeMap<String, Site>>,
    /// Names of the root that are not modules (items the root defines or re-exports), as
    /// `(from module, name, where)`.
    pub root_items: Vec<(String, String, Site)>,
}

impl ModuleGraph {
    /// Reads every `.rs` file under `src` (the crate's source folder).
    pub fn from_src(src: &Path) -> ModuleGraph {
        ModuleGraph::from_files(&read_tree(src))
    }

    /// Reads the submodules of `module` (a folder `src/MODULE/` with a `mod.rs`; `a/b` for a
    /// nested one): the nodes are its files and folders, and an import is a path through
    /// `crate::MODULE::` (`crate::a::b::`) or enough `super::` to climb to `MODULE`.
    pub fn from_module(src: &Path, module: &str) -> ModuleGraph {
        let files = read_tree(&src.join(module));
        let root = format!("crate::{}::", module.replace('/', "::"));
        let mut graph = ModuleGraph::read(&files, &root, "mod");
        let sites = graph.edges.values_mut().flat_map(|to| to.values_mut());
        for site in sites.chain(graph.root_items.iter_mut().map(|(_, _, site)| site)) {
            site.file = format!("{module}/{}", site.file);
        }
        graph
    }

    /// Builds the graph from `(path relative to src, text)` pairs, paths with `/` separators:
    /// `lib.rs` or `main.rs` is the root, `a.rs` and `a/b.rs` belong to module `a`.
    pub fn from_files<P: AsRef<str>, T: AsRef<str>>(files: &[(P, T)]) -> ModuleGraph {
        ModuleGraph::read(files, "crate::", "lib")
    }

    /// The graph of `files`, whose root file is `{root_file}.rs` (or `main.rs`) and whose root
    /// path is `root_path` (`crate::` or `crate::MODULE::`).
    fn read<P: AsRef<str>, T: AsRef<str>>(
        files: &[(P, T)],
        root_path: &str,
        root_file: &str,
    ) -> ModuleGraph {
        let module_of = |path: &str| -> Option<String> {
            let first = path.split('/').next().unwrap_or(path);
            let name = first.strip_suffix(".rs").unwrap_or(first);
            let is_root = !path.contains('/')
                && (name == root_file || (root_file == "lib" && name == "main"));
            (!is_root).then(|| name.to_string())
        };
        let mut graph = ModuleGraph::default();
        for (path, _) in files {
            if let Some(m) = module_of(path.as_ref()) {
                graph.edges.entry(m).or_default();
            }
        }
        let modules: BTreeSet<String> = graph.edges.keys().cloned().collect();
        for (path, text) in files {
            let (path, text) = (path.as_ref(), text.as_ref());
            let Some(from) = module_of(path) else {
                continue;
            };
            // `src/a.rs` is one level below the root, `src/a/b.rs` two.
            let depth = path.split('/').count();
            for (line, to, named_from_root) in references(&strip_comments(text), depth, root_path) {
                let site = Site {
                    file: path.to_string(),
                    line,
                };
                if modules.contains(&to) {
                    if to != from {
                        let targets = graph.edges.get_mut(&from).expect("every module is a node");
                        targets.entry(to).or_insert(site);
                    }
                } else if named_from_root && !to.is_empty() {
                    graph.root_items.push((from.clone(), to, site));
                }
            }
        }
        graph
    }

    /// Every import as `(from, to)`.
    pub fn edge_list(&self) -> Vec<(&str, &str)> {
        self.edges
            .iter()
            .flat_map(|(from, to)| to.keys().map(move |t| (from.as_str(), t.as_str())))
            .collect()
    }

    /// A cycle of imports `[a, b, ..., a]` if there is one (depth-first search).
    pub fn find_cycle(&self) -> Option<Vec<String>> {
        #[derive(Clone, Copy, PartialEq)]
        enum Mark {
            New,
            Open,
            Done,
        }
        fn visit<'a>(
            graph: &'a ModuleGraph,
            m: &'a str,
            marks: &mut BTreeMap<&'a str, Mark>,
            path: &mut Vec<&'a str>,
        ) -> Option<Vec<String>> {
            marks.insert(m, Mark::Open);
            path.push(m);
            for to in graph.edges[m].keys() {
                match marks[to.as_str()] {
                    Mark::Open => {
                        let start = path.iter().position(|p| p == to).expect("open is on path");
                        let mut cycle: Vec<String> =
                            path[start..].iter().map(|s| s.to_string()).collect();
                        cycle.push(to.clone());
                        return Some(cycle);
                    }
                    Mark::New => {
                        if let Some(cycle) = visit(graph, to, marks, path) {
                            return Some(cycle);
                        }
                    }
                    Mark::Done => {}
                }
            }
            path.pop();
            marks.insert(m, Mark::Done);
            None
        }
        let mut marks: BTreeMap<&str, Mark> =
            self.edges.keys().map(|m| (m.as_str(), Mark::New)).collect();
        for m in self.edges.keys() {
            if marks[m.as_str()] == Mark::New {
                if let Some(cycle) = visit(self, m, &mut marks, &mut Vec::new()) {
                    return Some(cycle);
                }
            }
        }
        None
    }

    /// Panics unless the graph is acyclic and holds `modules` and `edges` (which show that the
    /// reading was not vacuous).
    pub fn assert_acyclic(&self, modules: &[&str], edges: &[(&str, &str)]) {
        for module in modules {
            assert!(self.edges.contains_key(*module), "module {module} not read");
        }
        let found = self.edge_list();
        for edge in edges {
            assert!(
                found.contains(edge),
                "import {edge:?} not found in {found:?}"
            );
        }
        if let Some(cycle) = self.find_cycle() {
            panic!("import cycle: {}", self.describe(&cycle));
        }
    }

    /// A cycle spelled out with where each import is, for a failure message.
    pub fn describe(&self, cycle: &[String]) -> String {
        let steps: Vec<String> = cycle
            .windows(2)
            .map(|w| {
                let site = &self.edges[&w[0]][&w[1]];
                format!("{} -> {} (src/{}:{})", w[0], w[1], site.file, site.line)
            })
            .collect();
        steps.join(", ")
    }
}

/// `(path relative to src with / separators, text)` of every `.rs` file under `src`, sorted.
fn read_tree(src: &Path) -> Vec<(String, String)> {
    let mut files = Vec::new();
    collect(src, src, &mut files);
    files.sort();
    files
}

fn collect(src: &Path, dir: &Path, out: &mut Vec<(String, String)>) {
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            collect(src, &path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            let rel = path.strip_prefix(src).expect("under src");
            let rel: Vec<String> = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .collect();
            let text = std::fs::read_to_string(&path).expect("readable source");
            out.push((rel.join("/"), text));
        }
    }
}

/// Removes `//` comments (doc comments too), `/* */` comments and the contents of string
/// literals (raw ones too), keeping line breaks so that line numbers stay right.
fn strip_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    let keep_lines = |skipped: &str, out: &mut String| {
        out.extend(skipped.chars().filter(|&c| c == '\n'));
    };
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix("//") {
            let end = after.find('\n').unwrap_or(after.len());
            rest = &after[end..];
        } else if let Some(after) = rest.strip_prefix("/*") {
            let end = after.find("*/").map_or(after.len(), |e| e + 2);
            keep_lines(&after[..end], &mut out);
            rest = &after[end..];
        } else if let Some((open, close)) = raw_string_quotes(rest) {
            let after = &rest[open..];
            let end = after.find(&close).map_or(after.len(), |e| e + close.len());
            out.push_str("\"\"");
            keep_lines(&after[..end], &mut out);
            rest = &after[end..];
        } else if let Some(after) = rest.strip_prefix('"') {
            let mut end = after.len();
            let mut escaped = false;
            for (i, c) in after.char_indices() {
                match c {
                    '\\' if !escaped => escaped = true,
                    '"' if !escaped => {
                        end = i + 1;
                        break;
                    }
                    _ => escaped = false,
                }
            }
            out.push_str("\"\"");
            keep_lines(&after[..end], &mut out);
            rest = &after[end..];
        } else if let Some(len) = char_literal_len(rest) {
            out.push_str("' '");
            rest = &rest[len..];
        } else {
            let c = rest.chars().next().expect("not empty");
            out.push(c);
            rest = &rest[c.len_utf8()..];
        }
    }
    out
}

/// For text starting with a raw string (`r"`, `r#"`, `br##"`...): the length of its opening and
/// its closing quote.
fn raw_string_quotes(text: &str) -> Option<(usize, String)> {
    let after_b = text.strip_prefix('b').unwrap_or(text);
    let after_r = after_b.strip_prefix('r')?;
    let hashes = after_r.chars().take_while(|&c| c == '#').count();
    after_r[hashes..].starts_with('"').then(|| {
        let open = text.len() - after_r.len() + hashes + 1;
        (open, format!("\"{}", "#".repeat(hashes)))
    })
}

/// For text starting with a character literal (`'x'`, `'\n'`, `'\''`, `'\u{..}'`): its length.
/// Lifetimes (`'a`) are not literals.
fn char_literal_len(text: &str) -> Option<usize> {
    let body = text.strip_prefix('\'')?;
    let len = if let Some(escape) = body.strip_prefix('\\') {
        let escaped = escape.chars().next()?.len_utf8();
        1 + escaped + escape[escaped..].find('\'')?
    } else {
        body.chars().next()?.len_utf8()
    };
    body[len..].starts_with('\'').then_some(len + 2)
}

/// The names following each `root` path (`crate::` or `crate::MODULE::`) and each run of
/// `super::` that climbs to the root from a file `depth` levels below it, with their line
/// numbers and whether the name was reached through `root` (rather than `super::`);
/// `{a, b::c}` groups give each member's first name.
fn references(code: &str, depth: usize, root: &str) -> Vec<(usize, String, bool)> {
    let mut found = Vec::new();
    let is_ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut at = 0;
    while at < code.len() {
        let rest = &code[at..];
        let Some(c) = rest.chars().next() else { break };
        let before_ok = at == 0 || !code[..at].ends_with(|p: char| is_ident(p) || p == '$');
        let mut path = None;
        if before_ok && rest.starts_with(root) {
            path = Some(root.len());
        } else if before_ok && rest.starts_with("super::") {
            let mut len = 0;
            let mut supers = 0;
            while rest[len..].starts_with("super::") {
                len += "super::".len();
                supers += 1;
            }
            if supers >= depth {
                path = Some(len);
            } else {
                at += len;
                continue;
            }
        }
        let Some(len) = path else {
            at += c.len_utf8();
            continue;
        };
        let from_root = rest.starts_with(root);
        let line = code[..at].matches('\n').count() + 1;
        let tail = &code[at + len..];
        if let Some(group) = tail.strip_prefix('{') {
            for member in top_level_members(group) {
                let name: String = member.trim().chars().take_while(|&c| is_ident(c)).collect();
                if !name.is_empty() {
                    found.push((line, name, from_root));
                }
            }
        } else {
            let name = tail.chars().take_while(|&c| is_ident(c)).collect();
            found.push((line, name, from_root));
        }
        at += len;
    }
    found
}

/// The comma-separated members of a `{...}` group whose text starts after the `{`.
fn top_level_members(group: &str) -> Vec<&str> {
    let (mut members, mut depth, mut from) = (Vec::new(), 0usize, 0);
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                members.push(&group[from..i]);
                return members;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                members.push(&group[from..i]);
                from = i + 1;
            }
            _ => {}
        }
    }
    members.push(&group[from..]);
    members
}
