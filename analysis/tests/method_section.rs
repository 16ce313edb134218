//! The report's "Method" section: the viewing conditions as the study states them and as the
//! sessions recorded them, observers and screening, and the design, in BT.500 / P.910's order.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::Path;

use analysis::display::SessionDisplay;
use analysis::method::{Observers, method_text};
use protocols::manifest::StimulusManifest;
use protocols::{CodecCatalog, CodecInfo, StudyDefinition};
use results::ViewingRecord;

struct NoCodecs;

impl CodecCatalog for NoCodecs {
    fn codec(&self, _: &str) -> Option<CodecInfo> {
        None
    }
    fn names(&self) -> Vec<String> {
        Vec::new()
    }
}

/// A study of `protocol` over `conditions` with the test data's manifest, then `extra`.
fn parse(protocol: &str, conditions: &str, extra: &str) -> StudyDefinition {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../protocols/tests/data/studies/stimuli.json");
    let m: StimulusManifest =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let text = format!(
        "format_version = 1\nname = \"m\"\nprotocol = \"{protocol}\"\n\
         stimuli = \"stimuli.json\"\nseed = 1\n[conditions]\n{conditions}\n{extra}"
    );
    StudyDefinition::parse(&text, Path::new("m.toml"), move |_| Ok(m), &NoCodecs)
        .unwrap_or_else(|e| panic!("{e}"))
}

fn study(extra: &str) -> StudyDefinition {
    parse(
        "mos",
        "stimuli = [\"walk/wavelet-bone/cr10\", \"walk/wavelet-bone/cr20\", \
         \"walk/wavelet-bone/cr30\"]",
        extra,
    )
}

fn session(name: &str, hz: Option<f64>, viewing: Option<ViewingRecord>) -> SessionDisplay {
    SessionDisplay {
        session: name.into(),
        description: None,
        refresh_hz: hz,
        timed_trials: 0,
        frames_shown: 0,
        dropped: 0,
        mean_interval_sd_ms: None,
        dropped_percent: None,
        flagged: false,
        browser: None,
        viewing,
        group: None,
        subject: name.split(' ').next().unwrap_or(name).into(),
        subject_fields: std::collections::BTreeMap::new(),
    }
}

#[test]
fn the_method_states_targets_measurements_observers_and_design() {
    let st = study(
        "[presentation]\nreference_position = \"balanced\"\n[design]\norder = \"latin_square\"\n\
         [viewing]\ndistance_ph = 3\nscreen_diagonal_in = 27\nscreen_resolution = [2560, 1440]\n\
         peak_luminance_cd_m2 = 150\nbackground_luminance_cd_m2 = 22.5\nroom_illuminance_lux = 20\n",
    );
    let measured = |d: f64, lux: Option<f64>| ViewingRecord {
        confirmed: true,
        confirmed_ms: Some(1),
        distance_cm: Some(d),
        peak_luminance_cd_m2: None,
        background_luminance_cd_m2: None,
        room_illuminance_lux: lux,
    };
    let displays = [
        session(
            "S1 session 1",
            Some(60.0),
            Some(measured(101.0, Some(18.0))),
        ),
        session("S2 session 1", Some(59.94), Some(measured(102.5, None))),
        session("S3 session 1", Some(60.0), Some(ViewingRecord::default())),
    ];
    let text = method_text(
        &st,
        Observers {
            sessions: 3,
            subjects: 3,
            excluded_sessions: 1,
            rejected: Some(1),
        },
        &displays,
    );
    // 27 in at 2560 × 1440: picture height 27 × 2.54 × 1440 / hypot(2560, 1440) = 33.622 cm,
    // 3 H = 100.866 cm (Python: 3*27*2.54*1440/math.hypot(2560,1440) = 100.86634744).
    let want = [
        "Observers: 3 (3 sessions). 1 session(s) excluded by the study's catch-trial rules.",
        "Screening: ITU-R BT.500 observer screening (β2 kurtosis test on every presentation); 1 \
         observer(s) rejected, 2 retained.",
        "Viewing distance: 3 H (100.866 cm) (target); measured 101–102.5 cm in 2 of 3 sessions.",
        "Display: 27 in diagonal, 2560 × 1440 px; measured 59.94–60 Hz refresh in 3 of 3 \
         sessions.",
        "Peak luminance: 150 cd/m² (target); not measured.",
        "Background luminance: 22.5 cd/m² (target); not measured.",
        "Environment: room illumination 20 lux (target); measured 18 lux in 1 of 3 sessions.",
        "Viewing conditions confirmed by the experimenter before 2 of 3 sessions.",
        "Design: conditions ordered by a balanced Latin square (Williams design, 6 rows); \
         reference position counterbalanced within and across subjects.",
        "Compression ratios (CR): 4 bytes × channels × frames / stream bytes, on the file basis: every channel of the clip's file (62 for a CMU AMC clip, 96 for a CMU BVH).",
    ];
    assert_eq!(text, want);
}

