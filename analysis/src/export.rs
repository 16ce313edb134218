//! Interoperability: ratings as a tidy long CSV (R, pandas) and as a Netflix `sureal` dataset
//! file (so its MOS, DMOS and MLE subject models can be run on our data), and the data
//! dictionary of CSV exports as a Frictionless Data Package ([`data_package`]).

use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::{self, Write};

use crate::descriptive::Rating;
use crate::dmos::DscqsPair;
use crate::findings::ConditionInfo;
use crate::hashing::FastMap;
use crate::panel::{counting_sort, dense};
use crate::tables::csv_field;

/// Text written in pieces and handed to a writer in blocks of [`Chunks::BLOCK`] bytes, so a
/// million-row export is never one string in memory.
struct Chunks<W: Write> {
    text: String,
    out: W,
}

impl<W: Write> Chunks<W> {
    const BLOCK: usize = 1 << 16;

    fn new(out: W) -> Self {
        Self {
            text: String::with_capacity(Self::BLOCK + 1024),
            out,
        }
    }

    /// Hands the text over once a block is full.
    fn spill(&mut self) -> io::Result<()> {
        if self.text.len() >= Self::BLOCK {
            self.out.write_all(self.text.as_bytes())?;
            self.text.clear();
        }
        Ok(())
    }

    fn finish(mut self) -> io::Result<()> {
        self.out.write_all(self.text.as_bytes())?;
        self.out.flush()
    }
}

/// How many distinct floats [`FloatText`] keeps the text of.
const FLOAT_TEXTS: usize = 1 << 16;

/// The text of floats already written, by bit pattern: ratings repeat the few values of a
/// scale a million times, and formatting each anew was most of an export's time. The text is
/// `format`'s, whether it came from the cache or not.
struct FloatText {
    format: fn(f64, &mut String),
    known: FastMap<u64, Box<str>>,
}

impl FloatText {
    fn new(format: fn(f64, &mut String)) -> Self {
        Self {
            format,
            known: HashMap::default(),
        }
    }

    fn push(&mut self, out: &mut String, x: f64) {
        if let Some(text) = self.known.get(&x.to_bits()) {
            out.push_str(text);
            return;
        }
        let start = out.len();
        (self.format)(x, out);
        if self.known.len() < FLOAT_TEXTS {
            self.known.insert(x.to_bits(), out[start..].into());
        }
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
    let mut out = Vec::with_capacity(ratings.len() * 32 + 64);
    // Writing into memory cannot fail.
    let _ = write_tidy_csv(&mut out, subjects, ratings, conditions);
    String::from_utf8(out).unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned())
}

/// [`tidy_csv`] written to `out` a block at a time (a writer of its own buffers nothing more
/// than a block).
///
/// # Errors
/// The writer's.
pub fn write_tidy_csv(
    out: impl Write,
    subjects: &[String],
    ratings: &[Rating],
    conditions: &[ConditionInfo],
) -> io::Result<()> {
    let by_id: HashMap<u32, &ConditionInfo> = conditions.iter().map(|c| (c.id, c)).collect();
    // What follows the subject on every row of a condition, made once per condition.
    let mut tails: FastMap<u32, String> = FastMap::default();
    let names: Vec<String> = subjects.iter().map(|s| csv_field(s)).collect();
    let mut scores = FloatText::new(|x, out| {
        let _ = write!(out, "{x}");
    });
    let mut out = Chunks::new(out);
    out.text
        .push_str("subject,condition,codec,clip,compression_ratio,score\n");
    for r in ratings {
        match names.get(r.subject as usize) {
            Some(name) => out.text.push_str(name),
            None => {
                let _ = write!(out.text, "{}", r.subject);
            }
        }
        let tail = tails.entry(r.condition).or_insert_with(|| {
            let info = by_id.get(&r.condition);
            format!(
                ",{},{},{},{},",
                r.condition,
                info.map_or_else(String::new, |i| csv_field(&i.method())),
                info.map_or_else(String::new, |i| csv_field(&i.clip)),
                info.and_then(|i| i.compression_ratio)
                    .map_or_else(String::new, |x| x.to_string()),
            )
        });
        out.text.push_str(tail);
        scores.push(&mut out.text, r.score);
        out.text.push('\n');
        out.spill()?;
    }
    out.finish()
}

