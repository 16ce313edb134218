//! The protocol engines: deterministic state machines from study + seed + responses to the
//! next trial.
//!
//! A [`Session`] is built from a validated [`StudyDefinition`] and a subject index. MOS and DSCQS
//! sessions plan every trial up front from the study seed and the subject index (familiarization
//! block spanning the quality range, shuffled test trials, hidden repeats, reference positions);
//! staircase sessions decide each trial from the tracks' state (an up-down staircase, or a
//! QUEST+ / Psi posterior, [`crate::quest`]) and a per-trial random stream. Nothing depends on the wall clock except the time limit, whose clock the caller
//! passes in, so replaying logged responses regenerates the logged trials exactly (resume).

use serde::{Deserialize, Serialize};

use crate::design;
use crate::methods::{AnswerWidget, Refusal};
use crate::quest::{QuestError, QuestPlus};
use crate::record::{Answer, Arrangement, Block, Outcome, Position, Protocol, Response, Trial};
use crate::rng::{StudyRng, purpose};
use crate::staircase::{Staircase, StaircaseError};
use crate::study::{
    ClipOrder, Condition, ConditionOrder, LiveClip, RatingScale, ReferencePlacement,
    StaircaseStudy, StudyDefinition, Track,
};

/// Where a session stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SessionStatus {
    /// Trials remain.
    Running,
    /// Every planned trial was answered (MOS, DSCQS) or every staircase stopped.
    Complete,
    /// The session time limit ended the session; the rest was not shown.
    TimeLimit,
}

/// Why an engine refused a call.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EngineError {
    /// `respond` without a trial pending.
    #[error("no trial is waiting for a response")]
    NoPendingTrial,
    /// The answer does not fit the protocol.
    #[error("trial {trial}: a {protocol} trial needs {expected}, got {got:?}")]
    WrongAnswer {
        /// Trial index.
        trial: u32,
        /// Protocol.
        protocol: Protocol,
        /// What was expected.
        expected: &'static str,
        /// What came.
        got: Answer,
    },
    /// A rating is not on the study's scale.
    #[error("trial {trial}: rating {value} is not on the scale {min}..={max} (step {step:?})")]
    OffScale {
        /// Trial index.
        trial: u32,
        /// The rating.
        value: f64,
        /// Scale minimum.
        min: f64,
        /// Scale maximum.
        max: f64,
        /// Scale step.
        step: Option<f64>,
    },
    /// A staircase level has no stimulus (the study file changed or was not validated).
    #[error("staircase {track:?}: no stimulus for level {level}")]
    NoStimulus {
        /// Track name.
        track: String,
        /// Level.
        level: f64,
    },
    /// More replays than the study allows.
    #[error("trial {trial}: {replays} replays, the study allows {max}")]
    TooManyReplays {
        /// Trial index.
        trial: u32,
        /// Replays in the response.
        replays: u32,
        /// `presentation.max_replays`.
        max: u32,
    },
    /// Staircase state error.
    #[error(transparent)]
    Staircase(#[from] StaircaseError),
    /// QUEST+ / Psi state error.
    #[error(transparent)]
    Quest(#[from] QuestError),
    /// Replay regenerated a trial different from the logged one.
    #[error(
        "trial {trial}: logged {field} {logged:?} but the study gives {regenerated:?}; the row \
         does not follow from the study and the rows before it (edited or damaged log?)"
    )]
    ReplayMismatch {
        /// Trial index.
        trial: u32,
        /// Field that differs.
        field: &'static str,
        /// Logged value.
        logged: String,
        /// Regenerated value.
        regenerated: String,
    },
}

/// One adaptive track: an up-down staircase or a QUEST+ / Psi procedure.
#[derive(Debug, Clone)]
enum Procedure {
    UpDown(Staircase),
    Bayesian(QuestPlus),
}

impl Procedure {
    fn next_level(&self) -> Option<f64> {
        match self {
            Self::UpDown(s) => s.next_level(),
            Self::Bayesian(q) => q.next_level(),
        }
    }

