//! Conversion of the results store's typed trial records (`results::SessionResults`, rows of
//! `protocols::TrialRecord`) into this crate's plain inputs, with errors that name the file,
//! line and column of a record the analysis cannot use.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use protocols::manifest::{REFERENCE_CODEC, StimulusManifest};
use protocols::{Block, Protocol, TrialRecord};
use results::SessionResults;
use results::store::{SESSION_FILE, TRIALS_FILE};

use crate::crowd::CrowdDesign;
use crate::error::AnalysisError;
use crate::findings::ConditionInfo;
use crate::hashing::FastMap;
use crate::jnd::EncodedLevel;
use crate::staircase::StaircaseTrack;
use crate::study::StudyData;

/// A results directory turned into analysis inputs.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvertedResults {
    /// The data, with subjects and conditions numbered (the subjects' ids in
    /// [`StudyData::subjects`]).
    pub data: StudyData,
    /// The protocol every session ran.
    pub protocol: Protocol,
    /// Stimulus ids, indexed by the numeric condition id used in `data`.
    pub stimuli: Vec<String>,
}

pub(crate) struct Interner {
    ids: FastMap<String, u32>,
    names: Vec<String>,
}

impl Interner {
    fn new() -> Self {
        Self {
            ids: FastMap::default(),
            names: Vec::new(),
        }
    }

    pub(crate) fn id(&mut self, name: &str) -> u32 {
        if let Some(&id) = self.ids.get(name) {
            return id;
        }
        let id = self.names.len() as u32;
        self.ids.insert(name.to_owned(), id);
        self.names.push(name.to_owned());
        id
    }
}

pub(crate) fn bad(
    path: &Path,
    index: usize,
    column: &'static str,
    message: impl Into<String>,
) -> AnalysisError {
    // Row i of `records` is line i + 2 of trials.csv (line 1 is the header).
    AnalysisError::BadRecord {
        path: path.to_path_buf(),
        line: index + 2,
        column,
        message: message.into(),
    }
}

pub(crate) fn check_scale(
    path: &Path,
    index: usize,
    column: &'static str,
    v: f64,
    scale: Option<(f64, f64)>,
) -> Result<(), AnalysisError> {
    if !v.is_finite() {
        return Err(bad(path, index, column, format!("score {v} is not finite")));
    }
    if let Some((lo, hi)) = scale
        && (v < lo || v > hi)
    {
        return Err(bad(
            path,
            index,
            column,
            format!("score {v} is outside the scale [{lo}, {hi}]"),
        ));
    }
    Ok(())
}

/// One trial row of a session, where it is, and the study's scale (min, max) its scores must
/// lie on.
pub(crate) struct Row<'a> {
    pub(crate) record: &'a TrialRecord,
    pub(crate) path: &'a Path,
    /// Its place among the session's rows (line `index + 2` of `trials.csv`).
    pub(crate) index: usize,
    pub(crate) subject: u32,
    pub(crate) scale: Option<(f64, f64)>,
}

/// What the rows convert into: the stimuli by id, the analysis inputs, the staircases.
pub(crate) struct Inputs<'a> {
    pub(crate) stimuli: &'a mut Interner,
    pub(crate) data: &'a mut StudyData,
    pub(crate) tracks: &'a mut BTreeMap<(u32, u32, u32), StaircaseTrack>,
}

/// Converts every session of a results directory. Familiarization trials are dropped; hidden
/// repeats are kept as repeated ratings. `scale` (min, max) rejects scores outside the study's
/// rating scale. Stimuli rated as tests whose clip's reference was also rated (a hidden
/// reference) get an ACR-HR mapping in `reference_of`. A condition's compression ratio is the
/// stimulus' target ratio when it has one, else the achieved ratio. Staircase trials also
/// give the compression ratio reached at their level (`encoded_levels`), from the row's
/// encoding columns (live staircase) or the manifest.
///
/// # Errors
/// [`AnalysisError::MixedProtocols`] when sessions ran different protocols;
/// [`AnalysisError::BadRecord`] naming `trials.csv`, line and column for a record whose answer
/// does not fit its protocol, a missing staircase level, a score outside the scale, or a
/// stimulus missing from the manifest.
pub fn convert(
    sessions: &[SessionResults],
    manifest: &StimulusManifest,
    scale: Option<(f64, f64)>,
) -> Result<ConvertedResults, AnalysisError> {
    let mut converter = Converter::new(manifest, scale);
    for session in sessions {
        converter.add(session)?;
    }
    converter.finish()
}

/// [`convert`] one session at a time: a reader that reads, adds and drops each session holds
/// the plain analysis inputs of all of them, but the trial records of one only.
pub struct Converter<'a> {
    manifest: &'a StimulusManifest,
    scale: Option<(f64, f64)>,
    protocol: Option<Protocol>,
    subjects: Interner,
    stimuli: Interner,
    data: StudyData,
    tracks: BTreeMap<(u32, u32, u32), StaircaseTrack>,
}

impl<'a> Converter<'a> {
    /// A converter for sessions rated against `manifest` on `scale`.
    #[must_use]
    pub fn new(manifest: &'a StimulusManifest, scale: Option<(f64, f64)>) -> Self {
        Self {
            manifest,
            scale,
            protocol: None,
            subjects: Interner::new(),
            stimuli: Interner::new(),
            data: StudyData::default(),
            tracks: BTreeMap::new(),
        }
    }

