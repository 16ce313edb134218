//! `[rendering]`: how the runner draws the figures (nothing a protocol decides).

use serde::{Deserialize, Serialize};
use toml::Table;

use super::check::Ctx;

/// Rendering settings (`[rendering]`); every key has a default, so a study file without the
/// table loads as before.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RenderingSettings {
    /// Draw a ground shadow under each figure (a contact cue for foot sliding); default on.
    pub ground_shadow: bool,
}

impl Default for RenderingSettings {
    fn default() -> Self {
        RenderingSettings {
            ground_shadow: true,
        }
    }
}

pub(super) fn parse_rendering(t: &Table, cx: &mut Ctx) -> RenderingSettings {
    const R: &str = "rendering";
    cx.known(t, R, &["ground_shadow"]);
    RenderingSettings {
        ground_shadow: cx
            .boolean(t, R, "ground_shadow")
            .unwrap_or(RenderingSettings::default().ground_shadow),
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use crate::catalog::{CodecCatalog, CodecInfo};
    use crate::manifest::StimulusManifest;
    use crate::study::{StudyDefinition, StudyError};

    struct NoCodecs;

    impl CodecCatalog for NoCodecs {
        fn codec(&self, _: &str) -> Option<CodecInfo> {
            None
        }
        fn names(&self) -> Vec<String> {
            Vec::new()
        }
    }

    fn examples() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
    }

    /// The example MOS study with `extra` appended.
    fn parse(extra: &str) -> Result<StudyDefinition, StudyError> {
        let text = std::fs::read_to_string(examples().join("mos.toml")).unwrap() + extra;
        let json = std::fs::read_to_string(examples().join("stimuli.json")).unwrap();
        let manifest: StimulusManifest = serde_json::from_str(&json).unwrap();
        StudyDefinition::parse(
            &text,
            Path::new("mos.toml"),
            move |_| Ok(manifest),
            &NoCodecs,
        )
    }

    #[test]
    fn the_ground_shadow_is_on_unless_the_study_turns_it_off() {
        assert!(parse("").unwrap().rendering.ground_shadow);
        assert!(
            !parse("\n[rendering]\nground_shadow = false\n")
                .unwrap()
                .rendering
                .ground_shadow
        );
        match parse("\n[rendering]\nground_shadow = 1\nshadow = true\n") {
            Err(StudyError::Invalid { issues, .. }) => {
                let keys: Vec<(&str, &str)> = issues
                    .iter()
                    .map(|i| (i.key.as_str(), i.reason.as_str()))
                    .collect();
                assert!(
                    keys.iter().any(
                        |(k, r)| *k == "rendering.ground_shadow" && r.contains("true or false")
                    ),
                    "{keys:?}"
                );
                assert!(
                    keys.iter().any(|(k, r)| *k == "rendering.shadow"
                        && r.contains("unknown key (allowed: ground_shadow)")),
                    "{keys:?}"
                );
                assert_eq!(issues.len(), 2, "{keys:?}");
            }
            other => panic!("expected the two problems, got {other:?}"),
        }
    }
}
