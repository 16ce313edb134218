//! Live (codec-in-the-loop) staircase stimuli: each trial's distorted clip is the reference
//! encoded and decoded at the trial's level, on demand, cached by (clip, level).
//!
//! The protocol engine only names a live trial's stimulus (`live:<clip>/<codec>/<param>=<level>`,
//! see `protocols::StaircaseStudy::live_stimulus_id`); this module turns that name into clips:
//! it loads each source clip once from the manifest's reference stimulus (ASF + AMC or BVH),
//! encodes it with the study's codec at `param = level` (other parameters fixed by
//! `[staircase.live] params`), decodes it, and measures the compression ratio reached and the
//! joint-position RMS error. Both `study simulate` and the subject window call it, and both log
//! the exact parameters, CR and error in the trial's row.
//!
//! A new level takes as long as the codec needs for the whole clip (the primitive codec: about
//! 90 ms for a 10 s clip), too long to do between the answer and the next trial. The window
//! therefore calls [`LiveStimuli::prefetch`] with the trials a correct and a wrong answer lead
//! to (`protocols::Session::lookahead`) as soon as a trial starts: a background thread encodes
//! them while the subject watches, so after the answer the next stimulus is a cache lookup.
//! A trial whose level is still being encoded waits for that encoding instead of starting
//! another; one that failed in the background is encoded again in the foreground, which
//! reports the error.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;

use codecs::codec::{Codec, CodecContext, Params};
use codecs::primitives::Database;
use motion::Clip;
use protocols::{StaircaseStudy, StimulusEncoding, StudyError, StudyIssue, Trial};

use crate::catalog::Codecs;
use crate::error::{LabError, Result, chain, refused};
use crate::source::{StimulusSource, TrialStimuli};
use crate::stimulus::{self, Request};
use crate::study::StudyFile;

/// The stimuli of one live staircase study: its codec, source clips and a cache of encoded
/// levels, filled on demand or ahead of time by background threads.
pub struct LiveStimuli {
    encoder: Arc<Encoder>,
    cache: Arc<Cache>,
    /// Background encodings started by [`LiveStimuli::prefetch`] (finished ones are pruned).
    workers: Vec<JoinHandle<()>>,
}

/// What encodes a level: the codec, its fixed parameters and the source clips.
struct Encoder {
    staircase: StaircaseStudy,
    codec: Box<dyn Codec>,
    fixed: Params,
    /// (clip name, reference stimulus id, the source clip).
    clips: Vec<(String, String, Arc<Clip>)>,
}

/// A cache key: the clip's index and the level's bits.
type Key = (usize, u64);

/// Encoded levels, and the ones a thread is encoding now.
#[derive(Default)]
struct Cache {
    slots: Mutex<HashMap<Key, Slot>>,
    /// Signalled whenever an encoding ends (stored or failed).
    done: Condvar,
}

enum Slot {
    Encoding,
    Ready(LiveStimulus),
}

/// One trial's stimulus pair with how the distorted clip was made.
#[derive(Debug, Clone)]
pub struct LiveStimulus {
    /// The source clip (shown as the original).
    pub reference: Arc<Clip>,
    /// The decoded clip at the trial's level.
    pub test: Arc<Clip>,
    /// Exact codec parameters of the bitstream, the level's parameter included.
    pub params: BTreeMap<String, f64>,
    /// Compression ratio reached (4 bytes × channels × frames / bitstream bytes).
    pub achieved_cr: f64,
    /// Joint position RMS error of `test` against `reference`, cm.
    pub rms_cm: f64,
}

impl LiveStimulus {
    /// What a trial row logs about this stimulus (`codec_params`, `achieved_cr`, `rms_cm`).
    pub fn encoding(&self) -> StimulusEncoding {
        StimulusEncoding {
            codec_params: self.params.clone(),
            achieved_cr: self.achieved_cr,
            rms_cm: self.rms_cm,
        }
    }
}

