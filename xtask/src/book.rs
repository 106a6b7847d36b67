//! The user guide as a book: `mdbook build docs` (mdBook, installed when
//! missing), then every link inside the built book followed. A link to a
//! page or figure that is not in the book, or to a heading its page does
//! not have, is a broken link a reader would click; the check names each
//! and fails. Links to the web are not followed (CI has no network).
//!
//! Prints `book: N pages, M internal links checked, K broken`.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::{cargo, run};

/// The mdBook release the book is built with (installed with only the
/// search feature: no server or watcher is needed to build).
const MDBOOK_VERSION: &str = "0.5.4";

/// Installs mdBook when `mdbook` is not on the path (about a minute).
fn ensure_mdbook(root: &Path) -> Result<(), String> {
    if Command::new("mdbook").arg("--version").output().is_ok() {
        return Ok(());
    }
    run(
        root,
        "cargo install mdbook",
        cargo().args([
            "install",
            "mdbook",
            "--version",
            MDBOOK_VERSION,
            "--locked",
            "--no-default-features",
            "--features",
            "search",
        ]),
    )
}

/// Builds the book into `target/book` and checks its internal links.
pub fn run_check(root: &Path) -> Result<(), String> {
    ensure_mdbook(root)?;
    let out = root.join("target").join("book");
    let _ = std::fs::remove_dir_all(&out);
    run(
        root,
        "mdbook build docs",
        Command::new("mdbook")
            .args(["build", "docs", "--dest-dir"])
            .arg(&out),
    )?;
    let mut report = check_links(&out)?;
    let readme =
        std::fs::read_to_string(root.join("README.md")).map_err(|e| format!("README.md: {e}"))?;
    readme_links(root, &readme, &out, &mut report);
    println!(
        "book: {} pages, {} internal links checked, {} broken",
        report.pages,
        report.links,
        report.broken.len()
    );
    if report.broken.is_empty() {
        Ok(())
    } else {
        for b in &report.broken {
            eprintln!("book: BROKEN {b}");
        }
        Err(format!(
            "{} broken link(s) in the book",
            report.broken.len()
        ))
    }
}

/// What the link check found.
#[derive(Debug, Default)]
pub struct Report {
    /// HTML pages read.
    pub pages: usize,
    /// Internal links followed.
    pub links: usize,
    /// `page: link (why)` for each broken one.
    pub broken: Vec<String>,
}

/// Every HTML file under `dir`.
fn html_files(dir: &Path, out: &mut Vec<PathBuf>) -> Result<(), String> {
    for e in std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))? {
        let p = e.map_err(|e| e.to_string())?.path();
        if p.is_dir() {
            html_files(&p, out)?;
        } else if p.extension().is_some_and(|x| x == "html") {
            out.push(p);
        }
    }
    Ok(())
}

/// The values of `attr="..."` in `html`.
fn attr_values<'a>(html: &'a str, attr: &str) -> Vec<&'a str> {
    let pat = format!(" {attr}=\"");
    let mut out = Vec::new();
    let mut rest = html;
    while let Some(i) = rest.find(&pat) {
        rest = &rest[i + pat.len()..];
        if let Some(end) = rest.find('"') {
            out.push(&rest[..end]);
            rest = &rest[end..];
        }
    }
    out
}

/// Whether a link leaves the book (a scheme, or protocol-relative).
fn external(link: &str) -> bool {
    link.starts_with("//")
        || link
            .split_once(':')
            .is_some_and(|(s, _)| !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric()))
}