#[test]
fn a_study_without_viewing_conditions_says_so() {
    let text = method_text(
        &study(""),
        Observers {
            sessions: 1,
            subjects: 1,
            excluded_sessions: 0,
            rejected: None,
        },
        &[session("S1 session 1", None, None)],
    );
    assert!(
        text[2].starts_with("Viewing conditions: not stated by the study file"),
        "{text:?}"
    );
    // The design, then which channels the ratios count.
    assert_eq!(
        text[text.len() - 2],
        "Design: conditions in a random order per subject; reference position random per trial."
    );
    assert_eq!(
        text.last().unwrap(),
        "Compression ratios (CR): 4 bytes × channels × frames / stream bytes, on the file basis: every channel of the clip's file (62 for a CMU AMC clip, 96 for a CMU BVH)."
    );
}

/// A MUSHRA study's design: its screens (one per clip) in the subject's row of a Latin square
/// over the screens, not over the conditions; the panes shuffled, not a reference position;
/// and its training screens.
#[test]
fn a_mushra_study_states_its_screens_panes_and_training() {
    let st = parse(
        "mushra",
        "clips = [\"walk\", \"dance\"]\ncodecs = [\"wavelet-perceptual\"]\ntarget_cr = [10, 30]",
        "[mushra]\nanchors = [\"walk/wavelet-standard/cr70\", \"dance/wavelet-standard/cr70\"]\n\
         [design]\norder = \"latin_square\"\n[session]\nfamiliarization = 1\n",
    );
    let text = method_text(
        &st,
        Observers {
            sessions: 2,
            subjects: 2,
            excluded_sessions: 0,
            rejected: None,
        },
        &[session("S1 session 1", None, None)],
    );
    assert_eq!(
        text[text.len() - 2],
        "Design: screens (one per clip) ordered by a balanced Latin square (Williams design, 2 \
         rows); on each screen the tests, the hidden reference and the anchor in lettered panes \
         shuffled per screen and subject; 1 training screen(s) first (BS.1534-3's training \
         phase), not analysed."
    );
}

/// Typed subject fields are summarised once per subject: a number's range, mean and count, a
/// choice's and a yes/no's count per option in the study file's order, a text field's count;
/// an answer the field refuses (a log written before the field was typed) is counted apart.
#[test]
fn the_method_summarises_the_subjects_fields_by_kind() {
    let st = study(
        "[session]\nsubject_fields = [\"handedness\", \
         { name = \"age\", kind = \"number\", min = 18, max = 99, integer = true }, \
         { name = \"gender\", kind = \"choice\", options = [\"female\", \"male\", \"another\"] }, \
         { name = \"normal_vision\", kind = \"yes_no\", label = \"Normal vision\" }]\n",
    );
    let with = |name: &str, age: &str, gender: &str, vision: &str| {
        let mut s = session(name, None, None);
        s.subject_fields = [
            ("handedness", "left"),
            ("age", age),
            ("gender", gender),
            ("normal_vision", vision),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
        s
    };
    let sessions = [
        with("S01 session 1", "23", "female", "yes"),
        with("S02 session 1", "41", "male", "yes"),
        // The same subject's second session counts once.
        with("S02 session 2", "41", "male", "yes"),
        with("S03 session 1", "30", "female", "no"),
        with("S04 session 1", "abc", "female", "yes"),
    ];
    let text = method_text(
        &st,
        Observers {
            sessions: 5,
            subjects: 4,
            excluded_sessions: 0,
            rejected: None,
        },
        &sessions,
    );
    let line = text
        .iter()
        .find(|l| l.starts_with("Participants"))
        .unwrap_or_else(|| panic!("no participants line in {text:#?}"));
    assert_eq!(
        line,
        "Participants (4 subject(s), as stated before the session): handedness: answered by 4; \
         age: 23–41 (mean 31.3, n = 3) (and 1 answer(s) outside the field's rules, left out); \
         gender: female 3, male 1, another 0; Normal vision: yes 3, no 1."
    );
    // A study without subject fields has no such line.
    let plain = method_text(
        &study(""),
        Observers {
            sessions: 1,
            subjects: 1,
            excluded_sessions: 0,
            rejected: None,
        },
        &sessions[..1],
    );
    assert!(!plain.iter().any(|l| l.starts_with("Participants")));
}
