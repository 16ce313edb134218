//! MUSHRA-style multi-stimulus rating (ITU-R BS.1534-3 adapted): one screen per clip with
//! its reference, the hidden reference and a low anchor among the lettered versions, each
//! rated 0-100 on its own slider. The study file's `[mushra]` is `study::mushra`'s,
//! post-screening `analysis::mushra`'s.

use std::fmt::{self, Write as _};

use super::common::presentation_time;
use super::{AnswerWidget, Method, ReferenceRule, Sections};
use crate::design;
use crate::record::{Arrangement, Block, Position, Protocol, Trial};
use crate::rng::{StudyRng, purpose};
use crate::study::{
    AnchorRule, Condition, ConditionOrder, ReferencePlacement, ScaleKind, StudyDefinition,
    mushra_screens,
};
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

    fn answer_widget(&self, study: &StudyDefinition) -> AnswerWidget {
        AnswerWidget::SliderGrid {
            question: "Rate each lettered motion against the reference, from 0 (bad) to 100 \
                       (excellent)"
                .to_string(),
            words: crate::texts::scale_words(study),
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

    fn ordered_item_name(&self) -> &'static str {
        "screens (one per clip)"
    }

    fn ordered_items(&self, conditions: &[Condition]) -> usize {
        mushra_screens(conditions).len()
    }

    fn describe_reference(&self, _placement: ReferencePlacement) -> String {
        "a pane of its own, labelled; the rated stimuli shuffled over the lettered panes per \
         screen and subject"
            .to_string()
    }

    fn plan(&self, study: &StudyDefinition, subject: u32) -> Vec<Trial> {
        plan_screens(study, subject)
    }

    fn screens(&self) -> bool {
        true
    }

    /// BS.1534 (adapted): the reference and every rated stimulus at once, in a grid.
    fn arrangements(&self) -> &'static [(&'static str, Arrangement)] {
        &[("grid", Arrangement::Grid)]
    }

    fn reference_rule(&self) -> ReferenceRule {
        ReferenceRule::None {
            why: "a MUSHRA screen shows the labelled reference in a pane of its own and \
                  shuffles the rated stimuli over the others per screen: remove it",
            placement: ReferencePlacement::Random,
        }
    }

    fn labels_hidden(&self) -> Option<&'static str> {
        Some("a MUSHRA screen labels its panes itself: Reference, then A, B, C ...")
    }

    fn default_scale_kind(&self) -> ScaleKind {
        ScaleKind::Continuous
    }

    /// BS.1534: a 0-100 slider; whole points keep it keyboard-friendly.
    fn default_scale_step(&self, _kind: ScaleKind) -> Option<f64> {
        Some(1.0)
    }

    fn check_scale(
        &self,
        kind: ScaleKind,
        min: f64,
        max: f64,
        _step: Option<f64>,
    ) -> Option<String> {
        let zero_to_hundred = kind == ScaleKind::Continuous
            && (min - 0.0).abs() < 1e-12
            && (max - 100.0).abs() < 1e-12;
        (!zero_to_hundred).then(|| {
            format!(
                "MUSHRA rates on BS.1534's continuous 0-100 scale (its post-screening limits \
                 are on it): use kind = \"continuous\", min = 0, max = 100 (or omit [scale]), \
                 not {min}..{max}"
            )
        })
    }

    fn sections(&self) -> Sections {
        Sections::Screens
    }
}

/// Tag of the pane draws of a MUSHRA study's training screens.
const MUSHRA_TRAINING: u64 = 0x7472_6169;

/// MUSHRA plan (ITU-R BS.1534-3, adapted): one screen per clip, in a random order per subject
/// (or the subject's row of a balanced Latin square over the screens, `[design] order`); on
/// each screen the clip's test conditions, its hidden reference and its anchor, shuffled over
/// the panes A, B, C ... One trial per rated stimulus, in pane order; the labelled reference
/// is every trial's `reference`. Training screens (BS.1534-3's training phase) come first:
/// the screens of the first `training_screens` clips of `[conditions]` (the same for every
/// subject, so a session's length is known up front), block `familiarization`, their panes
/// shuffled by a draw of their own, so that the test screens are those of the same study
/// without training.
fn plan_screens(study: &StudyDefinition, subject: u32) -> Vec<Trial> {
    let mut rng = StudyRng::new(study.seed, &[u64::from(subject), purpose::PLAN]);
    let mut training_rng = StudyRng::new(study.seed, &[u64::from(subject), MUSHRA_TRAINING]);
    let screens = mushra_screens(&study.conditions);
    let mut order: Vec<usize> = (0..screens.len()).collect();
    match study.design.order {
        ConditionOrder::Random => rng.shuffle(&mut order),
        ConditionOrder::LatinSquare => order = design::williams_row(order.len(), subject as usize),
    }
    let (anchors, training) = study
        .mushra
        .as_ref()
        .map(|m| (m.anchors.as_slice(), m.training_screens as usize))
        .unwrap_or_default();
    let shown = (0..training.min(screens.len()))
        .map(|k| (k, Block::Familiarization))
        .chain(order.iter().map(|&k| (k, Block::Test)));
    let mut plan = Vec::new();
    for (k, block) in shown {
        let Some((reference, tests)) = screens.get(k) else {
            continue;
        };
        let mut rated: Vec<&str> = tests.iter().map(|c| c.stimulus.as_str()).collect();
        rated.push(reference);
        rated.extend(
            anchors
                .iter()
                .filter(|a| a.reference == *reference)
                .map(|a| a.stimulus.as_str()),
        );
        match block {
            Block::Familiarization => training_rng.shuffle(&mut rated),
            _ => rng.shuffle(&mut rated),
        }
        for (pane, stimulus) in rated.into_iter().enumerate() {
            plan.push(Trial {
                index: plan.len() as u32,
                block,
                condition: stimulus.to_string(),
                stimulus: stimulus.to_string(),
                reference: reference.clone(),
                arrangement: Arrangement::Grid,
                reference_position: Position::pane(pane).unwrap_or(Position::Pane(0)),
                staircase: None,
                level: None,
                break_before: false,
            });
        }
    }
    plan
}
