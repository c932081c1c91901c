//! The library's modules import each other in layers: no import cycle
//! between its files (issue 37 item 1: vocabulary every observer uses is
//! defined once, in a module no device owns, and `src/observer/` has no
//! import cycle; nor does the crate: `discretize` does not reach back
//! into `observer`), and README's "Layers" table lists the top-level
//! modules bottom up: each imports only those above it (and `error`).
//!
//! Read from the source as text: each file of `src/` (the test modules,
//! files whose name ends in `tests`, and each file's own `mod tests`
//! left out) is a module; each `use` of `crate::`, `super::` or `self::`
//! is an edge to the longest module its path names. Edges between a
//! module and its ancestors are not counted (a child reads its parent's
//! items, a parent re-exports its children's: Rust's usual shape).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type Graph = BTreeMap<String, BTreeSet<String>>;

/// Every `.rs` file below `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("read src/") {
        let path = entry.expect("dir entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `a/b.rs` -> `a::b`, `a/mod.rs` -> `a`, `lib.rs` -> `` (the root).
fn module_of(src: &Path, file: &Path) -> String {
    let relative = file.strip_prefix(src).expect("below src/");
    let mut parts: Vec<String> = relative
        .with_extension("")
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts.join("::")
}

/// The paths of a `use` tree (`a::{b, c::{d, e}}` -> `a::b`, `a::c::d`,
/// `a::c::e`), without `as` renames.
fn expand_use(tree: &str) -> Vec<String> {
    let tree = tree.trim();
    let Some(open) = tree.find('{') else {
        let path = tree.split(" as ").next().unwrap_or(tree).trim();
        return vec![path.to_string()];
    };
    let prefix = &tree[..open];
    let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
    let mut items = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, ch) in inner.char_indices() {
        match ch {
            '{' => depth += 1,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&inner[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items.push(&inner[start..]);
    items
        .into_iter()
        .filter(|item| !item.trim().is_empty())
        .flat_map(expand_use)
        .map(|path| format!("{prefix}{path}"))
        .collect()
}

/// The trees of the `use` declarations of `code` (a line that starts
/// one, visibility and all, to its `;`).
fn use_trees(code: &str) -> Vec<String> {
    let mut trees = Vec::new();
    let mut open: Option<String> = None;
    for line in code.lines() {
        let line = line.trim();
        // A public one is marked `pub ` (its re-exports count).
        let started = open.take().map(|tree| (tree, line)).or_else(|| {
            [
                ("use ", ""),
                ("pub use ", "pub "),
                ("pub(crate) use ", "pub "),
            ]
            .iter()
            .find_map(|(start, mark)| Some((mark.to_string(), line.strip_prefix(start)?)))
        });
        let Some((mut tree, rest)) = started else {
            continue;
        };
        match rest.find(';') {
            Some(end) => {
                tree.push_str(&rest[..end]);
                trees.push(tree);
            }
            None => {
                tree.push_str(rest);
                tree.push(' ');
                open = Some(tree);
            }
        }
    }
    trees
}

/// The module `path` names, seen from `module`: its longest prefix that
/// is a module of `modules` (`None` for other crates' paths).
fn resolve(module: &str, path: &str, modules: &BTreeSet<String>) -> Option<String> {
    let mut segments: Vec<&str> = path.split("::").map(str::trim).collect();
    let mut base: Vec<&str> = match segments.first()? {
        &"crate" => {
            segments.remove(0);
            Vec::new()
        }
        &"self" => {
            segments.remove(0);
            module.split("::").collect()
        }
        &"super" => {
            let mut base: Vec<&str> = module.split("::").collect();
            while segments.first() == Some(&"super") {
                segments.remove(0);
                base.pop();
            }
            base
        }
        // A path from a child module (`use tables::X` in `observer`).
        first if modules.contains(&join(module, first)) => module.split("::").collect(),
        _ => return None,
    };
    base.retain(|s| !s.is_empty());
    (0..=segments.len()).rev().find_map(|k| {
        let candidate = base
            .iter()
            .chain(&segments[..k])
            .copied()
            .collect::<Vec<_>>()
            .join("::");
        modules.contains(&candidate).then_some(candidate)
    })
}

/// `module::child` (`child` at the root).
fn join(module: &str, child: &str) -> String {
    if module.is_empty() {
        child.to_string()
    } else {
        format!("{module}::{child}")
    }
}

/// Where `path` leads from `module`: the module [`resolve`] names, or,
/// when it names an item that module re-exports (`reexports`), the
/// module that defines it.
fn target(
    module: &str,
    path: &str,
    modules: &BTreeSet<String>,
    reexports: &BTreeMap<(String, String), String>,
) -> Option<String> {
    let mut found = resolve(module, path, modules)?;
    let item = path.rsplit("::").next().unwrap_or("").trim().to_string();
    // Re-exports of re-exports, a few levels at most.
    for _ in 0..8 {
        match reexports.get(&(found.clone(), item.clone())) {
            Some(defined) if *defined != found => found = defined.clone(),
            _ => break,
        }
    }
    Some(found)
}

/// `a` is `b` or one of its ancestors.
fn is_ancestor_or_self(a: &str, b: &str) -> bool {
    a.is_empty() || a == b || b.starts_with(&format!("{a}::"))
}

/// The import graph of the library's non-test modules.
fn library_graph() -> Graph {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.retain(|f| {
        let stem = f.file_stem().map(|s| s.to_string_lossy().into_owned());
        !stem.is_some_and(|s| s.ends_with("tests"))
    });
    let modules: BTreeSet<String> = files.iter().map(|f| module_of(&src, f)).collect();
    let sources: Vec<(String, String)> = files
        .iter()
        .map(|file| {
            let text = std::fs::read_to_string(file).expect("read a source file");
            let code = match text.find("#[cfg(test)]\nmod tests") {
                Some(end) => text[..end].to_string(),
                None => text,
            };
            (module_of(&src, file), code)
        })
        .collect();
    // Each module's `pub use` of its descendants' items: an import of the
    // item through the module is an import of the module that defines it.
    let mut reexports = BTreeMap::new();
    for (module, code) in &sources {
        for tree in use_trees(code).iter().filter(|t| t.starts_with("pub ")) {
            for path in expand_use(tree.trim_start_matches("pub ")) {
                let Some(defined) = resolve(module, &path, &modules) else {
                    continue;
                };
                let item = path.rsplit("::").next().unwrap_or("").trim().to_string();
                if defined != *module && is_ancestor_or_self(module, &defined) {
                    reexports.insert((module.clone(), item), defined);
                }
            }
        }
    }
    let mut graph = Graph::new();
    for (module, code) in &sources {
        let module = module.clone();
        for tree in use_trees(code) {
            for path in expand_use(tree.trim_start_matches("pub ")) {
                let Some(target) = target(&module, &path, &modules, &reexports) else {
                    continue;
                };
                if !is_ancestor_or_self(&target, &module) && !is_ancestor_or_self(&module, &target)
                {
                    graph.entry(module.clone()).or_default().insert(target);
                }
            }
        }
    }
    graph
}

/// A cycle of `graph` as its modules in order, if there is one.
fn find_cycle(graph: &Graph) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &Graph,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == node) {
            let mut cycle = path[at..].to_vec();
            cycle.push(node.to_string());
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(cycle) = visit(next, graph, path, done) {
                return Some(cycle);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|node| visit(node, graph, &mut Vec::new(), &mut done))
}

#[test]
fn the_librarys_modules_import_each_other_without_a_cycle() {
    let graph = library_graph();
    // The reader found the layers it must see (it is not reading nothing).
    let observer_edges = graph
        .iter()
        .filter(|(m, _)| m.starts_with("observer::"))
        .count();
    assert!(observer_edges >= 10, "{graph:#?}");
    assert!(graph["observer::network"].contains("observer::consistency"));
    assert!(graph["observer::consistency"].contains("observer::vocabulary"));
    assert!(graph["observer::consistency"].contains("discretize::fixed"));
    if let Some(cycle) = find_cycle(&graph) {
        panic!("an import cycle: {}", cycle.join(" -> "));
    }
}

/// The modules of README's "Layers" table, in its order (bottom up).
fn readme_layers() -> Vec<String> {
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../README.md"))
            .expect("read README.md");
    let section = readme
        .split("\n## Layers\n")
        .nth(1)
        .expect("README has a Layers section");
    let section = section.split("\n## ").next().unwrap_or(section);
    section
        .lines()
        .filter_map(|line| line.strip_prefix("| `"))
        .filter_map(|row| row.split('`').next())
        .map(String::from)
        .collect()
}

#[test]
fn each_layer_of_readme_imports_only_the_layers_below_it() {
    let layers = readme_layers();
    let graph = library_graph();
    let top = |module: &str| module.split("::").next().unwrap_or("").to_string();
    // Every top-level module is in the table, but `error`, which all use.
    let tops: BTreeSet<String> = graph.keys().map(|m| top(m)).collect();
    for module in &tops {
        assert!(
            module == "error" || layers.contains(module),
            "module `{module}` is missing from README's Layers table {layers:?}"
        );
    }
    for (module, targets) in &graph {
        let Some(at) = layers.iter().position(|l| *l == top(module)) else {
            continue;
        };
        for target in targets.iter().map(|t| top(t)) {
            let below = target == "error" || layers[..at].contains(&target);
            assert!(
                below || target == top(module),
                "`{module}` imports `{target}`, which README's Layers table puts above it"
            );
        }
    }
}

#[test]
fn the_reader_finds_a_cycle_through_a_grouped_use() {
    // The checker itself: two modules that import each other, one through
    // a grouped `use` of `super::`, the other through `crate::`.
    let modules: BTreeSet<String> = ["observer", "observer::a", "observer::b", "discretize"]
        .map(String::from)
        .into();
    let paths = expand_use("super::{b::{Thing, Other}, a as alias}");
    assert_eq!(paths, ["super::b::Thing", "super::b::Other", "super::a"]);
    assert_eq!(
        resolve("observer::a", &paths[0], &modules).as_deref(),
        Some("observer::b")
    );
    assert_eq!(
        resolve("observer::b", "crate::observer::a::Item", &modules).as_deref(),
        Some("observer::a")
    );
    assert_eq!(resolve("observer::b", "core::fmt", &modules), None);
    let mut graph = Graph::new();
    graph
        .entry("observer::a".into())
        .or_default()
        .insert("observer::b".into());
    graph
        .entry("observer::b".into())
        .or_default()
        .insert("discretize".into());
    assert_eq!(find_cycle(&graph), None);
    graph
        .entry("discretize".into())
        .or_default()
        .insert("observer::a".into());
    assert_eq!(
        find_cycle(&graph).map(|c| c.join(" -> ")).as_deref(),
        Some("discretize -> observer::a -> observer::b -> discretize")
    );
}
