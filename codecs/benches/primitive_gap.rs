//! Why the `primitive` codec (thesis ch. 5) reaches a quarter of Table 5.1's CR at
//! `t_L = 0.01` (issue 21): what each part of the stream costs, how far the references are from
//! the segments, and the CR under the changes the thesis supports, per shared clip, each coded
//! with databases trained on the other four. Prints tables; no timing (`--bench primitive`
//! times the codec). `MOCAP_DATA=… cargo bench -p codecs --bench primitive_gap`.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

mod common;

use std::sync::Arc;

use codecs::codec::{self, CodecContext, Costs, Params, Part, PrimitiveCodec};
use codecs::primitives::{Database, SegmentParams, TrainParams};
use codecs::rate;
use motion::Clip;

const T_L: f64 = 0.01;

fn params(pairs: &[(&str, f64)]) -> Params {
    pairs.iter().map(|(k, v)| ((*k).to_string(), *v)).collect()
}

fn codec(db: Database) -> PrimitiveCodec {
    PrimitiveCodec::new(Arc::new(db))
}

fn cr(c: &PrimitiveCodec, clip: &Clip, p: &Params) -> f64 {
    let ctx = CodecContext::with_primitives(Arc::clone(c.database().unwrap()));
    let c = codec::by_name_in("primitive", &ctx).unwrap();
    c.encode(clip, p).unwrap().compression_ratio()
}

/// The primitives of `clips` trained one clip at a time and pooled per joint (thesis 5.4: "for
/// each type of motion the number of primitives ... for each joint was limited to 25").
fn pooled(clips: &[&Clip], p: &TrainParams) -> Database {
    let mut db = Database {
        segment: p.segment,
        joints: Vec::new(),
    };
    for clip in clips {
        for j in Database::train(&[clip], p, |_, _| {}).joints {
            match db.joints.iter_mut().find(|x| x.joint == j.joint) {
                Some(x) => {
                    x.primitives.extend(j.primitives);
                    x.error_rad = x.error_rad.max(j.error_rad);
                    x.segments += j.segments;
                }
                None => db.joints.push(j),
            }
        }
    }
    db
}

fn breakdown(name: &str, clip: &Clip, s: usize, c: &Costs) {
    let total: f64 = c.bits.iter().sum();
    let parts: Vec<String> = Part::ALL
        .iter()
        .map(|p| {
            let b = c.bits[*p as usize];
            format!("{} {:.0} B ({:.0} %)", p.name(), b / 8.0, 100.0 * b / total)
        })
        .collect();
    let mut r = c.reference_error.clone();
    r.sort_by(f64::total_cmp);
    let q = |f: f64| r[((r.len() - 1) as f64 * f).round() as usize];
    let within = r.iter().filter(|&&v| v <= 1.0).count();
    let raw = 4.0 * (clip.channel_count() * clip.frames()) as f64;
    let difference = c.bits[Part::Step as usize] + c.bits[Part::Coefficients as usize];
    let pct = |a: usize, b: usize| 100.0 * a as f64 / b.max(1) as f64;
    println!(
        "{name}: stream {s} B; {}; {} segments of {:.1} frames on average ({:.1} % at S_M), {} \
         coded ({:.0} %; {:.0} % of them on the 16 normalized frames), {:.1} nonzero \
         coefficients and {:.0} bits per coded segment; reference error / t_j: median {:.2}, \
         quartiles {:.2}-{:.2}, within t_j {:.0} %; CR if no difference were coded {:.1}",
        parts.join(", "),
        c.segments,
        c.segment_frames as f64 / c.segments.max(1) as f64,
        pct(c.at_max, c.segments),
        c.coded,
        pct(c.coded, c.segments),
        pct(c.normalized, c.coded),
        c.coefficients as f64 / c.coded.max(1) as f64,
        difference / c.coded.max(1) as f64,
        q(0.5),
        q(0.25),
        q(0.75),
        pct(within, r.len()),
        raw / (s as f64 - difference / 8.0),
    );
}

