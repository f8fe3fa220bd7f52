//! `cargo xtask crates`: the workspace's crates, their lines, the
//! workspace crates each depends on, and the circles among each crate's
//! top-level modules (module `a` uses `crate::b` and `b` uses `crate::a`,
//! through any chain). Issue 36 asks for arrows one way: `--check` fails
//! when a crate has a circle.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// One crate of the workspace as the report shows it.
struct CrateReport {
    folder: String,
    package: String,
    /// The manifest's description: the crate's job in one line.
    job: String,
    lines: usize,
    depends_on: Vec<String>,
    circles: Vec<Vec<String>>,
}

/// Print the report as a Markdown table; with `check`, fail on a circle.
pub fn run(check: bool) -> Result<()> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .context("xtask lives inside the workspace")?
        .to_path_buf();
    let mut reports = Vec::new();
    let mut folders: Vec<PathBuf> = fs::read_dir(root.join("crates"))?
        .filter_map(|entry| entry.ok().map(|e| e.path()))
        .filter(|path| path.join("Cargo.toml").is_file() && path.join("src").is_dir())
        .collect();
    folders.sort();
    for folder in folders {
        reports.push(report(&folder)?);
    }
    println!("| crate | package | job | lines | depends on (workspace) | module circles |");
    println!("|---|---|---|---:|---|---|");
    for r in &reports {
        let circles: Vec<String> = r.circles.iter().map(|c| c.join(" / ")).collect();
        println!(
            "| `crates/{}` | `{}` | {} | {} | {} | {} |",
            r.folder,
            r.package,
            r.job,
            r.lines,
            if r.depends_on.is_empty() {
                "-".to_string()
            } else {
                r.depends_on.join(", ")
            },
            if circles.is_empty() {
                "none".to_string()
            } else {
                circles.join("; ")
            }
        );
    }
    let with_circles: Vec<&str> = reports
        .iter()
        .filter(|r| !r.circles.is_empty())
        .map(|r| r.package.as_str())
        .collect();
    if check && !with_circles.is_empty() {
        bail!(
            "module circles inside {}: move the shared type or constant to one side",
            with_circles.join(", ")
        );
    }
    Ok(())
}

