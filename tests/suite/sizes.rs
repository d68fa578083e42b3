//! Sizes: no source file over 600 lines and no function over 80, outside the test crate and
//! the matrix kernels (whose hand-unrolled loops are long by design). A function is counted
//! from its `fn` line to its closing brace, comments and strings blanked first so that their
//! braces do not count; a unit-test module lives in a file of its own once its file would
//! pass 600.

use std::path::{Path, PathBuf};

use crate::layers::SOURCE_DIRS;
use crate::source::blank;

/// The source folder exempt from the limits: the matrix kernels.
const EXEMPT: &str = "kernels/src";

const MAX_FILE_LINES: usize = 600;
const MAX_FN_LINES: usize = 80;

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Every function with a body in `src`: its name, first line (1-based) and length in lines.
fn functions(src: &str) -> Vec<(String, usize, usize)> {
    let t = blank(src);
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let line_of = |at: usize| t[..at].iter().filter(|&&c| c == b'\n').count() + 1;
    let mut found = Vec::new();
    let mut i = 0;
    while i + 3 < t.len() {
        let word =
            &t[i..i + 2] == b"fn" && (i == 0 || !ident(t[i - 1])) && t[i + 2].is_ascii_whitespace();
        if !word {
            i += 1;
            continue;
        }
        let name_at = i
            + 2
            + t[i + 2..]
                .iter()
                .take_while(|c| c.is_ascii_whitespace())
                .count();
        let name: String = t[name_at..]
            .iter()
            .take_while(|&&c| ident(c))
            .map(|&c| c as char)
            .collect();
        // The body opens at the first `{` before any `;` (a declaration has no body).
        let Some(open) = t[name_at..]
            .iter()
            .position(|&c| c == b'{' || c == b';')
            .map(|p| name_at + p)
            .filter(|&p| t[p] == b'{')
        else {
            i = name_at;
            continue;
        };
        let mut depth = 0usize;
        let mut close = open;
        for (k, &c) in t[open..].iter().enumerate() {
            match c {
                b'{' => depth += 1,
                b'}' => {
                    depth -= 1;
                    if depth == 0 {
                        close = open + k;
                        break;
                    }
                }
                _ => {}
            }
        }
        found.push((name, line_of(i), line_of(close) - line_of(i) + 1));
        i = name_at;
    }
    found
}

/// The files over [`MAX_FILE_LINES`] and the functions over [`MAX_FN_LINES`] among `files`
/// (path, text), as one line each.
fn oversized(files: &[(String, String)]) -> Vec<String> {
    let mut found = Vec::new();
    for (path, text) in files {
        let lines = text.lines().count();
        if lines > MAX_FILE_LINES {
            found.push(format!("{path}: {lines} lines (at most {MAX_FILE_LINES})"));
        }
        for (name, line, length) in functions(text) {
            if length > MAX_FN_LINES {
                found.push(format!(
                    "{path}:{line}: fn {name} is {length} lines (at most {MAX_FN_LINES})"
                ));
            }
        }
    }
    found
}

#[test]
fn no_file_over_600_lines_and_no_function_over_80() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut paths = Vec::new();
    for dir in SOURCE_DIRS.iter().filter(|&&d| d != EXEMPT) {
        rust_files(&root.join(dir), &mut paths);
    }
    let files: Vec<(String, String)> = paths
        .iter()
        .map(|p| {
            let rel = p
                .strip_prefix(&root)
                .unwrap()
                .to_string_lossy()
                .into_owned();
            (rel, std::fs::read_to_string(p).unwrap())
        })
        .collect();
    assert!(files.len() > 100, "only {} source files found", files.len());
    let found = oversized(&files);
    assert!(found.is_empty(), "too large:\n{}", found.join("\n"));
}

#[test]
fn a_planted_long_function_and_a_long_file_are_named() {
    let body: String = (0..MAX_FN_LINES)
        .map(|k| format!("    let x{k} = {k};\n"))
        .collect();
    // 80 body lines between the `fn` line and the closing brace: 82 in all.
    let long = format!("fn long() {{\n{body}}}\n");
    // Braces in comments and strings do not count; a declaration without body is skipped.
    let short =
        "fn short() -> &'static str {\n    // }}}\n    \"{{\"\n}\ntrait T { fn d(&self); }\n";
    assert_eq!(functions(short), vec![("short".to_string(), 1, 4)]);
    let found = oversized(&[("a.rs".into(), long.clone()), ("b.rs".into(), short.into())]);
    assert_eq!(
        found,
        vec![format!(
            "a.rs:1: fn long is 82 lines (at most {MAX_FN_LINES})"
        )]
    );
    let file = "\n".repeat(MAX_FILE_LINES + 1);
    let found = oversized(&[("c.rs".into(), file)]);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(found[0].starts_with("c.rs: 601 lines"), "{found:?}");
}