fn main() {
    // Criterion passes `--bench`; this target only prints.
    let clips: Vec<(String, Clip)> = common::shared_clips();
    let at = params(&[("t_l", T_L)]);
    let defaults = TrainParams::default();
    for (i, (name, clip)) in clips.iter().enumerate() {
        let others = common::others(&clips, i);
        let base = codec(Database::train(&others, &defaults, |_, _| {}));
        let (s, costs) = base.costs(clip, &at).unwrap();
        breakdown(name, clip, s.byte_len(), &costs);
        let own_length = params(&[("t_l", T_L), ("normalized", 0.0)]);
        let (s0, costs0) = base.costs(clip, &own_length).unwrap();
        breakdown(
            &format!("{name} (own length)"),
            clip,
            s0.byte_len(),
            &costs0,
        );
        let empty = codec(Database {
            segment: defaults.segment,
            joints: Vec::new(),
        });
        let own = codec(Database::train(&[clip], &defaults, |_, _| {}));
        let pool = codec(pooled(&others, &defaults));
        let (_, pool_costs) = pool.costs(clip, &at).unwrap();
        println!(
            "{name}: CR at t_L = {T_L}: database of the other four {:.1} (own length {:.1}); no \
             database (hold) {:.1}; pooled per clip ({} primitives per joint at most) {:.1} ({:.0} \
             % coded); trained on the clip itself {:.1}",
            s.compression_ratio(),
            s0.compression_ratio(),
            cr(&empty, clip, &at),
            pool.database()
                .unwrap()
                .joints
                .iter()
                .map(|j| j.primitives.len())
                .max()
                .unwrap_or(0),
            cr(&pool, clip, &at),
            100.0 * pool_costs.coded as f64 / pool_costs.segments as f64,
            cr(&own, clip, &at),
        );
        let by_sm: Vec<String> = [16, 32, 64]
            .into_iter()
            .map(|s_m| {
                let p = TrainParams {
                    segment: SegmentParams {
                        min_frames: 15,
                        max_frames: s_m,
                    },
                    ..defaults
                };
                let c = codec(Database::train(&others, &p, |_, _| {}));
                let (n, k) = c.costs(clip, &at).unwrap();
                format!(
                    "S_M {s_m}: {:.1} (own length {:.1}; {:.1} frames per segment, {:.0} % at S_M)",
                    n.compression_ratio(),
                    cr(&c, clip, &own_length),
                    k.segment_frames as f64 / k.segments as f64,
                    100.0 * k.at_max as f64 / k.segments as f64,
                )
            })
            .collect();
        println!("{name}: CR by S_M (Table 5.4): {}", by_sm.join(", "));
        let ctx = CodecContext::with_primitives(Arc::clone(base.database().unwrap()));
        let c = codec::by_name_in("primitive", &ctx).unwrap();
        let at_cr: Vec<String> = [48.0, 38.0]
            .into_iter()
            .map(
                |target| match rate::encode_to_cr(c.as_ref(), clip, &Params::new(), target) {
                    Ok(s) => {
                        let t = s.params["t_l"];
                        let (_, k) = base.costs(clip, &params(&[("t_l", t)])).unwrap();
                        format!(
                            "{target}:1 at t_L = {t:.3} rad ({:.1}°; {:.0} % coded)",
                            t.to_degrees(),
                            100.0 * k.coded as f64 / k.segments as f64
                        )
                    }
                    Err(e) => format!("{target}:1: {e}"),
                },
            )
            .collect();
        println!("{name}: {}", at_cr.join("; "));
        let lo = cr(&base, clip, &params(&[("t_l", 1e-4)]));
        let hi = cr(&base, clip, &params(&[("t_l", 1.0)]));
        println!("{name}: t_l from 1e-4 to 1 spans {lo:.1}:1 to {hi:.1}:1");
    }
    rate_searches(&clips);
}

/// Encodes per rate search (docs/codecs.md), database of charleston1, pirouette, 02_01.
fn rate_searches(clips: &[(String, Clip)]) {
    let three: Vec<&Clip> = clips
        .iter()
        .filter(|(n, _)| ["charleston1", "pirouette", "02_01"].contains(&n.as_str()))
        .map(|(_, c)| c)
        .collect();
    let db = Arc::new(Database::train(&three, &TrainParams::default(), |_, _| {}));
    let c = codec::by_name_in("primitive", &CodecContext::with_primitives(db)).unwrap();
    for target in [10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0] {
        let counts: Vec<String> = clips
            .iter()
            .map(|(name, clip)| {
                match rate::search_to_cr(c.as_ref(), clip, &Params::new(), target) {
                    Ok(s) => format!("{name} {}", s.encodes),
                    Err(e) => format!("{name} ({e})"),
                }
            })
            .collect();
        println!("rate search to {target}:1: encodes {}", counts.join(", "));
    }
}
