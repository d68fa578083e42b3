//! The figures check: a Markdown table whose header has a `source` column names, in each
//! row, the committed results file its figures come from (a path in backticks or a link,
//! relative to the Markdown file). Every decimal figure of the row's other cells must be
//! in that file, written to the same number of decimals, or the check fails. It reads
//! README.md, the shipped model's card and every page under docs/.

use std::path::{Path, PathBuf};

/// One table row that names its source.
#[derive(Debug)]
struct SourcedRow {
    /// 1-based line of the row in its file.
    line: usize,
    cells: Vec<String>,
    source: PathBuf,
}

/// The cells of a Markdown table line (`| a | b |` -> `["a", "b"]`).
fn cells(line: &str) -> Vec<String> {
    let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
    inner.split('|').map(|c| c.trim().to_string()).collect()
}

/// The path a source cell names: a link target `[..](path)` or a path in backticks.
fn source_path(cell: &str) -> Option<String> {
    if let Some(start) = cell.find("](") {
        let rest = &cell[start + 2..];
        return rest.find(')').map(|end| rest[..end].to_string());
    }
    let mut parts = cell.split('`');
    parts.next();
    parts.next().map(str::to_string)
}

/// The sourced rows of every table in `text` (a file in `dir`), and the lines of rows whose
/// source cell names nothing.
fn sourced_rows(text: &str, dir: &Path) -> (Vec<SourcedRow>, Vec<usize>) {
    let (mut rows, mut unnamed) = (Vec::new(), Vec::new());
    let lines: Vec<&str> = text.lines().collect();
    let mut k = 0;
    while k < lines.len() {
        if !lines[k].trim_start().starts_with('|') {
            k += 1;
            continue;
        }
        let header = cells(lines[k]);
        let source_col = header.iter().position(|h| h.eq_ignore_ascii_case("source"));
        k += 2; // the header and its separator
        while k < lines.len() && lines[k].trim_start().starts_with('|') {
            if let Some(col) = source_col {
                let row = cells(lines[k]);
                match row.get(col).and_then(|c| source_path(c)) {
                    Some(path) => rows.push(SourcedRow {
                        line: k + 1,
                        cells: row
                            .iter()
                            .enumerate()
                            .filter(|(c, _)| *c != col)
                            .map(|(_, c)| c.clone())
                            .collect(),
                        source: dir.join(path),
                    }),
                    None => unnamed.push(k + 1),
                }
            }
            k += 1;
        }
    }
    (rows, unnamed)
}

/// The decimal figures of a cell (`36.98`, `-0.5`), as written; text in backticks (paths,
/// commands) holds none.
fn decimal_figures(cell: &str) -> Vec<String> {
    let plain: String = cell
        .split('`')
        .enumerate()
        .filter(|(k, _)| k % 2 == 0)
        .map(|(_, s)| s)
        .collect::<Vec<_>>()
        .join(" ");
    let bytes = plain.as_bytes();
    let mut out = Vec::new();
    let mut k = 0;
    while k < bytes.len() {
        let starts = bytes[k].is_ascii_digit()
            && (k == 0 || !(bytes[k - 1].is_ascii_alphanumeric() || bytes[k - 1] == b'.'));
        if !starts {
            k += 1;
            continue;
        }
        let signed =
            k > 0 && bytes[k - 1] == b'-' && (k == 1 || !bytes[k - 2].is_ascii_alphanumeric());
        let start = if signed { k - 1 } else { k };
        let mut end = k;
        while end < bytes.len() && bytes[end].is_ascii_digit() {
            end += 1;
        }
        if end + 1 < bytes.len() && bytes[end] == b'.' && bytes[end + 1].is_ascii_digit() {
            end += 1;
            while end < bytes.len() && bytes[end].is_ascii_digit() {
                end += 1;
            }
            // An exponent (`6.90e-7`) belongs to the figure.
            let mut e = end;
            if e < bytes.len() && matches!(bytes[e], b'e' | b'E') {
                e += 1;
                if e < bytes.len() && matches!(bytes[e], b'-' | b'+') {
                    e += 1;
                }
                if e < bytes.len() && bytes[e].is_ascii_digit() {
                    while e < bytes.len() && bytes[e].is_ascii_digit() {
                        e += 1;
                    }
                    end = e;
                }
            }
            out.push(plain[start..end].to_string());
        }
        k = end.max(k + 1);
    }
    out
}

/// Every number written in `text` (integers, decimals, exponents).
fn numbers_in(text: &str) -> Vec<f64> {
    let mut out = Vec::new();
    let mut token = String::new();
    for ch in text.chars().chain(std::iter::once(' ')) {
        if ch.is_ascii_digit() || matches!(ch, '.' | '-' | '+' | 'e' | 'E') {
            token.push(ch);
            continue;
        }
        let t = token.trim_matches(|c: char| !c.is_ascii_digit());
        let t = if token.starts_with('-') && !t.is_empty() {
            format!("-{t}")
        } else {
            t.to_string()
        };
        if let Ok(v) = t.parse::<f64>() {
            out.push(v);
        }
        token.clear();
    }
    out
}

