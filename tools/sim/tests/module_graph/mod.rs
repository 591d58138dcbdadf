//! The import graph between the top-level modules of a crate, read from its source files, and a
//! cycle finder. Shared by `tools/sim/tests/module_cycles.rs` and
//! `tools/cli/tests/module_cycles.rs` (the latter includes this file by path).
//!
//! A module is a file `src/NAME.rs` together with everything under `src/NAME/`; the crate root
//! (`lib.rs` or `main.rs`) is not a node. A module imports another when its code (comments
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
}

impl ModuleGraph {
    /// Reads every `.rs` file under `src` (the crate's source folder).
    pub fn from_src(src: &Path) -> ModuleGraph {
        let mut files = Vec::new();
        collect(src, src, &mut files);
        files.sort();
        let borrowed: Vec<(&str, &str)> = files
            .iter()
            .map(|(p, t)| (p.as_str(), t.as_str()))
            .collect();
        ModuleGraph::from_files(&borrowed)
    }

    /// Builds the graph from `(path relative to src, text)` pairs, paths with `/` separators:
    /// `lib.rs` or `main.rs` is the root, `a.rs` and `a/b.rs` belong to module `a`.
    pub fn from_files(files: &[(&str, &str)]) -> ModuleGraph {
        let module_of = |path: &str| -> Option<String> {
            let first = path.split('/').next().unwrap_or(path);
            let name = first.strip_suffix(".rs").unwrap_or(first);
            let is_root = !path.contains('/') && (name == "lib" || name == "main");
            (!is_root).then(|| name.to_string())
        };
        let mut graph = ModuleGraph::default();
        for (path, _) in files {
            if let Some(m) = module_of(path) {
                graph.edges.entry(m).or_default();
            }
        }
        let modules: BTreeSet<String> = graph.edges.keys().cloned().collect();
        for (path, text) in files {
            let Some(from) = module_of(path) else {
                continue;
            };
            // `src/a.rs` is one level below the root, `src/a/b.rs` two.
            let depth = path.split('/').count();
            for (line, to) in references(&strip_comments(text), depth) {
                if to != from && modules.contains(&to) {
                    let site = Site {
                        file: path.to_string(),
                        line,
                    };
                    let targets = graph.edges.get_mut(&from).expect("every module is a node");
                    targets.entry(to).or_insert(site);
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

/// Removes `//` comments (doc comments too) and `/* */` comments, keeping line breaks.
fn strip_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix("//") {
            let end = after.find('\n').unwrap_or(after.len());
            rest = &after[end..];
        } else if let Some(after) = rest.strip_prefix("/*") {
            let end = after.find("*/").map_or(after.len(), |e| e + 2);
            out.extend(after[..end].chars().filter(|&c| c == '\n'));
            rest = &after[end..];
        } else {
            let c = rest.chars().next().expect("not empty");
            out.push(c);
            rest = &rest[c.len_utf8()..];
        }
    }
    out
}

/// The names following each `crate::` and each run of `super::` that climbs to the crate root
/// from a file `depth` levels below it, with their line numbers; `{a, b::c}` groups give each
/// member's first name.
fn references(code: &str, depth: usize) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    let is_ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut at = 0;
    while at < code.len() {
        let rest = &code[at..];
        let Some(c) = rest.chars().next() else { break };
        let before_ok = at == 0 || !code[..at].ends_with(|p: char| is_ident(p) || p == '$');
        let mut path = None;
        if before_ok && rest.starts_with("crate::") {
            path = Some("crate::".len());
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
        let line = code[..at].matches('\n').count() + 1;
        let tail = &code[at + len..];
        if let Some(group) = tail.strip_prefix('{') {
            for member in top_level_members(group) {
                let name: String = member.trim().chars().take_while(|&c| is_ident(c)).collect();
                if !name.is_empty() {
                    found.push((line, name));
                }
            }
        } else {
            found.push((line, tail.chars().take_while(|&c| is_ident(c)).collect()));
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