/// The type of a column of a CSV export, as a Frictionless Table Schema names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ColumnType {
    /// Text.
    String,
    /// A whole number.
    Integer,
    /// A number (a float in its shortest round-trip decimal form, never an exponent).
    Number,
    /// `TRUE` or `FALSE` (as R writes them and R, pandas and the Table Schema read them).
    Boolean,
}

impl ColumnType {
    /// The Table Schema's name of the type.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::String => "string",
            Self::Integer => "integer",
            Self::Number => "number",
            Self::Boolean => "boolean",
        }
    }
}

/// A column of a CSV export, described as a Frictionless Table Schema field
/// (<https://specs.frictionlessdata.io/table-schema/>): name, type, description and the
/// constraints known before any row is read. An empty value is a missing one.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// The header's name.
    pub name: String,
    /// Its type.
    pub kind: ColumnType,
    /// What it holds, in words.
    pub description: String,
    /// Every row has a value.
    pub required: bool,
    /// The only values it takes (text columns), in order; empty: any.
    pub values: Vec<String>,
    /// Smallest value (numbers).
    pub minimum: Option<f64>,
    /// Largest value (numbers).
    pub maximum: Option<f64>,
}

impl Column {
    /// A column of `kind` without constraints.
    pub fn new(name: impl Into<String>, kind: ColumnType, description: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            kind,
            description: description.into(),
            required: false,
            values: Vec::new(),
            minimum: None,
            maximum: None,
        }
    }

    /// The column, with a value in every row.
    #[must_use]
    pub fn required(mut self) -> Self {
        self.required = true;
        self
    }

    /// The column, taking only `values`.
    #[must_use]
    pub fn one_of<S: Into<String>>(mut self, values: impl IntoIterator<Item = S>) -> Self {
        self.values = values.into_iter().map(Into::into).collect();
        self
    }

    /// The column, at least `min`.
    #[must_use]
    pub fn at_least(mut self, min: f64) -> Self {
        self.minimum = Some(min);
        self
    }

    /// The column, within `min..=max`.
    #[must_use]
    pub fn within(mut self, min: f64, max: f64) -> Self {
        self.minimum = Some(min);
        self.maximum = Some(max);
        self
    }

    /// The Table Schema field.
    fn field(&self) -> serde_json::Value {
        let mut field = serde_json::json!({
            "name": self.name,
            "type": self.kind.as_str(),
            "description": self.description,
        });
        if self.kind == ColumnType::Boolean {
            field["trueValues"] = serde_json::json!(["TRUE"]);
            field["falseValues"] = serde_json::json!(["FALSE"]);
        }
        let mut constraints = serde_json::Map::new();
        if self.required {
            constraints.insert("required".into(), true.into());
        }
        if !self.values.is_empty() {
            constraints.insert("enum".into(), self.values.clone().into());
        }
        let bound = |x: f64| -> serde_json::Value {
            if self.kind == ColumnType::Integer && x.fract() == 0.0 && x.abs() < 9.0e15 {
                serde_json::Value::from(x as i64)
            } else {
                serde_json::Value::from(x)
            }
        };
        if let Some(x) = self.minimum {
            constraints.insert("minimum".into(), bound(x));
        }
        if let Some(x) = self.maximum {
            constraints.insert("maximum".into(), bound(x));
        }
        if !constraints.is_empty() {
            field["constraints"] = constraints.into();
        }
        field
    }
}

/// A CSV file of a data package: its file name, what it holds and its columns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Resource<'a> {
    /// File name, relative to the package's folder (`trials_tidy.csv`).
    pub path: &'a str,
    /// What a row is, in words.
    pub description: &'a str,
    /// Its columns, in order.
    pub columns: &'a [Column],
}

