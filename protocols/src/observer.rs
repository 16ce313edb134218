//! Simulated observers, so a whole study can be dry-run before a subject comes in.
//!
//! A rating observer turns a stimulus's objective error into a latent quality (an exponential
//! fall from the top of the scale), adds a per-subject bias and per-trial noise, and snaps the
//! result to the scale. A 2AFC observer answers correctly with the probability of a Weibull or
//! logistic psychometric function of the level, or (`detection = "error"`) of the distorted
//! stimulus's objective error, which a live staircase's runner measures on the clip it just
//! decoded and passes in ([`Observer::respond_measured`]); guess rate 1/2 and a lapse rate. A
//! pair comparison observer (Thurstone case V) draws both stimuli's latent qualities with
//! their own noise and prefers the higher, so the conditions' true scale is known. Every
//! answer draws from a stream seeded by (seed, subject, trial index), so an answer does not
//! depend on how many answers came before it in this process (resume gives the same answers).

use crate::manifest::{REFERENCE_CODEC, SceneStimulus};
use crate::record::{Protocol, Response, Trial};
use crate::rng::{StudyRng, purpose};
use crate::study::{
    Detection, Metric, Psychometric, RatingScale, SimulationSettings, StudyDefinition,
};

/// Why an observer could not answer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ObserverError {
    /// A test stimulus has no objective metrics in the manifest.
    #[error("stimulus {id:?} has no metrics in the manifest; a simulated rating needs them")]
    NoMetrics {
        /// Stimulus id.
        id: String,
    },
    /// The stimulus is not in the manifest.
    #[error("stimulus {id:?} is not in the manifest")]
    UnknownStimulus {
        /// Stimulus id.
        id: String,
    },
    /// A 2AFC trial without a level.
    #[error("trial {trial} has no staircase level")]
    NoLevel {
        /// Trial index.
        trial: u32,
    },
}

/// A 2AFC psychometric function with guess rate γ = 1/2 and lapse λ:
/// `p(x) = γ + (1 - γ - λ) F(x)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PsychometricFunction {
    /// Family of `F`.
    pub family: Psychometric,
    /// α: Weibull scale (F = 1 - 1/e) or logistic midpoint (F = 1/2).
    pub threshold: f64,
    /// β: slope.
    pub slope: f64,
    /// λ: lapse rate.
    pub lapse: f64,
}

/// Guess rate of a two-alternative forced choice.
pub const GUESS_2AFC: f64 = 0.5;

impl PsychometricFunction {
    /// `F(x)`, the detection probability without guessing and lapses.
    pub fn detect(&self, x: f64) -> f64 {
        match self.family {
            Psychometric::Weibull => {
                if x <= 0.0 {
                    0.0
                } else {
                    1.0 - (-(x / self.threshold).powf(self.slope)).exp()
                }
            }
            Psychometric::Logistic => 1.0 / (1.0 + (-self.slope * (x - self.threshold)).exp()),
        }
    }

    /// Probability of a correct 2AFC answer at level `x`.
    pub fn p_correct(&self, x: f64) -> f64 {
        GUESS_2AFC + (1.0 - GUESS_2AFC - self.lapse) * self.detect(x)
    }

    /// The level at which `p_correct` equals `p`, or `None` when `p` is out of reach.
    pub fn level_for(&self, p: f64) -> Option<f64> {
        let f = (p - GUESS_2AFC) / (1.0 - GUESS_2AFC - self.lapse);
        if !(f > 0.0 && f < 1.0) {
            return None;
        }
        Some(match self.family {
            Psychometric::Weibull => self.threshold * (-(1.0 - f).ln()).powf(1.0 / self.slope),
            Psychometric::Logistic => self.threshold - ((1.0 - f) / f).ln() / self.slope,
        })
    }
}

/// A simulated subject.
#[derive(Debug, Clone)]
pub struct Observer {
    seed: u64,
    subject: u32,
    protocol: Protocol,
    settings: SimulationSettings,
    scale: RatingScale,
    bias: f64,
    allow_replay: bool,
    study: StudyDefinition,
}

