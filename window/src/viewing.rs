//! The experimenter's confirmation of a study's viewing conditions (`[viewing]`, ITU-R BT.500,
//! ITU-T P.910), shown before the subject's welcome screen: the study's targets beside what
//! was measured (given to `study run --measured-*`, or typed here), and "Conditions
//! confirmed", which records both in `session.json` (`viewing`).

use egui::{RichText, Ui, Vec2};
use protocols::study::ViewingSettings;
use results::ViewingRecord;

/// The measured values as the experimenter edits them.
pub struct ViewingForm {
    /// (label, unit, text) of distance, peak, background, room.
    fields: [(&'static str, &'static str, String); 4],
    /// Why the last "Conditions confirmed" was not taken.
    problem: Option<String>,
}

/// Shown on the confirmation button.
pub const CONFIRM: &str = "Conditions confirmed";

impl ViewingForm {
    /// A form over what the session's manifest already holds.
    pub fn new(record: &ViewingRecord) -> Self {
        let text = |v: Option<f64>| v.map(|v| v.to_string()).unwrap_or_default();
        Self {
            fields: [
                ("measured viewing distance", "cm", text(record.distance_cm)),
                (
                    "measured peak luminance",
                    "cd/m²",
                    text(record.peak_luminance_cd_m2),
                ),
                (
                    "measured background luminance",
                    "cd/m²",
                    text(record.background_luminance_cd_m2),
                ),
                (
                    "measured room illumination",
                    "lux",
                    text(record.room_illuminance_lux),
                ),
            ],
            problem: None,
        }
    }

    /// The record the form holds, confirmed at `now_ms`; a field that is not a number from 0
    /// to 10^6 (empty: not measured) is named instead.
    fn record(&self, now_ms: u64) -> Result<ViewingRecord, String> {
        let mut values = [None; 4];
        for (slot, (label, unit, text)) in values.iter_mut().zip(&self.fields) {
            let t = text.trim();
            if t.is_empty() {
                continue;
            }
            match t.parse::<f64>() {
                Ok(v) if v.is_finite() && (0.0..=1e6).contains(&v) => *slot = Some(v),
                _ => return Err(format!("{label}: {t:?} is not a number of {unit}")),
            }
        }
        Ok(ViewingRecord {
            confirmed: true,
            confirmed_ms: Some(now_ms),
            distance_cm: values[0],
            peak_luminance_cd_m2: values[1],
            background_luminance_cd_m2: values[2],
            room_illuminance_lux: values[3],
        })
    }

    /// Draws the screen; returns the confirmed record once the experimenter confirms.
    pub fn ui(
        &mut self,
        ui: &mut Ui,
        targets: &ViewingSettings,
        active: bool,
        now_ms: u64,
    ) -> Option<ViewingRecord> {
        let mut confirmed = None;
        egui::CentralPanel::default().show(ui, |ui| {
            ui.vertical_centered(|ui| {
                ui.add_space(24.0);
                ui.heading("Viewing conditions (experimenter)");
                ui.add_space(8.0);
                ui.label(
                    "Before the subject begins, check that the room and display are as the \
                     study states, and enter what you measured (leave a field empty if it was \
                     not measured).",
                );
            });
            ui.add_space(12.0);
            egui::Grid::new("viewing targets")
                .num_columns(2)
                .show(ui, |ui| {
                    for (what, value) in targets.describe() {
                        ui.label(format!("target {what}"));
                        ui.label(RichText::new(value).strong());
                        ui.end_row();
                    }
                    for (label, unit, text) in &mut self.fields {
                        let l = ui.label(format!("{label} ({unit})"));
                        ui.add_enabled(active, egui::TextEdit::singleline(text))
                            .labelled_by(l.id);
                        ui.end_row();
                    }
                });
            ui.add_space(12.0);
            ui.vertical_centered(|ui| {
                let button = egui::Button::new(RichText::new(CONFIRM).size(18.0))
                    .min_size(Vec2::new(220.0, 40.0));
                if ui.add_enabled(active, button).clicked() {
                    match self.record(now_ms) {
                        Ok(r) => confirmed = Some(r),
                        Err(e) => self.problem = Some(e),
                    }
                }
                if let Some(p) = &self.problem {
                    ui.label(RichText::new(p).color(egui::Color32::from_rgb(200, 60, 40)));
                }
            });
        });
        confirmed
    }
}
