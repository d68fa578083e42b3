//! Layering: the crates depend downward, as `docs/crates.md` draws them (its list of each
//! crate's dependencies is Cargo.lock's, each naming only crates listed after it), and the
//! module graph of every crate (core, kernels, prepare, model, export, train, infer,
//! pipeline, bench and the command line) has no cycle.
//!
//! Crates: what each crate reaches through its dependencies, direct or not, is read from
//! `Cargo.lock`: of nldf's crates only those below it, and none of the ML frameworks it must
//! stay clear of (candle, tract, onnxruntime). The lock lists a member's dev-dependencies
//! with its others, so a crate's tests keep its layering too, and a crate that uses another
//! also answers for that one's dev-dependencies.
//!
//! Modules: each `*.rs` file under a crate's `src/` is a module (`mod.rs` is its folder's module,
//! `lib.rs` the crate root). A module depends on another that it names in a path:
//! `crate::a::b`, `super::b` (from the file, or from the inline module it is written in),
//! `self::b`, or a child module by its bare name (`b::f()` beside `mod b;`), with `use`
//! groups expanded; the module is the longest prefix of the path that is a file. Comments,
//! doc links and strings do not count. The crate root declares and re-exports every module,
//! so it is left out. The check fails naming each cycle it meets, as
//! `rays -> bounds -> dataset -> rays`. nldf-train's folders are layered too: `ops`,
//! `networks`, `trainers`, `reports`, `job`, a module in one reaching none in a later one.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use crate::source::blank;

/// The crates checked: their source folders, relative to the workspace root.
pub(crate) const SOURCE_DIRS: [&str; 10] = [
    "core/src",
    "kernels/src",
    "prepare/src",
    "model/src",
    "export/src",
    "train/src",
    "infer/src",
    "pipeline/src",
    "bench/src",
    "src",
];

/// The crates whose dependencies are checked: each with the nldf crates it may reach and
/// the frameworks it must not (a framework is a package of that name or starting with it
/// and `-`: `tract` is every `tract-*`).
const CRATE_RULES: [(&str, &[&str], &[&str]); 6] = [
    ("nldf-core", &[], &["candle", "tract", "ort"]),
    ("nldf-model", &["nldf-core"], &["candle", "tract", "ort"]),
    (
        "nldf-export",
        &["nldf-core", "nldf-model"],
        &["candle", "tract", "ort"],
    ),
    ("nldf-infer", &["nldf-core", "nldf-model"], &["candle"]),
    (
        "nldf-train",
        &["nldf-core", "nldf-kernels"],
        &["tract", "ort"],
    ),
    (
        "nldf-pipeline",
        &[
            "nldf-core",
            "nldf-kernels",
            "nldf-model",
            "nldf-export",
            "nldf-infer",
            "nldf-train",
        ],
        &[],
    ),
];

/// Each package of a `Cargo.lock` with the names of the packages it depends on (the
/// versions of one name merged).
fn lock_dependencies(lock: &str) -> BTreeMap<String, BTreeSet<String>> {
    let mut deps: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for package in lock.split("[[package]]").skip(1) {
        let name = package
            .lines()
            .find_map(|l| l.strip_prefix("name = "))
            .unwrap()
            .trim_matches('"');
        let list = package
            .split_once("dependencies = [")
            .map_or("", |(_, rest)| rest.split(']').next().unwrap_or(""));
        let entry = deps.entry(name.to_string()).or_default();
        // An entry is `"name"`, or `"name version"` where two versions are locked.
        for dep in list.split(',') {
            if let Some(n) = dep.trim().trim_matches('"').split_whitespace().next() {
                entry.insert(n.to_string());
            }
        }
    }
    deps
}

/// Every package that `from` reaches through its dependencies.
fn reachable(deps: &BTreeMap<String, BTreeSet<String>>, from: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    let mut todo = vec![from.to_string()];
    while let Some(p) = todo.pop() {
        for d in deps.get(&p).into_iter().flatten() {
            if seen.insert(d.clone()) {
                todo.push(d.clone());
            }
        }
    }
    seen
}

/// The dependencies that break `rules` (see [`CRATE_RULES`]) in the `Cargo.lock` text
/// `lock`, as `crate -> package`.
fn forbidden_dependencies(lock: &str, rules: &[(&str, &[&str], &[&str])]) -> Vec<String> {
    let deps = lock_dependencies(lock);
    let mut found = Vec::new();
    for &(krate, allowed, banned) in rules {
        assert!(deps.contains_key(krate), "{krate}: not in Cargo.lock");
        for dep in reachable(&deps, krate) {
            let nldf = dep.starts_with("nldf") && !allowed.contains(&dep.as_str());
            let framework = banned
                .iter()
                .any(|b| dep == *b || dep.starts_with(&format!("{b}-")));
            if nldf || framework {
                found.push(format!("{krate} -> {dep}"));
            }
        }
    }
    found
}