/// A Frictionless Data Package (`datapackage.json`, profile `tabular-data-package`,
/// <https://specs.frictionlessdata.io/data-package/>) describing CSV `resources`: each one's
/// dialect (comma, header row, `"` quotes doubled), its Table Schema (every column's name,
/// type, description and constraints) and that an empty value is a missing one. `name` is
/// made a valid package name (lower case; letters, digits, `-`, `_`, `.`).
pub fn data_package(name: &str, title: &str, resources: &[Resource<'_>]) -> String {
    let slug = |s: &str| -> String {
        s.chars()
            .map(|c| {
                let c = c.to_ascii_lowercase();
                if c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.') {
                    c
                } else {
                    '-'
                }
            })
            .collect()
    };
    let resources: Vec<serde_json::Value> = resources
        .iter()
        .map(|r| {
            serde_json::json!({
                "name": slug(r.path.trim_end_matches(".csv")),
                "path": r.path,
                "profile": "tabular-data-resource",
                "description": r.description,
                "format": "csv",
                "mediatype": "text/csv",
                "encoding": "utf-8",
                "dialect": {"delimiter": ",", "header": true, "doubleQuote": true, "quoteChar": "\""},
                "schema": {
                    "fields": r.columns.iter().map(Column::field).collect::<Vec<_>>(),
                    "missingValues": [""],
                },
            })
        })
        .collect();
    let package = serde_json::json!({
        "profile": "tabular-data-package",
        "name": slug(name),
        "title": title,
        "resources": resources,
    });
    // A `Value` always serializes.
    serde_json::to_string_pretty(&package).unwrap_or_default() + "\n"
}

/// The columns of [`tidy_csv`] (`ratings.csv`), described.
pub fn ratings_columns() -> Vec<Column> {
    use ColumnType::{Integer, Number, String};
    vec![
        Column::new("subject", String, "Subject id, as the sessions record it.").required(),
        Column::new(
            "condition",
            Integer,
            "Condition number of the analysis (the report's \"Condition ids\" name each).",
        )
        .required()
        .at_least(0.0),
        Column::new(
            "codec",
            String,
            "The condition's method: the codec, with its varied parameters when it has any; empty for an unknown condition.",
        ),
        Column::new(
            "clip",
            String,
            "The source clip; empty for an unknown condition.",
        ),
        Column::new(
            "compression_ratio",
            Number,
            "Compression ratio x of x:1; empty for a reference.",
        ),
        Column::new("score", Number, "The rating as the analysis takes it.").required(),
    ]
}

fn py_str(s: &str) -> String {
    format!("'{}'", s.replace('\\', "\\\\").replace('\'', "\\'"))
}

/// A float as a Python literal (`{:?}` gives `4.5`, `1e-7`; non-finite values, which the
/// converters reject before here, become `float('nan')` and the like, which sureal reads as
/// missing or as they are).
fn py_float(x: f64) -> String {
    let mut out = String::new();
    push_py_float(x, &mut out);
    out
}

