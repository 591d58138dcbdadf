//! The modules of the `topoloc` command import each other without cycles (their imports form a
//! DAG). The checker is topoloc-sim's (its own tests show it catches cycles).

#[path = "../../sim/tests/module_graph/mod.rs"]
mod module_graph;

use module_graph::ModuleGraph;
use std::path::Path;

#[test]
fn cli_modules_import_each_other_without_cycles() {
    let graph = ModuleGraph::from_src(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src"));
    // Not vacuous: the graph holds the command's modules and imports that are known to exist.
    for module in ["demo", "scenario_args", "simulate", "suite", "sweep"] {
        assert!(graph.edges.contains_key(module), "module {module} not read");
    }
    let edges = graph.edge_list();
    for edge in [
        ("demo", "scenario_args"),
        ("simulate", "scenario_args"),
        ("suite", "demo"),
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
