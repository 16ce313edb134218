//! Which channels a compression ratio counts (issue 38, item 4).
//!
//! A CR is `4 bytes × channels × frames / stream bytes`. On the **file** basis (the default)
//! `channels` is every channel the clip's file holds: 62 for a CMU ASF/AMC clip, 96 for the
//! CMU BVH conversion (`131_01.bvh`, three rotations on every joint). The seeds count fewer:
//! "the skeleton hierarchy used was composed of 20 bones, controlled by a total of 56 DOFs
//! ... thus the input size was 56×4×(number of frames) bytes" (paper 000 §V, thesis §3.3),
//! and "30 joints with a total of 56 DOFs (53 rotational and 3 translational)" (thesis ch. 4
//! and 5). A CMU ASF has 62 channels: the root's 6 and 56 rotations of 30 bones; the seeds'
//! 56 are the root's 3 translations and 53 rotations, so 6 rotations are left out, and the
//! only 6 that make up whole bones are the hands' detail, `lfingers` (1), `lthumb` (2),
//! `rfingers` (1), `rthumb` (2), which the CMU viewer the seeds used does not animate
//! visibly and which have no bones in the seeds' 20-bone count. (That the root's 3 rotations
//! are counted as "rotational" and not left out instead is the reading that makes 53 + 3 =
//! 56 with the 3 translations.) So the **seed** basis counts:
//!
//! - an ASF skeleton: every channel but those of bones named `lfingers`, `lthumb`,
//!   `rfingers`, `rthumb` (56 of 62 for every CMU skeleton);
//! - the CMU BVH conversion (its 31 joint names, `LFingers` ... `RThumb`): each joint's
//!   degrees of freedom in the CMU ASF it was converted from (a knee's 1, not the BVH's 3),
//!   fingers and thumbs left out: 56 of 96;
//! - any other BVH: refused, naming a joint; a BVH gives every joint three rotations whatever
//!   its real freedom, and the seeds say nothing of other skeletons.
//!
//! The seed-basis CR of a stream is its file-basis CR × seed / file channels (× 56/62 =
//! 0.903 on CMU AMC, × 56/96 = 0.583 on CMU BVH): the bytes are the same, only the raw size
//! they are compared with changes.

use std::fmt;

use motion::clip::{Skeleton, SkeletonFormat};

/// The ASF bones the seed basis leaves out: the hands' fingers and thumbs.
pub const HAND_DETAIL_BONES: [&str; 4] = ["lfingers", "lthumb", "rfingers", "rthumb"];

/// The CMU BVH conversion's joints with channels, and the degrees of freedom of the CMU ASF
/// bone each was converted from.
const CMU_BVH_DOF: [(&str, usize); 31] = [
    ("Hips", 6),
    ("LHipJoint", 0),
    ("LeftHip", 3),
    ("LeftKnee", 1),
    ("LeftAnkle", 2),
    ("LeftToe", 1),
    ("RHipJoint", 0),
    ("RightHip", 3),
    ("RightKnee", 1),
    ("RightAnkle", 2),
    ("RightToe", 1),
    ("lowerback", 3),
    ("Chest", 3),
    ("Chest2", 3),
    ("lowerneck", 3),
    ("Neck", 3),
    ("Head", 3),
    ("LeftCollar", 2),
    ("LeftShoulder", 3),
    ("LeftElbow", 1),
    ("LeftWrist", 1),
    ("lhand", 2),
    ("LFingers", 1),
    ("LThumb", 2),
    ("RightCollar", 2),
    ("RightShoulder", 3),
    ("RightElbow", 1),
    ("RightWrist", 1),
    ("rhand", 2),
    ("RFingers", 1),
    ("RThumb", 2),
];

/// The CMU BVH joints the seed basis leaves out.
const CMU_BVH_HAND_DETAIL: [&str; 4] = ["LFingers", "LThumb", "RFingers", "RThumb"];

/// Which channels a CR counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CrBasis {
    /// Every channel of the clip's file.
    #[default]
    File,
    /// The degrees of freedom the seeds count (see the module docs).
    Seed,
}

/// Why a skeleton has no seed basis.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "the seeds' CR basis is defined for CMU skeletons (ASF, or the CMU BVH conversion); \
     skeleton {skeleton:?} {why}: use the file basis"
)]
pub struct NoSeedBasis {
    /// The skeleton's name.
    pub skeleton: String,
    /// What does not match.
    pub why: String,
}

