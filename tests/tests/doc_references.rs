//! Every reference in the tree resolves to a file in the repository: each `docs/...` path cited
//! in code, configuration or documentation exists (and a section quoted after a device note,
//! `docs/devices/allegro.md, "Bus timing"`, is one of its headings), and nothing cites the
//! design notes kept outside the repository (a `notes/` folder, `../shared`, `/work/shared`).
//!
//! Reads files only: no processes, no IPC.

use std::path::{Path, PathBuf};

/// The repository's root (this crate is `tests/`).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_path_buf()
}

/// Every `.rs`, `.toml` and `.md` file of the repository, outside build output, version control
/// and recordings, except this file (which names what it looks for).
fn sources(root: &Path) -> Vec<PathBuf> {
    let me = root.join(file!());
    let mut files = Vec::new();
    let mut dirs = vec![root.to_path_buf()];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).expect("readable folder") {
            let path = entry.expect("folder entry").path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if path.is_dir() {
                if !name.starts_with('.') && name != "target" && name != "recordings" {
                    dirs.push(path);
                }
            } else if matches!(
                path.extension().and_then(|e| e.to_str()),
                Some("rs" | "toml" | "md")
            ) && path != me
            {
                files.push(path);
            }
        }
    }
    files.sort();
    files
}

/// A character that may be part of a cited path.
fn path_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.' | '/')
}

/// The `docs/...` paths cited in `line`, each with the section quoted right after it (`, "..."`
/// closed on the same line), trailing punctuation removed.
fn doc_citations(line: &str) -> Vec<(String, Option<String>)> {
    let mut found = Vec::new();
    let mut from = 0;
    while let Some(at) = line[from..].find("docs/").map(|i| i + from) {
        from = at + "docs/".len();
        if line[..at].chars().next_back().is_some_and(path_char) {
            continue; // part of another path (`a/docs/...`) or word
        }
        let path: String = line[at..].chars().take_while(|c| path_char(*c)).collect();
        let path = path.trim_end_matches(['.', '/']).to_string();
        let rest = &line[at + path.len()..];
        let section = rest
            .trim_start_matches(['`', ')'])
            .strip_prefix(", \"")
            .and_then(|s| s.split_once('"'))
            .map(|(quoted, _)| quoted.to_string());
        found.push((path, section));
    }
    found
}

/// The headings of a Markdown file, without their `#` marks.
fn headings(text: &str) -> Vec<&str> {
    text.lines()
        .filter(|l| l.starts_with('#'))
        .map(|l| l.trim_start_matches('#').trim())
        .collect()
}

#[test]
fn every_cited_docs_path_exists_and_its_quoted_section_is_a_heading() {
    let root = root();
    let mut missing = Vec::new();
    let mut cited = 0;
    for file in sources(&root) {
        let text = std::fs::read_to_string(&file).expect("readable source");
        for (n, line) in text.lines().enumerate() {
            for (path, section) in doc_citations(line) {
                cited += 1;
                let where_ = format!("{}:{}", file.strip_prefix(&root).unwrap().display(), n + 1);
                let target = root.join(&path);
                if !target.exists() {
                    missing.push(format!("{where_}: {path} does not exist"));
                    continue;
                }
                let (Some(section), true) = (section, path.ends_with(".md")) else {
                    continue;
                };
                let doc = std::fs::read_to_string(&target).expect("readable document");
                if !headings(&doc).iter().any(|h| h.starts_with(&section)) {
                    missing.push(format!("{where_}: {path} has no section {section:?}"));
                }
            }
        }
    }
    assert!(
        cited > 0,
        "no docs/ citation found: is the walk looking at the tree?"
    );
    assert!(missing.is_empty(), "{}", missing.join("\n"));
}

#[test]
fn nothing_cites_the_notes_outside_the_repository() {
    let root = root();
    let mut found = Vec::new();
    for file in sources(&root) {
        let text = std::fs::read_to_string(&file).expect("readable source");
        for (n, line) in text.lines().enumerate() {
            let notes = line.match_indices("notes/").any(|(at, _)| {
                !line[..at]
                    .chars()
                    .next_back()
                    .is_some_and(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            });
            if notes || line.contains("../shared") || line.contains("/work/shared") {
                found.push(format!(
                    "{}:{}: {}",
                    file.strip_prefix(&root).unwrap().display(),
                    n + 1,
                    line.trim()
                ));
            }
        }
    }
    assert!(
        found.is_empty(),
        "cites notes that are not in the repository (put the fact in docs/devices/ and cite \
         that):\n{}",
        found.join("\n")
    );
}

#[test]
fn citations_are_found_with_their_sections() {
    assert_eq!(
        doc_citations(r#"// (docs/devices/allegro.md, "Bus timing at 1 Mbit/s"): x"#),
        [(
            "docs/devices/allegro.md".to_string(),
            Some("Bus timing at 1 Mbit/s".to_string())
        )]
    );
    assert_eq!(
        doc_citations("see `docs/devices/shadow.md`. And docs/viewer.png, not a/docs/x"),
        [
            ("docs/devices/shadow.md".to_string(), None),
            ("docs/viewer.png".to_string(), None)
        ]
    );
    assert_eq!(
        doc_citations(r#"docs/devices/shadow.md, "Layouts" and"#)[0].1,
        Some("Layouts".to_string())
    );
    assert!(doc_citations("no citation, only docs").is_empty());
}
