//! No file under `results/` holds an absolute path of the machine it was made on (`/root/`,
//! `/work/`, `/tmp/`, `/home/` and the like): a log, script or report there must read the
//! same on any clone, so its paths are relative to the repository or to the run's folder.
//! Tool paths of the system (`/usr/bin/time`, `#!/usr/bin/env`) are not the machine's and
//! pass.

use std::path::{Path, PathBuf};

/// Roots of absolute paths that belong to one machine or one user.
const MACHINE_ROOTS: [&str; 12] = [
    "/root/",
    "/work/",
    "/tmp/",
    "/home/",
    "/Users/",
    "/mnt/",
    "/media/",
    "/opt/",
    "/srv/",
    "/scratch/",
    "/private/",
    "/var/",
];

/// Whether `c` can sit inside a path, so that a root after it is part of a relative path
/// (`runs/x/tmp/`) rather than the start of an absolute one.
fn in_path(c: char) -> bool {
    c.is_ascii_alphanumeric() || "_.-~/$".contains(c)
}

/// Each absolute machine path in `text`: its 1-based line and the path up to the next
/// blank, quote or bracket. A Windows user folder (`C:\Users\`) counts too.
fn machine_paths(text: &str) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (n, line) in text.lines().enumerate() {
        for (at, _) in line.char_indices() {
            let rest = &line[at..];
            let unix = MACHINE_ROOTS.iter().any(|r| rest.starts_with(r));
            let windows = rest.len() > 9
                && rest.as_bytes()[0].is_ascii_alphabetic()
                && rest[1..].starts_with(":\\Users\\");
            let starts = line[..at].chars().next_back().is_none_or(|c| !in_path(c));
            if (unix || windows) && starts {
                let end = rest
                    .find(|c: char| c.is_whitespace() || "\"'`()[]{}<>,;|".contains(c))
                    .unwrap_or(rest.len());
                found.push((n + 1, rest[..end].to_string()));
            }
        }
    }
    found
}

/// Every file under `dir`, sub-folders included.
fn files_under(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files_under(&path, out);
        } else {
            out.push(path);
        }
    }
}

#[test]
fn the_detector_finds_planted_machine_paths_and_passes_relative_ones() {
    let planted = [
        "cd /work/main",
        "N=/work/rel/release/nldf",
        r#"  "data": "/tmp/benchscene","#,
        "model in /root/.cache/x.onnx",
        "(/home/ana/runs/t512)",
        "'/Users/ana/nldf'",
        r"C:\Users\ana\nldf\runs",
        "--out=/mnt/disk/runs",
    ];
    for text in planted {
        assert_eq!(machine_paths(text).len(), 1, "not found in {text:?}");
    }
    let clean = [
        "runs/t512/data/aud.npy",
        "#!/usr/bin/env bash",
        "/usr/bin/time -v $N train teacher",
        "runs/x/tmp/frames and results/home/a.json",
        r#""file": "cmp_new/frontier/models/student.fp32.onnx""#,
        "${R}.tmp/y",
        "12.0 s of sc/aud.wav (300 frames)",
    ];
    for text in clean {
        assert_eq!(machine_paths(text), vec![], "flagged in {text:?}");
    }
}

#[test]
fn no_results_file_holds_an_absolute_machine_path() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let results = root.join("results");
    let mut files = Vec::new();
    files_under(&results, &mut files);
    files.sort();
    let mut text_files = 0;
    let mut bad = Vec::new();
    for file in &files {
        let bytes = std::fs::read(file).unwrap();
        // Images, arrays and other binary files hold no paths to read.
        let Ok(text) = std::str::from_utf8(&bytes) else {
            continue;
        };
        if text.contains('\0') {
            continue;
        }
        text_files += 1;
        let rel = file
            .strip_prefix(&root)
            .unwrap_or(file)
            .display()
            .to_string();
        for (line, path) in machine_paths(text) {
            bad.push(format!("{rel}:{line}: {path}"));
        }
    }
    println!(
        "{text_files} text files of {} under results/ read",
        files.len()
    );
    assert!(
        text_files > 100,
        "only {text_files} text files under results/"
    );
    assert!(
        bad.is_empty(),
        "{} absolute machine paths under results/ (make them relative to the repository or \
         the run's folder):\n{}",
        bad.len(),
        bad.join("\n")
    );
}