    fn is_finished(&self) -> bool {
        match self {
            Self::UpDown(s) => s.is_finished(),
            Self::Bayesian(q) => q.is_finished(),
        }
    }

    /// Records an answer; the reversal flag an up-down staircase logs (`None`: no such thing
    /// in a Bayesian track).
    fn add_response(&mut self, correct: bool) -> Result<Option<bool>, EngineError> {
        Ok(match self {
            Self::UpDown(s) => Some(s.add_response(correct)?.reversal),
            Self::Bayesian(q) => {
                q.add_response(correct)?;
                None
            }
        })
    }

    /// The staircase's mean of its last reversals, or the posterior mean threshold.
    fn threshold(&self) -> Option<f64> {
        match self {
            Self::UpDown(s) => s.threshold(),
            Self::Bayesian(q) => (!q.levels().is_empty()).then(|| q.threshold().mean),
        }
    }
}

#[derive(Debug, Clone)]
struct Stairs {
    tracks: Vec<Track>,
    staircases: Vec<Procedure>,
    tolerance: f64,
    live: Option<LiveRun>,
    /// Practice trials before the staircases (block `familiarization`), and their level
    /// (`None`: each track's start).
    practice: u32,
    practice_level: Option<f64>,
}

impl Stairs {
    /// The adaptive tracks of subject `subject`'s session of `study` (`None`: the study has no
    /// `[staircase]`).
    fn of(study: &StudyDefinition, subject: u32) -> Result<Option<Self>, EngineError> {
        let Some(sc) = &study.staircase else {
            return Ok(None);
        };
        let staircases = sc
            .tracks
            .iter()
            .map(|t| match &sc.quest {
                None => Ok(Procedure::UpDown(Staircase::new(t.settings.clone())?)),
                Some(q) => Ok(Procedure::Bayesian(QuestPlus::new(q.clone())?)),
            })
            .collect::<Result<Vec<_>, EngineError>>()?;
        let live = sc.live.as_ref().map(|l| {
            let mut clips = l.clips.clone();
            if l.order == ClipOrder::Shuffled {
                let mut rng = StudyRng::new(study.seed, &[u64::from(subject), purpose::LIVE_CLIPS]);
                rng.shuffle(&mut clips);
            }
            LiveRun {
                study: sc.clone(),
                clips,
            }
        });
        Ok(Some(Stairs {
            tracks: sc.tracks.clone(),
            staircases,
            tolerance: sc.level_tolerance,
            live,
            practice: sc.practice_trials,
            practice_level: sc.practice_level,
        }))
    }

    /// The test stimulus and reference of trial `index` of `track` at `level`. Live: the clips
    /// take turns across the session's trials, and the stimulus is named, not looked up; the
    /// runner encodes it.
    fn stimulus(
        &self,
        track: &Track,
        index: u32,
        level: f64,
    ) -> Result<(String, String), EngineError> {
        let missing = || EngineError::NoStimulus {
            track: track.name.clone(),
            level,
        };
        if let Some(live) = &self.live {
            let c = live
                .clips
                .get(index as usize % live.clips.len().max(1))
                .ok_or_else(missing)?;
            Ok((
                live.study.live_stimulus_id(&c.clip, level),
                c.reference.clone(),
            ))
        } else {
            let stimulus = track
                .stimulus_at(level, self.tolerance)
                .ok_or_else(missing)?;
            Ok((stimulus.to_string(), track.reference.clone()))
        }
    }
}

/// A live staircase's clips in this subject's order, and how to name a derived stimulus.
#[derive(Debug, Clone)]
struct LiveRun {
    study: StaircaseStudy,
    clips: Vec<LiveClip>,
}

