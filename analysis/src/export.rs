//! Interoperability: ratings as a tidy long CSV (R, pandas) and as a Netflix `sureal` dataset
//! file (so its MOS, DMOS and MLE subject models can be run on our data).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;

use crate::descriptive::Rating;
use crate::dmos::DscqsPair;
use crate::findings::ConditionInfo;

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_owned()
    }
}

/// One row per rating: `subject,condition,codec,clip,compression_ratio,score` (empty ratio for
/// references, empty codec and clip for unknown conditions); `codec` is the condition's method,
/// with its varied parameters when it has any ([`ConditionInfo::method`]). Reads with `pandas.read_csv` and
/// `readr::read_csv` as is.
///
/// `subjects` names the numeric subjects (their ids from the results, as
/// [`crate::study::StudyData::subjects`]); a subject past its end is written as its number.
pub fn tidy_csv(subjects: &[String], ratings: &[Rating], conditions: &[ConditionInfo]) -> String {
    let by_id: HashMap<u32, &ConditionInfo> = conditions.iter().map(|c| (c.id, c)).collect();
    let mut out = String::with_capacity(ratings.len() * 32 + 64);
    out.push_str("subject,condition,codec,clip,compression_ratio,score\n");
    for r in ratings {
        let info = by_id.get(&r.condition);
        let _ = writeln!(
            out,
            "{},{},{},{},{},{}",
            subjects
                .get(r.subject as usize)
                .map_or_else(|| r.subject.to_string(), |s| csv_field(s)),
            r.condition,
            info.map_or_else(String::new, |i| csv_field(&i.method())),
            info.map_or_else(String::new, |i| csv_field(&i.clip)),
            info.and_then(|i| i.compression_ratio)
                .map_or_else(String::new, |x| x.to_string()),
            r.score
        );
    }
    out
}

fn py_str(s: &str) -> String {
    format!("'{}'", s.replace('\\', "\\\\").replace('\'', "\\'"))
}

/// A float as a Python literal (`{:?}` gives `4.5`, `1e-7`; non-finite values, which the
/// converters reject before here, become `float('nan')` and the like, which sureal reads as
/// missing or as they are).
fn py_float(x: f64) -> String {
    if x.is_finite() {
        format!("{x:?}")
    } else if x.is_nan() {
        "float('nan')".to_owned()
    } else if x > 0.0 {
        "float('inf')".to_owned()
    } else {
        "float('-inf')".to_owned()
    }
}

/// The inputs of a Netflix `sureal` dataset file ([`SurealDataset::to_python`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurealDataset<'a> {
    /// `dataset_name`.
    pub name: &'a str,
    /// Subject names (ids such as `S005`), indexed by the numeric subject id of the ratings
    /// ([`crate::study::StudyData::subjects`]); an id past the end, or with an
    /// empty name, is written `s<id>`.
    pub subjects: &'a [String],
    /// Absolute ratings (MOS studies, hidden references and hidden repeats included).
    pub ratings: &'a [Rating],
    /// DSCQS pairs. Conditions that have pairs are written from them (test and reference
    /// scores); their entries in `ratings` (`from_results` copies the test scores there) are
    /// skipped.
    pub dscqs: &'a [DscqsPair],
    /// What each condition id is; ratings of conditions not listed here are left out.
    pub conditions: &'a [ConditionInfo],
    /// `ref_score`: the score sureal's DMOS gives an unimpaired stimulus (the top of the scale).
    pub ref_score: f64,
}

/// Scores of one entry: subject id → that subject's scores, in presentation order.
type EntryScores = BTreeMap<u32, Vec<f64>>;

