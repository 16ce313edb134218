//! A study's results directory: its run manifest (`run.json`), the archived study, and one
//! folder per session. Created on first use, checked on every later one, never overwritten.
//! Or the same as a run of a PostgreSQL database ([`open_database_for_subjects`],
//! [`open_database_for_simulation`]).

use std::fs;
use std::path::{Path, PathBuf};

use results::RunManifest;
use results::backend::{GROUPS_FILE, GROUPS_LOCK_FILE};
#[cfg(feature = "postgres")]
use results::pg::{Archive, Database, PgStore};
use results::store::{
    LOCK_FILE, MANIFEST_FORMAT_VERSION, RUN_FILE, SESSION_FILE, TRIALS_FILE, read_manifest,
    write_json, write_new,
};

use crate::error::{Result, io_error, refused};
use crate::session::{FRAMES_FILE, check_subject, now_ms};
use crate::study::{MANIFEST_COPY, STUDY_COPY, StudyFile};

/// What a run manifest of `study` says before any session: the observers' seed and count
/// (simulation), or none (real subjects).
fn run_manifest(study: &StudyFile, observer_seed: Option<u64>, subjects: u32) -> RunManifest {
    RunManifest {
        format_version: MANIFEST_FORMAT_VERSION,
        study: study.definition.name.clone(),
        study_hash: study.hash.clone(),
        manifest_hash: Some(study.manifest_hash.clone()),
        study_file: STUDY_COPY.into(),
        plan_seed: study.definition.seed,
        observer_seed,
        subjects,
        software_version: env!("CARGO_PKG_VERSION").into(),
        created_ms: now_ms(),
    }
}

/// The participants of a study served to browsers (`study serve`): one row per participant,
/// appended and fsynced before the participant gets their session link.
pub const PARTICIPANTS_FILE: &str = "participants.csv";

/// When a session served to a browser (`study serve`) first sent its pending trial, in the
/// session's folder: a restarted server takes no answer sooner than the stimuli can have
/// played since then.
pub const TRIAL_SENT_FILE: &str = "trial_sent.json";

/// Whether `name` is one of the files a results directory holds beside its sessions, or a
/// temporary file one of its writers left behind.
fn is_results_file(name: &str) -> bool {
    [
        RUN_FILE,
        STUDY_COPY,
        MANIFEST_COPY,
        PARTICIPANTS_FILE,
        GROUPS_FILE,
        GROUPS_LOCK_FILE,
    ]
    .iter()
    .any(|f| {
        name == *f
            || name
                .strip_prefix('.')
                .and_then(|n| n.strip_prefix(*f))
                .is_some_and(|rest| rest.starts_with('.'))
    })
}

/// Whether `dir` looks like a session folder: `<subject>_s<n>`, holding nothing but a
/// session's files.
fn is_session_dir(dir: &Path, name: &str) -> bool {
    let Some((subject, n)) = name.rsplit_once("_s") else {
        return false;
    };
    if check_subject(subject).is_err() || n.parse::<u32>().is_err() {
        return false;
    }
    let Ok(entries) = fs::read_dir(dir) else {
        return false;
    };
    entries.flatten().all(|e| {
        let f = e.file_name().to_string_lossy().into_owned();
        [
            SESSION_FILE,
            TRIALS_FILE,
            LOCK_FILE,
            FRAMES_FILE,
            TRIAL_SENT_FILE,
        ]
        .contains(&f.as_str())
            || f.starts_with("trials.csv.torn-")
            || f.starts_with(&format!(".{TRIAL_SENT_FILE}."))
            || f.starts_with(&format!(".{SESSION_FILE}."))
            || f.starts_with(&format!(".{TRIALS_FILE}."))
    })
}

/// What `out` holds that is not a study's results (up to a few names, for the message).
fn foreign_entries(out: &Path) -> Result<Vec<String>> {
    let mut found = Vec::new();
    for entry in fs::read_dir(out).map_err(io_error(out))? {
        let entry = entry.map_err(io_error(out))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let path = entry.path();
        let ours = if path.is_dir() {
            is_session_dir(&path, &name)
        } else {
            is_results_file(&name)
        };
        if !ours {
            found.push(name);
        }
    }
    found.sort();
    Ok(found)
}

