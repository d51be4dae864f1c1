//! Inside each crate, no cycle between its top-level modules: the graph of `crate::x` paths
//! (and a top-level file's `super::x`) between the modules under `src/`, read from the source
//! with comments and test modules left out, must be acyclic. A module that needs a sibling's
//! item and is needed by it means one concern is split across two files; the fix is to move
//! the shared item below both (as `formats::mesh` holds the `Mesh` every reader fills).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The workspace's `crates/` folder.
fn crates_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The identifiers that follow `prefix` (as a whole path segment) in `text`.
fn segments_after<'a>(text: &'a str, prefix: &str) -> Vec<&'a str> {
    let ident = |c: char| c.is_alphanumeric() || c == '_';
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(i) = text[from..].find(prefix) {
        let at = from + i;
        from = at + prefix.len();
        if text[..at].chars().next_back().is_some_and(ident) {
            continue;
        }
        let rest = &text[from..];
        let end = rest.find(|c: char| !ident(c)).unwrap_or(rest.len());
        if end > 0 {
            out.push(&rest[..end]);
        }
    }
    out
}

/// The code of a file without its comment lines and its `#[cfg(test)] mod tests`.
fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(i) => &text[..i],
        None => &text[..],
    };
    text.lines()
        .filter(|l| !l.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// A crate's top-level modules, each with the sibling modules its code names.
fn module_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut names = BTreeSet::new();
    for e in std::fs::read_dir(src).unwrap() {
        let p = e.unwrap().path();
        let stem = p.file_stem().unwrap().to_string_lossy().into_owned();
        if p.is_dir() || p.extension().is_some_and(|e| e == "rs") {
            names.insert(stem);
        }
    }
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for f in files {
        let rel = f.strip_prefix(src).unwrap().with_extension("");
        let mut parts: Vec<String> = rel
            .iter()
            .map(|s| s.to_string_lossy().into_owned())
            .collect();
        if matches!(
            parts.last().map(String::as_str),
            Some("mod" | "lib" | "main")
        ) {
            parts.pop();
        }
        if parts.is_empty() || parts.iter().any(|p| p == "tests") {
            continue;
        }
        let top = parts[0].clone();
        let text = code(&f);
        let mut targets = segments_after(&text, "crate::");
        // A top-level file's `super::` is the crate root: its siblings.
        if parts.len() == 1 {
            targets.extend(segments_after(&text, "super::"));
        }
        let edges = g.entry(top.clone()).or_default();
        for t in targets {
            if t != top && names.contains(t) {
                edges.insert(t.to_string());
            }
        }
    }
    g
}

/// A cycle through `start`, as the path of modules from it back to it, if there is one.
fn cycle_through(g: &BTreeMap<String, BTreeSet<String>>, start: &str) -> Option<Vec<String>> {
    let mut stack = vec![(start.to_string(), vec![start.to_string()])];
    let mut seen = BTreeSet::new();
    while let Some((node, path)) = stack.pop() {
        for next in g.get(&node).into_iter().flatten() {
            if next == start {
                let mut p = path.clone();
                p.push(start.to_string());
                return Some(p);
            }
            if seen.insert(next.clone()) {
                let mut p = path.clone();
                p.push(next.clone());
                stack.push((next.clone(), p));
            }
        }
    }
    None
}

#[test]
fn no_crate_has_a_cycle_between_its_modules() {
    let mut cycles = Vec::new();
    let mut crates = 0;
    let mut entries: Vec<PathBuf> = std::fs::read_dir(crates_dir())
        .unwrap()
        .map(|e| e.unwrap().path().join("src"))
        .filter(|p| p.is_dir())
        .collect();
    entries.sort();
    for src in entries {
        crates += 1;
        let g = module_graph(&src);
        for m in g.keys() {
            if let Some(c) = cycle_through(&g, m) {
                cycles.push(format!("{}: {}", src.display(), c.join(" -> ")));
                break;
            }
        }
    }
    assert!(crates >= 10, "found only {crates} crates");
    assert!(cycles.is_empty(), "module cycles:\n{}", cycles.join("\n"));
}

#[test]
fn the_scanner_finds_a_cycle_and_skips_comments_and_tests() {
    let d = tempfile::tempdir().unwrap();
    let src = d.path();
    std::fs::write(src.join("lib.rs"), "pub mod a;\npub mod b;\npub mod c;\n").unwrap();
    std::fs::write(src.join("a.rs"), "use crate::b::X;\n").unwrap();
    std::fs::create_dir(src.join("b")).unwrap();
    std::fs::write(src.join("b/mod.rs"), "pub struct X;\nmod inner;\n").unwrap();
    std::fs::write(src.join("b/inner.rs"), "// crate::a::Y\nuse crate::c::Z;\n").unwrap();
    std::fs::write(
        src.join("c.rs"),
        "pub struct Z;\n#[cfg(test)]\nmod tests {\n    use crate::a;\n}\n",
    )
    .unwrap();
    let g = module_graph(src);
    assert_eq!(cycle_through(&g, "a"), None, "{g:?}");
    assert!(g["b"].contains("c") && !g["b"].contains("a"), "{g:?}");
    std::fs::write(src.join("c.rs"), "use super::a;\npub struct Z;\n").unwrap();
    let g = module_graph(src);
    assert_eq!(
        cycle_through(&g, "a").unwrap(),
        ["a", "b", "c", "a"].map(String::from)
    );
}
