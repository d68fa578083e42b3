//! The figures check: every figure of every table in README.md, the shipped model's card and
//! the pages under docs/ is tied to the value it prints. Under a table, a block
//!
//! ```text
//! <!-- figures
//! 1: metrics_val.json#models[label=teacher].head_psnr; L19.val.psnr
//! 2: timing.json#parts[what=synthetic scene].seconds
//! -->
//! ```
//!
//! gives, per data row (1-based), one key per decimal figure of the row in reading order
//! (the `source` column's cell aside). The check reads the value each key names and
//! compares it with the figure at the figure's printed precision, so a changed digit in any
//! cell fails. A key is relative to the file the row's `source` cell names (see [`Key`]). A
//! table whose figures cannot be tied to files says why in a line `unchecked: why` instead;
//! a figure that is part of a name (the bar `within 1.0 dB`) has the key `label`.
//! Integers are names here (sizes, seeds, step counts in labels) and are not checked.
//! `scripts/figure_keys.py` drafts the keys of a table from its sources.

use std::path::{Path, PathBuf};

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

/// A figure's key: which value of which file a table cell prints.
///
/// `[FILE#]PATH[*SCALE]`. FILE is relative to the row's source file's folder (or, in a
/// table without a `source` column, to the Markdown file's folder) and defaults to the
/// row's source. PATH walks the file:
/// - a `.json` file is its JSON value; a `.csv` file an array of row objects keyed by the
///   header; any other file an array of lines, chosen with `L<n>` (1-based line);
/// - `.name` (or `name` at the start): an object's member; `[i]`: an array's element (0-based); `[name=value]`: the
///   first element whose member `name` is written `value`;
/// - `{k}`: the k-th number (1-based) written in a string or a line; a line that holds a
///   JSON value can instead be walked with `.name` and `[..]`;
/// - `*SCALE` multiplies the value (100 for a share printed in percent, 1000 for seconds
///   printed in milliseconds).
#[derive(Debug, Clone, PartialEq)]
struct Key {
    file: Option<String>,
    path: Vec<Step>,
    scale: f64,
}

#[derive(Debug, Clone, PartialEq)]
enum Step {
    Line(usize),
    Member(String),
    Index(usize),
    Select(String, String),
    Number(usize),
}

fn parse_key(text: &str) -> Result<Key, String> {
    let text = text.trim();
    let (file, rest) = match text.split_once('#') {
        Some((f, r)) => (Some(f.trim().to_string()), r),
        None => (None, text),
    };
    let (path_text, scale) = match rest.rsplit_once('*') {
        Some((p, s)) => (
            p,
            s.trim()
                .parse::<f64>()
                .map_err(|_| format!("key {text:?}: scale {s:?} is not a number"))?,
        ),
        None => (rest, 1.0),
    };
    let mut path = Vec::new();
    let chars: Vec<char> = path_text.chars().collect();
    let mut k = 0;
    let bad = |why: &str| format!("key {text:?}: {why}");
    let take_until = |k: &mut usize, stop: &dyn Fn(char) -> bool| {
        let start = *k;
        while *k < chars.len() && !stop(chars[*k]) {
            *k += 1;
        }
        chars[start..*k].iter().collect::<String>()
    };
    while k < chars.len() {
        match chars[k] {
            'L' if path.is_empty() && chars.get(k + 1).is_some_and(char::is_ascii_digit) => {
                k += 1;
                let n = take_until(&mut k, &|c| !c.is_ascii_digit());
                let n = n
                    .parse::<usize>()
                    .map_err(|_| bad("L takes a line number"))?;
                path.push(Step::Line(n));
            }
            '.' => {
                k += 1;
                let name = take_until(&mut k, &|c| matches!(c, '.' | '[' | '{'));
                if name.is_empty() {
                    return Err(bad("an empty member name"));
                }
                path.push(Step::Member(name));
            }
            // A path may start with a member's name, without its dot.
            c if path.is_empty() && !c.is_whitespace() && !matches!(c, '[' | '{') => {
                let name = take_until(&mut k, &|c| matches!(c, '.' | '[' | '{'));
                if name.is_empty() {
                    return Err(bad("an empty member name"));
                }
                path.push(Step::Member(name));
            }
            '[' => {
                k += 1;
                let inner = take_until(&mut k, &|c| c == ']');
                if k >= chars.len() {
                    return Err(bad("[ without ]"));
                }
                k += 1;
                match inner.split_once('=') {
                    Some((name, value)) => path.push(Step::Select(name.into(), value.into())),
                    None => path.push(Step::Index(
                        inner.parse().map_err(|_| bad("[i] takes an index"))?,
                    )),
                }
            }
            '{' => {
                k += 1;
                let inner = take_until(&mut k, &|c| c == '}');
                if k >= chars.len() {
                    return Err(bad("{ without }"));
                }
                k += 1;
                let n: usize = inner.parse().map_err(|_| bad("{k} takes a count"))?;
                if n == 0 {
                    return Err(bad("{k} counts from 1"));
                }
                path.push(Step::Number(n));
            }
            c if c.is_whitespace() => k += 1,
            c => return Err(bad(&format!("unexpected {c:?}"))),
        }
    }
    if path.is_empty() {
        return Err(bad("no path"));
    }
    Ok(Key { file, path, scale })
}

