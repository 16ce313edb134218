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
use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex, PoisonError};
use std::thread::JoinHandle;

use anyhow::{Context as _, anyhow, bail};
use codecs::codec::CodecContext;
use codecs::codec::{Codec, Params, RateControl};
use codecs::primitives::Database;
use motion::clip::Clip;
use protocols::{StaircaseStudy, StimulusEncoding, StudyDefinition, Trial};

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

/// The codec called `name`, with the decoder context loaded from the study (the primitive
/// codec's database).
fn codec_named(name: &str, database: Option<Arc<Database>>) -> anyhow::Result<Box<dyn Codec>> {
    let ctx = CodecContext {
        primitives: database,
    };
    codecs::codec::by_name_in(name, &ctx).ok_or_else(|| {
        let known: Vec<&str> = codecs::codec::registry_in(&ctx)
            .iter()
            .map(|c| c.name())
            .collect();
        anyhow!(
            "unknown codec {name:?} (known: {}; `study codecs` lists them)",
            known.join(", ")
        )
    })
}

impl LiveStimuli {
    /// The live stimuli of `study` (read from `study_path`), or `None` when the study has no
    /// live staircase. Checks the codec and its parameters and loads every source clip and
    /// the decoder context, so a bad setting stops the session before its first trial.
    ///
    /// # Errors
    /// Unknown codec or parameter, a level range the codec cannot encode, an unreadable clip
    /// or database (named by file).
    pub fn from_study(
        study: &StudyDefinition,
        study_path: &Path,
    ) -> anyhow::Result<Option<LiveStimuli>> {
        let Some(sc) = &study.staircase else {
            return Ok(None);
        };
        let Some(live) = &sc.live else {
            return Ok(None);
        };
        let where_ = || format!("{}: staircase.live", study_path.display());
        let base = study_path.parent().unwrap_or(Path::new("."));
        let database = match &live.database {
            Some(db) => {
                let path = base.join(db);
                let d = Database::read(&path).with_context(|| {
                    format!("{}: staircase.live.database", study_path.display())
                })?;
                Some(Arc::new(d))
            }
            None => None,
        };
        let codec = codec_named(&sc.codec, database)
            .with_context(|| format!("{}: staircase.codec", study_path.display()))?;
        let accepted = codec.default_params();
        let list = || accepted.keys().cloned().collect::<Vec<_>>().join(", ");
        if !accepted.contains_key(&sc.param) {
            bail!(
                "{}: staircase.param: codec {:?} has no parameter {:?} (accepted: {})",
                study_path.display(),
                sc.codec,
                sc.param,
                list()
            );
        }
        for k in live.params.keys() {
            if !accepted.contains_key(k) {
                bail!(
                    "{}.params.{k}: codec {:?} has no such parameter (accepted: {})",
                    where_(),
                    sc.codec,
                    list()
                );
            }
        }
        if sc.param == "cr" {
            if codec.rate_control() == RateControl::None {
                bail!(
                    "{}: staircase.param: codec {:?} takes no target compression ratio",
                    study_path.display(),
                    sc.codec
                );
            }
            for t in &sc.tracks {
                if t.settings.min.is_none_or(|m| m <= 0.0) {
                    bail!(
                        "{}: staircase.min: a compression ratio level needs min > 0",
                        study_path.display()
                    );
                }
            }
        }
        let manifest_path = base.join(&study.stimuli_path);
        let manifest_dir = manifest_path.parent().unwrap_or(Path::new("."));
        let mut clips = Vec::with_capacity(live.clips.len());
        for c in &live.clips {
            let s = study.manifest.get(&c.reference).ok_or_else(|| {
                anyhow!(
                    "{}: reference {:?} is not in the manifest",
                    where_(),
                    c.reference
                )
            })?;
            let file: PathBuf = manifest_dir.join(&s.file);
            let skeleton = s.skeleton.as_deref().map(|k| manifest_dir.join(k));
            let clip = motion::io::read_clip(skeleton.as_deref(), &file).with_context(|| {
                format!(
                    "loading the source of live clip {:?} (stimulus {:?} in {})",
                    c.clip,
                    c.reference,
                    manifest_path.display()
                )
            })?;
            clips.push((c.clip.clone(), c.reference.clone(), Arc::new(clip)));
        }
        Ok(Some(LiveStimuli {
            encoder: Arc::new(Encoder {
                staircase: sc.clone(),
                codec,
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

    /// Encodes+decodes (cached) the trial's distorted stimulus. A level that a background
    /// thread is encoding is waited for.
    ///
    /// # Errors
    /// A trial that is not one of this study's live trials (unknown reference, no level, a
    /// stimulus id that does not name this codec and level), or a codec error at that level.
    pub fn resolve(&self, trial: &Trial) -> anyhow::Result<LiveStimulus> {
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
    fn fetch(&self, encoder: &Encoder, key: Key) -> anyhow::Result<LiveStimulus> {
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
    fn key(&self, trial: &Trial) -> anyhow::Result<Key> {
        let idx = self
            .clips
            .iter()
            .position(|(_, r, _)| *r == trial.reference)
            .ok_or_else(|| {
                anyhow!(
                    "trial {}: reference {:?} is not a clip of this live staircase",
                    trial.index,
                    trial.reference
                )
            })?;
        let level = trial
            .level
            .filter(|l| l.is_finite())
            .ok_or_else(|| anyhow!("trial {}: no finite staircase level", trial.index))?;
        let expected = self.staircase.live_stimulus_id(&self.clips[idx].0, level);
        if trial.stimulus != expected {
            bail!(
                "trial {}: stimulus {:?} is not the live stimulus {expected:?} of this study",
                trial.index,
                trial.stimulus
            );
        }
        Ok((idx, level.to_bits()))
    }

    /// Encodes, decodes and measures clip `key.0` at level `key.1`.
    fn encode(&self, (idx, bits): Key) -> anyhow::Result<LiveStimulus> {
        let level = f64::from_bits(bits);
        let (name, _, source) = &self.clips[idx];
        let mut requested = self.fixed.clone();
        requested.insert(self.staircase.param.clone(), level);
        let stream = self.codec.encode(source, &requested).with_context(|| {
            format!(
                "encoding clip {name:?} with {} at {} = {level}",
                self.codec.name(),
                self.staircase.param
            )
        })?;
        let decoded = self
            .codec
            .decode(&stream, &source.skeleton)
            .with_context(|| {
                format!(
                    "decoding clip {name:?} at {} = {level}",
                    self.staircase.param
                )
            })?;
        let metrics = codecs::metrics::compare(source, &decoded).with_context(|| {
            format!(
                "measuring clip {name:?} at {} = {level}",
                self.staircase.param
            )
        })?;
        // The stream's parameters are what the encoder really used (e.g. the α a rate search
        // found); the requested ones fill in what it does not store (a target `cr`).
        let mut params = stream.params.clone();
        for (k, v) in requested {
            params.entry(k).or_insert(v);
        }
        Ok(LiveStimulus {
            reference: Arc::clone(source),
            test: Arc::new(decoded),
            params,
            achieved_cr: stream.compression_ratio(),
            rms_cm: metrics.rms_cm,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> (StudyDefinition, PathBuf) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/live-staircase.toml");
        (StudyDefinition::load(&path).unwrap(), path)
    }

    fn same(a: &LiveStimulus, b: &LiveStimulus) {
        assert_eq!(a.params, b.params);
        assert_eq!(a.achieved_cr.to_bits(), b.achieved_cr.to_bits());
        assert_eq!(a.rms_cm.to_bits(), b.rms_cm.to_bits());
        assert_eq!(a.test.data(), b.test.data());
    }

    /// Over a whole session answered at random, every trial after the first was prefetched
    /// while the previous one ran, and equals what a fresh cache encodes in the foreground.
    #[test]
    fn every_next_trial_is_prefetched_and_equals_a_foreground_encoding() {
        use protocols::{Answer, Response, Session};
        let (study, path) = example();
        let mut live = LiveStimuli::from_study(&study, &path).unwrap().unwrap();
        let fresh = LiveStimuli::from_study(&study, &path).unwrap().unwrap();
        let mut session = Session::new(&study, 1).unwrap();
        let mut trials = 0;
        while let Some(t) = session.next_trial(0).unwrap()
            && trials < 12
        {
            if trials > 0 {
                let before = live.cached();
                let got = live.resolve(&t).unwrap();
                assert_eq!(live.cached(), before, "trial {} was prefetched", t.index);
                same(&got, &fresh.resolve(&t).unwrap());
            } else {
                live.resolve(&t).unwrap();
            }
            let ahead = session.lookahead(0);
            assert!(!ahead.is_empty());
            live.prefetch(&ahead);
            live.wait_prefetch();
            let answer = if t.index % 3 == 0 {
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
            trials += 1;
        }
        assert_eq!(trials, 12);
    }

    /// A trial that asks for a level while it is being prefetched waits for that encoding;
    /// trials that are not live trials of the study are not prefetched.
    #[test]
    fn a_level_in_flight_is_awaited_and_foreign_trials_are_skipped() {
        use protocols::Session;
        let (study, path) = example();
        let mut live = LiveStimuli::from_study(&study, &path).unwrap().unwrap();
        let mut session = Session::new(&study, 0).unwrap();
        let t = session.next_trial(0).unwrap().unwrap();
        let mut foreign = t.clone();
        foreign.reference = "nobody/reference".into();
        live.prefetch(&[t.clone(), foreign.clone()]);
        let got = live.resolve(&t).unwrap();
        live.wait_prefetch();
        assert_eq!(live.cached(), 1);
        let fresh = LiveStimuli::from_study(&study, &path).unwrap().unwrap();
        same(&got, &fresh.resolve(&t).unwrap());
        let err = live.resolve(&foreign).unwrap_err().to_string();
        assert!(err.contains("not a clip of this live staircase"), "{err}");
    }

    /// A level the codec refuses fails in the background without leaving the level marked as
    /// in flight: the trial's own resolve encodes it again and reports the codec's error.
    #[test]
    fn a_failed_prefetch_is_reported_by_the_trial_that_needs_it() {
        use protocols::Session;
        let (study, path) = example();
        let mut live = LiveStimuli::from_study(&study, &path).unwrap().unwrap();
        let mut session = Session::new(&study, 0).unwrap();
        let mut t = session.next_trial(0).unwrap().unwrap();
        let sc = study.staircase.as_ref().unwrap();
        let clip = live.clips().next().unwrap().0.to_string();
        t.level = Some(1e5);
        t.stimulus = sc.live_stimulus_id(&clip, 1e5);
        live.prefetch(std::slice::from_ref(&t));
        live.wait_prefetch();
        assert_eq!(live.cached(), 0);
        let err = format!("{:#}", live.resolve(&t).unwrap_err());
        assert!(
            err.contains("at cr = 100000") && err.contains("0.1..=10000"),
            "{err}"
        );
    }
}
