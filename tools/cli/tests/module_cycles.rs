//! The modules of the `topoloc` command import each other without cycles (their imports form a
//! DAG). The checker is the library's (`tests/layers.rs` shows it catches cycles).

#[path = "../../../tests/module_graph/mod.rs"]
mod module_graph;

use module_graph::ModuleGraph;
use std::path::Path;

#[test]
fn cli_modules_import_each_other_without_cycles() {
    let graph = ModuleGraph::from_src(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"));
    graph.assert_acyclic(
        &["demo", "scenario_args", "simulate", "suite", "sweep"],
        &[
            ("demo", "scenario_args"),
            ("simulate", "scenario_args"),
            ("suite", "demo"),
        ],
    );
}