/// Whether `figure` (as written, with `d` decimals) is one of `numbers` to `d` decimals; a
/// figure with an exponent (`6.90e-7`) is compared in that form.
fn appears(figure: &str, numbers: &[f64]) -> bool {
    let lower = figure.to_ascii_lowercase();
    if let Some((mantissa, _)) = lower.split_once('e') {
        let d = mantissa.split('.').nth(1).map_or(0, str::len);
        return numbers.iter().any(|v| format!("{v:.d$e}") == lower);
    }
    let d = figure.split('.').nth(1).map_or(0, str::len);
    numbers.iter().any(|v| format!("{v:.d$}") == figure)
}

/// The problems of the sourced tables of Markdown file `path`, one line each.
fn check_file(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let dir = path.parent().unwrap();
    let (rows, unnamed) = sourced_rows(&text, dir);
    let mut problems: Vec<String> = unnamed
        .into_iter()
        .map(|line| format!("{}:{line}: the row names no source file", path.display()))
        .collect();
    for row in rows {
        let Ok(source) = std::fs::read_to_string(&row.source) else {
            problems.push(format!(
                "{}:{}: source {} is not a committed file",
                path.display(),
                row.line,
                row.source.display()
            ));
            continue;
        };
        let numbers = numbers_in(&source);
        for figure in row.cells.iter().flat_map(|c| decimal_figures(c)) {
            if !appears(&figure, &numbers) {
                problems.push(format!(
                    "{}:{}: {figure} is not in {}",
                    path.display(),
                    row.line,
                    row.source.display()
                ));
            }
        }
    }
    problems
}

/// README.md, the shipped model's card and every Markdown page under docs/.
fn checked_files() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut files = vec![root.join("README.md"), root.join("models/demo/README.md")];
    if let Ok(entries) = std::fs::read_dir(root.join("docs")) {
        let mut docs: Vec<PathBuf> = entries
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|x| x == "md"))
            .collect();
        docs.sort();
        files.extend(docs);
    }
    files
}

#[test]
fn every_sourced_figure_is_in_its_results_file() {
    let files = checked_files();
    let mut sourced = 0;
    let mut problems = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        sourced += sourced_rows(&text, f.parent().unwrap()).0.len();
        problems.extend(check_file(f));
    }
    assert!(
        sourced >= 2,
        "only {sourced} sourced rows: the headline names no source"
    );
    assert!(
        problems.is_empty(),
        "figures without a source:\n{}",
        problems.join("\n")
    );
}

#[test]
fn the_figures_check_catches_a_wrong_digit() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("run.json"),
        r#"{"psnr": 36.975848, "ssim": 0.97593, "ms": 25.9, "delta": -0.81, "steps": 1792}"#,
    )
    .unwrap();
    let page = |psnr: &str| {
        format!(
            "# t\n\n| model | PSNR | SSIM | ms | gap | source |\n| --- | --- | --- | --- | --- | --- |\n\
             | student 16 x 128 | {psnr} dB | 0.9759 | 25.9 (`x 1.5`) | -0.81 | [run](run.json) |\n"
        )
    };
    let good = dir.path().join("good.md");
    std::fs::write(&good, page("36.98")).unwrap();
    assert_eq!(check_file(&good), Vec::<String>::new());
    let planted = dir.path().join("planted.md");
    std::fs::write(&planted, page("36.89")).unwrap();
    let problems = check_file(&planted);
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(problems[0].contains("36.89 is not in"), "{problems:?}");
    // A row with no source, and a source that is not there, are problems too.
    let bad = dir.path().join("bad.md");
    std::fs::write(
        &bad,
        "| a | source |\n| --- | --- |\n| 1.5 | none |\n| 2.5 | `missing.json` |\n",
    )
    .unwrap();
    let problems = check_file(&bad);
    assert!(
        problems[0].contains(":3: the row names no source"),
        "{problems:?}"
    );
    assert!(
        problems[1].contains("missing.json is not a committed file"),
        "{problems:?}"
    );
}

#[test]
fn figures_are_read_as_written() {
    assert_eq!(
        decimal_figures("36.44 dB, 0.9694; x1.5 v2.0 `3.14` -0.5 16 x 128, 0.8-1.3"),
        vec!["36.44", "0.9694", "-0.5", "0.8", "1.3"]
    );
    let n = numbers_in("\"psnr\":36.975,\"x\":1e-3, 14m1.155s, -2.5");
    assert_eq!(n, vec![36.975, 1e-3, 14.0, 1.155, -2.5]);
    // An exponent is part of the figure, and compared as written.
    assert_eq!(
        decimal_figures("6.90e-7 and 1.2E+3, 4.5 e"),
        vec!["6.90e-7", "1.2E+3", "4.5"]
    );
    let logged = numbers_in("worst difference 6.90e-7 of the largest output");
    assert!(appears("6.90e-7", &logged));
    assert!(!appears("6.90", &logged) && !appears("6.91e-7", &logged));
}
