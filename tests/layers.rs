//! Holds the library's module structure against its source:
//! - a module may name another module of the crate (`use crate::x`, or a `crate::x::` path in
//!   code) only when that module sits in a lower layer of the table in `src/lib.rs` (the one
//!   place that table lives; this test reads it from there);
//! - `eval` reads the core and is read by no module but the C ABI, which exposes its trajectory
//!   metrics;
//! - inside every module, the submodules import each other without cycles.

mod module_graph;

use module_graph::ModuleGraph;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Modules that no other module of the library may import, but the ones listed with them.
const NEVER_IMPORTED: &[(&str, &[&str])] = &[("eval", &["ffi"])];

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// The layer of every module, from the `# Layers` table of a crate root's doc comment: rows
/// `//! | N | [`a`], `b` | what |`.
fn layers_from_doc(lib_rs: &str) -> BTreeMap<String, u32> {
    let mut layers = BTreeMap::new();
    for line in lib_rs.lines() {
        let Some(row) = line.strip_prefix("//! |") else {
            continue;
        };
        let cells: Vec<&str> = row.split('|').collect();
        let Some(Ok(layer)) = cells.first().map(|c| c.trim().parse::<u32>()) else {
            continue;
        };
        let names = cells.get(1).copied().unwrap_or("");
        for name in names.split(',') {
            let name = name
                .trim()
                .trim_matches(|c| c == '[' || c == ']' || c == '`');
            if !name.is_empty() {
                layers.insert(name.to_string(), layer);
            }
        }
    }
    layers
}

/// What breaks the layer order in `graph`: `(from, to, where)` for each import of a module in
/// the same or a higher layer, of a module that may not be imported, of a module missing from
/// the table, or of a crate-root item (it hides which layer it comes from).
fn violations(graph: &ModuleGraph, layers: &BTreeMap<String, u32>) -> Vec<String> {
    let mut found = Vec::new();
    for (from, targets) in &graph.edges {
        let Some(&own) = layers.get(from) else {
            found.push(format!(
                "{from}: module missing from the table in src/lib.rs"
            ));
            continue;
        };
        for (to, site) in targets {
            let allowed = layers.get(to).is_some_and(|&layer| layer < own)
                && NEVER_IMPORTED
                    .iter()
                    .all(|(module, readers)| module != to || readers.contains(&from.as_str()));
            if !allowed {
                found.push(format!("{from} -> {to} (src/{}:{})", site.file, site.line));
            }
        }
    }
    for (from, name, site) in &graph.root_items {
        if name != "VERSION" {
            found.push(format!(
                "{from} -> crate::{name}, a crate-root item (src/{}:{})",
                site.file, site.line
            ));
        }
    }
    found
}

#[test]
fn every_module_imports_only_from_lower_layers() {
    let layers = layers_from_doc(&std::fs::read_to_string(src().join("lib.rs")).unwrap());
    assert!(
        layers.len() >= 10,
        "too few modules in the table: {layers:?}"
    );
    assert_eq!(layers.get("ffi"), Some(&8), "{layers:?}");
    assert_eq!(layers.get("errors"), Some(&1), "{layers:?}");
    let graph = ModuleGraph::from_src(&src());
    let modules: Vec<&String> = graph.edges.keys().collect();
    let listed: Vec<&String> = layers.keys().collect();
    assert_eq!(
        modules, listed,
        "src/ and the table in src/lib.rs name other modules"
    );
    let found = violations(&graph, &layers);
    assert!(
        found.is_empty(),
        "imports against the layer order (src/lib.rs): {found:#?}"
    );
}

/// Every module folder (a folder with a `mod.rs`) under `dir`, as a path relative to `src`.
fn module_folders(src: &Path, dir: &Path, out: &mut Vec<String>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            if path.join("mod.rs").is_file() {
                let relative = path.strip_prefix(src).unwrap();
                out.push(relative.to_string_lossy().replace('\\', "/"));
            }
            module_folders(src, &path, out);
        }
    }
}

