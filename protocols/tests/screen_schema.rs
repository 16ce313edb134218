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
    assert_eq!(top.len(), 6, "{top:?}");
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

/// A crowd study's screens place every character of its `[scene]` as the study file says
/// (read here with the toml crate, not the study parser): the camera and light of the file,
/// each character at its `x_cm` and at its distance on the pane's level, performing the
/// stimulus the manifest's scene names for it, in the reference scene and in the compressed
/// one.
#[test]
fn crowd_screens_place_the_scene_the_study_file_describes() {
    use protocols::screen::PaneContent;
    let path = repo().join("examples/crowd-run1.toml");
    let file: toml::Table = std::fs::read_to_string(&path).unwrap().parse().unwrap();
    let scene = file["scene"].as_table().unwrap();
    let num = |v: &toml::Value| v.as_float().or(v.as_integer().map(|i| i as f64)).unwrap();
    let levels: Vec<&str> = scene["levels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_str().unwrap())
        .collect();
    let study = StudyDefinition::load(&path, &common::TestCodecs).unwrap();
    let trials = study.method().plan(&study, 0);
    assert!(trials.len() >= 12);
    for trial in &trials {
        let screen = Screen::of(&study, trial, 2.0);
        assert_eq!(screen.panes.len(), 2);
        for pane in &screen.panes {
            let PaneContent::CrowdScene(crowd) = &pane.content else {
                panic!("{}: not a crowd scene", pane.stimulus)
            };
            let level = levels.iter().position(|l| *l == crowd.level).unwrap();
            let same = |a: f64, b: f64| (a - b).abs() < 1e-12;
            assert!(same(
                crowd.camera.height_cm,
                num(&scene["camera"]["height_cm"])
            ));
            assert!(same(
                crowd.camera.pitch_deg,
                num(&scene["camera"]["pitch_deg"])
            ));
            assert!(same(
                crowd.light.azimuth_deg,
                num(&scene["light"]["azimuth_deg"])
            ));
            let characters = scene["characters"].as_array().unwrap();
            assert_eq!(crowd.characters.len(), characters.len());
            let members = &study.manifest.get(&pane.stimulus).unwrap().scene;
            let members = &members.as_ref().unwrap().characters;
            for ((c, want), member) in crowd.characters.iter().zip(characters).zip(members) {
                assert_eq!(c.name, want["name"].as_str().unwrap());
                assert!(same(c.x_cm, num(&want["x_cm"])), "{}", c.name);
                let distance = match &want["distance_cm"] {
                    toml::Value::Array(d) => num(&d[level]),
                    d => num(d),
                };
                assert!(
                    same(c.distance_cm, distance),
                    "{} on {}",
                    c.name,
                    crowd.level
                );
                assert_eq!(c.stimulus, member.stimulus);
                // The compressed scene's characters are compressed versions, the reference
                // scene's the clips themselves.
                assert_eq!(
                    pane.reference,
                    study.manifest.get(&c.stimulus).unwrap().codec == "reference",
                    "{}",
                    c.stimulus
                );
            }
        }
    }
}
