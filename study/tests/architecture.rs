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

/// The standard output of `cargo ARGS` run in the workspace at `root`, which must succeed.
fn cargo(root: &Path, args: &[&str]) -> Vec<u8> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args(args)
        .current_dir(root)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "cargo {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// `cargo metadata` of the workspace at `root` with `args`, offline.
fn metadata(root: &Path, args: &[&str]) -> serde_json::Value {
    let args = [&["metadata", "--format-version", "1", "--offline"], args].concat();
    serde_json::from_slice(&cargo(root, &args)).unwrap()
}

#[test]
fn crate_dependencies_follow_the_architecture_table() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let table = rules(&std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap());
    let meta = metadata(&root, &["--no-deps"]);
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

/// The platform this test runs on (`rustc -vV`'s host).
fn host() -> String {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let out = Command::new(rustc).arg("-vV").output().unwrap();
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: "))
        .unwrap()
        .to_string()
}

/// Package id → (name, its dependencies' package ids with whether each is a dev-dependency
/// only).
type Graph = BTreeMap<String, (String, Vec<(String, bool)>)>;

/// The full dependency graph on this platform (the crates of other platforms are not
/// downloaded here).
fn graph(root: &Path) -> Graph {
    let meta = metadata(root, &["--locked", "--filter-platform", &host()]);
    let names: BTreeMap<String, String> = meta["packages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["id"].as_str().unwrap().to_string(),
                p["name"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    meta["resolve"]["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| {
            let id = n["id"].as_str().unwrap().to_string();
            let deps = n["deps"]
                .as_array()
                .unwrap()
                .iter()
                .map(|d| {
                    let dev_only = d["dep_kinds"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .all(|k| k["kind"].as_str() == Some("dev"));
                    (d["pkg"].as_str().unwrap().to_string(), dev_only)
                })
                .collect();
            (id.clone(), (names[&id].clone(), deps))
        })
        .collect()
}

/// The chain of crates from `start` to the first crate named in `targets`, if any: the
/// start's own dependencies of every kind, then what those need to build (their
/// dev-dependencies are not built for it).
fn path_to(g: &Graph, start: &str, targets: &BTreeSet<String>) -> Option<Vec<String>> {
    let mut seen = BTreeSet::new();
    let mut queue =
        std::collections::VecDeque::from([(start.to_string(), vec![g[start].0.clone()])]);
    while let Some((id, chain)) = queue.pop_front() {
        for (dep, dev_only) in &g[&id].1 {
            if (*dev_only && id != start) || !seen.insert(dep.clone()) {
                continue;
            }
            let mut next = chain.clone();
            next.push(g[dep].0.clone());
            if targets.contains(&g[dep].0) {
                return Some(next);
            }
            queue.push_back((dep.clone(), next));
        }
    }
    None
}

#[test]
fn no_library_crate_reaches_a_gui_crate_through_any_path() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let g = graph(&root);
    let gui: BTreeSet<String> = GUI.iter().map(|s| (*s).to_string()).collect();
    let table = rules(&std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap());
    let mut problems = Vec::new();
    let mut checked = 0;
    for (id, (name, _)) in &g {
        let Some(rule) = table.get(name) else {
            continue;
        };
        if !rule.forbidden.contains("wgpu") {
            continue;
        }
        checked += 1;
        if let Some(chain) = path_to(&g, id, &gui) {
            problems.push(chain.join(" -> "));
        }
    }
    assert_eq!(
        checked,
        table.len() - 2,
        "every crate but window and study is GUI-free"
    );
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    // The check can fail: study itself reaches the GUI stack.
    let study = g.iter().find(|(_, (n, _))| n == "study").unwrap().0;
    assert!(path_to(&g, study, &gui).is_some());
}

/// The packages `cargo tree -p CRATE` lists for `crate` built on its own (its own features,
/// not the workspace's union), normal and build dependencies.
fn tree(root: &Path, krate: &str) -> BTreeSet<String> {
    let args = [
        "tree",
        "--offline",
        "--locked",
        "-e",
        "normal,build",
        "--prefix",
        "none",
        "--format",
        "{p}",
        "-p",
        krate,
    ];
    String::from_utf8(cargo(root, &args))
        .unwrap()
        .lines()
        .filter_map(|l| l.split_whitespace().next())
        .map(str::to_owned)
        .collect()
}

#[test]
fn the_pure_libraries_compile_no_database_client() {
    // The PostgreSQL store is behind `results`' feature `postgres`, which only the binary
    // (through `lab`'s feature) turns on: the statistics and the protocols build without a
    // database client or an async runtime.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for krate in ["analysis", "protocols", "results", "lab", "report"] {
        let deps = tree(&root, krate);
        assert!(deps.contains(krate), "cargo tree -p {krate} lists {deps:?}");
        for client in ["postgres", "tokio-postgres", "tokio"] {
            assert!(
                !deps.contains(client),
                "cargo tree -p {krate} lists {client}"
            );
        }
    }
    // The check can fail: the binary has the database client.
    assert!(tree(&root, "study").contains("postgres"));
}

