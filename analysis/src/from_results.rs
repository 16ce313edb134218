//! Conversion of the results store's typed trial records (`results::SessionResults`, rows of
//! `protocols::TrialRecord`) into this crate's plain inputs, with errors that name the file,
//! line and column of a record the analysis cannot use.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use protocols::manifest::{REFERENCE_CODEC, StimulusManifest};
use protocols::{Answer, Block, Protocol, TrialRecord};
use results::SessionResults;
use results::store::{SESSION_FILE, TRIALS_FILE};

use crate::bradley_terry::PairChoice;
use crate::crowd::CrowdDesign;
use crate::descriptive::Rating;
use crate::dmos::DscqsPair;
use crate::error::AnalysisError;
use crate::findings::ConditionInfo;
use crate::hashing::FastMap;
use crate::jnd::EncodedLevel;
use crate::psychometric::TwoAfcTrial;
use crate::staircase::{StaircaseStep, StaircaseTrack};
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

struct Interner {
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

    fn id(&mut self, name: &str) -> u32 {
        if let Some(&id) = self.ids.get(name) {
            return id;
        }
        let id = self.names.len() as u32;
        self.ids.insert(name.to_owned(), id);
        self.names.push(name.to_owned());
        id
    }
}

fn bad(
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

fn check_scale(
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
            convert_record(
                record,
                &path,
                index,
                subject,
                &mut self.stimuli,
                &mut self.data,
                &mut self.tracks,
                self.scale,
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
            data.conditions.push(ConditionInfo {
                id: id as u32,
                codec: s.codec.clone(),
                params: s.variant.clone(),
                clip: s.clip.clone(),
                // The nominal (target) ratio groups codecs made for the same rate, as the
                // seeds' tables do ("20:1"); the achieved ratio stands in when there was no
                // target.
                compression_ratio: (!reference).then_some(s.target_cr.unwrap_or(s.achieved_cr)),
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
        if matches!(protocol, Protocol::Mos | Protocol::Acr) {
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

#[expect(
    clippy::too_many_arguments,
    reason = "one record's context; a struct would only rename the same eight values"
)]
fn convert_record(
    record: &TrialRecord,
    path: &Path,
    index: usize,
    subject: u32,
    stimuli: &mut Interner,
    data: &mut StudyData,
    tracks: &mut BTreeMap<(u32, u32, u32), StaircaseTrack>,
    scale: Option<(f64, f64)>,
) -> Result<(), AnalysisError> {
    match record.protocol {
        // A MUSHRA row rates one pane: a test condition, the hidden reference or the anchor.
        Protocol::Mos | Protocol::Acr | Protocol::Dcr | Protocol::Mushra => {
            let Answer::Rating(score) = record.response.answer else {
                return Err(bad(
                    path,
                    index,
                    "response",
                    format!("a {} trial needs one rating", record.protocol),
                ));
            };
            check_scale(path, index, "score", score, scale)?;
            let condition = stimuli.id(&record.trial.stimulus);
            data.ratings.push(Rating {
                subject,
                condition,
                score,
            });
        }
        Protocol::Dscqs => {
            let reference_score = record
                .outcome
                .score_reference
                .ok_or_else(|| bad(path, index, "score_reference", "missing"))?;
            let test_score = record
                .outcome
                .score_test
                .ok_or_else(|| bad(path, index, "score_test", "missing"))?;
            check_scale(path, index, "score_reference", reference_score, scale)?;
            check_scale(path, index, "score_test", test_score, scale)?;
            let condition = stimuli.id(&record.trial.stimulus);
            data.dscqs.push(DscqsPair {
                subject,
                condition,
                reference_score,
                test_score,
            });
            // The absolute test ratings also give a MOS table, screening and repeats.
            data.ratings.push(Rating {
                subject,
                condition,
                score: test_score,
            });
        }
        Protocol::PairComparison => {
            let choice = pair_choice(record, path, index, subject, stimuli)?;
            data.pair_choices.push(choice);
        }
        Protocol::Staircase => {
            let staircase = record
                .trial
                .staircase
                .ok_or_else(|| bad(path, index, "staircase", "missing staircase index"))?;
            // Logs written before the exact level grid hold accumulated levels
            // (0.003999999999999993 beside 0.004): every table keys them on the grid.
            let level = record
                .trial
                .level
                .map(protocols::staircase::canonical_level)
                .ok_or_else(|| bad(path, index, "level", "missing staircase level"))?;
            if !level.is_finite() {
                return Err(bad(
                    path,
                    index,
                    "level",
                    format!("level {level} is not finite"),
                ));
            }
            let correct = record
                .outcome
                .correct
                .ok_or_else(|| bad(path, index, "correct", "missing"))?;
            // A QUEST+ or Psi trial logs no reversal flag (an up-down staircase's always
            // does).
            let track = tracks
                .entry((subject, record.session, staircase))
                .or_insert_with(|| StaircaseTrack {
                    subject,
                    label: record.trial.condition.clone(),
                    steps: Vec::new(),
                    bayesian: record.outcome.reversal.is_none(),
                    logged_threshold: None,
                });
            track.bayesian &= record.outcome.reversal.is_none();
            track.steps.push(StaircaseStep {
                level,
                correct,
                reversal: record.outcome.reversal.unwrap_or(false),
            });
            data.two_afc.push(TwoAfcTrial { level, correct });
        }
    }
    Ok(())
}

/// A pair comparison row as the choice it logs: the `reference` column holds the pair's
/// other test stimulus, shown at the reference position.
fn pair_choice(
    record: &TrialRecord,
    path: &Path,
    index: usize,
    subject: u32,
    stimuli: &mut Interner,
) -> Result<PairChoice, AnalysisError> {
    let t = &record.trial;
    let choice = match record.response.answer {
        Answer::Choice(p) if p.fits(t.arrangement) => p,
        other => {
            return Err(bad(
                path,
                index,
                "response",
                format!(
                    "a pair_comparison trial needs a position of arrangement {}, got {other:?}",
                    t.arrangement
                ),
            ));
        }
    };
    let (a, b) = (stimuli.id(&t.stimulus), stimuli.id(&t.reference));
    let (winner, loser) = if choice == t.reference_position {
        (b, a)
    } else {
        (a, b)
    };
    Ok(PairChoice {
        subject,
        winner,
        loser,
    })
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
        (s.achieved_cr, s.metrics.map(|m| m.rms_cm))
    };
    Some(EncodedLevel {
        clip,
        level,
        achieved_cr,
        rms_cm,
    })
}