impl LiveStimuli {
    /// The live stimuli of `study`, or `None` when the study has no live staircase. Loads
    /// the decoder context and every source clip now, so a missing file stops the session
    /// before its first trial; the study's codec settings were checked when it was loaded.
    ///
    /// # Errors
    /// Every decoder context or source clip that cannot be read, in one
    /// [`StudyError::Invalid`] keyed by the study file's entries.
    pub fn from_study(study: &StudyFile) -> Result<Option<LiveStimuli>> {
        let def = &study.definition;
        let Some(sc) = &def.staircase else {
            return Ok(None);
        };
        let Some(live) = &sc.live else {
            return Ok(None);
        };
        let mut issues = Vec::new();
        let mut issue = |key: String, err: &LabError| {
            issues.push(StudyIssue {
                key,
                reason: chain(err),
                line: None,
            });
        };
        let database = match &live.database {
            Some(db) => match Database::read(&study.dir().join(db)) {
                Ok(d) => Some(Arc::new(d)),
                Err(e) => {
                    issue("staircase.live.database".into(), &e.into());
                    None
                }
            },
            None => None,
        };
        let manifest_dir = study.manifest_dir();
        let mut clips = Vec::with_capacity(live.clips.len());
        for (i, c) in live.clips.iter().enumerate() {
            match source_clip(def, &manifest_dir, &c.reference) {
                Ok(clip) => clips.push((c.clip.clone(), c.reference.clone(), Arc::new(clip))),
                Err(e) => issue(format!("staircase.live.clips[{i}]"), &e),
            }
        }
        if !issues.is_empty() {
            return Err(StudyError::Invalid {
                path: study.path.clone(),
                issues,
            }
            .into());
        }
        let codecs = Codecs::new(CodecContext {
            primitives: database,
            external: study.external_codecs.clone(),
        });
        Ok(Some(LiveStimuli {
            encoder: Arc::new(Encoder {
                staircase: sc.clone(),
                codec: codecs.get(&sc.codec)?,
                fixed: live.params.clone(),
                clips,
            }),
            cache: Arc::default(),
            workers: Vec::new(),
        }))
    }

    /// The codec's name.
    pub fn codec_name(&self) -> &'static str {
        self.encoder.codec.name()
    }

    /// Levels encoded so far (distinct clip × level pairs), prefetched ones included.
    pub fn cached(&self) -> usize {
        self.cache
            .lock()
            .values()
            .filter(|s| matches!(s, Slot::Ready(_)))
            .count()
    }

    /// The clips in the study's order: (clip name, reference stimulus id).
    pub fn clips(&self) -> impl Iterator<Item = (&str, &str)> {
        self.encoder
            .clips
            .iter()
            .map(|(c, r, _)| (c.as_str(), r.as_str()))
    }

    /// `study check`'s lines of a live staircase (in place of
    /// [`protocols::describe::method`]'s): its codec, clips and tracks, and every clip encoded
    /// once at the first start level (proves the codec takes the settings and shows what a
    /// trial will look like).
    ///
    /// # Errors
    /// A codec error at that level.
    pub fn describe(&self, study: &protocols::StudyDefinition) -> Result<String> {
        use std::fmt::Write as _;
        let mut text = String::new();
        let (Some(sc), Some(live)) = (
            &study.staircase,
            study.staircase.as_ref().and_then(|s| s.live.as_ref()),
        ) else {
            return Ok(text);
        };
        let names: Vec<&str> = live.clips.iter().map(|c| c.clip.as_str()).collect();
        // Writing into a String cannot fail.
        let _ = writeln!(
            text,
            "  live staircase: codec {} encodes {} = level on the fly; clips {}: {}",
            self.codec_name(),
            sc.param,
            match live.order {
                protocols::ClipOrder::InTurn => "in turn",
                protocols::ClipOrder::Shuffled => "in turn, order shuffled per subject",
            },
            names.join(", ")
        );
        for t in &sc.tracks {
            let lo = t.settings.min.unwrap_or(f64::NEG_INFINITY);
            let hi = t.settings.max.unwrap_or(f64::INFINITY);
            let _ = match &sc.quest {
                // A Bayesian track has no start: it picks each level from its posterior.
                Some(q) => writeln!(
                    text,
                    "  {} track {:?}: {} levels in [{lo}, {hi}], each chosen from the posterior",
                    match q.method {
                        protocols::QuestMethod::QuestPlus => "QUEST+",
                        protocols::QuestMethod::Psi => "Psi",
                    },
                    t.name,
                    q.levels.len()
                ),
                None => writeln!(
                    text,
                    "  staircase {:?}: start {} in [{lo}, {hi}]",
                    t.name, t.settings.start
                ),
            };
        }
        let Some(t) = sc.tracks.first() else {
            return Ok(text);
        };
        let level = t.settings.start;
        for (i, (clip, _)) in self.clips().enumerate() {
            let s = self.at_level(i, level)?;
            let _ = writeln!(
                text,
                "  clip {clip:?}: {} frames; at {} = {level}: CR {:.2}:1, RMS {:.3} cm ({} decoded frames)",
                s.reference.frames(),
                sc.param,
                s.achieved_cr,
                s.rms_cm,
                s.test.frames()
            );
        }
        Ok(text)
    }

    /// Clip `index` (in [`Self::clips`] order) encoded at `level` (cached), without a trial:
    /// what a check shows of the settings before any session.
    ///
    /// # Errors
    /// No such clip, or a codec error at that level.
    pub fn at_level(&self, index: usize, level: f64) -> Result<LiveStimulus> {
        if index >= self.encoder.clips.len() || !level.is_finite() {
            return Err(refused(format!(
                "live clip {index} at level {level}: no such clip or level"
            )));
        }
        self.cache.fetch(&self.encoder, (index, level.to_bits()))
    }

    /// Encodes+decodes (cached) the trial's distorted stimulus. A level that a background
    /// thread is encoding is waited for.
    ///
    /// # Errors
    /// A trial that is not one of this study's live trials (unknown reference, no level, a
    /// stimulus id that does not name this codec and level), or a codec error at that level.
    pub fn resolve(&self, trial: &Trial) -> Result<LiveStimulus> {
        let key = self.encoder.key(trial)?;
        self.cache.fetch(&self.encoder, key)
    }

    /// Starts encoding, in the background, the stimuli of `trials` that are not cached or
    /// being encoded yet (the trials that can follow the current one). Trials that are not
    /// this study's live trials are skipped; a failed encoding is left for [`Self::resolve`]
    /// to repeat and report.
    pub fn prefetch(&mut self, trials: &[Trial]) {
        self.workers.retain(|w| !w.is_finished());
        let keys: Vec<Key> = trials
            .iter()
            .filter_map(|t| self.encoder.key(t).ok())
            .filter(|k| !self.cache.lock().contains_key(k))
            .collect();
        if keys.is_empty() {
            return;
        }
        let encoder = Arc::clone(&self.encoder);
        let cache = Arc::clone(&self.cache);
        let spawned = std::thread::Builder::new()
            .name("live-prefetch".into())
            .spawn(move || {
                for key in keys {
                    // Errors are the foreground's to report (resolve encodes again).
                    let _ = cache.fetch(&encoder, key);
                }
            });
        // Without a thread the trials are simply encoded when they come.
        if let Ok(handle) = spawned {
            self.workers.push(handle);
        }
    }

    /// Waits until every background encoding has ended.
    pub fn wait_prefetch(&mut self) {
        for w in self.workers.drain(..) {
            // A worker that panicked has already cleared its slot (see `Claim`); the level is
            // encoded again, and the error reported, when a trial asks for it.
            let _ = w.join();
        }
    }
}