/// Every `*.rs` file under `dir` with its text, by its path relative to `dir`.
fn rust_files(dir: &Path) -> BTreeMap<PathBuf, String> {
    let mut files = BTreeMap::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                todo.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                let text = std::fs::read_to_string(&path).unwrap();
                files.insert(path.strip_prefix(dir).unwrap().to_path_buf(), text);
            }
        }
    }
    files
}

/// The module a file holds: `synth/splits.rs` is `synth::splits`, `synth/mod.rs` is
/// `synth`, `lib.rs` (or a binary's `main.rs`) the root (empty).
fn module_of(rel: &Path) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let file = parts.pop().unwrap_or_default();
    let stem = file.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" && stem != "main" {
        parts.push(stem.to_string());
    }
    parts
}

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// The identifier starting at `t[i]`, empty if none does.
fn ident_at(t: &[u8], i: usize) -> String {
    let starts = t
        .get(i)
        .is_some_and(|&c| c.is_ascii_alphabetic() || c == b'_');
    if !starts {
        return String::new();
    }
    let n = t[i..].iter().take_while(|&&c| is_ident(c)).count();
    String::from_utf8_lossy(&t[i..i + n]).into_owned()
}

fn skip_ws(t: &[u8], mut i: usize) -> usize {
    while t.get(i).is_some_and(|c| c.is_ascii_whitespace()) {
        i += 1;
    }
    i
}

/// Parses the path or `use` tree at `t[i..]` below `prefix`, adding each whole path to
/// `paths`; returns where it ends.
fn parse_tree(t: &[u8], mut i: usize, prefix: &[String], paths: &mut Vec<Vec<String>>) -> usize {
    let mut segments = prefix.to_vec();
    loop {
        i = skip_ws(t, i);
        match t.get(i) {
            Some(b'{') => {
                i += 1;
                loop {
                    i = skip_ws(t, i);
                    match t.get(i) {
                        None => return i,
                        Some(b'}') => return i + 1,
                        Some(b',') => i += 1,
                        Some(_) => {
                            let end = parse_tree(t, i, &segments, paths);
                            i = if end == i { i + 1 } else { end };
                        }
                    }
                }
            }
            Some(b'*') => {
                paths.push(segments);
                return i + 1;
            }
            _ => {}
        }
        let word = ident_at(t, i);
        if word.is_empty() {
            paths.push(segments);
            return i;
        }
        i += word.len();
        segments.push(word);
        let next = skip_ws(t, i);
        if !t[next..].starts_with(b"::") {
            paths.push(segments);
            return i;
        }
        i = next + 2;
    }
}

/// The modules that the file of `module` depends on (see the module docs): neither itself
/// nor the root. `modules` holds every module of the crate.
fn dependencies(
    module: &[String],
    src: &str,
    modules: &BTreeSet<Vec<String>>,
) -> BTreeSet<Vec<String>> {
    let t = blank(src);
    let mut paths = Vec::new();
    // Inline modules (`mod tests { .. }`) open at a brace depth: `super` starts from them.
    let mut inline: Vec<(String, usize)> = Vec::new();
    let mut depth = 0;
    let mut i = 0;
    while i < t.len() {
        match t[i] {
            b'{' => {
                depth += 1;
                i += 1;
                continue;
            }
            b'}' => {
                if inline.last().is_some_and(|&(_, d)| d == depth) {
                    inline.pop();
                }
                depth = depth.saturating_sub(1);
                i += 1;
                continue;
            }
            _ => {}
        }
        let word = if i > 0 && is_ident(t[i - 1]) {
            String::new()
        } else {
            ident_at(&t, i)
        };
        if word.is_empty() {
            i += 1;
            continue;
        }
        let mut next = skip_ws(&t, i + word.len());
        if word == "mod" {
            let name = ident_at(&t, next);
            let after = skip_ws(&t, next + name.len());
            if !name.is_empty() && t.get(after) == Some(&b'{') {
                depth += 1;
                inline.push((name, depth));
                i = after + 1;
            } else {
                i = next;
            }
            continue;
        }
        let starts_path = t[next..].starts_with(b"::") && !t[..i].trim_ascii_end().ends_with(b"::");
        let here = || -> Vec<String> {
            let inner = inline.iter().map(|(name, _)| name.clone());
            module.iter().cloned().chain(inner).collect()
        };
        let mut child = module.to_vec();
        child.push(word.clone());
        let base = match word.as_str() {
            _ if !starts_path => None,
            "crate" => Some(Vec::new()),
            "self" => Some(here()),
            "super" => {
                let mut base = here();
                base.pop();
                loop {
                    let at = skip_ws(&t, next + 2);
                    let after = skip_ws(&t, at + "super".len());
                    if ident_at(&t, at) != "super" || !t[after..].starts_with(b"::") {
                        break;
                    }
                    base.pop();
                    next = after;
                }
                Some(base)
            }
            _ if inline.is_empty() && modules.contains(&child) => Some(child),
            _ => None,
        };
        match base {
            Some(base) => i = parse_tree(&t, next + 2, &base, &mut paths),
            None => i += word.len(),
        }
    }
    paths
        .iter()
        .filter_map(|p| {
            (0..=p.len())
                .rev()
                .map(|n| p[..n].to_vec())
                .find(|m| modules.contains(m))
        })
        .filter(|m| !m.is_empty() && m.as_slice() != module)
        .collect()
}

