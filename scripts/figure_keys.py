#!/usr/bin/env python3
"""Drafts the `<!-- figures` key blocks of Markdown tables (the figures check in
tests/suite/figures.rs reads them).

For every table of the given Markdown files whose figures have no keys yet, it looks each
decimal figure up in the file the row's `source` cell names (JSON, CSV, or lines of text,
JSON lines walked as JSON) and writes the key of the value that prints as the figure. When
a figure prints from several places, it prefers the record (JSON object, CSV row, line)
that holds most of the row's figures. Figures it cannot find are written as `?` for a
person to fill in; the check fails on them until then. Read the drafted keys before
committing them: a key is a claim about where a figure comes from.

Usage: scripts/figure_keys.py FILE.md [FILE.md ...] [--rewrite]
"""

import json
import math
import os
import re
import sys

SCALES = [1.0, 100.0, 1000.0, 1e-3, 1e-6, 1e-9]
SELECTORS = ["label", "what", "name", "split", "model", "key", "way", "id", "part"]


def cells(line):
    inner = line.strip().strip("|")
    return [c.strip() for c in inner.split("|")]


def decimal_figures(cell):
    """The decimal figures of a cell, as the Rust check reads them."""
    plain = " ".join(p for k, p in enumerate(cell.split("`")) if k % 2 == 0)
    out = []
    k = 0
    b = plain
    while k < len(b):
        starts = b[k].isdigit() and (k == 0 or not (b[k - 1].isalnum() or b[k - 1] == "."))
        if not starts:
            k += 1
            continue
        signed = k > 0 and b[k - 1] == "-" and (k == 1 or not b[k - 2].isalnum())
        start = k - 1 if signed else k
        end = k
        while end < len(b) and b[end].isdigit():
            end += 1
        if end + 1 < len(b) and b[end] == "." and b[end + 1].isdigit():
            end += 1
            while end < len(b) and b[end].isdigit():
                end += 1
            e = end
            if e < len(b) and b[e] in "eE":
                e += 1
                if e < len(b) and b[e] in "-+":
                    e += 1
                if e < len(b) and b[e].isdigit():
                    while e < len(b) and b[e].isdigit():
                        e += 1
                    end = e
            out.append(b[start:end])
        k = max(end, k + 1)
    return out


def numbers_in(text):
    """Every number written in `text`, as the Rust check reads them."""
    out = []
    token = ""
    for ch in text + " ":
        if ch.isdigit() or ch in ".-+eE":
            token += ch
            continue
        t = re.sub(r"^[^0-9]+|[^0-9]+$", "", token)
        if token.startswith("-") and t:
            t = "-" + t
        try:
            out.append(float(t))
        except ValueError:
            pass
        token = ""
    return out


def prints_as(figure, value):
    if not math.isfinite(value):
        return False
    low = figure.lower()
    if "e" in low:
        mant = low.split("e")[0]
        d = len(mant.split(".")[1]) if "." in mant else 0
        s = f"{value:.{d}e}"
        # Rust writes exponents without a plus sign or leading zeros.
        m, e = s.split("e")
        return f"{m}e{int(e)}" == low
    d = len(figure.split(".")[1]) if "." in figure else 0
    printed = f"{value:.{d}f}"
    return printed == figure or (printed == "-" + figure and set(figure) <= set("0."))


def safe(value):
    return all(c not in value for c in "];#*") and value.strip() == value and value != ""


def leaves(value, path, record):
    """(path, record, number) for every number under `value`; `record` names the
    innermost object or line that holds it."""
    if isinstance(value, bool) or value is None:
        return
    if isinstance(value, (int, float)):
        yield path, record, float(value)
    elif isinstance(value, str):
        try:
            yield path, record, float(value.strip())
            return
        except ValueError:
            pass
        for k, v in enumerate(numbers_in(value)):
            yield f"{path}{{{k + 1}}}", record, v
    elif isinstance(value, dict):
        for key, v in value.items():
            if any(c in key for c in ".[{;#*") or not key:
                continue
            sub = f"{path}.{key}" if path else key
            yield from leaves(v, sub, sub if isinstance(v, (dict, list)) else record)
    elif isinstance(value, list):
        sel = None
        if value and all(isinstance(v, dict) for v in value):
            for name in SELECTORS + sorted({k for v in value for k in v}):
                written = [
                    v.get(name) if isinstance(v.get(name), str) else json.dumps(v.get(name))
                    for v in value
                ]
                # Names and counts identify an element; a measured float does not.
                identity = all(
                    isinstance(v.get(name), (str, int)) and not isinstance(v.get(name), bool)
                    for v in value
                )
                if identity and len(set(written)) == len(written) and all(safe(w) for w in written):
                    sel = (name, written)
                    break
        for i, v in enumerate(value):
            step = f"[{sel[0]}={sel[1][i]}]" if sel else f"[{i}]"
            sub = f"{path}{step}"
            yield from leaves(v, sub, sub)