/// Refuses `out` when it holds anything but a study's results, unless `force`.
fn check_only_results(out: &Path, force: bool) -> Result<()> {
    if force || !out.exists() {
        return Ok(());
    }
    let found = foreign_entries(out)?;
    if found.is_empty() {
        return Ok(());
    }
    let shown: Vec<&str> = found.iter().take(5).map(String::as_str).collect();
    Err(refused(format!(
        "{} holds files that are not a study's results ({}{}); choose an empty or new folder, or use --force to add results beside them",
        out.display(),
        shown.join(", "),
        if found.len() > shown.len() {
            format!(" and {} more", found.len() - shown.len())
        } else {
            String::new()
        }
    )))
}

/// Refuses `run` (read from `path`) when it records another study than `study`.
fn check_same_study(path: &Path, run: &RunManifest, study: &StudyFile) -> Result<()> {
    if run.study != study.definition.name {
        return Err(refused(format!(
            "{} holds results of study {:?}; {} is study {:?}",
            path.display(),
            run.study,
            study.path.display(),
            study.definition.name
        )));
    }
    Ok(())
}

/// Checks, writing nothing, that `out` can take a real subject's session of `study`: it is
/// new, empty, or holds this study's results and nothing else (anything else with `force`).
/// Returns its run manifest, if it has one.
///
/// # Errors
/// `out` holds another study or other files, or its run manifest cannot be read.
pub fn check_for_subjects(
    out: &Path,
    study: &StudyFile,
    force: bool,
) -> Result<Option<RunManifest>> {
    check_only_results(out, force)?;
    let run_path = out.join(RUN_FILE);
    if !run_path.exists() {
        return Ok(None);
    }
    let run: RunManifest = read_manifest(&run_path)?;
    check_same_study(&run_path, &run, study)?;
    Ok(Some(run))
}

/// Opens `out` for a real subject's session of `study`: on first use creates it with its run
/// manifest and the archived study; later, checks that it holds this study. A folder that
/// holds anything but this study's results is refused unless `force`. Returns notes for the
/// experimenter (the study file or stimuli changed since the first session).
///
/// # Errors
/// `out` holds another study or other files, or cannot be created or written.
pub fn open_for_subjects(out: &Path, study: &StudyFile, force: bool) -> Result<Vec<String>> {
    let mut notes = Vec::new();
    let run_path = out.join(RUN_FILE);
    if let Some(run) = check_for_subjects(out, study, force)? {
        if run.study_hash != study.hash
            || run
                .manifest_hash
                .as_ref()
                .is_some_and(|h| *h != study.manifest_hash)
        {
            notes.push(format!(
                "note: {} or its stimuli changed since the first session in {} (study hash {} -> {})",
                study.path.display(),
                out.display(),
                run.study_hash,
                study.hash
            ));
        }
    } else {
        fs::create_dir_all(out).map_err(io_error(out))?;
        let run = run_manifest(study, None, 0);
        write_new(&run_path, &serde_json::to_vec_pretty(&run)?)?;
    }
    study.archive(out)?;
    Ok(notes)
}