impl Observer {
    /// Subject `subject` of a simulation seeded with `seed` for `study`.
    pub fn new(study: &StudyDefinition, seed: u64, subject: u32) -> Self {
        let mut rng = StudyRng::new(seed, &[u64::from(subject), purpose::OBSERVER_SUBJECT]);
        let bias = study.simulation.bias_sd * rng.normal();
        Self {
            seed,
            subject,
            protocol: study.protocol,
            settings: study.simulation.clone(),
            scale: study.scale,
            bias,
            allow_replay: study.presentation.max_replays != Some(0),
            study: study.clone(),
        }
    }

    /// The study this observer takes part in.
    pub fn study(&self) -> &StudyDefinition {
        &self.study
    }

    /// This subject's constant bias (drawn with SD `[simulation] bias_sd`), scale units: it
    /// shifts every rating alike (a comparison scale's: towards the second version).
    pub fn bias(&self) -> f64 {
        self.bias
    }

    /// The psychometric function of the 2AFC observer.
    pub fn psychometric(&self) -> PsychometricFunction {
        PsychometricFunction {
            family: self.settings.psychometric,
            threshold: self.settings.threshold,
            slope: self.settings.slope,
            lapse: self.settings.lapse,
        }
    }

    /// The objective error (`[simulation] metric`) of a manifest stimulus; 0 for a reference.
    ///
    /// # Errors
    /// [`ObserverError`] when the stimulus or its metrics are missing.
    pub fn manifest_error(&self, id: &str) -> Result<f64, ObserverError> {
        let s = self
            .study
            .manifest
            .get(id)
            .ok_or_else(|| ObserverError::UnknownStimulus { id: id.to_string() })?;
        if s.codec == REFERENCE_CODEC {
            return Ok(0.0);
        }
        if let Some(scene) = &s.scene {
            return self.scene_error(scene);
        }
        let m = s
            .metrics
            .ok_or_else(|| ObserverError::NoMetrics { id: id.to_string() })?;
        Ok(match self.settings.metric {
            Metric::RmsCm => m.rms_cm,
            Metric::MaxCm => m.max_cm,
            Metric::MeanAngleDeg => m.mean_angle_deg,
        })
    }

    /// The error a simulated observer sees in a crowd scene (a model of this simulator, not
    /// the thesis's): each character's error scaled by its apparent size, the nearest
    /// character's distance over its own (a figure twice as far is drawn half as tall, so its
    /// errors span half the pixels), averaged with the weights of `[simulation] attention`
    /// (by character name, else group, else 1). Run 2 of thesis 6.5 (attend to the back
    /// characters) is a study whose attention favours them.
    fn scene_error(&self, scene: &SceneStimulus) -> Result<f64, ObserverError> {
        let nearest = scene
            .characters
            .iter()
            .map(|c| c.distance_cm)
            .fold(f64::INFINITY, f64::min);
        let (mut sum, mut weights) = (0.0, 0.0);
        for c in &scene.characters {
            let a = self
                .settings
                .attention
                .get(&c.name)
                .or_else(|| self.settings.attention.get(&c.group))
                .copied()
                .unwrap_or(1.0);
            if a == 0.0 {
                continue;
            }
            let size = if c.distance_cm > 0.0 {
                nearest / c.distance_cm
            } else {
                1.0
            };
            sum += a * size * self.manifest_error(&c.stimulus)?;
            weights += a;
        }
        Ok(if weights > 0.0 { sum / weights } else { 0.0 })
    }

    /// Latent quality of a stimulus whose objective error is `error` (metric units).
    pub fn quality_of_error(&self, error: f64) -> f64 {
        let range = self.scale.max - self.scale.min;
        self.scale.min + range * (-error.max(0.0) / self.settings.quality_scale).exp()
    }

    /// The normal noise of each judgement (`[simulation] noise_sd`), in scale units.
    pub fn noise_sd(&self) -> f64 {
        self.settings.noise_sd
    }