/// A parsed results file.
enum Doc {
    Json(serde_json::Value),
    Lines(Vec<String>),
}

/// Reads `path` as the key language sees it (JSON, CSV as an array of row objects, or
/// lines).
fn read_doc(path: &Path) -> Result<Doc, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|_| format!("{} is not a committed file", path.display()))?;
    match path.extension().and_then(|e| e.to_str()) {
        Some("json") => serde_json::from_str(&text)
            .map(Doc::Json)
            .map_err(|e| format!("{}: not JSON ({e})", path.display())),
        Some("csv") => Ok(Doc::Json(csv_rows(&text))),
        _ => Ok(Doc::Lines(text.lines().map(str::to_string).collect())),
    }
}

/// The fields of one CSV line (double quotes around fields that hold commas).
fn csv_fields(line: &str) -> Vec<String> {
    let (mut fields, mut field, mut quoted) = (Vec::new(), String::new(), false);
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' if quoted && chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            '"' => quoted = !quoted,
            ',' if !quoted => fields.push(std::mem::take(&mut field)),
            c => field.push(c),
        }
    }
    fields.push(field);
    fields
}

/// A CSV file as an array of objects, one per row, keyed by the header.
fn csv_rows(text: &str) -> serde_json::Value {
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header = lines.next().map(csv_fields).unwrap_or_default();
    serde_json::Value::Array(
        lines
            .map(|l| {
                let row = header
                    .iter()
                    .cloned()
                    .zip(csv_fields(l).into_iter().map(serde_json::Value::String))
                    .collect();
                serde_json::Value::Object(row)
            })
            .collect(),
    )
}

