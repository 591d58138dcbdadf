//! README's layout block stays in step with the tree: it names every file of `src/ffi` (the C
//! ABI's modules, which the Python package mirrors) and every subcommand of the `topoloc` CLI.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The fenced block under README's `## Layout` heading.
fn layout_block() -> String {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let section = readme
        .split("\n## Layout\n")
        .nth(1)
        .expect("README has a ## Layout section");
    let block = section
        .split("```")
        .nth(1)
        .expect("a fenced block in ## Layout");
    block.to_string()
}

/// The entry of the layout block that starts with `prefix`: its line and the indented lines
/// that continue it.
fn layout_line(prefix: &str) -> String {
    let block = layout_block();
    let mut lines = block.lines().skip_while(|l| !l.starts_with(prefix));
    let first = lines
        .next()
        .unwrap_or_else(|| panic!("no line for {prefix} in README's layout block"));
    let rest = lines.take_while(|l| l.starts_with(' '));
    std::iter::once(first)
        .chain(rest)
        .collect::<Vec<_>>()
        .join(" ")
}

/// Whether `line` names `word` as a whole word (letters, digits, `_` and `-` join words).
fn names(line: &str, word: &str) -> bool {
    let joins = |c: char| c.is_alphanumeric() || c == '_' || c == '-';
    line.match_indices(word).any(|(at, _)| {
        let before = line[..at].chars().next_back();
        let after = line[at + word.len()..].chars().next();
        !before.is_some_and(joins) && !after.is_some_and(joins)
    })
}

#[test]
fn the_layout_names_every_file_of_the_c_abi() {
    let line = layout_line("src/ffi/");
    let mut missing = Vec::new();
    for entry in std::fs::read_dir(repo().join("src/ffi")).unwrap() {
        let path = entry.unwrap().path();
        let stem = path.file_stem().unwrap().to_string_lossy().into_owned();
        if stem != "mod" && !names(&line, &stem) {
            missing.push(stem);
        }
    }
    assert!(
        missing.is_empty(),
        "README's src/ffi/ line lacks {missing:?}: {line}"
    );
}

#[test]
fn the_layout_names_every_subcommand() {
    let help = Command::new(env!("CARGO_BIN_EXE_topoloc"))
        .arg("--help")
        .output()
        .unwrap();
    let help = String::from_utf8(help.stdout).unwrap();
    let commands: Vec<&str> = help
        .split("Commands:")
        .nth(1)
        .expect("a Commands: list")
        .lines()
        .skip(1)
        .take_while(|l| !l.trim().is_empty())
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .collect();
    assert!(commands.len() >= 10, "{commands:?}");
    let line = layout_line("tools/cli");
    let missing: Vec<&&str> = commands.iter().filter(|c| !names(&line, c)).collect();
    assert!(
        missing.is_empty(),
        "README's tools/cli line lacks {missing:?}: {line}"
    );
}

#[test]
fn a_word_is_named_whole() {
    assert!(names("demo, build-map, eval", "eval"));
    assert!(!names("demo, build-map, eval-verify", "eval"));
    assert!(!names("map_keypoints", "map"));
    assert!(names("map, map_keypoints", "map"));
}