/// The module graph of a crate's source files (by path relative to `src/`): each module,
/// named as a path (`synth::splits`), with the modules it depends on.
fn module_graph(files: &BTreeMap<PathBuf, String>) -> BTreeMap<String, BTreeSet<String>> {
    let modules: BTreeSet<Vec<String>> = files.keys().map(|p| module_of(p)).collect();
    files
        .iter()
        .filter(|(p, _)| !module_of(p).is_empty())
        .map(|(p, src)| {
            let module = module_of(p);
            let deps = dependencies(&module, src, &modules)
                .iter()
                .map(|m| m.join("::"))
                .collect();
            (module.join("::"), deps)
        })
        .collect()
}

/// Every cycle that a depth-first search of `graph` (modules and their dependencies in
/// sorted order) meets, one per edge back to a module on its path, as `a -> b -> a`.
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<String> {
    fn visit<'a>(
        m: &'a str,
        graph: &'a BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<&'a str>,
        done: &mut BTreeSet<&'a str>,
        found: &mut Vec<String>,
    ) {
        path.push(m);
        for next in graph.get(m).into_iter().flatten() {
            if let Some(at) = path.iter().position(|p| *p == next.as_str()) {
                let mut cycle = path[at..].to_vec();
                cycle.push(next);
                found.push(cycle.join(" -> "));
            } else if !done.contains(next.as_str()) {
                visit(next, graph, path, done, found);
            }
        }
        path.pop();
        done.insert(m);
    }
    let (mut done, mut found) = (BTreeSet::new(), Vec::new());
    for m in graph.keys() {
        if !done.contains(m.as_str()) {
            visit(m, graph, &mut Vec::new(), &mut done, &mut found);
        }
    }
    found
}

/// The cycles of the module graph of the files given as (path relative to `src/`, text).
fn cycles_of(files: &[(&str, &str)]) -> Vec<String> {
    let files: BTreeMap<PathBuf, String> = files
        .iter()
        .map(|&(p, s)| (PathBuf::from(p), s.to_string()))
        .collect();
    cycles(&module_graph(&files))
}

#[test]
fn crates_depend_only_downward() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let lock = std::fs::read_to_string(root.join("Cargo.lock")).unwrap();
    let found = forbidden_dependencies(&lock, &CRATE_RULES);
    assert!(
        found.is_empty(),
        "crates that reach what they must not:\n{}",
        found.join("\n")
    );
}

#[test]
fn a_planted_dependency_is_named() {
    // nldf-model reaches candle-core through `tool` and tract-onnx as a dev-dependency;
    // nldf-core is allowed, `tractor` is not tract.
    let lock = r#"
version = 4

[[package]]
name = "nldf-model"
version = "0.1.0"
dependencies = [
 "nldf-core",
 "tool 1.0.0",
 "tract-onnx",
 "tractor",
]

[[package]]
name = "tool"
version = "1.0.0"
dependencies = [
 "candle-core",
]

[[package]]
name = "nldf-core"
version = "0.1.0"

[[package]]
name = "candle-core"
version = "0.11.0"

[[package]]
name = "tract-onnx"
version = "0.23.0"

[[package]]
name = "tractor"
version = "0.1.0"
"#;
    let rules: [(&str, &[&str], &[&str]); 1] =
        [("nldf-model", &["nldf-core"], &["candle", "tract", "ort"])];
    assert_eq!(
        forbidden_dependencies(lock, &rules),
        ["nldf-model -> candle-core", "nldf-model -> tract-onnx"]
    );
}

