//! A study file as a run uses it: its text and its hash (recorded with every session), the
//! checked definition, and the copy kept with its results.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use codecs::codec::external::Definition;
use protocols::StudyDefinition;
use protocols::study::content_hash;
use results::store::write_new;

use crate::catalog::Codecs;
use crate::error::{Context as _, Result, refused};

/// The name of the study copy inside a results directory.
pub const STUDY_COPY: &str = "study.toml";
/// The name of the stimulus manifest copy inside a results directory.
pub const MANIFEST_COPY: &str = "stimuli.json";

/// A loaded study file.
#[derive(Debug, Clone)]
pub struct StudyFile {
    /// Where it was read from.
    pub path: PathBuf,
    /// Its text, as read once: what the definition, the hash and the archived copy come from.
    pub text: String,
    /// [`content_hash`] of the text.
    pub hash: String,
    /// [`content_hash`] of the stimulus manifest as the definition holds it (its JSON), so a
    /// re-made stimulus set under an unchanged study file is told apart.
    pub manifest_hash: String,
    /// The checked definition.
    pub definition: StudyDefinition,
    /// The command-defined codecs its `[staircase.live] codecs` file defines, read once when
    /// the study was loaded and checked against them (empty without the key).
    pub external_codecs: Vec<Arc<Definition>>,
}

/// The codecs a study file at `path` is checked against: the built-in ones, and those of the
/// command-defined codecs file its `[staircase.live] codecs` names. A file that does not parse
/// gets the built-in ones (the study's own check then says what is wrong with it).
///
/// # Errors
/// The codec definitions file cannot be read or has problems: a study problem keyed
/// `staircase.live.codecs`.
fn study_codecs(path: &Path) -> Result<Codecs> {
    let Ok(text) = fs::read_to_string(path) else {
        return Ok(Codecs::default());
    };
    let Ok(table) = text.parse::<toml::Table>() else {
        return Ok(Codecs::default());
    };
    let file = table
        .get("staircase")
        .and_then(|s| s.get("live"))
        .and_then(|l| l.get("codecs"))
        .and_then(toml::Value::as_str);
    match file {
        None => Ok(Codecs::default()),
        Some(f) => {
            let dir = path.parent().unwrap_or(Path::new("."));
            Codecs::with_files(None, Some(&dir.join(f))).map_err(|e| {
                protocols::StudyError::Invalid {
                    path: path.to_path_buf(),
                    issues: vec![protocols::StudyIssue {
                        key: "staircase.live.codecs".into(),
                        reason: crate::error::chain(&e),
                        line: None,
                    }],
                }
                .into()
            })
        }
    }
}

impl StudyFile {
    /// Reads and checks the study file at `path` and its stimulus manifest, the codec settings
    /// against the codec registry included: every problem comes back in one
    /// [`protocols::StudyError`].
    ///
    /// # Errors
    /// The study's problems (an unreadable file among them).
    pub fn load(path: &Path) -> Result<StudyFile> {
        let codecs = study_codecs(path)?;
        let (definition, text) = StudyDefinition::load_text(path, &codecs)?;
        Ok(StudyFile {
            external_codecs: codecs.context().external.clone(),
            path: path.to_path_buf(),
            hash: content_hash(text.as_bytes()),
            manifest_hash: content_hash(&serde_json::to_vec(&definition.manifest)?),
            text,
            definition,
        })
    }

    /// The folder the study's relative paths start from.
    pub fn dir(&self) -> &Path {
        self.path.parent().unwrap_or(Path::new("."))
    }

    /// The stimulus manifest's folder (its file paths are relative to it).
    pub fn manifest_dir(&self) -> PathBuf {
        let manifest = self.dir().join(&self.definition.stimuli_path);
        manifest
            .parent()
            .map_or_else(|| self.dir().to_path_buf(), Path::to_path_buf)
    }

    /// Keeps the study file and its stimulus manifest inside the results directory `out`, so
    /// that the folder is self-contained: a report finds both without the original files, and
    /// a lab can archive one folder. The copy's `stimuli` key is pointed at the manifest copy,
    /// whose file paths are made absolute. A copy already there is kept.
    ///
    /// # Errors
    /// A manifest copy differs from this manifest, or the copies cannot be written.
    pub fn archive(&self, out: &Path) -> Result<()> {
        let copy = out.join(STUDY_COPY);
        if copy.exists() {
            return Ok(());
        }
        let (study_copy, manifest_bytes) = self.archive_copies()?;
        // A run killed between the two copies left a complete manifest copy (write_new is
        // atomic) but no study copy: keep an identical one instead of refusing the resume.
        let manifest_copy = out.join(MANIFEST_COPY);
        match fs::read(&manifest_copy) {
            Ok(existing) if existing == manifest_bytes => {}
            Ok(_) => {
                return Err(refused(format!(
                    "{} exists and differs from the manifest of {}; results are never overwritten",
                    manifest_copy.display(),
                    self.path.display()
                )));
            }
            Err(_) => write_new(&manifest_copy, &manifest_bytes)?,
        }
        write_new(&copy, &study_copy)
            .context(|| format!("keeping a copy of {}", self.path.display()))?;
        Ok(())
    }

    /// The copies [`Self::archive`] keeps (`study.toml`, `stimuli.json`), as bytes: a
    /// database keeps them with its run.
    ///
    /// # Errors
    /// The study file no longer parses as TOML, or the copy cannot be written as TOML.
    pub fn archive_copies(&self) -> Result<(Vec<u8>, Vec<u8>)> {
        let original = &self.path;
        let mut table: toml::Table = self.text.parse().map_err(|e: toml::de::Error| {
            refused(format!("re-reading {}: {e}", original.display()))
        })?;
        // The manifest's file paths are relative to its own folder: make them absolute in the
        // copy so they still name the clips from inside the results directory.
        let base = self.dir();
        let manifest_dir = table
            .get("stimuli")
            .and_then(toml::Value::as_str)
            .map(|m| base.join(m))
            .and_then(|m| m.parent().map(Path::to_path_buf))
            .unwrap_or_else(|| base.to_path_buf());
        let manifest_dir = fs::canonicalize(&manifest_dir).unwrap_or(manifest_dir);
        let mut manifest = self.definition.manifest.clone();
        let absolute = |p: &str| manifest_dir.join(p).display().to_string();
        for st in &mut manifest.stimuli {
            st.file = absolute(&st.file);
            st.skeleton = st.skeleton.as_deref().map(absolute);
            st.bitstream = st.bitstream.as_deref().map(absolute);
        }
        table.insert("stimuli".into(), toml::Value::String(MANIFEST_COPY.into()));
        // A live staircase's decoder context and codec definitions are named relative to the
        // study file: point the copy at the originals so the copy still loads them.
        if let Some(live) = table
            .get_mut("staircase")
            .and_then(|s| s.get_mut("live"))
            .and_then(toml::Value::as_table_mut)
        {
            for key in ["database", "codecs"] {
                if let Some(toml::Value::String(file)) = live.get_mut(key) {
                    let p = base.join(file.as_str());
                    *file = fs::canonicalize(&p).unwrap_or(p).display().to_string();
                }
            }
        }
        let body =
            toml::to_string(&table).map_err(|e| refused(format!("writing the study copy: {e}")))?;
        let header = format!(
            "# Copy of {} kept with its results; `stimuli` points at the manifest copy beside it.\n",
            original.display()
        );
        Ok((
            format!("{header}{body}").into_bytes(),
            serde_json::to_vec_pretty(&manifest)?,
        ))
    }
}
