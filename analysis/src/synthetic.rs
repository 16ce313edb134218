//! Synthetic studies with simulated observers of known behaviour: used to check that the
//! analysis recovers what was put in (threshold coverage, power by simulation) and to benchmark
//! `study report` on a million rows. Every function takes an explicit seed (ChaCha8).

use std::collections::BTreeMap;

use rand::{Rng, RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::descriptive::Rating;
use crate::findings::ConditionInfo;
use crate::psychometric::{PsychometricFit, TwoAfcTrial};
use crate::staircase::{StaircaseStep, StaircaseTrack};
use crate::study::StudyData;

/// A standard normal draw by Box–Muller (keeps the dependency list to `rand` alone).
pub fn standard_normal<R: Rng>(rng: &mut R) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Parameters of a simulated MOS study (1-5 scale in 0.5 steps, as seed 000).
#[derive(Debug, Clone, PartialEq)]
pub struct MosStudySpec {
    /// RNG seed.
    pub seed: u64,
    /// Number of subjects.
    pub subjects: u32,
    /// Clip names.
    pub clips: Vec<String>,
    /// (codec name, MOS lost per 10:1 of compression ratio above 10:1).
    pub codecs: Vec<(String, f64)>,
    /// Compression ratios tested.
    pub ratios: Vec<f64>,
    /// SD of a rating around the observer's opinion.
    pub noise_sd: f64,
    /// SD of the per-observer offset.
    pub observer_bias_sd: f64,
    /// The first this-many subjects answer at random (uniform on 1-5), the observers BT.500
    /// screening is meant to catch.
    pub erratic_subjects: u32,
    /// Times every condition is shown to every subject (≥ 1; > 1 gives hidden repeats).
    pub showings: u32,
}

impl Default for MosStudySpec {
    fn default() -> Self {
        Self {
            seed: 1,
            subjects: 15,
            clips: vec!["2_2".to_owned(), "49_14".to_owned()],
            codecs: vec![("perceptual".to_owned(), 0.35), ("wavelet".to_owned(), 0.6)],
            ratios: vec![20.0, 25.0, 30.0, 35.0, 40.0],
            noise_sd: 0.4,
            observer_bias_sd: 0.15,
            erratic_subjects: 0,
            showings: 1,
        }
    }
}

/// The true MOS of a codec at a ratio under the spec's linear model (clipped to 1-5).
pub fn true_mos(loss_per_10: f64, ratio: f64) -> f64 {
    (5.0 - loss_per_10 * (ratio - 10.0) / 10.0).clamp(1.0, 5.0)
}

/// Generates conditions and ratings of a simulated MOS study.
pub fn mos_study(spec: &MosStudySpec) -> StudyData {
    let mut rng = ChaCha8Rng::seed_from_u64(spec.seed);
    let mut conditions = Vec::new();
    let mut id = 0;
    for clip in &spec.clips {
        for (codec, _) in &spec.codecs {
            for &ratio in &spec.ratios {
                conditions.push(ConditionInfo {
                    id,
                    codec: codec.clone(),
                    params: BTreeMap::new(),
                    clip: clip.clone(),
                    compression_ratio: Some(ratio),
                });
                id += 1;
            }
        }
    }
    let loss: Vec<f64> = conditions
        .iter()
        .map(|c| {
            spec.codecs
                .iter()
                .find(|(n, _)| *n == c.codec)
                .map_or(0.0, |(_, l)| *l)
        })
        .collect();
    let mut ratings =
        Vec::with_capacity(spec.subjects as usize * conditions.len() * spec.showings as usize);
    for subject in 0..spec.subjects {
        let bias = spec.observer_bias_sd * standard_normal(&mut rng);
        for _ in 0..spec.showings.max(1) {
            for (c, l) in conditions.iter().zip(&loss) {
                let truth = true_mos(*l, c.compression_ratio.unwrap_or(10.0));
                let raw = if subject < spec.erratic_subjects {
                    1.0 + 4.0 * rng.random::<f64>()
                } else {
                    truth + bias + spec.noise_sd * standard_normal(&mut rng)
                };
                let score = ((raw * 2.0).round() / 2.0).clamp(1.0, 5.0);
                ratings.push(Rating {
                    subject,
                    condition: c.id,
                    score,
                });
            }
        }
    }
    StudyData {
        conditions,
        ratings,
        ..StudyData::default()
    }
}

/// Runs a two-down-one-up staircase (thesis §5.4: start 0.024, step 0.002) on an observer whose
/// probability of a correct answer at level x is `observer.probability(x)`. Levels never go
/// below `step`. Reversals are marked from the levels.
pub fn staircase<R: Rng>(
    rng: &mut R,
    observer: &PsychometricFit,
    subject: u32,
    start: f64,
    step: f64,
    trials: usize,
) -> (StaircaseTrack, Vec<TwoAfcTrial>) {
    let mut level = start;
    let mut streak = 0;
    let mut steps = Vec::with_capacity(trials);
    let mut afc = Vec::with_capacity(trials);
    for _ in 0..trials {
        let correct = rng.random::<f64>() < observer.probability(level);
        steps.push(StaircaseStep {
            level,
            correct,
            reversal: false,
        });
        afc.push(TwoAfcTrial { level, correct });
        if correct {
            streak += 1;
            if streak == 2 {
                streak = 0;
                // Integer steps on the grid avoid drift from repeated float subtraction.
                level = ((level / step).round() - 1.0).max(1.0) * step;
            }
        } else {
            streak = 0;
            level = ((level / step).round() + 1.0) * step;
        }
    }
    let track = StaircaseTrack {
        bayesian: false,
        logged_threshold: None,
        subject,
        label: "t_L".to_owned(),
        steps,
    }
    .with_detected_reversals();
    (track, afc)
}