#[test]
fn module_graphs_have_no_cycle() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut found = Vec::new();
    for dir in SOURCE_DIRS {
        let files = rust_files(&root.join(dir));
        assert!(!files.is_empty(), "{dir}: no source files found");
        found.extend(
            cycles(&module_graph(&files))
                .into_iter()
                .map(|c| format!("{dir}: {c}")),
        );
    }
    assert!(
        found.is_empty(),
        "import cycles between modules:\n{}",
        found.join("\n")
    );
}

#[test]
fn a_planted_cycle_is_named() {
    let found = cycles_of(&[
        (
            "lib.rs",
            "pub mod a;\npub mod b;\npub mod c;\npub use a::X;",
        ),
        ("a.rs", "use crate::{b::{Y, self}, c};\npub struct X;"),
        ("b.rs", "pub fn y() -> u8 { crate::c::z() }"),
        ("c.rs", "pub fn z() -> u8 { let _ = $crate::a::X; 0 }"),
    ]);
    // One cycle per edge back: `a -> c -> a` is not named again, as the search has finished
    // `c` (through `b`) when it comes back to `a`.
    assert_eq!(found, ["a -> b -> c -> a"]);
}

#[test]
fn parents_children_and_super_count() {
    let found = cycles_of(&[
        ("lib.rs", "pub mod synth;"),
        (
            "synth/mod.rs",
            "mod splits;\nfn f() { splits::g() }\npub struct Cfg;",
        ),
        ("synth/splits.rs", "use super::Cfg;\npub fn g() {}"),
    ]);
    assert_eq!(found, ["synth -> synth::splits -> synth"]);
    let found = cycles_of(&[
        ("lib.rs", "pub mod synth;"),
        ("synth/mod.rs", "pub mod head;\npub mod trace;"),
        (
            "synth/head.rs",
            "pub use super::trace::render;\npub struct Head;",
        ),
        (
            "synth/trace.rs",
            "use super::super::synth::head::Head;\npub fn render() {}",
        ),
    ]);
    assert_eq!(found, ["synth::head -> synth::trace -> synth::head"]);
}

#[test]
fn comments_strings_and_test_modules_do_not_count() {
    let found = cycles_of(&[
        ("lib.rs", "pub mod a;\npub mod b;"),
        ("a.rs", "use crate::b::Y;\npub struct X;"),
        (
            "b.rs",
            "//! See [`crate::a::X`].\n/* crate::a:: /* nested */ crate::a:: */\n\
             pub struct Y;\nfn f() -> char { let _ = \"crate::a::X {\"; \
             let _ = r#\"crate::a::X\"#; '{' }\n\
             #[cfg(test)]\nmod tests {\n    use super::*;\n    fn g<'a>(y: &'a Y) {}\n}\n\
             fn h() -> nldf::a::X { todo!() }",
        ),
    ]);
    assert!(found.is_empty(), "{found:?}");
}

/// nldf-train's folders by concept, lowest first: a module in one reaches none in a later
/// one (the fused ops, the networks built on them, the trainers, the reports on trained
/// models, the jobs).
const TRAIN_FOLDERS: [&str; 5] = ["ops", "networks", "trainers", "reports", "job"];

/// Each dependency of `graph` from a module in one of `folders` to a module in a later one,
/// as `a -> b`.
fn upward_edges(graph: &BTreeMap<String, BTreeSet<String>>, folders: &[&str]) -> Vec<String> {
    let rank = |m: &str| {
        folders
            .iter()
            .position(|f| m == *f || m.starts_with(&format!("{f}::")))
    };
    let mut edges = Vec::new();
    for (module, deps) in graph {
        for dep in deps {
            if let (Some(a), Some(b)) = (rank(module), rank(dep))
                && b > a
            {
                edges.push(format!("{module} -> {dep}"));
            }
        }
    }
    edges
}