/// A subject's session: the state machine of one protocol.
#[derive(Debug, Clone)]
pub struct Session {
    protocol: Protocol,
    subject: u32,
    seed: u64,
    arrangement: Arrangement,
    placement: ReferencePlacement,
    scale: RatingScale,
    time_limit_ms: Option<u64>,
    break_every: Option<u32>,
    max_replays: Option<u32>,
    /// The answers a choice screen offers (its buttons); empty for other answer widgets.
    offered: Vec<Position>,
    plan: Vec<Trial>,
    stairs: Option<Stairs>,
    next_index: u32,
    pending: Option<Trial>,
    status: SessionStatus,
}

/// The reference's position: fixed, drawn from `rng`, or (counterbalanced) `balanced`.
fn place(
    placement: ReferencePlacement,
    arrangement: Arrangement,
    rng: &mut StudyRng,
    balanced: Position,
) -> Position {
    match placement {
        ReferencePlacement::Fixed(p) => p,
        ReferencePlacement::Balanced => balanced,
        ReferencePlacement::Random => {
            let first = match arrangement {
                Arrangement::SideBySide => Position::Left,
                Arrangement::Sequential => Position::First,
                Arrangement::Abab => Position::A,
                // Nothing to place: the reference is not shown.
                Arrangement::Single => return Position::Hidden,
                // A MUSHRA plan places every stimulus itself.
                Arrangement::Grid => return Position::Pane(0),
            };
            if rng.coin() { first } else { first.other() }
        }
    }
}

impl Session {
    /// The session of subject `subject` (0-based) of `study`.
    ///
    /// # Errors
    /// [`EngineError::Staircase`] if staircase settings are invalid (not possible for a
    /// validated study).
    pub fn new(study: &StudyDefinition, subject: u32) -> Result<Self, EngineError> {
        let arrangement = study.presentation.arrangement;
        let placement = study.presentation.reference_position;
        let method = study.method();
        // A method plans its trials up front; an adaptive one's tracks pick each trial.
        let plan = method.plan(study, subject);
        let stairs = if method.adaptive() {
            Stairs::of(study, subject)?
        } else {
            None
        };
        let offered = match method.answer_widget(study) {
            AnswerWidget::Choice { options, .. } => options.iter().map(|o| o.answer).collect(),
            _ => Vec::new(),
        };
        Ok(Self {
            protocol: study.protocol,
            subject,
            seed: study.seed,
            arrangement,
            placement,
            scale: study.scale,
            time_limit_ms: study.session.time_limit_ms,
            break_every: study.session.break_every_trials,
            max_replays: study.presentation.max_replays,
            offered,
            plan,
            stairs,
            next_index: 0,
            pending: None,
            status: SessionStatus::Running,
        })
    }

    /// Protocol of this session.
    pub fn protocol(&self) -> Protocol {
        self.protocol
    }

    /// Where the session stands.
    pub fn status(&self) -> SessionStatus {
        self.status
    }

    /// Trials answered so far.
    pub fn answered(&self) -> u32 {
        self.next_index
    }