/// Checks every `href` and `src` in the built book at `book`: the file it
/// names exists in the book, and a `#fragment` is an `id` of that page.
/// mdBook's own theme assets and the print page's copies are skipped
/// (the print page repeats every page's links).
pub fn check_links(book: &Path) -> Result<Report, String> {
    let mut files = Vec::new();
    html_files(book, &mut files)?;
    let mut ids: HashMap<PathBuf, HashSet<String>> = HashMap::new();
    let mut texts = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).map_err(|e| format!("{}: {e}", f.display()))?;
        let set = attr_values(&text, "id")
            .into_iter()
            .map(str::to_string)
            .collect();
        ids.insert(f.clone(), set);
        texts.push((f.clone(), text));
    }
    let mut report = Report::default();
    for (page, text) in &texts {
        let rel = page.strip_prefix(book).unwrap_or(page);
        if rel == Path::new("print.html") || rel == Path::new("404.html") {
            continue;
        }
        report.pages += 1;
        // Only the page's own content: the sidebar and the theme's links
        // are mdBook's.
        let main = text
            .split_once("<main>")
            .and_then(|(_, m)| m.split_once("</main>"))
            .map_or(text.as_str(), |(m, _)| m);
        let dir = page.parent().unwrap_or(book);
        for link in attr_values(main, "href")
            .into_iter()
            .chain(attr_values(main, "src"))
        {
            if link.is_empty() || external(link) {
                continue;
            }
            report.links += 1;
            let (path, fragment) = match link.split_once('#') {
                Some((p, f)) => (p, Some(f)),
                None => (link, None),
            };
            let target = if path.is_empty() {
                page.clone()
            } else {
                normalize(&dir.join(path.replace("%20", " ")))
            };
            let target = if target.is_dir() {
                target.join("index.html")
            } else {
                target
            };
            if !target.starts_with(book) || !target.exists() {
                report.broken.push(format!(
                    "{}: {link} (no such file in the book)",
                    rel.display()
                ));
                continue;
            }
            if let Some(frag) = fragment.filter(|f| !f.is_empty()) {
                let known = ids.get(&target).is_some_and(|s| s.contains(frag));
                if target.extension().is_some_and(|x| x == "html") && !known {
                    report.broken.push(format!(
                        "{}: {link} (no heading #{frag} there)",
                        rel.display()
                    ));
                }
            }
        }
    }
    Ok(report)
}

/// The front page's relative links (`](PATH)` in README.md): a file of
/// the repository, and a `docs/PAGE.md#heading` a heading of the built
/// page, counted into `report`.
fn readme_links(root: &Path, readme: &str, book: &Path, report: &mut Report) {
    for link in readme
        .split("](")
        .skip(1)
        .filter_map(|r| r.split(')').next())
    {
        if external(link) {
            continue;
        }
        report.links += 1;
        let (path, fragment) = link.split_once('#').unwrap_or((link, ""));
        if path.is_empty() {
            // A heading of the README itself: GitHub's ids are the book's.
            let id = format!("\n## {}", fragment.replace('-', " "));
            if !readme.to_lowercase().contains(&id) {
                report
                    .broken
                    .push(format!("README.md: {link} (no such heading)"));
            }
            continue;
        }
        if !root.join(path).exists() {
            report
                .broken
                .push(format!("README.md: {link} (no such file)"));
            continue;
        }
        let page = path
            .strip_prefix("docs/")
            .and_then(|p| p.strip_suffix(".md"))
            .map(|p| book.join(format!("{p}.html")));
        if let (Some(page), false) = (page, fragment.is_empty()) {
            let text = std::fs::read_to_string(&page).unwrap_or_default();
            if !text.contains(&format!(" id=\"{fragment}\"")) {
                report
                    .broken
                    .push(format!("README.md: {link} (no heading #{fragment} there)"));
            }
        }
    }
}

/// `a/b/../c` as `a/c` (without touching the file system).
fn normalize(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        match c {
            std::path::Component::ParentDir => {
                out.pop();
            }
            std::path::Component::CurDir => {}
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A page linking to a missing page, a missing heading, a present
    /// heading and the web: the two missing ones are reported.
    #[test]
    fn broken_pages_and_headings_are_found() {
        let dir = std::env::temp_dir().join(format!("book-check-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("img")).unwrap_or_default();
        let page = r##"<html><nav><a href="gone.html">x</a></nav><main>
<h2 id="here">Here</h2>
<a href="b.html#there">ok</a> <a href="b.html#nowhere">bad</a>
<a href="missing.html">bad</a> <a href="https://example.org/">web</a>
<img src="img/a.svg"> <a href="#here">self</a></main></html>"##;
        std::fs::write(dir.join("a.html"), page).unwrap_or_default();
        std::fs::write(dir.join("b.html"), r#"<main><h1 id="there">T</h1></main>"#)
            .unwrap_or_default();
        std::fs::write(dir.join("img/a.svg"), "<svg/>").unwrap_or_default();
        let r = check_links(&dir).unwrap_or_default();
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(r.pages, 2);
        assert_eq!(r.links, 5, "{r:?}");
        assert_eq!(r.broken.len(), 2, "{r:?}");
        assert!(r.broken[0].contains("#nowhere") && r.broken[1].contains("missing.html"));
    }
}