#[test]
fn every_file_the_architecture_names_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let text = std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap();
    let mut named = 0;
    for cell in text.split('`').skip(1).step_by(2) {
        let is_path = cell.contains('/')
            && cell
                .split('/')
                .next()
                .is_some_and(|c| root.join(c).join("Cargo.toml").is_file());
        if is_path {
            named += 1;
            assert!(
                root.join(cell).exists(),
                "ARCHITECTURE.md names {cell}, which is not there"
            );
        }
    }
    assert!(named >= 20, "only {named} files named");
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

/// The lines of the Rust files under `dir`, each file with its count.
fn rust_lines(dir: &Path) -> Vec<(String, usize)> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(rust_lines(&path));
        } else if path.extension().is_some_and(|e| e == "rs") {
            let text = std::fs::read_to_string(&path).unwrap();
            out.push((path.display().to_string(), text.lines().count()));
        }
    }
    out
}

#[test]
fn the_binary_stays_thin() {
    // Every command is a short function over the libraries (ARCHITECTURE.md): what a
    // command does beyond parsing its arguments and printing belongs in a library crate,
    // where the window, `study serve` and tests can call it too.
    const MOST: usize = 3_000;
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = rust_lines(&src);
    let total: usize = files.iter().map(|(_, n)| n).sum();
    files.sort_by_key(|(_, n)| std::cmp::Reverse(*n));
    assert!(files.len() >= 10, "{files:?}");
    assert!(
        total <= MOST,
        "study/src has {total} lines (at most {MOST}); the largest: {:?}",
        &files[..3]
    );
}

/// Where production code names a protocol (`Protocol::Mos`, ...) outside the method modules
/// (`protocols/src/methods/`, their analysis in `analysis/src/methods/`) and the enum's own
/// file: each file with its count. Test code
/// (after `#[cfg(test)]`, `*_tests.rs`, `tests/`) is not counted.
fn protocol_names_outside_methods(root: &Path) -> Vec<(String, usize)> {
    const VARIANTS: [&str; 8] = [
        "Mos",
        "Dscqs",
        "Acr",
        "Dcr",
        "PairComparison",
        "Mushra",
        "Staircase",
        "Ccr",
    ];
    let mut out = Vec::new();
    for (path, _) in rust_lines(root)
        .into_iter()
        .filter(|(p, _)| p.contains("/src/") && !p.contains("/target/"))
    {
        let relative = path
            .strip_prefix(&format!("{}/", root.display()))
            .unwrap_or(&path)
            .to_owned();
        if relative.starts_with("protocols/src/methods/")
            || relative.starts_with("analysis/src/methods/")
            || relative == "protocols/src/record.rs"
            || relative.ends_with("_tests.rs")
        {
            continue;
        }
        let text = std::fs::read_to_string(&path).unwrap();
        let production = text.split("#[cfg(test)]").next().unwrap_or_default();
        let count = production
            .match_indices("Protocol::")
            .filter(|(at, _)| {
                let rest = &production[at + "Protocol::".len()..];
                VARIANTS.iter().any(|v| {
                    rest.starts_with(v)
                        && !rest[v.len()..].starts_with(|c: char| c.is_alphanumeric() || c == '_')
                })
            })
            .count();
        if count > 0 {
            out.push((relative, count));
        }
    }
    out.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    out
}

#[test]
fn code_outside_the_method_modules_names_no_protocol() {
    // Issue 35's seam: a method's code lives in its module under protocols/src/methods/,
    // and the rest of the workspace asks the study's method (`study.method()`) instead of
    // matching on the protocol's name; a method's analysis is registered the same way in
    // analysis/src/methods/. Nothing else branches on a name (the browser page draws the
    // Screen it is sent).
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let root = root.canonicalize().unwrap();
    let found = protocol_names_outside_methods(&root);
    assert!(
        found.is_empty(),
        "protocol names outside protocols/src/methods/ and analysis/src/methods/: {found:?}"
    );
    // The count can fail: a name in production code is seen, one in a test module or a
    // longer name is not.
    let scratch = std::env::temp_dir().join(format!("arch-names-{}", std::process::id()));
    std::fs::create_dir_all(scratch.join("x/src")).unwrap();
    std::fs::write(
        scratch.join("x/src/a.rs"),
        "fn f() { Protocol::Mos; Protocol::Mosaic; }\n#[cfg(test)]\nProtocol::Dcr\n",
    )
    .unwrap();
    let seen = protocol_names_outside_methods(&scratch.canonicalize().unwrap());
    std::fs::remove_dir_all(&scratch).unwrap();
    assert_eq!(seen, [("x/src/a.rs".to_owned(), 1)]);
}

/// The participant's page draws the `Screen` it is sent: no script of it names a protocol
/// (as a string the server's JSON would carry: `'mos'`, `"pair_comparison"`, ...).
#[test]
fn the_browser_page_names_no_protocol() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../web/page/src");
    let names = [
        "mos",
        "dscqs",
        "acr",
        "dcr",
        "pair_comparison",
        "mushra",
        "staircase",
        "ccr",
    ];
    let mut scripts = 0;
    for entry in std::fs::read_dir(&root).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "js") {
            continue;
        }
        scripts += 1;
        let text = std::fs::read_to_string(&path).unwrap();
        for name in names {
            for quote in ['\'', '"', '`'] {
                let literal = format!("{quote}{name}{quote}");
                assert!(
                    !text.contains(&literal),
                    "{}: names the protocol {literal}",
                    path.display()
                );
            }
        }
    }
    assert!(scripts >= 4, "the page's scripts in {}", root.display());
}