#[test]
fn the_submodules_of_every_module_import_each_other_without_cycles() {
    let mut folders = Vec::new();
    module_folders(&src(), &src(), &mut folders);
    assert!(folders.len() >= 8, "only {folders:?} read");
    for module in &folders {
        let graph = ModuleGraph::from_module(&src(), module);
        if let Some(cycle) = graph.find_cycle() {
            panic!("import cycle inside {module}: {}", graph.describe(&cycle));
        }
    }
    // Not vacuous: imports known to exist are found.
    let localize = ModuleGraph::from_module(&src(), "localize");
    let edges = localize.edge_list();
    for edge in [("localizer", "verification"), ("localizer", "options")] {
        assert!(edges.contains(&edge), "{edge:?} not in {edges:?}");
    }
}

#[test]
fn the_layer_table_is_read_from_the_doc_rows() {
    let doc = "//! # Layers\n//! | layer | modules | what |\n//! |---|---|---|\n\
               //! | 3 | [`describe`], [`verify`] | backends |\n//! | 1 | `errors` | kinds |\n";
    let layers = layers_from_doc(doc);
    assert_eq!(
        layers.into_iter().collect::<Vec<_>>(),
        [
            ("describe".into(), 3),
            ("errors".into(), 1),
            ("verify".into(), 3)
        ]
    );
}

/// The layer check over a crate of `files` with the table `layers`.
fn check(files: &[(&str, &str)], layers: &[(&str, u32)]) -> Vec<String> {
    let layers = layers.iter().map(|(m, l)| (m.to_string(), *l)).collect();
    violations(&ModuleGraph::from_files(files), &layers)
}

const TWO_LAYERS: &[(&str, u32)] = &[("eval", 2), ("ffi", 3), ("image", 1), ("map", 2)];

#[test]
fn the_check_catches_a_back_import_in_every_form() {
    let lib = (
        "lib.rs",
        "pub mod eval;\npub mod ffi;\npub mod image;\npub mod map;\n",
    );
    let back = [lib, ("image.rs", "use crate::map::Map;\n"), ("map.rs", "")];
    assert_eq!(check(&back, TWO_LAYERS), ["image -> map (src/image.rs:1)"]);
    let grouped = [
        lib,
        ("image/x.rs", "use crate::{\n    map::Map,\n};\n"),
        ("map.rs", ""),
    ];
    assert_eq!(
        check(&grouped, TWO_LAYERS),
        ["image -> map (src/image/x.rs:1)"]
    );
    let inline = [
        lib,
        ("image.rs", "fn f() {\n    crate::ffi::g();\n}\n"),
        ("ffi.rs", ""),
    ];
    assert_eq!(
        check(&inline, TWO_LAYERS),
        ["image -> ffi (src/image.rs:2)"]
    );
    let same_layer = [lib, ("map.rs", "use crate::eval::X;\n"), ("eval.rs", "")];
    assert_eq!(check(&same_layer, TWO_LAYERS).len(), 1);
    let eval_read = [lib, ("ffi.rs", "use crate::eval::X;\n"), ("eval.rs", "")];
    assert!(
        check(&eval_read, TWO_LAYERS).is_empty(),
        "the C ABI may read eval"
    );
    let root = [lib, ("map.rs", "use crate::Map;\nuse crate::VERSION;\n")];
    assert_eq!(
        check(&root, TWO_LAYERS),
        ["map -> crate::Map, a crate-root item (src/map.rs:1)"]
    );
    let unknown = [lib, ("newthing.rs", "")];
    assert_eq!(
        check(&unknown, TWO_LAYERS).len(),
        1,
        "a module missing from the table fails"
    );
}

#[test]
fn comments_strings_and_downward_imports_pass() {
    let fine = "//! See [`crate::ffi`].\n/// [`crate::map::Map`]\nuse crate::image::ImageView;\n\
                let s = \"crate::ffi\";\nlet r = r#\"crate::ffi \"quoted\"\"#;\nlet q = '\"';\n\
                use super::x; // crate::ffi\nlet t = \"after crate::ffi\";\n";
    let files = [("lib.rs", ""), ("map.rs", fine), ("image.rs", "")];
    assert_eq!(check(&files, TWO_LAYERS), Vec::<String>::new());
}

