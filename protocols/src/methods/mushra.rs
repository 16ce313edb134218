//! MUSHRA-style multi-stimulus rating (ITU-R BS.1534-3 adapted): one screen per clip with
//! its reference, the hidden reference and a low anchor among the lettered versions, each
//! rated 0-100 on its own slider. The screens and pane order are `engine`'s (`plan_mushra`),
//! the study file's `[mushra]` is `study::mushra`'s, post-screening `analysis::mushra`'s.

use std::fmt::{self, Write as _};

use super::common::presentation_time;
use super::{AnswerKind, AnswerWidget, Method};
use crate::record::{Answer, Protocol, Trial};
use crate::study::{AnchorRule, RatingScale, ReferencePlacement, StudyDefinition, mushra_screens};
use crate::texts::Planned;

/// MUSHRA screens.
pub(super) struct Mushra;

/// The default instructions of a MUSHRA study.
const INSTRUCTIONS: &str = "Each screen shows the original motion, labelled “Reference”, and beside it several \
     versions of it, lettered A, B, C ... One of them is the original itself, hidden \
     among them; rate it 100 when you find it. Rate each lettered motion from 0 (bad) \
     to 100 (excellent) against the reference on its slider: click it, drag, or press \
     Tab to go from slider to slider and the arrow keys to move one (Page Up and Page \
     Down by 10). The sliders open once every motion has played through; Replay shows \
     them again. Press Continue (Enter) when every letter has its rating.";

impl Method for Mushra {
    fn protocol(&self) -> Protocol {
        Protocol::Mushra
    }

    fn answer_kind(&self) -> AnswerKind {
        AnswerKind::Rating
    }

    fn answer_widget(&self, _study: &StudyDefinition) -> AnswerWidget {
        AnswerWidget::SliderGrid {
            question: "Rate each lettered motion against the reference, from 0 (bad) to 100 \
                       (excellent)"
                .to_string(),
        }
    }

    fn instructions(&self, _study: &StudyDefinition) -> String {
        INSTRUCTIONS.to_string()
    }

    fn planned_trials(&self, study: &StudyDefinition) -> Planned {
        // One row per rated pane: each screen's conditions, hidden reference and anchor, the
        // training screens' first.
        let training = study.mushra.as_ref().map_or(0, |m| m.training_screens) as usize;
        let panes = |s: &(String, Vec<&crate::study::Condition>)| s.1.len() + 2;
        let screens = mushra_screens(&study.conditions);
        let test: usize = screens.iter().map(panes).sum();
        let trained: usize = screens.iter().take(training).map(panes).sum();
        Planned::Exactly((test + trained) as u32)
    }

    /// Its screens (one per clip) with their panes, the anchors and the post-screening rules.
    fn describe(&self, study: &StudyDefinition, text: &mut String) -> fmt::Result {
        let Some(m) = &study.mushra else {
            return Ok(());
        };
        let screens = mushra_screens(&study.conditions);
        let rated: usize = screens.iter().map(|(_, c)| c.len() + 2).sum();
        writeln!(
            text,
            "  screens per session: {} (one per clip), {rated} rated panes in all",
            screens.len()
        )?;
        if m.training_screens > 0 {
            writeln!(
                text,
                "  training (BS.1534-3): the screen(s) of the first {} clip(s) shown first, \
                 rated, not analysed",
                m.training_screens
            )?;
        }
        for (reference, tests) in &screens {
            let anchor = m
                .anchors
                .iter()
                .find(|a| a.reference == *reference)
                .map_or("?", |a| a.stimulus.as_str());
            writeln!(
                text,
                "  screen {reference:?}: {} test conditions + hidden reference + anchor \
                 {anchor:?}",
                tests.len()
            )?;
        }
        writeln!(
            text,
            "  post-screening (BS.1534-3): excluded when the hidden reference is rated below {} \
             on more than {}% of the screens; the anchor rated above {} on more than {}%: {}",
            m.reference_below,
            100.0 * m.max_fraction,
            m.anchor_above,
            100.0 * m.max_fraction,
            match m.anchor_rule {
                AnchorRule::Report => "reported, kept",
                AnchorRule::Exclude => "excluded",
            }
        )?;
        presentation_time(text, study, screens.len() + m.training_screens as usize)
    }

    fn ordered_items(&self, study: &StudyDefinition) -> usize {
        mushra_screens(&study.conditions).len()
    }

    fn describe_reference(&self, _placement: ReferencePlacement) -> String {
        "a pane of its own, labelled; the rated stimuli shuffled over the lettered panes per \
         screen and subject"
            .to_string()
    }

    fn distinct_answers(&self, _trial: &Trial, scale: &RatingScale) -> Vec<Answer> {
        vec![Answer::Rating(scale.min)]
    }
}