    /// What a 2AFC observer's detection depends on (`[simulation] detection`).
    pub fn detection(&self) -> Detection {
        self.settings.detection
    }

    /// A rating of a stimulus whose objective error is `error`: its latent quality, the
    /// subject's bias and the judgement's noise, snapped to the scale.
    pub fn rate(&self, error: f64, rng: &mut StudyRng) -> f64 {
        let q = self.quality_of_error(error) + self.bias + self.settings.noise_sd * rng.normal();
        self.scale.snap(q)
    }

    /// This observer's response to `trial`, with the stimuli's errors from the manifest.
    ///
    /// # Errors
    /// [`ObserverError`] when the stimulus cannot be rated.
    pub fn respond(&self, trial: &Trial) -> Result<Response, ObserverError> {
        self.respond_measured(trial, None)
    }

    /// This observer's response to `trial` when the caller measured the objective error
    /// (`[simulation] metric`, e.g. RMS cm) of the trial's distorted stimulus itself, as a live
    /// staircase does on the clip it just decoded. `measured_error` replaces the manifest's
    /// metrics of `trial.stimulus`; with `[simulation] detection = "error"` the 2AFC
    /// observer's detection probability is the psychometric function of that error. The
    /// random draws are the same with and without it, so a resumed simulation answers as an
    /// uninterrupted one.
    ///
    /// # Errors
    /// [`ObserverError`] when an error is needed and neither given nor in the manifest.
    pub fn respond_measured(
        &self,
        trial: &Trial,
        measured_error: Option<f64>,
    ) -> Result<Response, ObserverError> {
        let test_error = || match measured_error {
            Some(e) => Ok(e),
            None => self.manifest_error(&trial.stimulus),
        };
        let mut rng = StudyRng::new(
            self.seed,
            &[
                u64::from(self.subject),
                purpose::OBSERVER_TRIAL,
                u64::from(trial.index),
            ],
        );
        let answer =
            crate::methods::of(self.protocol).simulate(self, trial, &test_error, &mut rng)?;
        let base = self.settings.response_time_ms as f64;
        let response_time_ms = (base * (0.5 + rng.unit_f64())).round() as u64;
        let replay = rng.below(10) == 0;
        // A screen shown whole (MUSHRA) is replayed whole: its panes' trials share one draw,
        // made from the screen (its reference and block), so each pane logs the screen's
        // replays as the window and the page do.
        let replay = if crate::methods::of(self.protocol).screens() {
            let reference: Vec<u64> = trial.reference.bytes().map(u64::from).collect();
            StudyRng::new(
                self.seed,
                &[
                    u64::from(self.subject),
                    purpose::OBSERVER_SCREEN,
                    trial.block as u64,
                    crate::rng::derive_seed(0, &reference),
                ],
            )
            .below(10)
                == 0
        } else {
            replay
        };
        let replays = u32::from(self.allow_replay && replay);
        Ok(Response {
            answer,
            response_time_ms,
            replays,
            dropped_frames: 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weibull_inverse_round_trips() {
        let f = PsychometricFunction {
            family: Psychometric::Weibull,
            threshold: 0.012,
            slope: 3.5,
            lapse: 0.02,
        };
        for p in [0.6, 0.707, 0.8035, 0.9] {
            let x = f.level_for(p).unwrap();
            assert!((f.p_correct(x) - p).abs() < 1e-12);
        }
        assert!(
            f.level_for(0.99).is_none(),
            "above 1 - lapse/2 is out of reach"
        );
        let g = PsychometricFunction {
            family: Psychometric::Logistic,
            threshold: 1.0,
            slope: 4.0,
            lapse: 0.0,
        };
        assert!((g.p_correct(g.level_for(0.75).unwrap()) - 0.75).abs() < 1e-12);
        assert!(
            (g.level_for(0.75).unwrap() - 1.0).abs() < 1e-12,
            "logistic midpoint is the 75 % point"
        );
    }
}