fn report(folder: &Path) -> Result<CrateReport> {
    let manifest_path = folder.join("Cargo.toml");
    let manifest: toml::Table = fs::read_to_string(&manifest_path)?
        .parse()
        .with_context(|| format!("{}", manifest_path.display()))?;
    let package = manifest
        .get("package")
        .and_then(|p| p.get("name"))
        .and_then(|n| n.as_str())
        .with_context(|| format!("{}: no package name", manifest_path.display()))?
        .to_string();
    let job = manifest
        .get("package")
        .and_then(|p| p.get("description"))
        .and_then(|d| d.as_str())
        .with_context(|| {
            format!(
                "{}: no description: say the crate's job in one line",
                manifest_path.display()
            )
        })?
        .to_string();
    let depends_on = manifest
        .get("dependencies")
        .and_then(|d| d.as_table())
        .map(|table| {
            table
                .keys()
                .filter(|k| k.starts_with("twostage"))
                .cloned()
                .collect()
        })
        .unwrap_or_default();
    let src = folder.join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files)?;
    let mut lines = 0;
    let mut modules: BTreeMap<String, Vec<(PathBuf, String)>> = BTreeMap::new();
    for file in files {
        let text = fs::read_to_string(&file)?;
        lines += text.lines().count();
        let relative = file.strip_prefix(&src)?;
        let Some(module) = top_module(relative) else {
            continue;
        };
        modules
            .entry(module)
            .or_default()
            .push((relative.to_path_buf(), text));
    }
    let names: BTreeSet<String> = modules.keys().cloned().collect();
    let root = ["lib.rs", "main.rs"]
        .iter()
        .map(|f| src.join(f))
        .find(|p| p.is_file())
        .map(fs::read_to_string)
        .transpose()?
        .unwrap_or_default();
    let exports = root_exports(&root);
    let mut uses: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (module, files) in &modules {
        let used = uses.entry(module.clone()).or_default();
        for (relative, text) in files {
            // `super::` means the crate root only in a top-level module's
            // own file.
            let at_top = relative.components().count() == 1
                || relative.file_name().is_some_and(|n| n == "mod.rs")
                    && relative.components().count() == 2;
            for target in referenced_modules(text, at_top, &exports) {
                if target != *module && names.contains(&target) {
                    used.insert(target);
                }
            }
        }
    }
    Ok(CrateReport {
        folder: folder
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        package,
        job,
        lines,
        depends_on,
        circles: circles(&uses),
    })
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) -> Result<()> {
    for entry in fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_dir() {
            rust_files(&path, out)?;
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    Ok(())
}

/// The top-level module a file under `src/` belongs to (`a.rs`,
/// `a/mod.rs` and `a/b.rs` to `a`); none for the crate root and binaries.
fn top_module(relative: &Path) -> Option<String> {
    let first = relative.components().next()?.as_os_str().to_string_lossy();
    let name = first.strip_suffix(".rs").unwrap_or(&first).to_string();
    (!matches!(name.as_str(), "lib" | "main" | "bin")).then_some(name)
}

/// A file's code without its `//` comments and its unit tests (a
/// `#[cfg(test)]` item at the file's top level and all after it: tests
/// are not part of the crate's build), as one text (use groups span
/// lines).
fn code_of(text: &str) -> String {
    text.lines()
        .take_while(|line| !line.starts_with("#[cfg(test)]"))
        .map(|line| line.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The first path segment of each item of a use group that starts right
/// after its `{` in `rest`, and the text after its `}`.
fn group_items(rest: &str) -> (Vec<String>, &str) {
    let mut items = Vec::new();
    let (mut depth, mut item_start) = (1usize, true);
    for (at, c) in rest.char_indices() {
        match c {
            '{' => depth += 1,
            '}' => {
                depth -= 1;
                if depth == 0 {
                    return (items, &rest[at + 1..]);
                }
            }
            ',' if depth == 1 => item_start = true,
            c if item_start && (c.is_alphanumeric() || c == '_') => {
                let name: String = rest[at..]
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                items.push(name);
                item_start = false;
            }
            _ => {}
        }
    }
    (items, "")
}

/// The names the crate root re-exports (`pub use module::{A, B}`), each
/// with the top-level module it comes from: a file that names `crate::A`
/// depends on that module.
fn root_exports(root: &str) -> BTreeMap<String, String> {
    let code = code_of(root);
    let mut exports = BTreeMap::new();
    let mut rest = code.as_str();
    while let Some(at) = rest.find("pub use ") {
        rest = &rest[at + "pub use ".len()..];
        let module: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        let after = &rest[module.len()..];
        let Some(path) = after.strip_prefix("::") else {
            continue;
        };
        let names = if let Some(group) = path.strip_prefix('{') {
            // `pub use m::{A, B as C}`: the names as the root shows them.
            let end = group.find('}').unwrap_or(group.len());
            group[..end]
                .split(',')
                .filter_map(|item| item.split_whitespace().last())
                .map(|name| name.rsplit("::").next().unwrap_or(name).to_string())
                .collect::<Vec<_>>()
        } else {
            let end = path.find(';').unwrap_or(path.len());
            let item = &path[..end];
            vec![
                item.split_whitespace()
                    .last()
                    .map(|n| n.rsplit("::").next().unwrap_or(n).to_string())
                    .unwrap_or_default(),
            ]
        };
        for name in names.into_iter().filter(|n| !n.is_empty() && n != "*") {
            exports.insert(name, module.clone());
        }
    }
    exports
}

/// The top-level modules a file names as `crate::x` (and `super::x` at the
/// top level), outside comments: directly, in a use group, or through a
/// name the root re-exports (`exports`).
fn referenced_modules(
    text: &str,
    at_top: bool,
    exports: &BTreeMap<String, String>,
) -> BTreeSet<String> {
    let code = code_of(text);
    let mut found = BTreeSet::new();
    let mut prefixes = vec!["crate::"];
    if at_top {
        prefixes.push("super::");
    }
    let mut note = |name: String| {
        found.insert(exports.get(&name).cloned().unwrap_or(name));
    };
    for prefix in prefixes {
        let mut rest = code.as_str();
        while let Some(at) = rest.find(prefix) {
            let preceded_by_word = rest[..at]
                .chars()
                .next_back()
                .is_some_and(|c| c.is_alphanumeric() || c == '_');
            rest = &rest[at + prefix.len()..];
            if preceded_by_word {
                continue;
            }
            if let Some(group) = rest.strip_prefix('{') {
                let (items, after) = group_items(group);
                items.into_iter().for_each(&mut note);
                rest = after;
                continue;
            }
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                note(name);
            }
        }
    }
    found
}

/// The groups of two or more modules that reach each other.
fn circles(uses: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    let reach = |from: &String| -> BTreeSet<String> {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.clone()];
        while let Some(module) = stack.pop() {
            for next in uses.get(&module).into_iter().flatten() {
                if seen.insert(next.clone()) {
                    stack.push(next.clone());
                }
            }
        }
        seen
    };
    let reached: BTreeMap<&String, BTreeSet<String>> = uses.keys().map(|m| (m, reach(m))).collect();
    let mut grouped = BTreeSet::new();
    let mut groups = Vec::new();
    for module in uses.keys() {
        if grouped.contains(module) {
            continue;
        }
        let group: Vec<String> = uses
            .keys()
            .filter(|other| {
                *other == module
                    || reached[module].contains(*other) && reached[*other].contains(module)
            })
            .cloned()
            .collect();
        if group.len() > 1 {
            grouped.extend(group.iter().cloned());
            groups.push(group);
        }
    }
    groups
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(edges: &[(&str, &str)], nodes: &[&str]) -> BTreeMap<String, BTreeSet<String>> {
        let mut uses: BTreeMap<String, BTreeSet<String>> = nodes
            .iter()
            .map(|n| (n.to_string(), BTreeSet::new()))
            .collect();
        for (a, b) in edges {
            uses.get_mut(*a).map(|s| s.insert(b.to_string()));
        }
        uses
    }

    #[test]
    fn a_chain_has_no_circle_and_a_loop_through_three_is_one() {
        let chain = graph(&[("a", "b"), ("b", "c")], &["a", "b", "c", "d"]);
        assert!(circles(&chain).is_empty());
        let looped = graph(
            &[("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")],
            &["a", "b", "c", "d"],
        );
        assert_eq!(circles(&looped), vec![vec!["a", "b", "c"]]);
        let two = graph(
            &[("a", "b"), ("b", "a"), ("c", "d"), ("d", "c")],
            &["a", "b", "c", "d"],
        );
        assert_eq!(circles(&two).len(), 2);
    }

    #[test]
    fn references_are_read_from_code_not_comments() {
        let text = "use crate::layout::V1;\n// crate::file is only mentioned\nlet x = super::space::f();\nmy_crate::other\n#[cfg(test)]\nmod tests {\n    use crate::tested::T;\n}\n";
        let none = BTreeMap::new();
        let top: Vec<String> = referenced_modules(text, true, &none).into_iter().collect();
        assert_eq!(top, ["layout", "space"]);
        let deep: Vec<String> = referenced_modules(text, false, &none).into_iter().collect();
        assert_eq!(deep, ["layout"]);
    }

    /// The workspace as it stands: no crate has a module circle (what
    /// `cargo xtask crates --check` says, kept by the test suite).
    #[test]
    fn the_workspace_has_no_module_circles() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
        let mut checked = 0;
        for entry in fs::read_dir(root.join("crates")).unwrap() {
            let folder = entry.unwrap().path();
            if !folder.join("Cargo.toml").is_file() {
                continue;
            }
            let report = report(&folder).unwrap();
            assert!(
                report.circles.is_empty(),
                "{}: {:?}",
                report.package,
                report.circles
            );
            checked += 1;
        }
        assert!(checked > 10, "{checked} crates");
    }

    /// A name the root re-exports leads to its module, also inside a use
    /// group that spans lines.
    #[test]
    fn names_the_root_reexports_lead_to_their_modules() {
        let root = "mod config;\npub use transform::{SignalTransform, Transformed as Shaped};\npub use arx::Arx;\n// pub use gone::Gone;\n";
        let exports = root_exports(root);
        assert_eq!(exports.get("Shaped").map(String::as_str), Some("transform"));
        assert_eq!(
            exports.get("SignalTransform").map(String::as_str),
            Some("transform")
        );
        assert_eq!(exports.get("Arx").map(String::as_str), Some("arx"));
        assert!(!exports.contains_key("Gone"));
        let text = "use crate::error::Result;\nuse crate::{\n    Arx, Compressor,\n    Shaped, error::{A, B},\n};\n";
        let found: Vec<String> = referenced_modules(text, false, &exports)
            .into_iter()
            .collect();
        assert_eq!(found, ["Compressor", "arx", "error", "transform"]);
    }
}