impl CrBasis {
    /// Its name in files and options: `file` or `seed`.
    pub fn name(self) -> &'static str {
        match self {
            CrBasis::File => "file",
            CrBasis::Seed => "seed",
        }
    }

    /// The basis called `name`.
    pub fn parse(name: &str) -> Option<CrBasis> {
        match name {
            "file" => Some(CrBasis::File),
            "seed" => Some(CrBasis::Seed),
            _ => None,
        }
    }

    /// The channels a CR of a clip of `skeleton` counts on this basis.
    ///
    /// # Errors
    /// [`NoSeedBasis`] on the seed basis for a BVH skeleton that is not the CMU conversion.
    pub fn channels(self, skeleton: &Skeleton) -> Result<usize, NoSeedBasis> {
        let all = skeleton.channel_count();
        if self == CrBasis::File {
            return Ok(all);
        }
        match skeleton.format {
            SkeletonFormat::Asf => Ok(all
                - skeleton
                    .joints
                    .iter()
                    .filter(|j| HAND_DETAIL_BONES.contains(&j.name.as_str()))
                    .map(|j| j.dofs.len())
                    .sum::<usize>()),
            SkeletonFormat::Bvh => {
                let refuse = |why: String| NoSeedBasis {
                    skeleton: skeleton.name.clone(),
                    why,
                };
                let mut seen = 0;
                let mut dof = 0;
                for j in skeleton.joints.iter().filter(|j| !j.dofs.is_empty()) {
                    let Some(&(_, d)) = CMU_BVH_DOF.iter().find(|(n, _)| *n == j.name) else {
                        return Err(refuse(format!(
                            "has joint {:?}, which the CMU conversion does not",
                            j.name
                        )));
                    };
                    seen += 1;
                    if !CMU_BVH_HAND_DETAIL.contains(&j.name.as_str()) {
                        dof += d;
                    }
                }
                if seen != CMU_BVH_DOF.len() {
                    return Err(refuse(format!(
                        "has {seen} of the CMU conversion's {} joints",
                        CMU_BVH_DOF.len()
                    )));
                }
                Ok(dof)
            }
        }
    }

    /// The factor from a file-basis CR to this basis' for `skeleton`: channels on this basis
    /// over the file's (1 on the file basis).
    ///
    /// # Errors
    /// As [`CrBasis::channels`].
    pub fn factor(self, skeleton: &Skeleton) -> Result<f64, NoSeedBasis> {
        let all = skeleton.channel_count().max(1);
        Ok(self.channels(skeleton)? as f64 / all as f64)
    }

    /// How a report or a command names the basis for `skeleton`, e.g. `seed basis: 56 of 62
    /// channels (the seeds' DOF, fingers and thumbs left out)`.
    ///
    /// # Errors
    /// As [`CrBasis::channels`].
    pub fn describe(self, skeleton: &Skeleton) -> Result<String, NoSeedBasis> {
        let n = self.channels(skeleton)?;
        let all = skeleton.channel_count();
        Ok(match self {
            CrBasis::File => format!("file basis: all {all} channels of the file"),
            CrBasis::Seed => format!(
                "seed basis: {n} of {all} channels (the seeds' DOF, fingers and thumbs left out)"
            ),
        })
    }
}

impl fmt::Display for CrBasis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_generated_walk_and_names_are_counted() {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
        let sk = &clip.skeleton;
        assert_eq!(CrBasis::File.channels(sk).unwrap(), sk.channel_count());
        // The generated walker has no finger or thumb bones: nothing is left out.
        assert_eq!(CrBasis::Seed.channels(sk).unwrap(), sk.channel_count());
        assert_eq!(CrBasis::parse("seed"), Some(CrBasis::Seed));
        assert_eq!(CrBasis::parse("Seed"), None);
        // Converted to BVH it is no CMU skeleton: refused, naming a joint.
        let bvh = motion::convert::asf_to_bvh(&clip).unwrap();
        let e = CrBasis::Seed
            .channels(&bvh.skeleton)
            .unwrap_err()
            .to_string();
        assert!(e.contains("CMU") && e.contains("joint"), "{e}");
    }

    #[test]
    fn the_cmu_table_counts_the_seeds_56() {
        let all: usize = CMU_BVH_DOF.iter().map(|(_, d)| d).sum();
        let hands: usize = CMU_BVH_DOF
            .iter()
            .filter(|(n, _)| CMU_BVH_HAND_DETAIL.contains(n))
            .map(|(_, d)| d)
            .sum();
        // The CMU ASF's 62 channels, 6 of them the hands' detail.
        assert_eq!((all, hands), (62, 6));
    }
}