impl Drop for LiveStimuli {
    /// A prefetch never outlives the session that asked for it.
    fn drop(&mut self) {
        self.wait_prefetch();
    }
}

impl Cache {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<Key, Slot>> {
        self.slots.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The stimulus of `key`: cached, awaited from the thread encoding it, or encoded now.
    fn fetch(&self, encoder: &Encoder, key: Key) -> Result<LiveStimulus> {
        let mut slots = self.lock();
        loop {
            match slots.get(&key) {
                Some(Slot::Ready(hit)) => return Ok(hit.clone()),
                Some(Slot::Encoding) => {
                    slots = self
                        .done
                        .wait(slots)
                        .unwrap_or_else(PoisonError::into_inner);
                }
                None => break,
            }
        }
        slots.insert(key, Slot::Encoding);
        drop(slots);
        let claim = Claim { cache: self, key };
        let made = encoder.encode(key);
        if let Ok(stimulus) = &made {
            self.lock().insert(key, Slot::Ready(stimulus.clone()));
        }
        drop(claim);
        made
    }
}

/// A slot marked as being encoded by this thread. Dropping it (after storing the result, on
/// an error, or while unwinding from a panic) clears a mark still standing and wakes every
/// thread waiting for the level, so no one waits for an encoding that will never end.
struct Claim<'a> {
    cache: &'a Cache,
    key: Key,
}

impl Drop for Claim<'_> {
    fn drop(&mut self) {
        let mut slots = self.cache.lock();
        if matches!(slots.get(&self.key), Some(Slot::Encoding)) {
            slots.remove(&self.key);
        }
        drop(slots);
        self.cache.done.notify_all();
    }
}

impl Encoder {
    /// The cache key of a live trial of this study.
    fn key(&self, trial: &Trial) -> Result<Key> {
        let idx = self
            .clips
            .iter()
            .position(|(_, r, _)| *r == trial.reference)
            .ok_or_else(|| {
                refused(format!(
                    "trial {}: reference {:?} is not a clip of this live staircase",
                    trial.index, trial.reference
                ))
            })?;
        let level = trial
            .level
            .filter(|l| l.is_finite())
            .ok_or_else(|| refused(format!("trial {}: no finite staircase level", trial.index)))?;
        let expected = self.staircase.live_stimulus_id(&self.clips[idx].0, level);
        if trial.stimulus != expected {
            return Err(refused(format!(
                "trial {}: stimulus {:?} is not the live stimulus {expected:?} of this study",
                trial.index, trial.stimulus
            )));
        }
        Ok((idx, level.to_bits()))
    }