#[test]
fn the_training_crates_folders_are_layered() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let files = rust_files(&root.join("train/src"));
    for folder in TRAIN_FOLDERS {
        assert!(
            files.keys().any(|p| p.starts_with(folder)),
            "train/src/{folder}: no source files"
        );
    }
    let edges = upward_edges(&module_graph(&files), &TRAIN_FOLDERS);
    assert!(
        edges.is_empty(),
        "train/src: modules reaching a folder above their own:\n{}",
        edges.join("\n")
    );
    // Planted: a network that reads a trainer's config is named.
    let planted: BTreeMap<PathBuf, String> = [
        ("networks/field.rs", "use crate::trainers::config::Cfg;"),
        ("trainers/config.rs", "pub struct Cfg;"),
        ("trainers/run.rs", "use crate::networks::field;"),
    ]
    .iter()
    .map(|&(p, s)| (PathBuf::from(p), s.to_string()))
    .collect();
    assert_eq!(
        upward_edges(&module_graph(&planted), &TRAIN_FOLDERS),
        ["networks::field -> trainers::config"]
    );
}

/// The crate graph as `docs/crates.md` lists it (the fenced block after its
/// `<!-- crate graph` marker): each line `crate -> deps`, in its order.
fn drawn_graph(doc: &str) -> Vec<(String, Vec<String>)> {
    let after = doc
        .split_once("<!-- crate graph")
        .expect("docs/crates.md: no crate graph marker")
        .1;
    let block = after
        .split_once("```text\n")
        .and_then(|(_, rest)| rest.split_once("```"))
        .expect("docs/crates.md: no fenced crate graph after the marker")
        .0;
    block
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let (krate, deps) = l.split_once("->").unwrap_or((l, ""));
            let deps = deps.split_whitespace().map(str::to_string).collect();
            (krate.trim().to_string(), deps)
        })
        .collect()
}

/// What is wrong with the drawn graph `drawn` against the locked one `locked` (each nldf
/// crate's direct nldf dependencies): a crate missing or extra, dependencies that differ,
/// and any dependency not drawn on a later line (an edge pointing up).
fn drawn_graph_problems(
    drawn: &[(String, Vec<String>)],
    locked: &BTreeMap<String, BTreeSet<String>>,
) -> Vec<String> {
    let mut problems = Vec::new();
    let names: BTreeSet<&String> = drawn.iter().map(|(k, _)| k).collect();
    let nldf: BTreeSet<&String> = locked.keys().filter(|k| k.starts_with("nldf")).collect();
    for missing in nldf.difference(&names) {
        problems.push(format!("{missing}: not drawn"));
    }
    for (i, (krate, deps)) in drawn.iter().enumerate() {
        let drawn_deps: BTreeSet<String> = deps.iter().cloned().collect();
        let lock_deps: BTreeSet<String> = locked
            .get(krate)
            .map(|d| {
                d.iter()
                    .filter(|d| d.starts_with("nldf"))
                    .cloned()
                    .collect()
            })
            .unwrap_or_default();
        if !locked.contains_key(krate) {
            problems.push(format!("{krate}: not in Cargo.lock"));
        } else if drawn_deps != lock_deps {
            problems.push(format!(
                "{krate}: drawn with {drawn_deps:?}, Cargo.lock has {lock_deps:?}"
            ));
        }
        for dep in deps {
            if !drawn[i + 1..].iter().any(|(k, _)| k == dep) {
                problems.push(format!(
                    "{krate} -> {dep}: points up (or {dep} is not drawn below)"
                ));
            }
        }
    }
    problems
}

#[test]
fn the_drawn_crate_graph_is_the_locked_one_and_points_down() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let doc = std::fs::read_to_string(root.join("docs/crates.md")).unwrap();
    let lock = std::fs::read_to_string(root.join("Cargo.lock")).unwrap();
    let locked = lock_dependencies(&lock);
    let drawn = drawn_graph(&doc);
    let problems = drawn_graph_problems(&drawn, &locked);
    assert!(
        problems.is_empty(),
        "docs/crates.md's crate graph:\n{}",
        problems.join("\n")
    );
    // Planted: nldf-model drawn above nldf-export, and an edge Cargo.lock lacks.
    let mut planted = drawn.clone();
    let model = planted.iter().position(|(k, _)| k == "nldf-model").unwrap();
    let export = planted
        .iter()
        .position(|(k, _)| k == "nldf-export")
        .unwrap();
    planted.swap(model, export);
    planted[0].1.push("nldf-kernels".into());
    let problems = drawn_graph_problems(&planted, &locked);
    assert!(
        problems
            .iter()
            .any(|p| p.starts_with("nldf-export -> nldf-model: points up")),
        "{problems:?}"
    );
    assert!(
        problems.iter().any(|p| p.starts_with("nldf: drawn with")),
        "{problems:?}"
    );
}
