//! The README and `docs/`: the README is the user guide (at most 300 lines, the two commands
//! on its first screen), and every relative link in them resolves inside the repository.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README.md and every Markdown file under docs/.
fn documents() -> Vec<PathBuf> {
    let mut out = vec![root().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    assert!(!docs.is_empty(), "no docs/*.md");
    out.extend(docs);
    out
}

/// The targets of the Markdown links `[text](target)` in `text`, outside code spans and
/// fenced blocks.
fn link_targets(text: &str) -> Vec<String> {
    let mut out = vec![];
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        // Code spans hold no links.
        let mut plain = String::new();
        for (k, part) in line.split('`').enumerate() {
            if k % 2 == 0 {
                plain.push_str(part);
            }
        }
        let mut rest = plain.as_str();
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(end) = after.find(')') else { break };
            out.push(after[..end].trim().to_string());
            rest = &after[end..];
        }
    }
    out
}

#[test]
fn every_relative_link_resolves_inside_the_repository() {
    let root = root().canonicalize().unwrap();
    let mut broken = vec![];
    let mut checked = 0;
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        let dir = doc.parent().unwrap();
        for target in link_targets(&text) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let path = target.split('#').next().unwrap_or_default();
            if path.is_empty() {
                continue;
            }
            checked += 1;
            let resolved = dir.join(path);
            let inside = resolved
                .canonicalize()
                .is_ok_and(|p| p.starts_with(&root) && p.exists());
            if !inside {
                broken.push(format!("{}: ({target})", doc.display()));
            }
        }
    }
    assert!(
        checked > 10,
        "only {checked} links found: is the parser right?"
    );
    assert!(
        broken.is_empty(),
        "links that do not resolve inside the repository:\n{}",
        broken.join("\n")
    );
}

#[test]
fn no_document_names_files_outside_the_repository() {
    for doc in documents() {
        let text = std::fs::read_to_string(&doc).unwrap();
        for (n, line) in text.lines().enumerate() {
            assert!(
                !line.contains("../shared")
                    && !line.contains("shared/")
                    && !line.contains("DESIGN.md"),
                "{}:{}: names a file outside the repository: {line}",
                doc.display(),
                n + 1
            );
        }
    }
}

#[test]
fn the_readme_is_a_user_guide_with_the_two_commands_on_its_first_screen() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines: Vec<&str> = readme.lines().collect();
    assert!(lines.len() <= 300, "README.md has {} lines", lines.len());
    let first_screen = lines[..lines.len().min(30)].join("\n");
    for command in ["cargo run --release -- demo", "cargo test --release"] {
        assert!(
            first_screen.contains(command),
            "the first screen lacks `{command}`"
        );
    }
    assert!(first_screen.contains("ahcmon"), "{first_screen}");
}

#[test]
fn the_ci_runs_exactly_the_readmes_test_command() {
    let ci = std::fs::read_to_string(root().join(".ci/run")).unwrap();
    let last = ci
        .lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or_default();
    assert_eq!(last.trim(), "cargo test --release");
    assert!(Path::new(&root().join("LICENSE-MIT")).exists());
    assert!(Path::new(&root().join("LICENSE-APACHE")).exists());
}

#[test]
fn the_link_parser_finds_links_and_skips_code() {
    let text = "see [a](docs/a.md) and `[b](nope.md)`\n```\n[c](x.md)\n```\n[d](e.md#part)";
    assert_eq!(link_targets(text), vec!["docs/a.md", "e.md#part"]);
}