    /// Encodes, decodes and measures clip `key.0` at level `key.1`.
    fn encode(&self, (idx, bits): Key) -> Result<LiveStimulus> {
        let level = f64::from_bits(bits);
        let (name, _, source) = &self.clips[idx];
        let mut requested = self.fixed.clone();
        requested.insert(self.staircase.param.clone(), level);
        let request = Request {
            params: requested,
            target_cr: None,
        };
        let made = stimulus::make(self.codec.as_ref(), source, &request).map_err(|e| {
            LabError::Context {
                what: format!(
                    "clip {name:?} with {} at {} = {level}",
                    self.codec.name(),
                    self.staircase.param
                ),
                source: Box::new(e),
            }
        })?;
        // The stream's parameters are what the encoder really used (e.g. the α a rate search
        // found); the requested ones fill in what it does not store (a target `cr`).
        let mut params = made.stream.params.clone();
        for (k, v) in request.params {
            params.entry(k).or_insert(v);
        }
        Ok(LiveStimulus {
            reference: Arc::clone(source),
            achieved_cr: made.achieved_cr(),
            rms_cm: made.metrics.rms_cm,
            test: Arc::new(made.decoded),
            params,
        })
    }
}

/// The source clip of reference stimulus `reference`, read from the manifest's files.
fn source_clip(
    def: &protocols::StudyDefinition,
    manifest_dir: &Path,
    reference: &str,
) -> Result<Clip> {
    let s = def
        .manifest
        .get(reference)
        .ok_or_else(|| refused(format!("reference {reference:?} is not in the manifest")))?;
    let file = manifest_dir.join(&s.file);
    let skeleton = s.skeleton.as_deref().map(|k| manifest_dir.join(k));
    Ok(motion::io::read_clip(skeleton.as_deref(), &file)?)
}

impl StimulusSource for LiveStimuli {
    fn stimuli(&self, trial: &Trial) -> Result<TrialStimuli> {
        let made = self.resolve(trial)?;
        Ok(TrialStimuli {
            encoding: Some(made.encoding()),
            reference: made.reference,
            test: made.test,
            crowd: Vec::new(),
        })
    }

    fn encoding(&self, trial: &Trial) -> Result<Option<StimulusEncoding>> {
        Ok(Some(self.resolve(trial)?.encoding()))
    }

    fn prepare(&mut self, upcoming: &[Trial]) {
        self.prefetch(upcoming);
    }

    fn settle(&mut self) {
        self.wait_prefetch();
    }

    fn ready(&self) -> usize {
        self.cached()
    }