impl SurealDataset<'_> {
    fn subject_name(&self, id: u32) -> String {
        match self.subjects.get(id as usize) {
            Some(name) if !name.is_empty() => name.clone(),
            _ => format!("s{id}"),
        }
    }

    fn os_text(&self, os: &EntryScores) -> String {
        os.iter()
            .map(|(&s, scores)| {
                let list = scores
                    .iter()
                    .map(|&x| py_float(x))
                    .collect::<Vec<_>>()
                    .join(", ");
                format!("{}: [{list}]", py_str(&self.subject_name(s)))
            })
            .collect::<Vec<_>>()
            .join(", ")
    }

    fn write_entry(
        &self,
        out: &mut String,
        asset: u32,
        content: usize,
        path: &str,
        os: &EntryScores,
    ) {
        let _ = writeln!(
            out,
            "    {{'asset_id': {asset}, 'content_id': {content}, 'path': {}, 'os': {{{}}}}},",
            py_str(path),
            self.os_text(os)
        );
    }

    /// The dataset as Python source, as `sureal.tools.misc.import_python_file` (and so every
    /// `SubjectiveModel.from_dataset_file`) reads it, with the opinion scores of each
    /// distorted entry in sureal's dictionary form, `'os': {subject: [score, ...]}`: every
    /// score a subject gave the condition, hidden repeats included, as a list in
    /// presentation order (sureal's `RawDatasetReader` takes a list per subject and lays the
    /// repeats along the third axis of its opinion-score array; a subject who did not rate
    /// a condition is absent from its dict).
    ///
    /// Contents and references, as sureal's DMOS models find them (a distorted entry whose
    /// `path` equals its content's reference `path` is that content's reference):
    /// - ratings: one content per clip, its reference at `CLIP/reference`; a condition
    ///   without compression ratio (a hidden reference, ACR-HR) is written with that path, so
    ///   `DmosModel` runs wherever every clip's reference was rated;
    /// - DSCQS pairs: one content per test condition, whose reference entry holds the scores
    ///   the subjects gave the reference in that condition's pairs (path
    ///   `CLIP/METHOD_CR/reference`, asset ids after the largest condition id), so sureal's
    ///   DMOS of the condition is `ref_score` + mean(test) − mean(reference of its pairs).
    ///
    /// `asset_id` is the condition id.
    pub fn to_python(&self) -> String {
        let paired: BTreeSet<u32> = self.dscqs.iter().map(|p| p.condition).collect();
        let mut rated: BTreeMap<u32, EntryScores> = BTreeMap::new();
        for r in self
            .ratings
            .iter()
            .filter(|r| !paired.contains(&r.condition))
        {
            rated
                .entry(r.condition)
                .or_default()
                .entry(r.subject)
                .or_default()
                .push(r.score);
        }
        let mut tests: BTreeMap<u32, EntryScores> = BTreeMap::new();
        let mut references: BTreeMap<u32, EntryScores> = BTreeMap::new();
        for p in self.dscqs {
            tests
                .entry(p.condition)
                .or_default()
                .entry(p.subject)
                .or_default()
                .push(p.test_score);
            references
                .entry(p.condition)
                .or_default()
                .entry(p.subject)
                .or_default()
                .push(p.reference_score);
        }
        let path_of = |c: &ConditionInfo| match c.compression_ratio {
            Some(cr) => format!("{}/{}_{cr}", c.clip, c.method()),
            None => format!("{}/reference", c.clip),
        };
        // (content name, reference path) by content id, and the entries in file order:
        // (asset id, content id, path, scores).
        let mut contents: Vec<(String, String)> = Vec::new();
        let mut clip_content: HashMap<&str, usize> = HashMap::new();
        let mut entries: Vec<(u32, usize, String, &EntryScores)> = Vec::new();
        let mut references_out: Vec<(usize, String, &EntryScores)> = Vec::new();
        for c in self.conditions {
            if let Some(os) = rated.get(&c.id) {
                let content = *clip_content.entry(c.clip.as_str()).or_insert_with(|| {
                    contents.push((c.clip.clone(), format!("{}/reference", c.clip)));
                    contents.len() - 1
                });
                entries.push((c.id, content, path_of(c), os));
            }
            if let (Some(os), Some(ref_os)) = (tests.get(&c.id), references.get(&c.id)) {
                let path = path_of(c);
                let ref_path = format!("{path}/reference");
                contents.push((c.clip.clone(), ref_path.clone()));
                let content = contents.len() - 1;
                entries.push((c.id, content, path, os));
                references_out.push((content, ref_path, ref_os));
            }
        }
        let mut next_asset = self.conditions.iter().map(|c| c.id + 1).max().unwrap_or(0);
        let mut out = format!(
            "dataset_name = {}\nyuv_fmt = 'notyuv'\nwidth = 0\nheight = 0\nref_score = {}\n",
            py_str(self.name),
            py_float(self.ref_score)
        );
        out.push_str("ref_videos = [\n");
        for (id, (name, path)) in contents.iter().enumerate() {
            let _ = writeln!(
                out,
                "    {{'content_id': {id}, 'content_name': {}, 'path': {}}},",
                py_str(name),
                py_str(path)
            );
        }
        out.push_str("]\ndis_videos = [\n");
        for (asset, content, path, os) in &entries {
            self.write_entry(&mut out, *asset, *content, path, os);
        }
        for (content, path, os) in &references_out {
            self.write_entry(&mut out, next_asset, *content, path, os);
            next_asset += 1;
        }
        out.push_str("]\n");
        out
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

    use super::*;

    fn condition(id: u32, clip: &str, cr: Option<f64>) -> ConditionInfo {
        ConditionInfo {
            id,
            codec: if cr.is_some() { "wavelet" } else { "reference" }.to_owned(),
            params: BTreeMap::new(),
            clip: clip.to_owned(),
            compression_ratio: cr,
        }
    }

    fn rating(subject: u32, condition: u32, score: f64) -> Rating {
        Rating {
            subject,
            condition,
            score,
        }
    }

    fn line_of<'a>(py: &'a str, needle: &str) -> &'a str {
        py.lines()
            .find(|l| l.contains(needle))
            .unwrap_or_else(|| panic!("no line with {needle:?} in\n{py}"))
    }

    #[test]
    fn export_keeps_repeats_as_lists_under_subject_ids() {
        let conditions = [condition(0, "2_2", Some(20.0)), condition(1, "2_2", None)];
        let ratings = [
            rating(0, 0, 4.0),
            rating(1, 0, 3.5),
            rating(0, 1, 5.0),
            rating(0, 0, 4.5),
            rating(2, 0, 3.0),
        ];
        let subjects = ["S005".to_owned(), "S012".to_owned()];
        let py = SurealDataset {
            name: "it's",
            subjects: &subjects,
            ratings: &ratings,
            dscqs: &[],
            conditions: &conditions,
            ref_score: 5.0,
        }
        .to_python();
        assert!(py.starts_with("dataset_name = 'it\\'s'\n"), "{py}");
        assert_eq!(
            line_of(&py, "'asset_id': 0,"),
            "    {'asset_id': 0, 'content_id': 0, 'path': '2_2/wavelet_20', \
             'os': {'S005': [4.0, 4.5], 'S012': [3.5], 's2': [3.0]}},"
        );
        // The hidden reference is the content's reference: same path.
        assert_eq!(
            line_of(&py, "'asset_id': 1,"),
            "    {'asset_id': 1, 'content_id': 0, 'path': '2_2/reference', 'os': {'S005': [5.0]}},"
        );
        assert_eq!(
            line_of(&py, "'content_id': 0, 'content_name'"),
            "    {'content_id': 0, 'content_name': '2_2', 'path': '2_2/reference'},"
        );
        assert_eq!(py.matches("'content_name'").count(), 1);
    }

    #[test]
    fn dscqs_export_carries_the_reference_ratings_of_each_condition() {
        let conditions = [
            condition(0, "2_2", Some(20.0)),
            condition(1, "49_14", Some(30.0)),
        ];
        let pair = |subject, condition, reference_score, test_score| DscqsPair {
            subject,
            condition,
            reference_score,
            test_score,
        };
        let dscqs = [
            pair(0, 0, 5.0, 4.0),
            pair(1, 0, 4.5, 3.0),
            pair(0, 1, 4.0, 2.0),
            pair(0, 0, 4.0, 3.5),
        ];
        // from_results copies the test scores into the ratings: they must not come twice.
        let ratings: Vec<Rating> = dscqs
            .iter()
            .map(|p| rating(p.subject, p.condition, p.test_score))
            .collect();
        let subjects = ["S1".to_owned(), "S2".to_owned()];
        let py = SurealDataset {
            name: "d",
            subjects: &subjects,
            ratings: &ratings,
            dscqs: &dscqs,
            conditions: &conditions,
            ref_score: 5.0,
        }
        .to_python();
        assert_eq!(
            line_of(&py, "'asset_id': 0,"),
            "    {'asset_id': 0, 'content_id': 0, 'path': '2_2/wavelet_20', \
             'os': {'S1': [4.0, 3.5], 'S2': [3.0]}},"
        );
        assert_eq!(
            line_of(&py, "'asset_id': 2,"),
            "    {'asset_id': 2, 'content_id': 0, 'path': '2_2/wavelet_20/reference', \
             'os': {'S1': [5.0, 4.0], 'S2': [4.5]}},"
        );
        assert_eq!(
            line_of(&py, "'asset_id': 3,"),
            "    {'asset_id': 3, 'content_id': 1, 'path': '49_14/wavelet_30/reference', \
             'os': {'S1': [4.0]}},"
        );
        assert_eq!(
            line_of(&py, "'content_id': 1, 'content_name'"),
            "    {'content_id': 1, 'content_name': '49_14', 'path': '49_14/wavelet_30/reference'},"
        );
        assert_eq!(py.matches("'asset_id'").count(), 4);
    }

    #[test]
    fn non_finite_values_are_python_literals() {
        assert_eq!(py_float(1e-7), "1e-7");
        assert_eq!(py_float(f64::NAN), "float('nan')");
        assert_eq!(py_float(f64::NEG_INFINITY), "float('-inf')");
    }
}
