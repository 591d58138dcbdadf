//! The modules of topoloc-sim import each other without cycles (their imports form a DAG), and
//! the checker behind that catches cycles it is shown.

mod module_graph;

use module_graph::ModuleGraph;
use std::path::Path;

fn sim_graph() -> ModuleGraph {
    ModuleGraph::from_src(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"))
}

#[test]
fn sim_modules_import_each_other_without_cycles() {
    let graph = sim_graph();
    // Not vacuous: the graph holds the crate's modules and imports that are known to exist.
    for module in [
        "camera", "render", "rng", "scenario", "style", "texture", "world",
    ] {
        assert!(graph.edges.contains_key(module), "module {module} not read");
    }
    let edges = graph.edge_list();
    for edge in [
        ("scenario", "world"),
        ("render", "world"),
        ("texture", "rng"),
    ] {
        assert!(
            edges.contains(&edge),
            "import {edge:?} not found in {edges:?}"
        );
    }
    if let Some(cycle) = graph.find_cycle() {
        panic!("import cycle: {}", graph.describe(&cycle));
    }
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