/// How a JSON value is written, for `[name=value]` (a string without its quotes).
fn written(v: &serde_json::Value) -> String {
    match v {
        serde_json::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

/// The number `key` names in `doc`.
fn resolve(doc: &Doc, key: &Key) -> Result<f64, String> {
    let mut steps = key.path.iter().peekable();
    let line_value;
    let mut value: &serde_json::Value = match doc {
        Doc::Json(v) => v,
        Doc::Lines(lines) => {
            let Some(Step::Line(n)) = steps.next() else {
                return Err("a text file's key starts with L<line>".into());
            };
            let line = lines
                .get(n.wrapping_sub(1))
                .ok_or_else(|| format!("line {n} is past the end"))?;
            line_value = serde_json::from_str::<serde_json::Value>(line)
                .unwrap_or_else(|_| serde_json::Value::String(line.clone()));
            &line_value
        }
    };
    while let Some(step) = steps.next() {
        value = match (step, value) {
            (Step::Member(name), serde_json::Value::Object(map)) => {
                map.get(name).ok_or_else(|| format!("no member {name:?}"))?
            }
            (Step::Index(i), serde_json::Value::Array(items)) => {
                items.get(*i).ok_or_else(|| format!("no element {i}"))?
            }
            (Step::Select(name, want), serde_json::Value::Array(items)) => items
                .iter()
                .find(|item| item.get(name).is_some_and(|v| written(v) == *want))
                .ok_or_else(|| format!("no element with {name} = {want:?}"))?,
            (Step::Number(k), serde_json::Value::String(s)) => {
                if steps.peek().is_some() {
                    return Err(format!("{{{k}}} must be the key's last step"));
                }
                let v = numbers_in(s)
                    .get(k - 1)
                    .copied()
                    .ok_or_else(|| format!("{s:?} holds fewer than {k} numbers"))?;
                return Ok(v * key.scale);
            }
            (step, v) => {
                let shown: String = written(v).chars().take(80).collect();
                return Err(format!("{step:?} does not apply to {shown}"));
            }
        };
    }
    let number = match value {
        serde_json::Value::Number(n) => n.as_f64(),
        serde_json::Value::String(s) => s.trim().parse::<f64>().ok(),
        _ => None,
    };
    number
        .map(|v| v * key.scale)
        .ok_or_else(|| format!("{} is not a number", written(value)))
}

/// Whether `figure` (as written) is `value` at the figure's precision; a figure with an
/// exponent (`6.90e-7`) is compared in that form.
fn prints_as(figure: &str, value: f64) -> bool {
    let lower = figure.to_ascii_lowercase();
    if let Some((mantissa, _)) = lower.split_once('e') {
        let d = mantissa.split('.').nth(1).map_or(0, str::len);
        return format!("{value:.d$e}") == lower;
    }
    let d = figure.split('.').nth(1).map_or(0, str::len);
    let printed = format!("{value:.d$}");
    // A value that rounds to zero from below prints as `-0.00`, written `0.00`.
    printed == figure
        || (printed == format!("-{figure}") && figure.chars().all(|c| matches!(c, '0' | '.')))
}

/// The key of a figure that is part of a name (a bar, a flag's value, a preset), not a
/// measurement: it is not looked up.
const LABEL: &str = "label";

/// One Markdown table and the figure keys written under it.
#[derive(Debug)]
struct Table {
    /// 1-based line of the header.
    line: usize,
    header: Vec<String>,
    /// Each data row's 1-based line and cells.
    rows: Vec<(usize, Vec<String>)>,
    keys: Keys,
}

/// What the `<!-- figures ... -->` block under a table says.
#[derive(Debug, Default)]
struct Keys {
    /// `unchecked: why`: the table's figures are not tied to files, for this reason.
    unchecked: Option<String>,
    /// Per data row (1-based), the keys of its figures in order.
    rows: std::collections::BTreeMap<usize, Vec<String>>,
    /// Lines of the block that could not be read.
    bad: Vec<String>,
}

/// The cells of a Markdown table line (`| a | b |` -> `["a", "b"]`).
fn cells(line: &str) -> Vec<String> {
    let inner = line.trim().trim_start_matches('|').trim_end_matches('|');
    inner.split('|').map(|c| c.trim().to_string()).collect()
}

/// Reads a `<!-- figures` block's lines.
fn read_keys(lines: &[&str]) -> Keys {
    let mut keys = Keys::default();
    for line in lines.iter().map(|l| l.trim()).filter(|l| !l.is_empty()) {
        if let Some(why) = line.strip_prefix("unchecked:") {
            keys.unchecked = Some(why.trim().to_string());
            continue;
        }
        match line
            .split_once(':')
            .map(|(n, k)| (n.trim().parse::<usize>(), k))
        {
            Some((Ok(n), list)) => {
                let list = list.split(';').map(|k| k.trim().to_string());
                keys.rows
                    .insert(n, list.filter(|k| !k.is_empty()).collect());
            }
            _ => keys.bad.push(line.to_string()),
        }
    }
    keys
}

/// Every table of a Markdown text, with the keys block that follows it (blank lines may
/// stand between).
fn tables(text: &str) -> Vec<Table> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut k = 0;
    while k < lines.len() {
        if !lines[k].trim_start().starts_with('|') {
            k += 1;
            continue;
        }
        let (line, header) = (k + 1, cells(lines[k]));
        k += 2; // the header and its separator
        let mut rows = Vec::new();
        while k < lines.len() && lines[k].trim_start().starts_with('|') {
            rows.push((k + 1, cells(lines[k])));
            k += 1;
        }
        let mut next = k;
        while next < lines.len() && lines[next].trim().is_empty() {
            next += 1;
        }
        let mut keys = Keys::default();
        if next < lines.len() && lines[next].trim() == "<!-- figures" {
            let end = (next..lines.len())
                .find(|&j| lines[j].trim() == "-->")
                .unwrap_or(lines.len());
            keys = read_keys(&lines[next + 1..end]);
            k = end;
        }
        out.push(Table {
            line,
            header,
            rows,
            keys,
        });
    }
    out
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

/// The problems of the tables of Markdown text `text` (the file `name` in folder `dir`),
/// one line each, and how many figures were checked.
fn check_text(text: &str, dir: &Path, name: &str) -> (Vec<String>, usize) {
    let (problems, checked, _) = check_text_reading(text, dir, name);
    (problems, checked)
}

/// The files whose values the tables of every checked page print (README.md, the model
/// card, docs/): the results the figures check holds the pages to.
pub(crate) fn files_read() -> Vec<PathBuf> {
    let mut files = Vec::new();
    for f in checked_files() {
        let text = std::fs::read_to_string(&f).unwrap_or_default();
        let (_, _, read) = check_text_reading(&text, f.parent().unwrap(), "");
        files.extend(read);
    }
    files
}

/// [`check_text`], with the files it read.
fn check_text_reading(text: &str, dir: &Path, name: &str) -> (Vec<String>, usize, Vec<PathBuf>) {
    let mut problems = Vec::new();
    let mut checked = 0;
    let mut docs: std::collections::HashMap<PathBuf, Result<Doc, String>> = Default::default();
    for table in tables(text) {
        let source_col = table
            .header
            .iter()
            .position(|h| h.eq_ignore_ascii_case("source"));
        let figures: Vec<(usize, Vec<String>)> = table
            .rows
            .iter()
            .map(|(line, row)| {
                let figs = row
                    .iter()
                    .enumerate()
                    .filter(|(c, _)| Some(*c) != source_col)
                    .flat_map(|(_, cell)| decimal_figures(cell))
                    .collect();
                (*line, figs)
            })
            .collect();
        for bad in &table.keys.bad {
            problems.push(format!(
                "{name}:{}: unreadable keys line {bad:?}",
                table.line
            ));
        }
        if figures.iter().all(|(_, f)| f.is_empty()) {
            continue;
        }
        if let Some(why) = &table.keys.unchecked {
            if why.is_empty() {
                problems.push(format!(
                    "{name}:{}: `unchecked:` needs a reason",
                    table.line
                ));
            }
            continue;
        }
        if table.keys.rows.is_empty() {
            problems.push(format!(
                "{name}:{}: the table's figures have no keys (a `<!-- figures` block)",
                table.line
            ));
            continue;
        }
        if let Some(n) = table
            .keys
            .rows
            .keys()
            .find(|&&n| n == 0 || n > table.rows.len())
        {
            problems.push(format!(
                "{name}:{}: keys for row {n}, which is not there",
                table.line
            ));
        }
        for (index, ((line, row), (_, figs))) in table.rows.iter().zip(&figures).enumerate() {
            if figs.is_empty() {
                continue;
            }
            let keys = table
                .keys
                .rows
                .get(&(index + 1))
                .cloned()
                .unwrap_or_default();
            if keys.len() != figs.len() {
                problems.push(format!(
                    "{name}:{line}: {} figures but {} keys",
                    figs.len(),
                    keys.len()
                ));
                continue;
            }
            let source = source_col
                .and_then(|c| row.get(c))
                .and_then(|c| source_path(c));
            if source_col.is_some() && source.is_none() {
                problems.push(format!("{name}:{line}: the row names no source file"));
                continue;
            }
            let source = source.map(|s| dir.join(s));
            for (figure, key_text) in figs.iter().zip(&keys) {
                if key_text == LABEL {
                    continue;
                }
                let key = match parse_key(key_text) {
                    Ok(key) => key,
                    Err(e) => {
                        problems.push(format!("{name}:{line}: {e}"));
                        continue;
                    }
                };
                let file = match (&key.file, &source) {
                    (Some(f), Some(s)) => s.parent().unwrap_or(dir).join(f),
                    (Some(f), None) => dir.join(f),
                    (None, Some(s)) => s.clone(),
                    (None, None) => {
                        problems.push(format!(
                            "{name}:{line}: key {key_text:?} names no file and the table has no source column"
                        ));
                        continue;
                    }
                };
                let doc = docs.entry(file.clone()).or_insert_with(|| read_doc(&file));
                let outcome = match doc {
                    Ok(doc) => resolve(doc, &key),
                    Err(e) => Err(e.clone()),
                };
                checked += 1;
                match outcome {
                    Ok(v) if prints_as(figure, v) => {}
                    Ok(v) => problems.push(format!(
                        "{name}:{line}: {figure} but {} holds {v} at {key_text}",
                        file.display()
                    )),
                    Err(e) => problems.push(format!(
                        "{name}:{line}: {figure}: {} at {key_text}: {e}",
                        file.display()
                    )),
                }
            }
        }
    }
    (problems, checked, docs.into_keys().collect())
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
fn every_table_figure_is_the_value_its_key_names() {
    let (mut problems, mut checked) = (Vec::new(), 0);
    for f in checked_files() {
        let text = std::fs::read_to_string(&f).unwrap();
        let (p, n) = check_text(&text, f.parent().unwrap(), &f.display().to_string());
        problems.extend(p);
        checked += n;
    }
    assert!(checked >= 500, "only {checked} figures checked");
    assert!(
        problems.is_empty(),
        "{} problems:\n{}",
        problems.len(),
        problems.join("\n")
    );
}

/// `line` with the last digit of its `nth` figure (0-based, in cells other than `skip`)
/// changed.
fn plant_digit(line: &str, skip: Option<usize>, nth: usize) -> Option<String> {
    let mut row = cells(line);
    let (c, k, figure) = row
        .iter()
        .enumerate()
        .filter(|(c, _)| Some(*c) != skip)
        .flat_map(|(c, cell)| {
            decimal_figures(cell)
                .into_iter()
                .enumerate()
                .map(move |(k, f)| (c, k, f))
        })
        .nth(nth)?;
    // The figure's place in its cell: after the cell's first k figures.
    let mut at = 0;
    for earlier in decimal_figures(&row[c]).iter().take(k) {
        at = row[c][at..].find(earlier.as_str())? + at + earlier.len();
    }
    let at = row[c][at..].find(&figure)? + at;
    let last = at + figure.rfind(|ch: char| ch.is_ascii_digit())?;
    let digit = row[c].as_bytes()[last] - b'0';
    row[c].replace_range(last..last + 1, &((digit + 1) % 10).to_string());
    Some(format!("| {} |", row.join(" | ")))
}

#[test]
fn a_changed_digit_in_any_table_fails_the_check() {
    let mut planted = 0;
    for f in checked_files() {
        let text = std::fs::read_to_string(&f).unwrap();
        let dir = f.parent().unwrap();
        for table in tables(&text) {
            if table.keys.unchecked.is_some() || table.keys.rows.is_empty() {
                continue;
            }
            let source_col = table
                .header
                .iter()
                .position(|h| h.eq_ignore_ascii_case("source"));
            let Some((line, planted_line)) =
                table
                    .rows
                    .iter()
                    .enumerate()
                    .find_map(|(index, (line, row))| {
                        // The first figure of the row that is looked up.
                        let keys = table.keys.rows.get(&(index + 1))?;
                        let nth = keys.iter().position(|k| k != LABEL)?;
                        plant_digit(&format!("| {} |", row.join(" | ")), source_col, nth)
                            .map(|p| (*line, p))
                    })
            else {
                continue;
            };
            let changed: Vec<&str> = text
                .lines()
                .enumerate()
                .map(|(k, l)| {
                    if k + 1 == line {
                        planted_line.as_str()
                    } else {
                        l
                    }
                })
                .collect();
            let (problems, _) = check_text(&changed.join("\n"), dir, "planted");
            assert!(
                problems
                    .iter()
                    .any(|p| p.starts_with(&format!("planted:{line}:"))),
                "{}:{line}: a changed digit passed ({planted_line})",
                f.display()
            );
            planted += 1;
        }
    }
    assert!(planted >= 40, "only {planted} tables planted");
}

#[test]
fn keys_read_json_csv_and_lines() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| std::fs::write(dir.path().join(name), text).unwrap();
    write(
        "run.json",
        r#"{"models": [{"label": "teacher", "psnr": 36.975848, "repainted": 0.0322},
                       {"label": "student", "psnr": 35.4641, "step": 4500}],
            "note": "took 14m1.155s"}"#,
    );
    write(
        "scores.csv",
        "label,model,val\nteacher,\"6x128, 32\",37.4244\npixels,x,38.43\n",
    );
    write(
        "run.log",
        "start\n| a | 29.65 / 35.87 |\n{\"val\": {\"psnr\": 30.3645}}\n",
    );
    let page = |cells: &str, keys: &str| {
        format!(
            "# t\n\n| what | figures | source |\n| --- | --- | --- |\n| row | {cells} | [run](run.json) |\n\n<!-- figures\n1: {keys}\n-->\n"
        )
    };
    let check = |text: &str| check_text(text, dir.path(), "t.md");
    let keys = "models[label=teacher].psnr; models[1].psnr; models[label=teacher].repainted*100; \
                note{2}; scores.csv#[label=pixels].val; scores.csv#[model=6x128, 32].val; \
                run.log#L2{2}; run.log#L3.val.psnr";
    let good = page(
        "36.98 dB, 35.46; 3.2 %; 1.155 s; 38.43 / 37.42; 35.87; 30.36",
        keys,
    );
    assert_eq!(check(&good), (vec![], 8));
    // One changed digit, each kind of key.
    for (cells, needle) in [
        (
            "36.97 dB, 35.46; 3.2 %; 1.155 s; 38.43 / 37.42; 35.87; 30.36",
            "36.97 but",
        ),
        (
            "36.98 dB, 35.46; 3.3 %; 1.155 s; 38.43 / 37.42; 35.87; 30.36",
            "3.3 but",
        ),
        (
            "36.98 dB, 35.46; 3.2 %; 1.156 s; 38.43 / 37.42; 35.87; 30.36",
            "1.156 but",
        ),
        (
            "36.98 dB, 35.46; 3.2 %; 1.155 s; 38.43 / 37.43; 35.87; 30.36",
            "37.43 but",
        ),
        (
            "36.98 dB, 35.46; 3.2 %; 1.155 s; 38.43 / 37.42; 35.88; 30.36",
            "35.88 but",
        ),
        (
            "36.98 dB, 35.46; 3.2 %; 1.155 s; 38.43 / 37.42; 35.87; 30.37",
            "30.37 but",
        ),
    ] {
        let (problems, _) = check(&page(cells, keys));
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(problems[0].contains(needle), "{problems:?}");
    }
    // A figure under the wrong key, a missing key, a bad key, a missing file.
    let (p, _) = check(&page("35.46", "models[label=teacher].psnr"));
    assert!(
        p[0].contains("35.46 but") && p[0].contains("36.97"),
        "{p:?}"
    );
    let (p, _) = check(&page("35.46, 36.98", "models[1].psnr"));
    assert!(p[0].contains("2 figures but 1 keys"), "{p:?}");
    let (p, _) = check(&page("35.46", "models[label=nobody].psnr"));
    assert!(p[0].contains("no element with label = \"nobody\""), "{p:?}");
    let (p, _) = check(&page("35.46", "gone.json#models[1].psnr"));
    assert!(p[0].contains("gone.json is not a committed file"), "{p:?}");
    // A table with figures and no keys fails; one that says why it is unchecked passes,
    // but not without a reason.
    let bare = "| a | b |\n| --- | --- |\n| x | 1.6 |\n";
    assert!(check(bare).0[0].contains("have no keys"));
    let why = format!("{bare}\n<!-- figures\nunchecked: a worked example\n-->\n");
    assert_eq!(check(&why).0, Vec::<String>::new());
    let empty = format!("{bare}\n<!-- figures\nunchecked:\n-->\n");
    assert!(check(&empty).0[0].contains("needs a reason"));
    // A figure that is part of a name is not looked up; the others still are.
    let (p, n) = check(&page("within 1.0 dB: 35.46", "label; models[1].psnr"));
    assert_eq!((p, n), (vec![], 1));
    let (p, _) = check(&page("within 1.0 dB: 35.47", "label; models[1].psnr"));
    assert!(p[0].contains("35.47 but"), "{p:?}");
    // A table without a source column names the file in each key.
    let named =
        format!("{bare}\n<!-- figures\n1: run.json#models[label=teacher].repainted*50\n-->\n");
    assert_eq!(check(&named), (vec![], 1));
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
    assert!(prints_as("6.90e-7", 6.9e-7) && !prints_as("6.90", 6.9e-7));
    assert!(!prints_as("6.91e-7", 6.9e-7));
    assert!(prints_as("0.00", -0.001) && prints_as("-0.13", -0.131) && !prints_as("0.13", -0.131));
}
