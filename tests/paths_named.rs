//! Every file path the project's own text names (`core/src/gpu/ops/adam.rs` in a
//! shader's header, `docs/geometry.md` in the README, `tools/gpu-check` in a
//! comment) is a file of the checkout: a move that leaves a stale pointer
//! behind fails here, naming the file and line that still say the old path.

use std::path::{Path, PathBuf};

/// The folders a named path starts with (the checkout's top level).
const ROOTS: [&str; 7] = ["core/", "app/", "shaders/", "tools/", "docs/", "tests/", "assets/"];

/// The endings that make a token a file path worth checking (a folder or a
/// name pattern such as `assets/relief_*` is not checked).
const ENDINGS: [&str; 6] = [".rs", ".wgsl", ".md", ".py", ".toml", ".json"];

/// Folders whose text is not the project's (build output, the prepared GPU pack).
const SKIP: [&str; 4] = ["target", ".git", ".gpu-check", "node_modules"];

fn checkout() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The text files below `dir` whose paths the test reads.
fn text_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if p.is_dir() {
            if !SKIP.contains(&name.as_str()) {
                text_files(&p, out);
            }
        } else if ["rs", "wgsl", "md", "py", "toml", "sh"].iter().any(|x| name.ends_with(&format!(".{x}")))
            || name == "gpu-check"
            || name == "run"
        {
            out.push(p);
        }
    }
}

/// The tokens of `line` that start with one of [`ROOTS`] (after a character
/// that cannot be part of a path) and end with one of [`ENDINGS`].
fn named_paths(line: &str) -> Vec<&str> {
    let is_path = |c: char| c.is_ascii_alphanumeric() || "_./-".contains(c);
    let mut found = Vec::new();
    let bytes = line.as_bytes();
    for root in ROOTS {
        let mut from = 0;
        while let Some(i) = line[from..].find(root).map(|i| i + from) {
            from = i + root.len();
            if i > 0 && is_path(bytes[i - 1] as char) {
                continue;
            }
            let end = line[i..].find(|c: char| !is_path(c)).map_or(line.len(), |e| i + e);
            let token = line[i..end].trim_end_matches('.');
            if ENDINGS.iter().any(|x| token.ends_with(x)) {
                found.push(token);
            }
        }
    }
    found
}

#[test]
fn every_named_path_is_a_file_of_the_checkout() {
    let root = checkout();
    let mut files = Vec::new();
    text_files(&root, &mut files);
    assert!(files.len() > 100, "expected the checkout's sources below {}, found {} files", root.display(), files.len());
    let mut stale = Vec::new();
    let mut checked = 0;
    for f in &files {
        let Ok(text) = std::fs::read_to_string(f) else { continue };
        for (n, line) in text.lines().enumerate() {
            for p in named_paths(line) {
                checked += 1;
                if !root.join(p).exists() {
                    stale.push(format!("{}:{}: {p}", f.strip_prefix(&root).unwrap_or(f).display(), n + 1));
                }
            }
        }
    }
    assert!(checked > 50, "expected the project's text to name its files, found {checked} named paths");
    assert!(stale.is_empty(), "paths named that are not files of the checkout:\n{}", stale.join("\n"));
}

#[test]
fn a_path_is_found_only_where_it_starts() {
    assert_eq!(
        named_paths("// Adam (core/src/gpu/ops/adam.rs; CPU twin: style/adam.rs)."),
        ["core/src/gpu/ops/adam.rs"]
    );
    assert_eq!(named_paths("see `docs/geometry.md`."), ["docs/geometry.md"]);
    assert!(named_paths("score/src/x.rs assets/relief_*.png tools/").is_empty());
}