fn push_py_float(x: f64, out: &mut String) {
    if x.is_finite() {
        let _ = write!(out, "{x:?}");
    } else if x.is_nan() {
        out.push_str("float('nan')");
    } else if x > 0.0 {
        out.push_str("float('inf')");
    } else {
        out.push_str("float('-inf')");
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

/// Rows grouped by condition and, within a condition, by subject (each in ascending id), each
/// group in row order: two stable counting sorts over dense ids.
struct Cells {
    /// Sorted unique condition ids.
    conditions: Vec<u32>,
    /// Rows of `conditions[k]`: `order[starts[k]..starts[k + 1]]`.
    starts: Vec<usize>,
    /// Row numbers by (condition, subject, row).
    order: Vec<u32>,
}

impl Cells {
    fn new(subject: &[u32], condition: &[u32]) -> Self {
        let (subjects, s) = dense(subject);
        let (conditions, c) = dense(condition);
        let rows: Vec<u32> = (0..subject.len() as u32).collect();
        let by_subject = counting_sort(&rows, &s, subjects.len());
        drop(rows);
        let order = counting_sort(&by_subject, &c, conditions.len());
        let mut starts = vec![0usize; conditions.len() + 1];
        for k in &c {
            starts[*k as usize + 1] += 1;
        }
        for k in 0..conditions.len() {
            starts[k + 1] += starts[k];
        }
        Self {
            conditions,
            starts,
            order,
        }
    }

    /// The rows of condition `id` in (subject, row) order; `None` when it has none.
    fn of(&self, id: u32) -> Option<&[u32]> {
        let k = self.conditions.binary_search(&id).ok()?;
        Some(&self.order[self.starts[k]..self.starts[k + 1]])
    }
}

/// Where an entry's opinion scores come from: the rows of one condition in [`Cells`], and
/// every row's subject and score.
struct Scores<'c> {
    /// Rows into `subjects` and `scores`, by subject, each subject's in row order.
    rows: &'c [u32],
    subjects: &'c [u32],
    values: &'c [f64],
}

impl SurealDataset<'_> {
    fn push_subject_name(&self, out: &mut String, id: u32) {
        match self.subjects.get(id as usize) {
            Some(name) if !name.is_empty() => out.push_str(&py_str(name)),
            _ => out.push_str(&py_str(&format!("s{id}"))),
        }
    }

    /// `SUBJECT: [score, ...], ...`: the rows in (subject, row) order, one list per subject.
    fn push_os<W: Write>(
        &self,
        out: &mut Chunks<W>,
        names: &mut FastMap<u32, String>,
        floats: &mut FloatText,
        scores: &Scores<'_>,
    ) -> io::Result<()> {
        let mut previous: Option<u32> = None;
        for &row in scores.rows {
            let row = row as usize;
            let subject = scores.subjects[row];
            if previous == Some(subject) {
                out.text.push_str(", ");
            } else {
                if previous.is_some() {
                    out.text.push_str("], ");
                }
                let name = names.entry(subject).or_insert_with(|| {
                    let mut name = String::new();
                    self.push_subject_name(&mut name, subject);
                    name
                });
                out.text.push_str(name);
                out.text.push_str(": [");
                previous = Some(subject);
            }
            floats.push(&mut out.text, scores.values[row]);
            out.spill()?;
        }
        if previous.is_some() {
            out.text.push(']');
        }
        Ok(())
    }

    #[expect(
        clippy::too_many_arguments,
        reason = "one entry's fields and the writer's caches; a struct would only rename them"
    )]
    fn write_entry<W: Write>(
        &self,
        out: &mut Chunks<W>,
        names: &mut FastMap<u32, String>,
        floats: &mut FloatText,
        asset: u32,
        content: usize,
        path: &str,
        scores: &Scores<'_>,
    ) -> io::Result<()> {
        let _ = write!(
            out.text,
            "    {{'asset_id': {asset}, 'content_id': {content}, 'path': {}, 'os': {{",
            py_str(path)
        );
        self.push_os(out, names, floats, scores)?;
        out.text.push_str("}},\n");
        out.spill()
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
        let mut out = Vec::new();
        // Writing into memory cannot fail.
        let _ = self.write_python(&mut out);
        String::from_utf8(out)
            .unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned())
    }

    /// The dataset's head: its name, scale and reference videos (`contents`: name and path),
    /// up to the list of distorted videos.
    fn write_header<W: Write>(
        &self,
        out: &mut Chunks<W>,
        contents: &[(String, String)],
    ) -> io::Result<()> {
        let _ = write!(
            out.text,
            "dataset_name = {}\nyuv_fmt = 'notyuv'\nwidth = 0\nheight = 0\nref_score = {}\n",
            py_str(self.name),
            py_float(self.ref_score)
        );
        out.text.push_str("ref_videos = [\n");
        for (id, (name, path)) in contents.iter().enumerate() {
            let _ = writeln!(
                out.text,
                "    {{'content_id': {id}, 'content_name': {}, 'path': {}}},",
                py_str(name),
                py_str(path)
            );
            out.spill()?;
        }
        Ok(())
    }

    /// [`Self::to_python`] written to `out` a block at a time, from the ratings grouped by
    /// condition and subject in place (no map per condition and subject, no string per
    /// score).
    ///
    /// # Errors
    /// The writer's.
    pub fn write_python(&self, out: impl Write) -> io::Result<()> {
        // The pairs, and the ratings of conditions without pairs, by condition and subject.
        let pair_subjects: Vec<u32> = self.dscqs.iter().map(|p| p.subject).collect();
        let pairs = Cells::new(
            &pair_subjects,
            &self.dscqs.iter().map(|p| p.condition).collect::<Vec<_>>(),
        );
        let test_scores: Vec<f64> = self.dscqs.iter().map(|p| p.test_score).collect();
        let reference_scores: Vec<f64> = self.dscqs.iter().map(|p| p.reference_score).collect();
        let paired = |c: u32| pairs.conditions.binary_search(&c).is_ok();
        let (mut rated_subjects, mut rated_conditions, mut rated_scores) =
            (Vec::new(), Vec::new(), Vec::new());
        for r in self.ratings.iter().filter(|r| !paired(r.condition)) {
            rated_subjects.push(r.subject);
            rated_conditions.push(r.condition);
            rated_scores.push(r.score);
        }
        let rated = Cells::new(&rated_subjects, &rated_conditions);
        drop(rated_conditions);
        let path_of = |c: &ConditionInfo| match c.compression_ratio {
            Some(cr) => format!("{}/{}_{cr}", c.clip, c.method()),
            None => format!("{}/reference", c.clip),
        };
        // (content name, reference path) by content id, and the entries in file order:
        // (asset id, content id, path, scores).
        let mut contents: Vec<(String, String)> = Vec::new();
        let mut clip_content: HashMap<&str, usize> = HashMap::new();
        let mut entries: Vec<(u32, usize, String, Scores<'_>)> = Vec::new();
        let mut references_out: Vec<(usize, String, Scores<'_>)> = Vec::new();
        for c in self.conditions {
            if let Some(rows) = rated.of(c.id) {
                let content = *clip_content.entry(c.clip.as_str()).or_insert_with(|| {
                    contents.push((c.clip.clone(), format!("{}/reference", c.clip)));
                    contents.len() - 1
                });
                let scores = Scores {
                    rows,
                    subjects: &rated_subjects,
                    values: &rated_scores,
                };
                entries.push((c.id, content, path_of(c), scores));
            }
            if let Some(rows) = pairs.of(c.id) {
                let path = path_of(c);
                let ref_path = format!("{path}/reference");
                contents.push((c.clip.clone(), ref_path.clone()));
                let content = contents.len() - 1;
                let tests = Scores {
                    rows,
                    subjects: &pair_subjects,
                    values: &test_scores,
                };
                entries.push((c.id, content, path, tests));
                let references = Scores {
                    rows,
                    subjects: &pair_subjects,
                    values: &reference_scores,
                };
                references_out.push((content, ref_path, references));
            }
        }
        let mut next_asset = self.conditions.iter().map(|c| c.id + 1).max().unwrap_or(0);
        let mut out = Chunks::new(out);
        self.write_header(&mut out, &contents)?;
        out.text.push_str("]\ndis_videos = [\n");
        let (mut names, mut floats) = (FastMap::default(), FloatText::new(push_py_float));
        for (asset, content, path, scores) in &entries {
            self.write_entry(
                &mut out,
                &mut names,
                &mut floats,
                *asset,
                *content,
                path,
                scores,
            )?;
        }
        for (content, path, scores) in &references_out {
            self.write_entry(
                &mut out,
                &mut names,
                &mut floats,
                next_asset,
                *content,
                path,
                scores,
            )?;
            next_asset += 1;
        }
        out.text.push_str("]\n");
        out.finish()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

    use std::collections::BTreeMap;

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

    /// The exports as first written (a map per condition and subject, a string per score),
    /// kept as the oracle the streaming writers must match byte for byte.
    mod oracle {
        use std::collections::{BTreeMap, BTreeSet, HashMap};
        use std::fmt::Write as _;

        use super::super::{SurealDataset, csv_field, py_float, py_str};
        use crate::descriptive::Rating;
        use crate::findings::ConditionInfo;

        pub fn tidy_csv(
            subjects: &[String],
            ratings: &[Rating],
            conditions: &[ConditionInfo],
        ) -> String {
            let by_id: HashMap<u32, &ConditionInfo> =
                conditions.iter().map(|c| (c.id, c)).collect();
            let mut out = String::new();
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

        type EntryScores = BTreeMap<u32, Vec<f64>>;

        fn os_text(d: &SurealDataset<'_>, os: &EntryScores) -> String {
            os.iter()
                .map(|(&s, scores)| {
                    let list = scores
                        .iter()
                        .map(|&x| py_float(x))
                        .collect::<Vec<_>>()
                        .join(", ");
                    let name = match d.subjects.get(s as usize) {
                        Some(name) if !name.is_empty() => name.clone(),
                        _ => format!("s{s}"),
                    };
                    format!("{}: [{list}]", py_str(&name))
                })
                .collect::<Vec<_>>()
                .join(", ")
        }

        pub fn to_python(d: &SurealDataset<'_>) -> String {
            let paired: BTreeSet<u32> = d.dscqs.iter().map(|p| p.condition).collect();
            let mut rated: BTreeMap<u32, EntryScores> = BTreeMap::new();
            for r in d.ratings.iter().filter(|r| !paired.contains(&r.condition)) {
                rated
                    .entry(r.condition)
                    .or_default()
                    .entry(r.subject)
                    .or_default()
                    .push(r.score);
            }
            let mut tests: BTreeMap<u32, EntryScores> = BTreeMap::new();
            let mut references: BTreeMap<u32, EntryScores> = BTreeMap::new();
            for p in d.dscqs {
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
            let mut contents: Vec<(String, String)> = Vec::new();
            let mut clip_content: HashMap<&str, usize> = HashMap::new();
            let mut entries: Vec<(u32, usize, String, &EntryScores)> = Vec::new();
            let mut references_out: Vec<(usize, String, &EntryScores)> = Vec::new();
            for c in d.conditions {
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
            let mut next_asset = d.conditions.iter().map(|c| c.id + 1).max().unwrap_or(0);
            let mut out = format!(
                "dataset_name = {}\nyuv_fmt = 'notyuv'\nwidth = 0\nheight = 0\nref_score = {}\n",
                py_str(d.name),
                py_float(d.ref_score)
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
            let entry = |out: &mut String, asset: u32, content: usize, path: &str, os| {
                let _ = writeln!(
                    out,
                    "    {{'asset_id': {asset}, 'content_id': {content}, 'path': {}, 'os': {{{}}}}},",
                    py_str(path),
                    os_text(d, os)
                );
            };
            for (asset, content, path, os) in &entries {
                entry(&mut out, *asset, *content, path, os);
            }
            for (content, path, os) in &references_out {
                entry(&mut out, next_asset, *content, path, os);
                next_asset += 1;
            }
            out.push_str("]\n");
            out
        }
    }

    /// Random exports the way a results directory can make them and some it cannot (ids past
    /// the names, a condition listed twice or not at all, pairs and ratings of one condition,
    /// non-finite and thousands of distinct scores, names that need quoting): the streaming
    /// writers give the oracle's bytes.
    #[test]
    fn streaming_exports_match_the_oracle() {
        use rand::{RngExt as _, SeedableRng as _};
        for seed in 0..12_u64 {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
            let subjects: Vec<String> = ["S1", "", "a,b", "q\"x", "it's", "S\\6"]
                .iter()
                .take(rng.random_range(0..=6))
                .map(|s| (*s).to_owned())
                .collect();
            let mut conditions: Vec<ConditionInfo> = (0..rng.random_range(1..8_u32))
                .map(|id| {
                    let mut c = condition(
                        id * 3,
                        ["walk", "run,fast", "o'clock"][id as usize % 3],
                        (id % 4 != 0).then_some(10.0 * f64::from(id) + 0.5),
                    );
                    if id % 3 == 1 {
                        c.params.insert("qp".to_owned(), f64::from(id));
                    }
                    c
                })
                .collect();
            if seed % 3 == 0 {
                let twice = conditions[0].clone();
                conditions.push(twice);
            }
            let condition_ids = conditions.len() as u32 * 3 + 2;
            let score = |rng: &mut rand_chacha::ChaCha8Rng| match rng.random_range(0..40) {
                0 => f64::NAN,
                1 => f64::INFINITY,
                2 => 1e-7,
                k if seed % 2 == 0 => 1.0 + f64::from(k % 9) / 2.0,
                _ => rng.random::<f64>() * 100.0,
            };
            let n = if seed == 11 { 70_000 } else { 300 };
            let ratings: Vec<Rating> = (0..n)
                .map(|_| {
                    rating(
                        rng.random_range(0..9),
                        rng.random_range(0..condition_ids),
                        score(&mut rng),
                    )
                })
                .collect();
            let dscqs: Vec<DscqsPair> = (0..if seed % 4 == 1 { 200 } else { 0 })
                .map(|_| DscqsPair {
                    subject: rng.random_range(0..9),
                    condition: rng.random_range(0..condition_ids),
                    reference_score: score(&mut rng),
                    test_score: score(&mut rng),
                })
                .collect();
            let d = SurealDataset {
                name: "it's a \\ test",
                subjects: &subjects,
                ratings: &ratings,
                dscqs: &dscqs,
                conditions: &conditions,
                ref_score: 5.0,
            };
            assert_eq!(d.to_python(), oracle::to_python(&d), "seed {seed}");
            assert_eq!(
                tidy_csv(&subjects, &ratings, &conditions),
                oracle::tidy_csv(&subjects, &ratings, &conditions),
                "seed {seed}"
            );
        }
    }

    /// The data dictionary is a Table Schema other tools read: each field's name, type and
    /// description; booleans as `TRUE`/`FALSE`; an integer column's bounds as integers; the
    /// enum and `required` under `constraints`; `""` as the missing value; a package name
    /// made valid.
    #[test]
    fn data_package_describes_each_column() {
        let columns = [
            Column::new("age", ColumnType::Integer, "Age.").within(18.0, 99.0),
            Column::new("side", ColumnType::String, "Side.")
                .required()
                .one_of(["left", "right"]),
            Column::new("correct", ColumnType::Boolean, "Correct."),
            Column::new("score", ColumnType::Number, "Score.").within(1.0, 4.5),
        ];
        let text = data_package(
            "My Study 2",
            "t",
            &[Resource {
                path: "trials_tidy.csv",
                description: "rows",
                columns: &columns,
            }],
        );
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["profile"], "tabular-data-package");
        assert_eq!(v["name"], "my-study-2");
        let r = &v["resources"][0];
        assert_eq!(r["name"], "trials_tidy");
        assert_eq!(r["path"], "trials_tidy.csv");
        assert_eq!(r["schema"]["missingValues"], serde_json::json!([""]));
        let f = &r["schema"]["fields"];
        assert_eq!(f[0]["type"], "integer");
        assert_eq!(f[0]["constraints"]["minimum"], serde_json::json!(18));
        assert!(f[0]["constraints"]["minimum"].is_i64());
        assert_eq!(
            f[1]["constraints"]["enum"],
            serde_json::json!(["left", "right"])
        );
        assert_eq!(f[1]["constraints"]["required"], true);
        assert_eq!(f[2]["trueValues"], serde_json::json!(["TRUE"]));
        assert_eq!(f[2]["falseValues"], serde_json::json!(["FALSE"]));
        assert!(f[2].get("constraints").is_none());
        assert_eq!(f[3]["constraints"]["maximum"], serde_json::json!(4.5));
        assert_eq!(f[3]["description"], "Score.");
    }
}
