//! A clip described for a person: what `study clip info` prints.

use std::fmt::Write as _;

use crate::{Clip, SkeletonFormat};

/// `study clip info`'s report of `clip` (named `name`): format, joints, channels, frame
/// rate, units, each bone's part, depth and length, each channel's range, and warnings
/// (constant channels, Euler wraps, values outside the ASF limits).
pub fn describe(name: &str, clip: &Clip) -> String {
    let sk = &clip.skeleton;
    let u = sk.units;
    let mut s = String::new();
    let fmt = match sk.format {
        SkeletonFormat::Asf => "ASF/AMC",
        SkeletonFormat::Bvh => "BVH",
    };
    let _ = writeln!(s, "{name}");
    let _ = writeln!(s, "  format      {fmt} (skeleton `{}`)", sk.name);
    let points = sk.joints.len();
    let end_sites = sk.joints.iter().filter(|j| j.end_site).count();
    let _ = writeln!(s, "  joints      {points} points ({end_sites} end sites)");
    let _ = writeln!(s, "  DOF         {} channels", clip.channel_count());
    let _ = writeln!(s, "  frames      {}", clip.frames());
    let _ = writeln!(s, "  frame rate  {:.4} Hz", clip.frame_rate_hz);
    let _ = writeln!(s, "  duration    {:.3} s", clip.duration_s());
    let _ = writeln!(
        s,
        "  units       1 unit = {:.4} cm ({}), angles in degrees",
        u.cm_per_unit,
        if u.declared {
            "declared by the file"
        } else {
            "inferred from the skeleton's height"
        }
    );
    let _ = writeln!(s, "  bones       name  part  depth  length_cm");
    for j in sk.joints.iter().filter(|j| j.parent.is_some()) {
        let _ = writeln!(
            s,
            "    {:<14} {:<10} {:>2} {:>9.3}",
            j.name,
            j.body_part.name(),
            j.chain_depth,
            j.rest.length() * u.cm_per_unit
        );
    }
    let _ = writeln!(s, "  channels    name  min  max");
    let mut warnings = Vec::new();
    for c in 0..clip.channel_count() {
        let v = clip.channel(c);
        let (lo, hi) = v
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                (l.min(x), h.max(x))
            });
        let cname = clip.channel_name(c);
        let _ = writeln!(s, "    {cname:<22} {lo:>11.4} {hi:>11.4}");
        let ch = clip.channels()[c];
        #[expect(clippy::float_cmp, reason = "constant means every value is identical")]
        let constant = lo == hi;
        if clip.frames() > 1 && constant {
            warnings.push(format!("{cname} is constant ({lo})"));
        }
        if ch.kind.is_rotation() {
            let wraps = v.windows(2).filter(|w| (w[1] - w[0]).abs() > 180.0).count();
            if wraps > 0 {
                warnings.push(format!(
                    "{cname} jumps by more than 180° between frames {wraps} times (Euler wrap)"
                ));
            }
        }
        let joint = &sk.joints[ch.joint];
        let k = joint.dofs.iter().position(|d| *d == ch.kind);
        if let Some((min, max)) = k.and_then(|k| joint.limits.get(k)) {
            let out = v.iter().filter(|&&x| x < *min || x > *max).count();
            if out > 0 {
                warnings.push(format!(
                    "{cname} is outside its ASF limits ({min}, {max}) in {out} frames"
                ));
            }
        }
    }
    if warnings.is_empty() {
        let _ = writeln!(s, "  warnings    none");
    } else {
        let _ = writeln!(s, "  warnings    {}", warnings.len());
        for w in warnings {
            let _ = writeln!(s, "    - {w}");
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::describe;
    use crate::synth::{WalkParams, walking_clip};

    #[test]
    fn a_clip_is_described_with_its_counts_and_warnings() {
        let mut clip = walking_clip(&WalkParams::default());
        let text = describe("walk", &clip);
        assert!(text.starts_with("walk\n"), "{text}");
        assert!(
            text.contains(&format!("  frames      {}\n", clip.frames())),
            "{text}"
        );
        assert!(
            text.contains(&format!(
                "  DOF         {} channels\n",
                clip.channel_count()
            )),
            "{text}"
        );
        // A rotation that jumps by more than 180° between two frames is an Euler wrap.
        let c = (0..clip.channel_count())
            .find(|&c| clip.channels()[c].kind.is_rotation())
            .unwrap_or_default();
        let name = clip.channel_name(c);
        clip.channel_mut(c)[1] += 360.0;
        let text = describe("walk", &clip);
        assert!(
            text.contains(&format!(
                "{name} jumps by more than 180° between frames 2 times (Euler wrap)"
            )),
            "{text}"
        );
    }
}
