//! Statistics over study results and the reports a paper needs.
//!
//! Computes, the way the seeds and the standards do: MOS with Student-t and BT.500 normal
//! confidence intervals ([`descriptive`]), DSCQS and ACR-HR DMOS ([`dmos`]), paired / Welch /
//! Student t-tests with Holm correction ([`ttest`]), power analysis ([`power`]), BT.500 Annex 2
//! observer screening ([`screening`]), staircase thresholds ([`staircase`]) and the share of
//! viewers who would notice a level ([`jnd`]), Bradley-Terry scale values of pair
//! comparisons ([`bradley_terry`]), maximum-likelihood
//! psychometric fits with bootstrap CIs ([`psychometric`]), rate findings ([`findings`]), and
//! the tables, plots and report that `study report` writes.
//!
//! Inputs are plain types ([`Rating`], [`DscqsPair`], [`StaircaseTrack`], [`TwoAfcTrial`]) so
//! the statistics do not depend on the results store's file format. Every interval's level is
//! a [`Confidence`], checked to lie in (0, 1) once, when it is made.
//!
//! ```
//! use analysis::{Confidence, summarize, ttest::{paired, Alternative}};
//! let proposed = [4.5, 4.0, 5.0, 4.5, 4.0];
//! let wavelet = [3.5, 4.0, 4.0, 3.0, 3.5];
//! let s = summarize(&proposed, Confidence::default())?;
//! assert!((s.mean - 4.4).abs() < 1e-12);
//! let test = paired(&proposed, &wavelet, Alternative::Greater)?.expect("defined");
//! assert!(test.p < 0.05);
//! # Ok::<(), analysis::AnalysisError>(())
//! ```

pub mod bayesian;
pub mod bradley_terry;
pub mod clmm;
mod confidence;
pub mod crowd;
pub mod descriptive;
pub mod display;
mod dist;
pub mod dmos;
mod error;
pub mod exclusions;
pub mod export;
pub mod findings;
pub mod from_results;
mod hashing;
pub mod jnd;
mod linalg;
pub mod method;
mod methods;
pub mod mixed;
pub mod mle;
pub mod mushra;
mod panel;
pub mod plots;
pub mod power;
pub mod psychometric;
pub mod reliability;
pub mod report;
pub mod screening;
pub mod staircase;
pub mod study;
pub mod synthetic;
pub mod tables;
pub mod ttest;

pub use confidence::Confidence;
pub use descriptive::{
    Ci, CiMethod, ConditionStats, Rating, Summary, condition_stats, from_summary_statistics,
    summarize,
};
pub use dmos::{DscqsPair, acr_hr_dmos, dscqs_dmos, zscore_by_subject};
pub use error::AnalysisError;
pub use findings::{ConditionInfo, Limit, RateFinding, RatePoint, rate_findings};
pub use psychometric::{PsychometricFit, TwoAfcTrial};
pub use staircase::{StaircaseStep, StaircaseTrack};
pub use ttest::{Alternative, TTest, Undefined};
