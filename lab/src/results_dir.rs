//! A study's results directory: its run manifest (`run.json`), the archived study, and one
//! folder per session. Created on first use, checked on every later one, never overwritten.

use std::fs;
use std::path::Path;

use results::RunManifest;
use results::store::{MANIFEST_FORMAT_VERSION, RUN_FILE, read_json, write_json, write_new};

use crate::error::{Result, io_error, refused};
use crate::session::now_ms;
use crate::study::{STUDY_COPY, StudyFile};

/// What a run manifest of `study` says before any session: the observers' seed and count
/// (simulation), or none (real subjects).
fn run_manifest(study: &StudyFile, observer_seed: Option<u64>, subjects: u32) -> RunManifest {
    RunManifest {
        format_version: MANIFEST_FORMAT_VERSION,
        study: study.definition.name.clone(),
        study_hash: study.hash.clone(),
        study_file: STUDY_COPY.into(),
        plan_seed: study.definition.seed,
        observer_seed,
        subjects,
        software_version: env!("CARGO_PKG_VERSION").into(),
        created_ms: now_ms(),
    }
}

/// Opens `out` for a real subject's session of `study`: on first use creates it with its run
/// manifest and the archived study; later, checks that it holds this study. Returns notes for
/// the experimenter (the study file changed since the first session).
///
/// # Errors
/// `out` holds another study, or cannot be created or written.
pub fn open_for_subjects(out: &Path, study: &StudyFile) -> Result<Vec<String>> {
    let mut notes = Vec::new();
    if out.join(RUN_FILE).exists() {
        let run: RunManifest = read_json(&out.join(RUN_FILE))?;
        if run.study != study.definition.name {
            return Err(refused(format!(
                "{} holds results of study {:?}, not {:?}",
                out.display(),
                run.study,
                study.definition.name
            )));
        }
        if run.study_hash != study.hash {
            notes.push(format!(
                "note: {} changed since the first session in {} (hash {} -> {})",
                study.path.display(),
                out.display(),
                run.study_hash,
                study.hash
            ));
        }
    } else {
        fs::create_dir_all(out).map_err(io_error(out))?;
        let run = run_manifest(study, None, 0);
        write_new(&out.join(RUN_FILE), &serde_json::to_vec_pretty(&run)?)?;
    }
    study.archive(out)?;
    Ok(notes)
}

/// Creates `out` for `subjects` simulated observers of `study` (seed `seed`), or with `resume`
/// checks that an interrupted run there used the same seeds and count. Returns notes (the
/// study file changed since the run started).
///
/// # Errors
/// `out` exists without `resume`, is missing or was recorded with other settings with it, or
/// cannot be written.
pub fn open_for_simulation(
    out: &Path,
    study: &StudyFile,
    seed: u64,
    subjects: u32,
    resume: bool,
) -> Result<Vec<String>> {
    let run = run_manifest(study, Some(seed), subjects);
    let mut notes = Vec::new();
    if resume {
        if !out.is_dir() {
            return Err(refused(format!(
                "{}: no results directory to resume",
                out.display()
            )));
        }
        let run_path = out.join(RUN_FILE);
        if run_path.exists() {
            let old: RunManifest = read_json(&run_path)?;
            if old.observer_seed != run.observer_seed
                || old.subjects != run.subjects
                || old.plan_seed != run.plan_seed
            {
                return Err(refused(format!(
                    "{}: recorded with --seed {:?}, {} subjects, study seed {}; resume with the same values",
                    run_path.display(),
                    old.observer_seed,
                    old.subjects,
                    old.plan_seed
                )));
            }
            if old.study_hash != run.study_hash {
                notes.push(format!(
                    "note: the study file changed since this run started (hash {} -> {}); logged trials are checked by replay",
                    old.study_hash, run.study_hash
                ));
            }
        } else {
            write_json(&run_path, &run)?;
        }
    } else {
        if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
            fs::create_dir_all(parent).map_err(io_error(parent))?;
        }
        fs::create_dir(out).map_err(|e| {
            if e.kind() == std::io::ErrorKind::AlreadyExists {
                refused(format!(
                    "{} already exists; results are never overwritten (use --resume to continue)",
                    out.display()
                ))
            } else {
                io_error(out)(e)
            }
        })?;
        write_new(&out.join(RUN_FILE), &serde_json::to_vec_pretty(&run)?)?;
    }
    study.archive(out)?;
    Ok(notes)
}
