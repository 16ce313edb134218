//! The study window: a wgpu skeleton renderer, the subject's screens in egui, frame timing,
//! and the eframe (winit + wgpu) window that hosts them. The only crate with GUI
//! dependencies besides the `study` binary, which opens it (ARCHITECTURE.md).
//!
//! Layers, each testable on its own: [`scene`] (poses → shapes, camera; no GPU), [`render`]
//! (wgpu pipelines, also offscreen), [`flow`] (a trial's presentation schedule), [`timing`]
//! (frame intervals and drops), [`screens`] (egui screens over a session, driven by
//! `egui_kittest` in tests), [`native`] (the native window), [`run`] (a session's screens and
//! the display test in that window), [`test_input`] (keys from a test's script, for the
//! window's end-to-end tests), [`stills`] and [`video`] (clips drawn offscreen to a PNG, an
//! SVG or an MP4) and [`preview`] (a manifest's stimuli beside their references, with their
//! metrics, before a study is written).

pub mod flow;
pub mod native;
pub mod preview;
pub mod render;
pub mod run;
pub use lab::scene;
pub mod screens;
pub mod status;
pub mod stills;
pub mod test_input;
pub mod timing;
pub mod video;
pub mod viewing;

#[cfg(test)]
mod readable_tests;
#[cfg(test)]
mod render_tests;
#[cfg(test)]
mod ui_tests;