    /// Adds one session's records.
    ///
    /// # Errors
    /// As [`convert`], for this session.
    pub fn add(&mut self, session: &SessionResults) -> Result<(), AnalysisError> {
        let protocol = *self.protocol.get_or_insert(session.manifest.protocol);
        if session.manifest.protocol != protocol {
            return Err(AnalysisError::MixedProtocols {
                path: session.dir.join(SESSION_FILE),
                expected: protocol.as_str().to_owned(),
                found: session.manifest.protocol.as_str().to_owned(),
            });
        }
        let path: PathBuf = session.dir.join(TRIALS_FILE);
        let subject = self.subjects.id(&session.manifest.subject);
        for (index, record) in session.trials.records.iter().enumerate() {
            if record.protocol != protocol {
                return Err(bad(
                    &path,
                    index,
                    "protocol",
                    format!("{} row in a {} study", record.protocol, protocol),
                ));
            }
            if record.trial.block == Block::Familiarization {
                continue;
            }
            let row = Row {
                record,
                path: &path,
                index,
                subject,
                scale: self.scale,
            };
            crate::methods::of(record.protocol).add(
                &row,
                &mut Inputs {
                    stimuli: &mut self.stimuli,
                    data: &mut self.data,
                    tracks: &mut self.tracks,
                },
            )?;
            if let Some(e) = encoded_level(record, self.manifest) {
                self.data.encoded_levels.push(e);
            }
        }
        // The session's own threshold of each of its tracks, by name.
        for ((s, n, _), track) in self
            .tracks
            .range_mut((subject, session.manifest.session, 0)..)
        {
            if (*s, *n) != (subject, session.manifest.session) {
                break;
            }
            track.logged_threshold = session
                .manifest
                .thresholds
                .iter()
                .find(|(name, _)| *name == track.label)
                .and_then(|(_, t)| *t);
        }
        Ok(())
    }

    /// The analysis inputs of every session added.
    ///
    /// # Errors
    /// No session added ([`AnalysisError::TooFew`]), or a rated stimulus missing from the
    /// manifest.
    pub fn finish(self) -> Result<ConvertedResults, AnalysisError> {
        let Self {
            manifest,
            protocol,
            subjects,
            stimuli,
            mut data,
            tracks,
            ..
        } = self;
        let Some(protocol) = protocol else {
            return Err(AnalysisError::TooFew {
                what: "sessions in the results directory",
                needed: 1,
                got: 0,
            });
        };
        data.protocol = Some(protocol);
        for (id, name) in stimuli.names.iter().enumerate() {
            let Some(s) = manifest.get(name) else {
                return Err(AnalysisError::BadRecord {
                    path: PathBuf::from("stimuli.json"),
                    line: 0,
                    column: "stimulus",
                    message: format!(
                        "stimulus {name:?} rated in the results is not in the stimulus manifest"
                    ),
                });
            };
            let reference = s.codec == REFERENCE_CODEC;
            // The study loader refuses a shown stimulus of unknown CR; a results folder whose
            // manifest copy has one cannot be placed on any rate axis.
            let compression_ratio = if reference {
                None
            } else {
                Some(s.target_cr.or(s.achieved_cr).ok_or_else(|| AnalysisError::BadRecord {
                    path: PathBuf::from("stimuli.json"),
                    line: 0,
                    column: "achieved_cr",
                    message: format!(
                        "stimulus {name:?} is rated in the results but its compression ratio is unknown"
                    ),
                })?)
            };
            data.conditions.push(ConditionInfo {
                id: id as u32,
                codec: s.codec.clone(),
                params: s.variant.clone(),
                clip: s.clip.clone(),
                // The nominal (target) ratio groups codecs made for the same rate, as the
                // seeds' tables do ("20:1"); the achieved ratio stands in when there was no
                // target.
                compression_ratio,
            });
        }
        // Crowd scenes (thesis 6.5): a scene's ratio on the rate curves is that of the
        // characters the study varies (the back ones).
        let rated: Vec<(u32, &str)> = stimuli
            .names
            .iter()
            .enumerate()
            .map(|(id, s)| (id as u32, s.as_str()))
            .collect();
        data.crowd = CrowdDesign::from_manifest(&rated, manifest);
        if let Some(crowd) = &data.crowd {
            for c in &crowd.conditions {
                if let Some(info) = data.conditions.iter_mut().find(|i| i.id == c.condition) {
                    info.compression_ratio = Some(c.x);
                }
            }
        }
        // A test whose clip's reference was rated as a condition too (P.910 ACR-HR; a MOS
        // study with hidden references) gets its DMOS against that reference.
        if crate::methods::of(protocol).dmos_against_hidden_reference() {
            for c in &data.conditions {
                if c.compression_ratio.is_some()
                    && let Some(r) = manifest.reference_of(&c.clip)
                    && let Some(&rid) = stimuli.ids.get(&r.id)
                {
                    data.reference_of.insert(c.id, rid);
                }
            }
        }
        data.staircases = tracks.into_values().collect();
        data.subjects = subjects.names;
        Ok(ConvertedResults {
            data,
            protocol,
            stimuli: stimuli.names,
        })
    }
}

/// The CR (and error) a staircase trial's stimulus reached at its level: logged in the row by
/// a live staircase, else the manifest's for a prepared stimulus. The clip is the reference's.
fn encoded_level(record: &TrialRecord, manifest: &StimulusManifest) -> Option<EncodedLevel> {
    let level = record
        .trial
        .level
        .filter(|l| l.is_finite())
        .map(protocols::staircase::canonical_level)?;
    let clip = manifest
        .get(&record.trial.reference)
        .or_else(|| manifest.get(&record.trial.stimulus))?
        .clip
        .clone();
    let (achieved_cr, rms_cm) = if let Some(e) = &record.encoding {
        (e.achieved_cr, Some(e.rms_cm))
    } else {
        let s = manifest.get(&record.trial.stimulus)?;
        (s.achieved_cr?, s.metrics.map(|m| m.rms_cm))
    };
    Some(EncodedLevel {
        clip,
        level,
        achieved_cr,
        rms_cm,
    })
}
