//! `results/` keeps what the project cites: every file under it is named by a page (the
//! README, `docs/`, a results page that is itself cited), a test, a script or the source,
//! by its path from the repository's root or from the citing file's folder, or lies in a
//! folder so named (`results/sharp/xeon_512_rays/`, at least two levels down). A results
//! page, script or JSON file that is cited cites in turn what it names (a report's
//! `frontier.md` its JSON, `choices.json` the run folders it read), and the files whose
//! values the pages' tables print (the figures check's keys) are cited by those tables. Whatever is left
//! uncited is a measurement no claim rests on, and does not belong in the repository.

use std::collections::BTreeSet;
use std::path::{Component, Path, PathBuf};

/// Extensions of the files whose text can cite.
const CITING: [&str; 11] = [
    "md", "rs", "sh", "py", "json", "toml", "js", "html", "txt", "yml", "csv",
];

/// Folders never read as citing (build outputs, installed packages, version control).
const SKIP: [&str; 6] = [
    "target",
    ".git",
    ".venv",
    "node_modules",
    "results",
    "fuzz/target",
];

/// `path` with `.` and `..` resolved, without touching the disk; `None` when it climbs
/// above its start.
fn normal(path: &Path) -> Option<PathBuf> {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    return None;
                }
            }
            Component::Normal(p) => out.push(p),
            _ => return None,
        }
    }
    Some(out)
}

/// The path-like words of `text`: runs of letters, digits and `_ . - /` holding a `/` or a
/// `.`, with a trailing `.` or `,` dropped (the end of a sentence).
fn words(text: &str) -> Vec<&str> {
    let in_word = |c: char| c.is_ascii_alphanumeric() || "_.-/".contains(c);
    text.split(|c: char| !in_word(c))
        .map(|w| w.trim_end_matches(['.', ',']))
        .filter(|w| w.contains('/') || w.contains('.'))
        .collect()
}

/// What the text of `file` (a path from the root) cites: each word read from the root and
/// from the file's folder. Folders are kept with a trailing `/`.
fn cited_by(file: &Path, text: &str, out: &mut BTreeSet<String>) {
    let dir = file.parent().unwrap_or(Path::new(""));
    for w in words(text) {
        let folder = w.ends_with('/');
        for base in [Path::new(""), dir] {
            if let Some(p) = normal(&base.join(w)) {
                let mut s = p.to_string_lossy().replace('\\', "/");
                if folder {
                    s.push('/');
                }
                out.insert(s);
            }
        }
    }
}

/// Every file under `dir` (a path from `root`), as paths from the root, skipping [`SKIP`].
fn files_under(root: &Path, dir: &Path, skip: bool, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(root.join(dir)) else {
        return;
    };
    for entry in entries.flatten() {
        let rel = dir.join(entry.file_name());
        let name = rel.to_string_lossy().replace('\\', "/");
        if skip
            && SKIP
                .iter()
                .any(|s| name == *s || name.ends_with(&format!("/{s}")))
        {
            continue;
        }
        if entry.path().is_dir() {
            files_under(root, &rel, skip, out);
        } else {
            out.push(rel);
        }
    }
}

fn is_citing(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| CITING.contains(&e))
}

/// Whether `file` (a path from the root, under `results/`) is cited: named itself, or a
/// folder of it at least two levels below `results/` is.
fn is_cited(file: &str, cited: &BTreeSet<String>) -> bool {
    if cited.contains(file) {
        return true;
    }
    let parts: Vec<&str> = file.split('/').collect();
    (3..parts.len()).any(|n| cited.contains(&format!("{}/", parts[..n].join("/"))))
}

/// The files under `results/` that nothing cites, with the closure over cited results
/// pages (see the module docs); `read` (paths from the root) count as cited.
fn uncited(root: &Path, read: &[String]) -> Vec<String> {
    let mut sources = Vec::new();
    files_under(root, Path::new(""), true, &mut sources);
    let mut results = Vec::new();
    files_under(root, Path::new("results"), false, &mut results);
    let mut results: Vec<String> = (results.iter())
        .map(|p| p.to_string_lossy().replace('\\', "/"))
        .collect();
    results.sort();
    let mut cited: BTreeSet<String> = read.iter().cloned().collect();
    let mut queue: Vec<PathBuf> = sources.into_iter().filter(|p| is_citing(p)).collect();
    let mut read = BTreeSet::new();
    while let Some(file) = queue.pop() {
        if !read.insert(file.clone()) {
            continue;
        }
        if let Ok(text) = std::fs::read_to_string(root.join(&file)) {
            cited_by(&file, &text, &mut cited);
        }
        for r in &results {
            let p = PathBuf::from(r);
            if is_citing(&p) && !read.contains(&p) && is_cited(r, &cited) {
                queue.push(p);
            }
        }
    }
    results
        .into_iter()
        .filter(|r| !is_cited(r, &cited))
        .collect()
}

#[test]
fn every_results_file_is_cited() {
    let root = std::fs::canonicalize(Path::new(env!("CARGO_MANIFEST_DIR")).join("..")).unwrap();
    // The files the figures check reads are cited by the tables whose figures they hold.
    let read: Vec<String> = (crate::figures::files_read().iter())
        .filter_map(|f| std::fs::canonicalize(f).ok())
        .filter_map(|f| {
            f.strip_prefix(&root)
                .ok()
                .map(|p| p.to_string_lossy().replace('\\', "/"))
        })
        .collect();
    let left = uncited(&root, &read);
    assert!(
        left.is_empty(),
        "{} files under results/ that no page, test or script cites (remove them, or cite \
         them where a claim rests on them):\n{}",
        left.len(),
        left.join("\n")
    );
}

/// The check itself: a planted file nothing names is found, one named from a page beside
/// it or from the root is not, a folder citation covers its files, and a cited results
/// page passes its citations on while an uncited one does not.
#[test]
fn the_citation_check_finds_a_planted_uncited_file() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let write = |p: &str, text: &str| {
        let path = root.join(p);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    };
    write(
        "docs/a.md",
        "See [x](../results/a/b/x.json), results/a/c/ and results/a/b/page.md.",
    );
    write("results/a/b/x.json", "{}");
    write("results/a/c/y.png", "");
    write("results/a/c/z/deep.csv", "");
    write("results/a/b/page.md", "its data: data.json");
    write("results/a/b/data.json", "{}");
    write("results/a/d/lonely.md", "names friend.json");
    write("results/a/d/friend.json", "{}");
    write("results/a/b/stray.png", "");
    assert_eq!(
        uncited(root, &[]),
        [
            "results/a/b/stray.png",
            "results/a/d/friend.json",
            "results/a/d/lonely.md"
        ]
    );
    assert_eq!(
        words("(../results/p/q.md). and `results/p/`, end."),
        ["../results/p/q.md", "results/p/"]
    );
}
