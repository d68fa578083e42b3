//! Sizes: no source file over 600 lines and no function over 80, outside the test crate and
//! the matrix kernels (whose hand-unrolled loops are long by design). A function is counted
//! from its `fn` line to its closing brace, comments and strings blanked first so that their
//! braces do not count; a unit-test module lives in a file of its own once its file would
//! pass 600.

use std::path::{Path, PathBuf};

/// The crates' source folders checked, relative to the workspace root (every crate's but
/// the kernels', and the command line's).
const CHECKED: [&str; 9] = [
    "core/src",
    "prepare/src",
    "model/src",
    "export/src",
    "train/src",
    "infer/src",
    "pipeline/src",
    "bench/src",
    "src",
];

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

/// `src` with the insides of comments, strings and character literals turned to spaces,
/// newlines kept, so that byte offsets and line numbers stay those of `src`.
fn blank(src: &str) -> Vec<u8> {
    let s = src.as_bytes();
    let mut out = s.to_vec();
    let clear = |out: &mut Vec<u8>, from: usize, to: usize| {
        for b in &mut out[from..to.min(s.len())] {
            if *b != b'\n' {
                *b = b' ';
            }
        }
    };
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut i = 0;
    while i < s.len() {
        let rest = &s[i..];
        let raw = match rest {
            [b'b', b'r', ..] => 2,
            [b'r', ..] => 1,
            _ => 0,
        };
        let hashes = rest[raw..].iter().take_while(|&&c| c == b'#').count();
        let after_ident = i > 0 && ident(s[i - 1]);
        if rest.starts_with(b"//") {
            let end = i + rest.iter().position(|&c| c == b'\n').unwrap_or(rest.len());
            clear(&mut out, i, end);
            i = end;
        } else if rest.starts_with(b"/*") {
            let mut depth = 0usize;
            let start = i;
            while i < s.len() {
                if s[i..].starts_with(b"/*") {
                    depth += 1;
                    i += 2;
                } else if s[i..].starts_with(b"*/") {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
            clear(&mut out, start, i);
        } else if raw > 0 && !after_ident && rest.get(raw + hashes) == Some(&b'"') {
            let close: Vec<u8> = std::iter::once(b'"')
                .chain(std::iter::repeat_n(b'#', hashes))
                .collect();
            let body = i + raw + hashes + 1;
            let end = s[body..]
                .windows(close.len())
                .position(|w| w == close.as_slice())
                .map_or(s.len(), |e| body + e + close.len());
            clear(&mut out, i, end);
            i = end;
        } else if rest[0] == b'"' {
            let start = i;
            i += 1;
            while i < s.len() && s[i] != b'"' {
                i += if s[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
            clear(&mut out, start, i);
        } else if rest[0] == b'\'' && rest.get(1) == Some(&b'\\') {
            let end = s
                .get(i + 3..)
                .and_then(|r| r.iter().position(|&c| c == b'\''))
                .map_or(s.len(), |e| i + 3 + e + 1);
            clear(&mut out, i, end);
            i = end;
        } else if rest[0] == b'\''
            && src[i + 1..]
                .chars()
                .next()
                .is_some_and(|c| s.get(i + 1 + c.len_utf8()) == Some(&b'\''))
        {
            let end = i + 2 + src[i + 1..].chars().next().map_or(1, char::len_utf8);
            clear(&mut out, i, end);
            i = end;
        } else {
            i += 1;
        }
    }
    out
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
    for dir in CHECKED {
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
