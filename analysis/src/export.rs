//! Interoperability: ratings as a tidy long CSV (R, pandas) and as a Netflix `sureal` dataset
//! file (so its MLE subject models can be run on our data).

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;

use crate::descriptive::Rating;
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
pub fn tidy_csv(ratings: &[Rating], conditions: &[ConditionInfo]) -> String {
    let by_id: HashMap<u32, &ConditionInfo> = conditions.iter().map(|c| (c.id, c)).collect();
    let mut out = String::with_capacity(ratings.len() * 32 + 64);
    out.push_str("subject,condition,codec,clip,compression_ratio,score\n");
    for r in ratings {
        let info = by_id.get(&r.condition);
        let _ = writeln!(
            out,
            "{},{},{},{},{},{}",
            r.subject,
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

/// A `sureal` dataset (Python syntax, as `sureal.tools.misc.import_python_file` reads): one
/// reference "video" per clip, one distorted entry per condition with `os` a dict from subject
/// name (`s<id>`) to score. A subject's repeated ratings of a condition are averaged, because
/// sureal's dict form takes one score per subject. References (no compression ratio) point at
/// the reference path, which is how sureal recognises hidden references.
pub fn sureal_dataset(
    name: &str,
    ratings: &[Rating],
    conditions: &[ConditionInfo],
    ref_score: f64,
) -> String {
    let mut clips: BTreeMap<&str, usize> = BTreeMap::new();
    for c in conditions {
        let next = clips.len();
        clips.entry(c.clip.as_str()).or_insert(next);
    }
    let mut scores: BTreeMap<u32, BTreeMap<u32, (f64, u32)>> = BTreeMap::new();
    for r in ratings {
        let e = scores
            .entry(r.condition)
            .or_default()
            .entry(r.subject)
            .or_insert((0.0, 0));
        e.0 += r.score;
        e.1 += 1;
    }
    let mut out = format!(
        "dataset_name = {}\nyuv_fmt = 'notyuv'\nwidth = 0\nheight = 0\nref_score = {ref_score:?}\n",
        py_str(name)
    );
    out.push_str("ref_videos = [\n");
    for (clip, id) in &clips {
        let _ = writeln!(
            out,
            "    {{'content_id': {id}, 'content_name': {}, 'path': {}}},",
            py_str(clip),
            py_str(&format!("{clip}/reference"))
        );
    }
    out.push_str("]\ndis_videos = [\n");
    for c in conditions {
        let Some(os) = scores.get(&c.id) else {
            continue;
        };
        let content_id = clips.get(c.clip.as_str()).copied().unwrap_or(0);
        let path = match c.compression_ratio {
            Some(cr) => format!("{}/{}_{cr}", c.clip, c.method()),
            None => format!("{}/reference", c.clip),
        };
        let os_text = os
            .iter()
            .map(|(s, (sum, k))| format!("'s{s}': {:?}", sum / f64::from(*k)))
            .collect::<Vec<_>>()
            .join(", ");
        let _ = writeln!(
            out,
            "    {{'asset_id': {}, 'content_id': {content_id}, 'path': {}, 'os': {{{os_text}}}}},",
            c.id,
            py_str(&path)
        );
    }
    out.push_str("]\n");
    out
}