/// Creates `out` for `subjects` simulated observers of `study` (seed `seed`), or with `resume`
/// checks that an interrupted run there is of this study file and stimuli, with the same
/// seeds and count.
///
/// # Errors
/// `out` exists without `resume`; with it, is missing, holds another study or other files, or
/// was recorded with another study file, stimuli or settings; or cannot be written.
pub fn open_for_simulation(
    out: &Path,
    study: &StudyFile,
    seed: u64,
    subjects: u32,
    resume: bool,
) -> Result<()> {
    let run = run_manifest(study, Some(seed), subjects);
    if resume {
        if !out.is_dir() {
            return Err(refused(format!(
                "{}: no results directory to resume",
                out.display()
            )));
        }
        check_only_results(out, false)?;
        let run_path = out.join(RUN_FILE);
        if run_path.exists() {
            let old: RunManifest = read_manifest(&run_path)?;
            check_same_study(&run_path, &old, study)?;
            if old.study_hash != run.study_hash
                || old.manifest_hash.is_some() && old.manifest_hash != run.manifest_hash
            {
                return Err(refused(format!(
                    "{}: the run was started with another version of {} or its stimuli (study hash {}, now {}); resume with the files it was started with, or start a new run",
                    run_path.display(),
                    study.path.display(),
                    old.study_hash,
                    run.study_hash
                )));
            }
            check_same_settings(&run_path.display().to_string(), &old, &run)?;
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
    Ok(())
}

/// Refuses to continue simulated run `old` (named `what`) with other observer settings than
/// `run`'s.
fn check_same_settings(what: &str, old: &RunManifest, run: &RunManifest) -> Result<()> {
    if old.observer_seed != run.observer_seed
        || old.subjects != run.subjects
        || old.plan_seed != run.plan_seed
    {
        return Err(refused(format!(
            "{what}: recorded with --seed {:?}, {} subjects, study seed {}; resume with the same values",
            old.observer_seed, old.subjects, old.plan_seed
        )));
    }
    Ok(())
}

/// Where a run's results go: a results folder, or a run of a PostgreSQL database (by default
/// named after the study).
#[derive(Debug, Clone)]
pub enum Destination {
    /// A results folder.
    Folder(PathBuf),
    /// A database and the run's name in it (`None`: the study's name).
    #[cfg(feature = "postgres")]
    Database {
        /// The database.
        db: Box<Database>,
        /// The run.
        run: Option<String>,
    },
}

/// The run name `run` asks for, or the study's.
#[cfg(feature = "postgres")]
fn run_name(run: Option<&str>, study: &StudyFile) -> String {
    run.map_or_else(|| study.definition.name.clone(), str::to_owned)
}

#[cfg(feature = "postgres")]
fn archive(study: &StudyFile) -> Result<Archive> {
    let (study_copy, manifest_copy) = study.archive_copies()?;
    Ok(Archive {
        study_copy,
        manifest_copy,
    })
}

/// Opens run `run` (by default the study's name) of `db` for real subjects' sessions of
/// `study`, creating it on first use. Returns the store and notes for the experimenter (the
/// study file or stimuli changed since the run began), as [`open_for_subjects`] does.
///
/// # Errors
/// The run holds another study; database errors.
#[cfg(feature = "postgres")]
pub fn open_database_for_subjects(
    db: &Database,
    run: Option<&str>,
    study: &StudyFile,
) -> Result<(PgStore, Vec<String>)> {
    let name = run_name(run, study);
    let (store, _) =
        PgStore::open_or_create(db, &name, &run_manifest(study, None, 0), &archive(study)?)?;
    let old = store.run();
    let place = format!("{}/{name}", db.shown());
    check_same_study(Path::new(&place), old, study)?;
    let mut notes = Vec::new();
    if old.study_hash != study.hash
        || old
            .manifest_hash
            .as_ref()
            .is_some_and(|h| *h != study.manifest_hash)
    {
        notes.push(format!(
            "note: {} or its stimuli changed since the first session of {place} (study hash {} -> {})",
            study.path.display(),
            old.study_hash,
            study.hash
        ));
    }
    Ok((store, notes))
}

/// Opens run `run` (by default the study's name) of `db` for `subjects` simulated observers
/// of `study` (seed `seed`): created by the first station, joined by the others, which must
/// run the same study file, stimuli, seeds and count.
///
/// # Errors
/// The run holds another study, or was begun with other files or settings; database errors.
#[cfg(feature = "postgres")]
pub fn open_database_for_simulation(
    db: &Database,
    run: Option<&str>,
    study: &StudyFile,
    seed: u64,
    subjects: u32,
) -> Result<PgStore> {
    let name = run_name(run, study);
    let fresh = run_manifest(study, Some(seed), subjects);
    let (store, _) = PgStore::open_or_create(db, &name, &fresh, &archive(study)?)?;
    let old = store.run();
    let place = format!("{}/{name}", db.shown());
    check_same_study(Path::new(&place), old, study)?;
    if old.study_hash != fresh.study_hash
        || old.manifest_hash.is_some() && old.manifest_hash != fresh.manifest_hash
    {
        return Err(refused(format!(
            "{place}: the run was begun with another version of {} or its stimuli (study hash {}, now {}); use those files, or another run (--run)",
            study.path.display(),
            old.study_hash,
            fresh.study_hash
        )));
    }
    check_same_settings(&place, old, &fresh)?;
    Ok(store)
}
