//! Holds the library's layer order (documented in `src/lib.rs`) against its source: a module may
//! name another module of the crate (`use crate::x`, or a `crate::x::` path in code) only when
//! that module sits in a lower layer. `eval` reads the core and is read by no module but the C
//! ABI, which exposes its trajectory metrics.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Layer of every top-level module of `src/`; a module may import only from lower numbers.
const LAYERS: &[(&str, u32)] = &[
    ("errors", 1),
    ("image", 2),
    ("descriptor", 2),
    ("onnx_runtime", 2),
    ("describe", 3),
    ("verify", 3),
    ("map", 4),
    ("build", 5),
    ("skeleton", 5),
    ("eval", 5),
    ("localize", 6),
    ("loops", 7),
    ("ffi", 8),
];

/// Modules that no other module of the library may import, but the ones listed with them.
const NEVER_IMPORTED: &[(&str, &[&str])] = &[("eval", &["ffi"])];

/// One import that breaks the order: the file, its line, and the two modules.
#[derive(Debug, PartialEq)]
struct Violation {
    file: String,
    line: usize,
    from: String,
    to: String,
}

fn layer_of(module: &str) -> Option<u32> {
    LAYERS.iter().find(|(m, _)| *m == module).map(|&(_, l)| l)
}

/// The crate module names that `code` (one file's text, comments removed) refers to through
/// `crate::`, with the line each is on. `use crate::{a::X, b::Y}` groups count every member.
fn crate_references(code: &str) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    let bytes = code.as_bytes();
    let mut at = 0;
    while let Some(pos) = code[at..].find("crate::") {
        let start = at + pos;
        at = start + "crate::".len();
        // `topoloc_crate::` or `$crate::` are not this crate's paths.
        if start > 0 && (bytes[start - 1].is_ascii_alphanumeric() || bytes[start - 1] == b'_') {
            continue;
        }
        let line = code[..start].matches('\n').count() + 1;
        let rest = &code[at..];
        if let Some(group) = rest.strip_prefix('{') {
            let end = matching_brace(group);
            for member in split_top_level(&group[..end]) {
                let name: String = member
                    .trim()
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                if !name.is_empty() {
                    found.push((line, name));
                }
            }
        } else {
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            found.push((line, name));
        }
    }
    found
}

fn matching_brace(s: &str) -> usize {
    let mut depth = 0;
    for (i, c) in s.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => return i,
            '}' => depth -= 1,
            _ => {}
        }
    }
    s.len()
}

fn split_top_level(s: &str) -> Vec<&str> {
    let (mut parts, mut depth, mut from) = (Vec::new(), 0, 0);
    for (i, c) in s.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&s[from..i]);
                from = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&s[from..]);
    parts
}

/// Removes `//` comments (doc comments included: their links are not imports) and string
/// literals' contents, keeping line breaks so that line numbers stay right.
fn strip_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let mut in_str = false;
        let mut prev = '\0';
        let mut kept = String::new();
        let chars: Vec<char> = line.chars().collect();
        let mut i = 0;
        while i < chars.len() {
            let c = chars[i];
            if !in_str && c == '/' && chars.get(i + 1) == Some(&'/') {
                break;
            }
            if c == '"' && prev != '\\' {
                in_str = !in_str;
            }
            if !in_str || c == '"' {
                kept.push(c);
            }
            prev = c;
            i += 1;
        }
        out.push_str(&kept);
        out.push('\n');
    }
    out
}

/// Checks one file of module `from` and returns what breaks the order.
fn check_file(file: &str, from: &str, text: &str) -> Vec<Violation> {
    let Some(own) = layer_of(from) else {
        return vec![Violation {
            file: file.into(),
            line: 0,
            from: from.into(),
            to: "(module missing from LAYERS)".into(),
        }];
    };
    let mut violations = Vec::new();
    for (line, to) in crate_references(&strip_comments(text)) {
        if to == from || to == "VERSION" {
            continue;
        }
        let allowed = match layer_of(&to) {
            Some(layer) => {
                layer < own
                    && NEVER_IMPORTED
                        .iter()
                        .all(|(module, readers)| *module != to || readers.contains(&from))
            }
            // A crate-root item (re-exports in lib.rs) hides which layer it comes from.
            None => false,
        };
        if !allowed {
            violations.push(Violation {
                file: file.into(),
                line,
                from: from.into(),
                to,
            });
        }
    }
    violations
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("readable src/") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn every_module_imports_only_from_lower_layers() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut violations = Vec::new();
    let mut modules = BTreeMap::new();
    for path in &files {
        let relative = path.strip_prefix(&src).unwrap();
        let first = relative.components().next().unwrap().as_os_str();
        let module = first.to_string_lossy().trim_end_matches(".rs").to_string();
        if module == "lib" {
            continue;
        }
        *modules.entry(module.clone()).or_insert(0) += 1;
        let text = std::fs::read_to_string(path).unwrap();
        violations.extend(check_file(&relative.display().to_string(), &module, &text));
    }
    assert!(
        modules.len() >= 10,
        "the walk found too few modules: {modules:?}"
    );
    assert!(
        violations.is_empty(),
        "imports against the layer order (src/lib.rs): {violations:#?}"
    );
}

#[test]
fn the_check_catches_a_back_import_in_every_form() {
    let back = "use crate::map::DescriptorIdentity;\n";
    let found = check_file("describe/x.rs", "describe", back);
    assert_eq!(
        found,
        vec![Violation {
            file: "describe/x.rs".into(),
            line: 1,
            from: "describe".into(),
            to: "map".into(),
        }]
    );
    let grouped = "use crate::{\n    image::ImageView,\n    localize::Frame,\n};\n";
    let found = check_file("map/x.rs", "map", grouped);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!((found[0].line, found[0].to.as_str()), (1, "localize"));
    let inline = "fn f() {\n    let x = crate::ffi::something();\n}\n";
    assert_eq!(check_file("verify/x.rs", "verify", inline).len(), 1);
    let same_layer = "use crate::verify::Keypoints;\n";
    assert_eq!(check_file("describe/x.rs", "describe", same_layer).len(), 1);
    let eval = "use crate::eval::GraphMetrics;\n";
    assert_eq!(check_file("loops/x.rs", "loops", eval).len(), 1);
    assert!(
        check_file("ffi/x.rs", "ffi", eval).is_empty(),
        "the C ABI may read eval"
    );
    let root = "use crate::Map;\n";
    assert_eq!(check_file("localize/x.rs", "localize", root).len(), 1);
}

#[test]
fn comments_strings_and_downward_imports_pass() {
    let fine = "//! See [`crate::ffi`].\n/// [`crate::localize::Localizer`]\nuse crate::image::ImageView;\nlet s = \"crate::ffi\";\nuse super::x; // crate::ffi\n";
    assert_eq!(check_file("verify/x.rs", "verify", fine), vec![]);
    let unknown = check_file("newthing.rs", "newthing", "");
    assert_eq!(unknown.len(), 1, "a module missing from LAYERS must fail");
}
