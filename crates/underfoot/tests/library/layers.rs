//! The crate's layers, checked against its code.
//!
//! The module table in `lib.rs` is the one statement of the dependency order: reading it
//! row by row, left to right, gives every top-level module a rank, and a module may use
//! only modules of a lower rank. This test reads that table, then every `crate::` path in
//! the code (comments aside, `use crate::{a, b::c}` groups included), and fails on any
//! edge that points up the stack. It also checks that the README's layout table lists the
//! library's modules in the same order, so the three cannot drift apart.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The modules of `lib.rs`'s layer table, in order.
fn layer_order() -> Vec<String> {
    let lib = fs::read_to_string(crate_dir().join("src/lib.rs")).unwrap();
    let mut order = Vec::new();
    for line in lib.lines() {
        let Some(row) = line.strip_prefix("//! | ") else {
            continue;
        };
        let cells: Vec<&str> = row.split(" | ").collect();
        if cells.len() < 3 || cells[0].trim().parse::<usize>().is_err() {
            continue;
        }
        for name in cells[1].split(',') {
            let name = name.trim().trim_start_matches("[`").trim_end_matches("`]");
            assert!(
                !name.is_empty() && name.chars().all(|c| c.is_ascii_lowercase() || c == '_'),
                "layer table cell {:?} is not a list of [`module`] links",
                cells[1]
            );
            order.push(name.to_string());
        }
    }
    assert!(order.len() > 10, "no layer table found in lib.rs");
    order
}

/// Every `.rs` file under `dir`.
fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The code of a file without its comments (line, doc and block comments) and string
/// literals, so that a `crate::` path in a doc link or a message is not an edge.
fn code_only(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = String::with_capacity(text.len());
    let mut i = 0;
    let mut block = 0usize;
    while i < b.len() {
        if block > 0 {
            if b[i..].starts_with(b"*/") {
                block -= 1;
                i += 2;
            } else if b[i..].starts_with(b"/*") {
                block += 1;
                i += 2;
            } else {
                i += 1;
            }
            continue;
        }
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            block = 1;
            i += 2;
        } else if b[i] == b'"' {
            // A string literal (raw strings in this crate hold no `crate::`).
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("\"\"");
        } else if b[i] == b'\'' && i + 2 < b.len() && (b[i + 2] == b'\'' || b[i + 1] == b'\\') {
            // A character literal ('"' would otherwise open a string).
            let end = b[i + 1..]
                .iter()
                .position(|&c| c == b'\'')
                .map_or(b.len(), |p| i + 2 + p);
            i = end;
            out.push_str("' '");
        } else {
            out.push(char::from(b[i]));
            i += 1;
        }
    }
    out
}

/// The top-level modules a piece of code names through `crate::`.
fn crate_edges(code: &str) -> Vec<String> {
    let mut found = Vec::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        let before = rest[..at].chars().last();
        rest = &rest[at + "crate::".len()..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue; // `underfoot_crate::` or the like
        }
        if let Some(group) = rest.strip_prefix('{') {
            // `crate::{a::b, c, d::{e, f}}`: the first segment of every top-level item.
            let mut depth = 0;
            let mut item_start = true;
            for (k, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => {
                        rest = &group[k..];
                        break;
                    }
                    '}' => depth -= 1,
                    ',' if depth == 0 => item_start = true,
                    c if item_start && (c.is_alphanumeric() || c == '_') => {
                        let name: String = group[k..]
                            .chars()
                            .take_while(|c| c.is_alphanumeric() || *c == '_')
                            .collect();
                        found.push(name);
                        item_start = false;
                    }
                    _ => {}
                }
            }
        } else {
            let name: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            found.push(name);
        }
    }
    found
}

#[test]
fn no_crate_path_points_up_the_stack() {
    let order = layer_order();
    let rank: BTreeMap<&str, usize> = order
        .iter()
        .enumerate()
        .map(|(i, m)| (m.as_str(), i))
        .collect();
    let src = crate_dir().join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    files.sort();
    let mut violations = Vec::new();
    let mut edges = 0;
    for file in &files {
        let rel = file.strip_prefix(&src).unwrap();
        let top = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_str()
            .unwrap()
            .trim_end_matches(".rs")
            .to_string();
        if top == "lib" {
            continue;
        }
        let Some(&own) = rank.get(top.as_str()) else {
            violations.push(format!(
                "{}: module `{top}` is not in lib.rs's layer table",
                rel.display()
            ));
            continue;
        };
        let code = code_only(&fs::read_to_string(file).unwrap());
        for dep in crate_edges(&code) {
            if dep == top {
                continue;
            }
            edges += 1;
            match rank.get(dep.as_str()) {
                Some(&r) if r < own => {}
                Some(_) => violations.push(format!(
                    "{}: `{top}` uses `crate::{dep}`, which is not below it in lib.rs's table",
                    rel.display()
                )),
                None => violations.push(format!(
                    "{}: `crate::{dep}` is not a module of lib.rs's table",
                    rel.display()
                )),
            }
        }
    }
    assert!(
        edges > 100,
        "only {edges} crate:: edges found: is the scan broken?"
    );
    assert!(
        violations.is_empty(),
        "{} upward edge(s):\n{}",
        violations.len(),
        violations.join("\n")
    );
}

#[test]
fn every_module_of_lib_rs_is_in_the_table_and_the_readme_agrees() {
    let order = layer_order();
    let lib = fs::read_to_string(crate_dir().join("src/lib.rs")).unwrap();
    let declared: Vec<&str> = lib
        .lines()
        .filter_map(|l| l.trim().strip_prefix("pub mod "))
        .map(|l| l.trim_end_matches(';'))
        .collect();
    for m in &declared {
        assert!(
            order.iter().any(|o| o == m),
            "`pub mod {m}` is missing from the layer table"
        );
    }
    for m in &order {
        assert!(
            declared.contains(&m.as_str()),
            "the layer table names `{m}`, which lib.rs does not declare"
        );
    }
    // The README's layout table names the library's folders and files in the same order.
    let readme = fs::read_to_string(crate_dir().join("../../README.md")).unwrap();
    let mut listed: Vec<String> = Vec::new();
    for row in readme
        .lines()
        .filter(|l| l.starts_with("| `crates/underfoot/src/"))
    {
        let cell = row.split(" | ").next().unwrap();
        for path in cell.split('`').skip(1).step_by(2) {
            let name: String = path
                .trim_start_matches("crates/underfoot/src/")
                .chars()
                .take_while(|c| c.is_ascii_lowercase() || *c == '_')
                .collect();
            if !name.is_empty() && name != "lib" {
                listed.push(name);
            }
        }
    }
    let expected: Vec<String> = order
        .iter()
        .filter(|m| listed.contains(m))
        .cloned()
        .collect();
    assert_eq!(
        listed, expected,
        "the README's layout table is not in lib.rs's layer order"
    );
    let missing: Vec<&String> = order
        .iter()
        .filter(|m| !listed.contains(m) && m.as_str() != "fuzzing")
        .collect();
    assert!(
        missing.is_empty(),
        "the README's layout table leaves out {missing:?}"
    );
}

#[test]
fn the_scanner_sees_groups_and_ignores_comments() {
    let code = code_only(
        "use crate::{a::b, c, d::{e, f}};\n// crate::x\n/* crate::y */ let s = \"crate::z\";\nlet q = crate::g::h();\nlet c = '\"'; crate::k::l;",
    );
    assert_eq!(crate_edges(&code), ["a", "c", "d", "g", "k"]);
}
