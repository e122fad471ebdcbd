//! The documentation names only what exists: every relative markdown link
//! (`[text](path)`, anchors stripped, URLs skipped) and every repository path in
//! backticks (a single token containing a '/' that starts with one of the
//! repository's top-level folders, or ends in a source file's extension) in
//! README.md, RELIABILITY.md, BENCHMARKS.md and docs/**/*.md resolves to a file or
//! folder of the repository. Links resolve from the page's folder, backticked paths
//! from the repository root. Fenced code blocks are skipped (they hold commands and
//! output, whose paths are results of a run, not files of the repository).
//! Host-only: reads files, runs nothing.

#![allow(clippy::expect_used)]

use std::collections::BTreeSet;
use std::fs;
use std::path::{Path, PathBuf};

/// Extensions of files that live in the repository (a backticked token with a '/'
/// ending in one of these is a repository path even when its first folder is not a
/// top-level one, e.g. a path relative to a crate).
const SOURCE_EXTENSIONS: &[&str] = &["rs", "sh", "py", "toml", "md", "dbc", "yml", "yaml", "lock"];

fn repo_root() -> PathBuf {
    // tests/ is one level below the workspace root.
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// What .gitignore names at the root (target/, results/: not the repository's, and
/// absent from a clean clone). A backticked path under one of them is what a run
/// writes (`results/controller.toml`), not a file of the repository.
fn ignored_folders(root: &Path) -> BTreeSet<String> {
    fs::read_to_string(root.join(".gitignore"))
        .unwrap_or_default()
        .lines()
        .map(|l| l.trim().trim_matches('/').to_string())
        .filter(|l| !l.is_empty() && !l.contains('/') && !l.contains('*'))
        .collect()
}

/// The top-level folders of the repository: every directory at the root except
/// .git and the ignored ones.
fn top_level_folders(root: &Path) -> BTreeSet<String> {
    let ignored = ignored_folders(root);
    fs::read_dir(root)
        .expect("reading the repository root")
        .filter_map(Result::ok)
        .filter(|e| e.file_type().map(|t| t.is_dir()).unwrap_or(false))
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|name| name != ".git" && !ignored.contains(name))
        .collect()
}

/// The pages to check, relative to the root.
fn pages(root: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = ["README.md", "RELIABILITY.md", "BENCHMARKS.md"]
        .iter()
        .map(PathBuf::from)
        .filter(|p| root.join(p).is_file())
        .collect();
    let mut stack = vec![PathBuf::from("docs")];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = fs::read_dir(root.join(&dir)) else {
            continue;
        };
        for entry in entries.filter_map(Result::ok) {
            let rel = dir.join(entry.file_name());
            if entry.file_type().map(|t| t.is_dir()).unwrap_or(false) {
                stack.push(rel);
            } else if rel.extension().is_some_and(|e| e == "md") {
                out.push(rel);
            }
        }
    }
    out.sort();
    out
}

/// Markdown link targets on one line: what follows "](" up to the matching ")".
fn link_targets(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = line;
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        let Some(end) = after.find(')') else { break };
        out.push(after[..end].trim().to_string());
        rest = &after[end..];
    }
    out
}

/// Single-token code spans on one line (the text between paired backticks).
fn code_spans(line: &str) -> Vec<String> {
    line.split('`')
        .enumerate()
        .filter(|(i, _)| i % 2 == 1)
        .map(|(_, s)| s.to_string())
        .collect()
}

/// Whether a code span names a repository path, and which.
fn repo_path(span: &str, top: &BTreeSet<String>, ignored: &BTreeSet<String>) -> Option<String> {
    if span.is_empty() || span.chars().any(char::is_whitespace) || !span.contains('/') {
        return None;
    }
    // Placeholders and patterns (`fuzz/corpus/<target>/`, `results/shard-*`) and
    // URLs are not paths to check.
    if span.contains([
        '<', '>', '*', '$', '{', '}', '[', ']', '|', '=', ':', '#', '@',
    ]) || span.starts_with('/')
        || span.starts_with('.') && !top.iter().any(|t| span.starts_with(&format!("{t}/")))
    {
        return None;
    }
    let first = span.split('/').next().unwrap_or_default();
    if ignored.contains(first) {
        return None;
    }
    let ext_known = Path::new(span)
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| SOURCE_EXTENSIONS.contains(&e));
    (top.contains(first) || ext_known).then(|| span.to_string())
}

/// Every broken reference in one page's text: (line number, what, why).
fn check_page(root: &Path, page: &Path, text: &str) -> Vec<String> {
    let top = top_level_folders(root);
    let ignored = ignored_folders(root);
    let page_dir = root
        .join(page)
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default();
    let mut broken = Vec::new();
    let mut in_fence = false;
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
            continue;
        }
        if in_fence {
            continue;
        }
        for target in link_targets(line) {
            let path = target.split('#').next().unwrap_or_default();
            if path.is_empty() || path.contains("://") || path.starts_with("mailto:") {
                continue;
            }
            if !page_dir.join(path).exists() {
                broken.push(format!(
                    "{}:{}: link ({target}) does not exist",
                    page.display(),
                    n + 1
                ));
            } else if !page_dir
                .join(path)
                .canonicalize()
                .is_ok_and(|p| p.starts_with(root))
            {
                broken.push(format!(
                    "{}:{}: link ({target}) leads outside the repository",
                    page.display(),
                    n + 1
                ));
            }
        }
        for span in code_spans(line) {
            if let Some(path) = repo_path(&span, &top, &ignored)
                && !root.join(&path).exists()
            {
                broken.push(format!(
                    "{}:{}: path `{path}` does not exist",
                    page.display(),
                    n + 1
                ));
            }
        }
    }
    broken
}

#[test]
fn every_link_and_path_in_the_documentation_exists() {
    let root = repo_root();
    let root = root.canonicalize().unwrap_or(root);
    let pages = pages(&root);
    assert!(
        pages.iter().any(|p| p == Path::new("README.md")),
        "README.md not found under {}",
        root.display()
    );
    let mut broken = Vec::new();
    for page in &pages {
        let text = fs::read_to_string(root.join(page)).expect("reading a page");
        broken.extend(check_page(&root, page, &text));
    }
    assert!(
        broken.is_empty(),
        "{} broken reference(s) in the documentation:\n{}",
        broken.len(),
        broken.join("\n")
    );
}

#[test]
fn a_bad_link_and_a_bad_path_are_found() {
    let root = repo_root();
    let root = root.canonicalize().unwrap_or(root);
    let text = "See [the design](design.md#workspace), [nothing](no-such-page.md), \
                [a site](https://example.invalid/x), `sim/src/run.rs`, \
                `sim/src/no_such_file.rs`, `results/paper-hil/run.mcap`, and \
                [outside](../../shared/DESIGN.md).\n\
                ```sh\n`sim/src/also_missing.rs` [x](missing-in-a-fence.md)\n```\n";
    let broken = check_page(&root, Path::new("docs/example.md"), text);
    assert_eq!(broken.len(), 3, "{broken:#?}");
    assert!(broken[0].contains("no-such-page.md"), "{broken:#?}");
    assert!(broken[1].contains("shared/DESIGN.md"), "{broken:#?}");
    assert!(broken[2].contains("sim/src/no_such_file.rs"), "{broken:#?}");
}