    /// The next trial, or `None` when the session is over (see [`Self::status`]).
    ///
    /// `elapsed_ms` is the session clock; at or past the time limit no new trial starts and
    /// the session ends with [`SessionStatus::TimeLimit`]. Calling again before responding
    /// returns the same trial.
    ///
    /// # Errors
    /// [`EngineError::NoStimulus`] when a staircase level has no stimulus.
    pub fn next_trial(&mut self, elapsed_ms: u64) -> Result<Option<Trial>, EngineError> {
        if let Some(t) = &self.pending {
            return Ok(Some(t.clone()));
        }
        if self.status != SessionStatus::Running {
            return Ok(None);
        }
        let index = self.next_index;
        let mut trial = match &self.stairs {
            None => {
                let Some(t) = self.plan.get(index as usize) else {
                    self.status = SessionStatus::Complete;
                    return Ok(None);
                };
                t.clone()
            }
            Some(st) => {
                let practice = index < st.practice;
                let open: Vec<usize> = (0..st.staircases.len())
                    .filter(|&k| !st.staircases[k].is_finished())
                    .collect();
                if open.is_empty() && !practice {
                    self.status = SessionStatus::Complete;
                    return Ok(None);
                }
                if self.time_limit_ms.is_some_and(|l| elapsed_ms >= l) {
                    self.status = SessionStatus::TimeLimit;
                    return Ok(None);
                }
                let mut rng = StudyRng::new(
                    self.seed,
                    &[u64::from(self.subject), purpose::TRIAL, u64::from(index)],
                );
                // Practice trials take the tracks in turn; then the staircases are
                // interleaved at random among those still running.
                let k = if practice {
                    index as usize % st.tracks.len().max(1)
                } else {
                    open[rng.index(open.len())]
                };
                let reference_position = place(
                    self.placement,
                    self.arrangement,
                    &mut rng,
                    design::balanced_side_of_trial(
                        self.seed,
                        self.subject,
                        index,
                        self.arrangement,
                    ),
                );
                let Some(track) = st.tracks.get(k) else {
                    return Err(EngineError::NoPendingTrial);
                };
                let level = if practice {
                    st.practice_level.unwrap_or(track.settings.start)
                } else {
                    st.staircases[k]
                        .next_level()
                        .unwrap_or(track.settings.start)
                };
                let (stimulus, reference) = st.stimulus(track, index, level)?;
                Trial {
                    index,
                    block: if practice {
                        Block::Familiarization
                    } else {
                        Block::Test
                    },
                    condition: track.name.clone(),
                    stimulus,
                    reference,
                    arrangement: self.arrangement,
                    reference_position,
                    staircase: Some(k as u32),
                    level: Some(level),
                    break_before: false,
                }
            }
        };
        // A MUSHRA screen is shown whole: the time limit and breaks fall between screens, and
        // `break_every_trials` counts screens.
        let (starts_screen, count) = if crate::methods::of(self.protocol).screens() {
            let starts = index == 0 || self.screen_start(index as usize);
            let screen = self.plan[..=(index as usize).min(self.plan.len() - 1)]
                .iter()
                .enumerate()
                .filter(|(i, _)| *i == 0 || self.screen_start(*i))
                .count()
                - 1;
            (starts, screen as u32)
        } else {
            (true, index)
        };
        if starts_screen && self.time_limit_ms.is_some_and(|l| elapsed_ms >= l) {
            self.status = SessionStatus::TimeLimit;
            return Ok(None);
        }
        trial.break_before = starts_screen
            && count > 0
            && self
                .break_every
                .is_some_and(|n| n > 0 && count.is_multiple_of(n));
        self.pending = Some(trial.clone());
        Ok(Some(trial))
    }

    /// Scores `response` to the pending trial and advances the session.
    ///
    /// # Errors
    /// [`EngineError::NoPendingTrial`], [`EngineError::WrongAnswer`],
    /// [`EngineError::OffScale`] or [`EngineError::TooManyReplays`]; the trial stays pending on
    /// error.
    pub fn respond(&mut self, response: &Response) -> Result<Outcome, EngineError> {
        let Some(trial) = self.pending.as_ref() else {
            return Err(EngineError::NoPendingTrial);
        };
        if let Some(max) = self.max_replays
            && response.replays > max
        {
            return Err(EngineError::TooManyReplays {
                trial: trial.index,
                replays: response.replays,
                max,
            });
        }
        let wrong = |expected| EngineError::WrongAnswer {
            trial: trial.index,
            protocol: self.protocol,
            expected,
            got: response.answer,
        };
        let off_scale = |v: f64| EngineError::OffScale {
            trial: trial.index,
            value: v,
            min: self.scale.min,
            max: self.scale.max,
            step: self.scale.step,
        };
        // Only a button the screen showed answers a choice (no "no preference" unless offered).
        if let Answer::Choice(p) = response.answer
            && !self.offered.is_empty()
            && !self.offered.contains(&p)
        {
            return Err(wrong("one of the choices its screen offered"));
        }
        let mut outcome = crate::methods::of(self.protocol)
            .score(trial, response.answer, &self.scale)
            .map_err(|refusal| match refusal {
                Refusal::Expected(expected) => wrong(expected),
                Refusal::OffScale(v) => off_scale(v),
            })?;
        // An adaptive method's answer moves its track (thesis ch. 5: picking the original
        // motion is correct); a practice trial is scored for the log and moves none.
        if let Some(stairs) = &mut self.stairs {
            let correct = outcome.correct.unwrap_or(false);
            let k = trial.staircase.unwrap_or(0) as usize;
            outcome.reversal = match stairs.staircases.get_mut(k) {
                Some(_) if trial.block == Block::Familiarization => None,
                Some(sc) => sc.add_response(correct)?,
                None => return Err(EngineError::NoPendingTrial),
            };
        }
        self.pending = None;
        self.next_index += 1;
        Ok(outcome)
    }

