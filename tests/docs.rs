//! The docs stand alone: every relative link of the Markdown files
//! (README.md, docs/, the crates' READMEs) resolves to a file inside the
//! repository, and nothing, doc or code comment, sends the reader to the
//! project's planning files, which are not part of the repository.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Files below `dir` whose name ends in one of `exts`, skipping build
/// output, caches and hidden folders.
fn files(dir: &Path, exts: &[&str], out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().into_owned();
        if path.is_dir() {
            if !(name.starts_with('.') || name == "target" || name == "runs") {
                files(&path, exts, out);
            }
        } else if exts.iter().any(|e| name.ends_with(e)) {
            out.push(path);
        }
    }
}

/// `text` without its fenced code blocks and inline code spans (a link
/// there is an example, not a link).
fn prose(text: &str) -> String {
    let mut out = String::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            out.push('\n');
            continue;
        }
        if !fenced {
            // Drop `...` spans; an odd backtick leaves the rest as is.
            let mut parts = line.split('`');
            let mut kept = String::new();
            let mut inside = false;
            for part in parts.by_ref() {
                if !inside {
                    kept.push_str(part);
                }
                inside = !inside;
            }
            out.push_str(&kept);
        }
        out.push('\n');
    }
    out
}

/// The targets of the inline links and images (`[text](target)`,
/// `![alt](target "title")`) and of the reference definitions
/// (`[name]: target`) of a Markdown text.
fn link_targets(markdown: &str) -> Vec<String> {
    let text = prose(markdown);
    let mut targets = Vec::new();
    let mut rest = text.as_str();
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        if let Some(end) = rest.find(')') {
            let inner = rest[..end].trim();
            let target = inner.split_whitespace().next().unwrap_or("");
            targets.push(target.trim_matches(['<', '>']).to_string());
            rest = &rest[end..];
        }
    }
    for line in text.lines() {
        let line = line.trim_start();
        if line.starts_with('[')
            && let Some(i) = line.find("]:")
            && !line[1..i].contains(']')
        {
            let target = line[i + 2..].split_whitespace().next().unwrap_or("");
            targets.push(target.to_string());
        }
    }
    targets
}

/// Whether `target` leaves the repository's files: a URL or a bare anchor.
fn is_external(target: &str) -> bool {
    target.is_empty()
        || target.starts_with('#')
        || target.contains("://")
        || target.starts_with("mailto:")
}

/// README.md, the Markdown files under docs/ and each top-level folder's
/// README.md (the crates').
fn markdown_files() -> Vec<PathBuf> {
    let root = root();
    let mut md = vec![root.join("README.md")];
    files(&root.join("docs"), &[".md"], &mut md);
    for entry in std::fs::read_dir(&root).expect("the root lists").flatten() {
        let readme = entry.path().join("README.md");
        if readme.is_file() {
            md.push(readme);
        }
    }
    md.sort();
    md
}

#[test]
fn every_relative_markdown_link_resolves_inside_the_repository() {
    let root = root().canonicalize().expect("the repository root exists");
    let md = markdown_files();
    let names: Vec<String> = md
        .iter()
        .map(|p| p.strip_prefix(&root).unwrap_or(p).display().to_string())
        .collect();
    for required in [
        "README.md",
        "docs/implementation_details.md",
        "planner/README.md",
    ] {
        assert!(
            names.iter().any(|n| n == required),
            "{required} is among the checked files: {names:?}"
        );
    }
    let mut broken = Vec::new();
    let mut checked = 0;
    for file in &md {
        let text = std::fs::read_to_string(file).expect("a Markdown file reads");
        let dir = file.parent().expect("a file has a folder");
        for target in link_targets(&text) {
            if is_external(&target) {
                continue;
            }
            checked += 1;
            let path = target.split('#').next().unwrap_or("");
            let resolved = dir.join(path).canonicalize();
            let ok = resolved
                .as_ref()
                .is_ok_and(|p| p.starts_with(&root) && p.exists());
            if !ok {
                broken.push(format!(
                    "{}: ({target})",
                    file.strip_prefix(&root).unwrap_or(file).display()
                ));
            }
        }
    }
    assert!(
        broken.is_empty(),
        "links that do not resolve to a file in the repository:\n{}",
        broken.join("\n")
    );
    assert!(checked > 0, "some relative links were checked");
}

#[test]
fn nothing_points_outside_the_repository_to_the_planning_files() {
    let root = root();
    let mut sources = markdown_files();
    files(&root, &[".rs", ".toml", "Makefile"], &mut sources);
    files(&root.join(".ci"), &[""], &mut sources);
    files(&root.join("scripts"), &[".sh"], &mut sources);
    // The names of the planning files, spelled so this file does not
    // match itself.
    let outside = [
        format!("../{}", "shared"),
        format!("{}.md", "DESIGN"),
        format!("{}.md", "STYLE"),
    ];
    let mut found = Vec::new();
    for file in &sources {
        let Ok(text) = std::fs::read_to_string(file) else {
            continue;
        };
        for (n, line) in text.lines().enumerate() {
            for name in &outside {
                if line.contains(name.as_str()) {
                    found.push(format!(
                        "{}:{}: {name}",
                        file.strip_prefix(&root).unwrap_or(file).display(),
                        n + 1
                    ));
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "references to files that are not in the repository:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_link_reader_finds_links_images_and_references_but_not_code() {
    let md = "see [a](docs/a.md#x) and ![p](p.png \"t\")\n\
              [split\ntext](b.md)\n\
              `[not](c.md)`\n\
              ```\n[nor](d.md)\n```\n\
              [ref]: e.md\n\
              [web](https://example.invalid/x)\n";
    let t = link_targets(md);
    assert_eq!(
        t,
        [
            "docs/a.md#x",
            "p.png",
            "b.md",
            "https://example.invalid/x",
            "e.md"
        ]
    );
    assert!(is_external("https://example.invalid/x") && is_external("#anchor"));
    assert!(!is_external("docs/a.md"));
}
