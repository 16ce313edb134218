//! The JSON Schema of what a subject sees (`protocols::screen::Screen`) is generated from the
//! Rust types; `docs/screen.schema.json` is that schema, committed for the front ends that
//! are not Rust (the browser page). This test fails when the types change and the file was
//! not regenerated (`SCREEN_SCHEMA_WRITE=1 cargo test -p protocols --test screen_schema`
//! writes it), and checks that a screen of every example study serializes to JSON whose
//! shape the schema names.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

mod common;

use std::path::{Path, PathBuf};

use protocols::StudyDefinition;
use protocols::screen::{Screen, schema};
use serde_json::Value;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn the_committed_schema_is_the_one_the_types_generate() {
    let path = repo().join("docs/screen.schema.json");
    let generated = serde_json::to_string_pretty(&schema()).unwrap() + "\n";
    if std::env::var_os("SCREEN_SCHEMA_WRITE").is_some() {
        std::fs::write(&path, &generated).unwrap();
    }
    let committed =
        std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        committed == generated,
        "{} differs from the schema of protocols::screen::Screen: regenerate it with \
         SCREEN_SCHEMA_WRITE=1 cargo test -p protocols --test screen_schema",
        path.display()
    );
}

/// The properties a schema object requires, following `$ref`s into `$defs`.
fn required<'a>(root: &'a Value, node: &'a Value) -> Vec<&'a str> {
    let node = match node.get("$ref").and_then(Value::as_str) {
        Some(r) => {
            let name = r.rsplit('/').next().unwrap();
            &root["$defs"][name]
        }
        None => node,
    };
    node.get("required")
        .and_then(Value::as_array)
        .map(|a| a.iter().filter_map(Value::as_str).collect())
        .unwrap_or_default()
}

#[test]
fn every_example_screen_has_what_the_schema_requires() {
    let schema = schema();
    let top = required(&schema, &schema);
    assert_eq!(top.len(), 4, "{top:?}");
    let mut seen = 0;
    for entry in std::fs::read_dir(repo().join("examples")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let study = StudyDefinition::load(&path, &common::TestCodecs)
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let Some(trial) = study.method().plan(&study, 0).into_iter().next() else {
            continue;
        };
        let screen = Screen::of(&study, &trial, 2.0);
        let json = serde_json::to_value(&screen).unwrap();
        for key in &top {
            assert!(json.get(key).is_some(), "{}: no {key}", path.display());
        }
        let schedule = required(&schema, &schema["properties"]["schedule"]);
        for key in schedule {
            assert!(
                json["schedule"].get(key).is_some(),
                "{}: schedule has no {key}",
                path.display()
            );
        }
        assert_eq!(json["title"], study.title(), "{}", path.display());
        assert_ne!(
            json["title"],
            study.name,
            "{}: the internal name",
            path.display()
        );
        seen += 1;
    }
    assert!(seen >= 8, "only {seen} example studies planned a trial");
}