def csv_fields(line):
    fields, field, quoted, k = [], "", False, 0
    while k < len(line):
        c = line[k]
        if c == '"' and quoted and k + 1 < len(line) and line[k + 1] == '"':
            field += '"'
            k += 1
        elif c == '"':
            quoted = not quoted
        elif c == "," and not quoted:
            fields.append(field)
            field = ""
        else:
            field += c
        k += 1
    fields.append(field)
    return fields


def doc_leaves(path):
    text = open(path, encoding="utf-8").read()
    if path.endswith(".json"):
        return list(leaves(json.loads(text), "", ""))
    if path.endswith(".csv"):
        lines = [l for l in text.splitlines() if l.strip()]
        header = csv_fields(lines[0])
        rows = [dict(zip(header, csv_fields(l))) for l in lines[1:]]
        return list(leaves(rows, "", ""))
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        try:
            v = json.loads(line)
            if isinstance(v, (dict, list)):
                out.extend(leaves(v, f"L{n}", f"L{n}"))
                continue
        except ValueError:
            pass
        for k, v in enumerate(numbers_in(line)):
            out.append((f"L{n}{{{k + 1}}}", f"L{n}", v))
    return out


def draft_row(figs, source):
    found = []
    cands = doc_leaves(source)
    per_fig = []
    for fig in figs:
        m = []
        for path, record, v in cands:
            for scale in SCALES:
                if prints_as(fig, v * scale):
                    m.append((path, record, scale))
                    break
        per_fig.append(m)
    # How many of the row's figures each record holds.
    score = {}
    for m in per_fig:
        for rec in {r for _, r, _ in m}:
            score[rec] = score.get(rec, 0) + 1
    order = {path: i for i, (path, _, _) in enumerate(cands)}
    last, used = -1, set()
    for m in per_fig:
        if not m:
            found.append("?")
            continue
        best = max(score.get(r, 0) for _, r, _ in m)
        top = [t for t in m if score.get(t[1], 0) == best]
        # Reading order: the first match after the previous figure's, unused, unscaled.
        top.sort(key=lambda t: (t[0] in used, order[t[0]] <= last, t[2] != 1.0, order[t[0]]))
        path, _, scale = top[0]
        last = order[path]
        used.add(path)
        s = "" if scale == 1.0 else f"*{scale:g}"
        found.append(path + s)
    return found


def source_path(cell):
    m = re.search(r"\]\(([^)]*)\)", cell)
    if m:
        return m.group(1)
    parts = cell.split("`")
    return parts[1] if len(parts) > 2 else None


def process(md, rewrite):
    lines = open(md, encoding="utf-8").read().split("\n")
    out, k, drafted = [], 0, 0
    while k < len(lines):
        if not lines[k].lstrip().startswith("|"):
            out.append(lines[k])
            k += 1
            continue
        header = cells(lines[k])
        start = k
        k += 2
        while k < len(lines) and lines[k].lstrip().startswith("|"):
            k += 1
        table = lines[start:k]
        out.extend(table)
        nxt = k
        while nxt < len(lines) and not lines[nxt].strip():
            nxt += 1
        has_block = nxt < len(lines) and lines[nxt].strip() == "<!-- figures"
        if has_block and not rewrite:
            continue
        if has_block:
            end = next(j for j in range(nxt, len(lines)) if lines[j].strip() == "-->")
            if any(l.strip().startswith("unchecked:") for l in lines[nxt:end]):
                continue
            del lines[k:end + 1]
            while k < len(lines) and not lines[k].strip() and k + 1 < len(lines) and not lines[k + 1].strip():
                del lines[k]
        src_col = next((i for i, h in enumerate(header) if h.lower() == "source"), None)
        block = []
        for n, row in enumerate(table[2:], 1):
            rc = cells(row)
            figs = [f for i, c in enumerate(rc) if i != src_col for f in decimal_figures(c)]
            if not figs:
                continue
            src = source_path(rc[src_col]) if src_col is not None and src_col < len(rc) else None
            if src is None:
                block.append(f"{n}: " + "; ".join("?" for _ in figs))
                continue
            full = os.path.normpath(os.path.join(os.path.dirname(md), src))
            try:
                keys = draft_row(figs, full)
            except (OSError, ValueError) as e:
                print(f"{md}: {src}: {e}", file=sys.stderr)
                keys = ["?" for _ in figs]
            block.append(f"{n}: " + "; ".join(keys))
        if block:
            drafted += 1
            out.append("")
            out.append("<!-- figures")
            out.extend(block)
            out.append("-->")
    open(md, "w", encoding="utf-8").write("\n".join(out))
    return drafted


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    rewrite = "--rewrite" in sys.argv
    if not args:
        print(__doc__, file=sys.stderr)
        return 2
    for md in args:
        n = process(md, rewrite)
        print(f"{md}: drafted keys for {n} tables")
    return 0


if __name__ == "__main__":
    sys.exit(main())
