//! The book of `docs/` (`mdbook build docs`, run by CI) holds together: every page is in
//! `SUMMARY.md`, and every relative link of a page lands on a file of the book, so nothing in
//! the rendered book points outside it or at a page that is not there.

use std::path::{Path, PathBuf};

use crate::common;

fn docs() -> PathBuf {
    common::repo().join("docs")
}

fn pages(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("readable docs") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            pages(&path, out);
        } else if path.extension().is_some_and(|e| e == "md") {
            out.push(path);
        }
    }
}

/// The targets of the inline links `[text](target)` and images `![alt](target)` of `text`.
fn link_targets(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(at) = rest.find("](") {
        rest = &rest[at + 2..];
        if let Some(end) = rest.find(')') {
            out.push(rest[..end].to_string());
        }
    }
    out
}

#[test]
fn every_page_is_in_the_summary() {
    let summary = std::fs::read_to_string(docs().join("SUMMARY.md")).expect("SUMMARY.md");
    let listed = link_targets(&summary);
    let mut all = Vec::new();
    pages(&docs(), &mut all);
    let missing: Vec<String> = all
        .iter()
        .map(|p| p.strip_prefix(docs()).unwrap().display().to_string())
        .filter(|p| p != "SUMMARY.md" && !listed.contains(p))
        .collect();
    assert!(missing.is_empty(), "pages not in SUMMARY.md: {missing:?}");
    assert!(listed.len() > 20, "SUMMARY.md read no pages: {listed:?}");
}

#[test]
fn every_relative_link_lands_inside_the_book() {
    let mut all = Vec::new();
    pages(&docs(), &mut all);
    let root = docs().canonicalize().expect("docs");
    let mut broken = Vec::new();
    let mut checked = 0;
    for page in &all {
        let text = std::fs::read_to_string(page).expect("readable page");
        for target in link_targets(&text) {
            let target = target.split_whitespace().next().unwrap_or("");
            if target.is_empty() || target.starts_with('#') || target.contains("://") {
                continue;
            }
            let file = target.split('#').next().unwrap_or(target);
            let resolved = page.parent().unwrap().join(file);
            checked += 1;
            match resolved.canonicalize() {
                Ok(p) if p.starts_with(&root) => {}
                Ok(p) => broken.push(format!(
                    "{}: {target} leaves docs/ ({})",
                    page.display(),
                    p.display()
                )),
                Err(_) => broken.push(format!("{}: {target} is not there", page.display())),
            }
        }
    }
    assert!(
        broken.is_empty(),
        "links that break in the book:\n{}",
        broken.join("\n")
    );
    assert!(checked > 50, "only {checked} links read");
}

#[test]
fn the_book_is_configured_to_build_from_docs() {
    let book = std::fs::read_to_string(docs().join("book.toml")).expect("docs/book.toml");
    let book: toml::Table = toml::from_str(&book).expect("book.toml is TOML");
    assert_eq!(book["book"]["src"].as_str(), Some("."), "{book:?}");
}
