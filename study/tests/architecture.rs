//! The dependency rules of ARCHITECTURE.md, checked against `cargo metadata`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

const GUI: &[&str] = &[
    "winit",
    "wgpu",
    "egui",
    "eframe",
    "egui-wgpu",
    "egui_wgpu",
    "egui-winit",
    "egui_winit",
    "egui_kittest",
    "glow",
    "glutin",
];

struct Rule {
    allowed: BTreeSet<String>,
    forbidden: BTreeSet<String>,
}

fn names(cell: &str) -> Vec<String> {
    cell.split(',')
        .map(|s| s.trim().trim_matches('`').to_string())
        .filter(|s| !s.is_empty() && s != "—" && s != "-")
        .collect()
}

/// Parses the crate table of ARCHITECTURE.md.
fn rules(text: &str) -> BTreeMap<String, Rule> {
    let mut out = BTreeMap::new();
    let mut in_table = false;
    for line in text.lines() {
        if line.starts_with("| crate | job | may depend on | must not depend on |") {
            in_table = true;
            continue;
        }
        if in_table {
            if !line.starts_with('|') {
                break;
            }
            let cells: Vec<&str> = line.trim_matches('|').split('|').collect();
            if cells.len() != 4 || cells[0].contains("---") {
                continue;
            }
            let name = cells[0].trim().trim_matches('`').to_string();
            let mut forbidden = BTreeSet::new();
            for n in names(cells[3]) {
                if n == "GUI" {
                    forbidden.extend(GUI.iter().map(|s| (*s).to_string()));
                } else {
                    forbidden.insert(n);
                }
            }
            out.insert(
                name,
                Rule {
                    allowed: names(cells[2]).into_iter().collect(),
                    forbidden,
                },
            );
        }
    }
    out
}

#[test]
fn crate_dependencies_follow_the_architecture_table() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let table = rules(&std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap());
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(&root)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let packages = meta["packages"].as_array().unwrap();
    let ours: BTreeSet<String> = packages
        .iter()
        .map(|p| p["name"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(
        ours,
        table.keys().cloned().collect(),
        "every crate needs a row in the table"
    );
    let mut problems = Vec::new();
    for p in packages {
        let name = p["name"].as_str().unwrap();
        let rule = &table[name];
        for d in p["dependencies"].as_array().unwrap() {
            let dep = d["name"].as_str().unwrap().to_string();
            if rule.forbidden.contains(&dep) {
                problems.push(format!("{name} depends on {dep}, which the table forbids"));
            }
            if ours.contains(&dep) && !rule.allowed.contains(&dep) {
                problems.push(format!(
                    "{name} depends on workspace crate {dep}, not in its row"
                ));
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn the_rule_parser_sees_a_forbidden_dependency() {
    // The check above must be able to fail: a table that forbids what codecs uses trips it.
    let t = rules(
        "| crate | job | may depend on | must not depend on |\n| --- | --- | --- | --- |\n\
         | `codecs` | x | — | GUI, thiserror |\n",
    );
    assert!(t["codecs"].forbidden.contains("thiserror"));
    assert!(t["codecs"].forbidden.contains("wgpu"));
    assert!(t["codecs"].allowed.is_empty());
}