    fn summary(&self) -> Option<String> {
        Some(format!(
            "live staircase: {} clip × level stimuli encoded with {}",
            self.cached(),
            self.codec_name()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> StudyFile {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/live-staircase.toml");
        StudyFile::load(&path).unwrap()
    }

    fn same(a: &LiveStimulus, b: &LiveStimulus) {
        assert_eq!(a.params, b.params);
        assert_eq!(a.achieved_cr.to_bits(), b.achieved_cr.to_bits());
        assert_eq!(a.rms_cm.to_bits(), b.rms_cm.to_bits());
        assert_eq!(a.test.data(), b.test.data());
    }

    /// Runs subject `subject`'s session of `study` for at most `limit` trials, answering
    /// wrong where `wrong(index)`, preparing after each trial start the trials its answers
    /// lead to (waited for): every trial after the first must be a cache hit equal to a fresh
    /// foreground encoding. Returns how many trials each lookahead gave.
    fn prefetched_session(
        study: &StudyFile,
        subject: u32,
        limit: usize,
        wrong: fn(u32) -> bool,
    ) -> Vec<usize> {
        use protocols::{Answer, Response, Session};
        let mut live = LiveStimuli::from_study(study).unwrap().unwrap();
        let fresh = LiveStimuli::from_study(study).unwrap().unwrap();
        let mut session = Session::new(&study.definition, subject).unwrap();
        let mut ahead_counts = Vec::new();
        while let Some(t) = session.next_trial(0).unwrap()
            && ahead_counts.len() < limit
        {
            if ahead_counts.is_empty() {
                live.resolve(&t).unwrap();
            } else {
                let before = live.cached();
                let got = live.resolve(&t).unwrap();
                assert_eq!(live.cached(), before, "trial {} was prefetched", t.index);
                same(&got, &fresh.resolve(&t).unwrap());
            }
            let ahead = session.lookahead(0);
            ahead_counts.push(ahead.len());
            live.prefetch(&ahead);
            live.wait_prefetch();
            let answer = if wrong(t.index) {
                t.reference_position.other()
            } else {
                t.reference_position
            };
            session
                .respond(&Response {
                    answer: Answer::Choice(answer),
                    response_time_ms: 500,
                    replays: 0,
                    dropped_frames: 0,
                })
                .unwrap();
        }
        ahead_counts
    }

    /// Over a whole session answered at random, every trial after the first was prefetched
    /// while the previous one ran, and equals what a fresh cache encodes in the foreground.
    #[test]
    fn every_next_trial_is_prefetched_and_equals_a_foreground_encoding() {
        let study = example();
        let ahead = prefetched_session(&study, 1, 12, |i| i % 3 == 0);
        assert_eq!(ahead.len(), 12);
        assert!(ahead.iter().all(|n| *n > 0));
    }

    /// A live QUEST+ track: a correct and a wrong answer lead to two levels, both encoded in
    /// the background while the trial runs, so every next trial is a cache hit and equals a
    /// foreground encoding.
    #[test]
    fn a_live_quest_track_prefetches_both_next_levels() {
        let dir = std::env::temp_dir().join(format!("live-quest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let manifest = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/live/stimuli.json");
        let text = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/live-staircase.toml"),
        )
        .unwrap()
        .replace("live/stimuli.json", &manifest.display().to_string())
        .replace(
            "start = 64\nstep = 2\n",
            "method = \"quest_plus\"\nstep = 8\n",
        )
        .replace(
            "n_up = 1\nn_down = 2\nstop_reversals = 12\nmax_trials = 90\nthreshold_reversals = 6\n",
            "max_trials = 8\n\n[staircase.quest]\nthreshold = { min = 5, max = 120, count = 24, spacing = \"log\" }\nslope = [1, 2, 4]\nlapse = [0, 0.02]\n",
        );
        let file = dir.join("live-quest.toml");
        std::fs::write(&file, text).unwrap();
        let study = StudyFile::load(&file).unwrap();
        assert!(study.definition.staircase.as_ref().unwrap().quest.is_some());
        let ahead = prefetched_session(&study, 0, usize::MAX, |i| i % 3 == 1);
        assert_eq!(ahead.len(), 8);
        assert!(ahead[..7].iter().all(|n| *n == 2), "{ahead:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A trial that asks for a level while it is being prefetched waits for that encoding;
    /// trials that are not live trials of the study are not prefetched.
    #[test]
    fn a_level_in_flight_is_awaited_and_foreign_trials_are_skipped() {
        use protocols::Session;
        let study = example();
        let mut live = LiveStimuli::from_study(&study).unwrap().unwrap();
        let mut session = Session::new(&study.definition, 0).unwrap();
        let t = session.next_trial(0).unwrap().unwrap();
        let mut foreign = t.clone();
        foreign.reference = "nobody/reference".into();
        live.prefetch(&[t.clone(), foreign.clone()]);
        let got = live.resolve(&t).unwrap();
        live.wait_prefetch();
        assert_eq!(live.cached(), 1);
        let fresh = LiveStimuli::from_study(&study).unwrap().unwrap();
        same(&got, &fresh.resolve(&t).unwrap());
        let err = live.resolve(&foreign).unwrap_err().to_string();
        assert!(err.contains("not a clip of this live staircase"), "{err}");
    }

    /// A level the codec refuses fails in the background without leaving the level marked as
    /// in flight: the trial's own resolve encodes it again and reports the codec's error.
    #[test]
    fn a_failed_prefetch_is_reported_by_the_trial_that_needs_it() {
        use protocols::Session;
        let study = example();
        let mut live = LiveStimuli::from_study(&study).unwrap().unwrap();
        let mut session = Session::new(&study.definition, 0).unwrap();
        let mut t = session.next_trial(0).unwrap().unwrap();
        let sc = study.definition.staircase.as_ref().unwrap();
        let clip = live.clips().next().unwrap().0.to_string();
        t.level = Some(1e5);
        t.stimulus = sc.live_stimulus_id(&clip, 1e5);
        live.prefetch(std::slice::from_ref(&t));
        live.wait_prefetch();
        assert_eq!(live.cached(), 0);
        let err = chain(&live.resolve(&t).unwrap_err());
        assert!(
            err.contains("at cr = 100000") && err.contains("0.1..=10000"),
            "{err}"
        );
    }
}