    /// Replays one logged trial: regenerates the trial, checks it equals `logged`, feeds the
    /// logged response and checks the scoring equals `logged_outcome`.
    ///
    /// # Errors
    /// [`EngineError::ReplayMismatch`] naming the first field that differs, or any error of
    /// [`Self::next_trial`] / [`Self::respond`].
    pub fn replay(
        &mut self,
        logged: &Trial,
        response: &Response,
        logged_outcome: &Outcome,
    ) -> Result<(), EngineError> {
        // Logged trials were all shown before any time limit: replay ignores the clock.
        let regenerated = self.next_trial(0)?;
        let mismatch = |field, l: String, r: String| EngineError::ReplayMismatch {
            trial: logged.index,
            field,
            logged: l,
            regenerated: r,
        };
        let Some(t) = regenerated else {
            return Err(mismatch(
                "trial",
                format!("{}", logged.index),
                "end of session".into(),
            ));
        };
        let checks: [(&'static str, String, String); 8] = [
            ("index", logged.index.to_string(), t.index.to_string()),
            ("block", logged.block.to_string(), t.block.to_string()),
            ("condition", logged.condition.clone(), t.condition.clone()),
            ("stimulus", logged.stimulus.clone(), t.stimulus.clone()),
            ("reference", logged.reference.clone(), t.reference.clone()),
            (
                "arrangement",
                logged.arrangement.to_string(),
                t.arrangement.to_string(),
            ),
            (
                "reference_position",
                logged.reference_position.to_string(),
                t.reference_position.to_string(),
            ),
            (
                "staircase",
                format!("{:?}", logged.staircase),
                format!("{:?}", t.staircase),
            ),
        ];
        for (field, l, r) in checks {
            if l != r {
                return Err(mismatch(field, l, r));
            }
        }
        // A level logged by a build that accumulated its steps (before the exact grid) is the
        // same grid point within float rounding.
        let same_level = match (logged.level, t.level) {
            (Some(a), Some(b)) => {
                (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(f64::MIN_POSITIVE)
            }
            (a, b) => a.is_none() && b.is_none(),
        };
        if !same_level {
            return Err(mismatch(
                "level",
                format!("{:?}", logged.level),
                format!("{:?}", t.level),
            ));
        }
        let outcome = self.respond(response)?;
        if outcome != *logged_outcome {
            return Err(mismatch(
                "outcome",
                format!("{logged_outcome:?}"),
                format!("{outcome:?}"),
            ));
        }
        Ok(())
    }

    /// The trials that can follow the pending one at session clock `elapsed_ms`, one per
    /// answer that leads somewhere different, without changing this session. For a staircase
    /// trial these are the next trial after a correct and after a wrong choice; for MOS and
    /// DSCQS the next trial does not depend on the answer, so there is at most one. A runner
    /// uses this to prepare the next stimulus (a live staircase encodes it) while the subject
    /// watches the current one. Empty when no trial is pending or the session ends after it.
    pub fn lookahead(&self, elapsed_ms: u64) -> Vec<Trial> {
        let Some(trial) = &self.pending else {
            return Vec::new();
        };
        let answers = crate::methods::of(self.protocol).distinct_answers(trial, &self.scale);
        let mut next: Vec<Trial> = Vec::with_capacity(answers.len());
        for answer in answers {
            let mut branch = self.clone();
            let response = Response {
                answer,
                response_time_ms: 0,
                replays: 0,
                dropped_frames: 0,
            };
            if branch.respond(&response).is_err() {
                continue;
            }
            if let Ok(Some(t)) = branch.next_trial(elapsed_ms)
                && !next.contains(&t)
            {
                next.push(t);
            }
        }
        next
    }

    /// Whether plan trial `i` (> 0) begins a new MUSHRA screen: its clip or its block differs
    /// from the one before (a plan has one test screen per clip; a training screen of the
    /// clip may come right before it).
    fn screen_start(&self, i: usize) -> bool {
        match (
            i.checked_sub(1).and_then(|p| self.plan.get(p)),
            self.plan.get(i),
        ) {
            (Some(a), Some(b)) => a.reference != b.reference || a.block != b.block,
            _ => true,
        }
    }

    /// The rest of the pending trial's MUSHRA screen: the pending trial and the trials after
    /// it on the same screen, in pane order (the window shows them together, then answers
    /// each in this order). A session resumed in the middle of a screen gives the panes not
    /// yet answered. Empty without a pending trial; the pending trial alone for the other
    /// protocols.
    pub fn screen(&self) -> Vec<Trial> {
        let Some(pending) = &self.pending else {
            return Vec::new();
        };
        let mut out = vec![pending.clone()];
        if !crate::methods::of(self.protocol).screens() {
            return out;
        }
        let mut i = pending.index as usize + 1;
        while let Some(t) = self.plan.get(i).filter(|_| !self.screen_start(i)) {
            out.push(t.clone());
            i += 1;
        }
        out
    }

    /// Trials planned but not shown (after a time limit, or still to come).
    pub fn not_shown(&self) -> Vec<Trial> {
        let from = self.next_index as usize + usize::from(self.pending.is_some());
        self.plan
            .get(from..)
            .map(<[Trial]>::to_vec)
            .unwrap_or_default()
    }

    /// Track name and threshold for each interleaved track: the mean of the last reversals of
    /// an up-down staircase, the posterior mean of a QUEST+ or Psi track.
    pub fn thresholds(&self) -> Vec<(String, Option<f64>)> {
        self.stairs
            .as_ref()
            .map(|s| {
                s.tracks
                    .iter()
                    .zip(&s.staircases)
                    .map(|(t, sc)| (t.name.clone(), sc.threshold()))
                    .collect()
            })
            .unwrap_or_default()
    }
}

/// Tags of the two balanced side draws of a rated plan.
const SIDES_FAMILIARIZATION: u64 = 0x6661_6d69;
const SIDES_CONDITIONS: u64 = 0x636f_6e64;

/// One thing a rated plan shows in a trial: a condition (its test stimulus, and its
/// reference where the arrangement shows one), or a pair of a pair comparison.
pub(crate) struct PlanItem {
    condition: String,
    stimulus: String,
    reference: String,
}

impl PlanItem {
    pub(crate) fn condition(c: &Condition) -> Self {
        Self {
            condition: c.stimulus.clone(),
            stimulus: c.stimulus.clone(),
            reference: c.reference.clone(),
        }
    }

    /// P.910 PC: two conditions of one clip; `b` goes in the trial's reference column and is
    /// shown at its reference position, `a` at the other.
    pub(crate) fn pair(a: &Condition, b: &Condition) -> Self {
        Self {
            condition: format!("{} vs {}", a.stimulus, b.stimulus),
            stimulus: a.stimulus.clone(),
            reference: b.stimulus.clone(),
        }
    }
}

/// The plan of a method that rates the study's conditions (MOS, DSCQS, ACR, DCR):
/// [`plan_trials`] over the familiarization conditions and the test conditions.
pub(crate) fn plan_rated_conditions(study: &StudyDefinition, subject: u32) -> Vec<Trial> {
    let items =
        |list: &[Condition]| -> Vec<PlanItem> { list.iter().map(PlanItem::condition).collect() };
    plan_trials(
        study,
        &items(&study.familiarization),
        &items(&study.conditions),
        subject,
        study.presentation.arrangement,
        study.presentation.reference_position,
    )
}

/// MOS / DSCQS / ACR / DCR / pair comparison plan (paper 000 section IV): familiarization
/// spanning the quality range first (shuffled), then the test items (conditions, or a pair
/// comparison's pairs) shuffled per subject (or in the subject's row of a balanced Latin
/// square, `[design] order`) with hidden repeats inserted.
pub(crate) fn plan_trials(
    study: &StudyDefinition,
    fam: &[PlanItem],
    items: &[PlanItem],
    subject: u32,
    arrangement: Arrangement,
    placement: ReferencePlacement,
) -> Vec<Trial> {
    let mut rng = StudyRng::new(study.seed, &[u64::from(subject), purpose::PLAN]);
    let mut fam: Vec<&PlanItem> = fam.iter().collect();
    rng.shuffle(&mut fam);
    let mut test: Vec<(usize, Block)> = (0..items.len()).map(|c| (c, Block::Test)).collect();
    match study.design.order {
        ConditionOrder::Random => rng.shuffle(&mut test),
        ConditionOrder::LatinSquare => {
            test = design::williams_row(test.len(), subject as usize)
                .into_iter()
                .map(|c| (c, Block::Test))
                .collect();
        }
    }
    let n_rep = (study.session.hidden_repeats as usize).min(test.len());
    let mut pick: Vec<usize> = (0..test.len()).collect();
    // Partial Fisher-Yates: the first n_rep entries are a uniform sample of conditions.
    for i in 0..n_rep {
        let j = i + rng.index(pick.len() - i);
        pick.swap(i, j);
    }
    for &orig in &pick[..n_rep] {
        let pos = test
            .iter()
            .position(|&(c, b)| b == Block::Test && c == orig)
            .unwrap_or(0);
        // Never next to its original (before or after) when there is room, so the repeat
        // stays hidden: insertion indices pos and pos + 1 are skipped.
        let slots = test.len() + 1;
        let at = if slots > 2 {
            let k = rng.index(slots - 2);
            if k < pos { k } else { k + 2 }
        } else {
            rng.index(slots)
        };
        test.insert(at, (orig, Block::HiddenRepeat));
    }
    // Counterbalanced sides: per condition (a hidden repeat shows the other side), and over
    // the familiarization trials apart.
    let balanced = placement == ReferencePlacement::Balanced;
    let side_of = |tag: u64, n: usize| {
        if balanced {
            design::balanced_sides(study.seed, subject, &[tag], n, arrangement)
        } else {
            Vec::new()
        }
    };
    let fam_sides = side_of(SIDES_FAMILIARIZATION, fam.len());
    let cond_sides = side_of(SIDES_CONDITIONS, items.len());
    let first = design::first_position(arrangement);
    let fam_sides = fam_sides.into_iter().chain(std::iter::repeat(first));
    let test_sides = test.iter().map(|&(c, b)| {
        let s = cond_sides.get(c).copied().unwrap_or(first);
        if b == Block::HiddenRepeat {
            s.other()
        } else {
            s
        }
    });
    let sides: Vec<Position> = fam_sides.take(fam.len()).chain(test_sides).collect();
    let test = test
        .into_iter()
        .filter_map(|(c, b)| items.get(c).map(|c| (c, b)));
    fam.into_iter()
        .map(|c| (c, Block::Familiarization))
        .chain(test)
        .zip(sides)
        .enumerate()
        .map(|(i, ((c, block), side))| Trial {
            index: i as u32,
            block,
            condition: c.condition.clone(),
            stimulus: c.stimulus.clone(),
            reference: c.reference.clone(),
            arrangement,
            reference_position: place(placement, arrangement, &mut rng, side),
            staircase: None,
            level: None,
            break_before: false,
        })
        .collect()
}