#[test]
fn a_submodule_cycle_is_found_through_super_and_the_module_path() {
    let dir = tempfile::tempdir().unwrap();
    let module = dir.path().join("m");
    std::fs::create_dir_all(module.join("c")).unwrap();
    for (file, text) in [
        ("mod.rs", "mod a;\nmod b;\nmod c;\n"),
        ("a.rs", "use super::b::X;\nuse crate::b::Unrelated;\n"),
        ("b.rs", "fn f() {\n    crate::m::c::g();\n}\n"),
        ("c.rs", "mod inner;\n"),
        ("c/inner.rs", "use super::super::a::Y;\n"),
    ] {
        std::fs::write(module.join(file), text).unwrap();
    }
    let graph = ModuleGraph::from_module(dir.path(), "m");
    let cycle = graph.find_cycle().expect("a -> b -> c -> a");
    assert_eq!(cycle, ["a", "b", "c", "a"]);
    assert_eq!(
        graph.describe(&cycle),
        "a -> b (src/m/a.rs:1), b -> c (src/m/b.rs:2), c -> a (src/m/c/inner.rs:1)"
    );
}
#[test]
fn checker_finds_a_cycle_through_groups_paths_and_super() {
    let files = [
        ("lib.rs", "pub mod a;\npub mod b;\npub mod c;\npub mod d;\n"),
        ("a.rs", "use crate::b::X;\n"),
        // A group, and `d` (no cycle through it).
        ("b.rs", "use crate::{d, c::{Y, Z}};\n"),
        ("c.rs", "mod inner;\n"),
        // Back to `a` from a submodule of `c`, climbing to the root with `super::super::`.
        ("c/inner.rs", "fn f() {\n    super::super::a::g();\n}\n"),
        ("d.rs", "pub struct D;\n"),
    ];
    let graph = ModuleGraph::from_files(&files);
    let cycle = graph.find_cycle().expect("a -> b -> c -> a is a cycle");
    assert_eq!(cycle, ["a", "b", "c", "a"]);
    assert_eq!(
        graph.describe(&cycle),
        "a -> b (src/a.rs:1), b -> c (src/b.rs:1), c -> a (src/c/inner.rs:2)"
    );
}

#[test]
fn checker_finds_a_two_module_cycle_in_expression_paths() {
    let files = [
        ("main.rs", "mod x;\nmod y;\n"),
        ("x.rs", "fn f() -> u32 {\n    crate::y::g()\n}\n"),
        (
            "y.rs",
            "pub fn g() -> u32 {\n    1\n}\nfn h() {\n    crate::x::f();\n}\n",
        ),
    ];
    let cycle = ModuleGraph::from_files(&files).find_cycle();
    assert_eq!(cycle.expect("x <-> y"), ["x", "y", "x"]);
}

#[test]
fn checker_passes_a_dag_and_ignores_comments_and_local_paths() {
    let files = [
        ("lib.rs", "pub mod a;\npub mod b;\npub mod c;\n"),
        // Doc links and comments are not imports.
        (
            "a.rs",
            "//! See [`crate::c`].\nuse crate::b::X;\n/* crate::c::Y */\n",
        ),
        (
            "b.rs",
            "use crate::c::Y;\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n",
        ),
        // `super::` from a submodule stays inside `c`; `$crate::` is not this crate's path.
        (
            "c.rs",
            "mod sub;\nmacro_rules! m { () => { $crate::a::f() } }\n",
        ),
        ("c/sub.rs", "use super::Y;\n/// [`crate::a`]\nfn f() {}\n"),
    ];
    let graph = ModuleGraph::from_files(&files);
    assert_eq!(graph.edge_list(), [("a", "b"), ("b", "c")]);
    assert_eq!(graph.find_cycle(), None);
}
