//! The codec suite as the study file and the commands see it: names, parameters, rate control,
//! and the decoder context (the primitive database) a codec needs.

use std::path::Path;
use std::sync::Arc;

use codecs::codec::{self, Codec, CodecContext, RateControl};
use codecs::primitives::Database;
use protocols::{CodecCatalog, CodecInfo};

use crate::error::{Result, refused};

/// The codec registry, with the context its codecs are built in. What `protocols` checks a
/// study file's codec settings against ([`CodecCatalog`]), and where commands find a codec by
/// name.
#[derive(Debug, Clone, Default)]
pub struct Codecs {
    ctx: CodecContext,
}

impl Codecs {
    /// The codecs with decoder context `ctx`.
    pub fn new(ctx: CodecContext) -> Codecs {
        Codecs { ctx }
    }

    /// The codecs with the primitive database at `db`, if one is named.
    ///
    /// # Errors
    /// The database cannot be read (the error names the file).
    pub fn with_database(db: Option<&Path>) -> Result<Codecs> {
        Codecs::with_files(db, None)
    }

    /// The codecs with the primitive database at `db` and the command-defined codecs of the
    /// definitions file `defs` ([`crate::codec_defs`]), each if named.
    ///
    /// # Errors
    /// Either file cannot be read or has problems (the error names the file, and the key).
    pub fn with_files(db: Option<&Path>, defs: Option<&Path>) -> Result<Codecs> {
        let primitives = match db {
            Some(path) => Some(Arc::new(Database::read(path)?)),
            None => None,
        };
        let external = match defs {
            Some(path) => crate::codec_defs::read(path)?,
            None => Vec::new(),
        };
        Ok(Codecs::new(CodecContext {
            primitives,
            external,
        }))
    }

    /// The decoder context.
    pub fn context(&self) -> &CodecContext {
        &self.ctx
    }

    /// Every codec, in id order.
    pub fn all(&self) -> Vec<Box<dyn Codec>> {
        codec::registry_in(&self.ctx)
    }

    /// The codec called `name`.
    ///
    /// # Errors
    /// An unknown name, with the known ones.
    pub fn get(&self, name: &str) -> Result<Box<dyn Codec>> {
        codec::by_name_in(name, &self.ctx).ok_or_else(|| {
            refused(format!(
                "unknown codec `{name}`; known: {} (`study codecs` lists them)",
                self.names().join(", ")
            ))
        })
    }
}

impl Codecs {
    /// Checks that codec `name` takes every parameter of `keys` and that none is set by its
    /// rate control (`cr`, or its knob: `alpha`, `t_l`), which a sweep's target sets.
    ///
    /// # Errors
    /// [`crate::LabError::Refused`] naming the parameter, the codec and the keys it accepts.
    pub fn check_varied_params(&self, name: &str, keys: &[&str]) -> Result<()> {
        let c = self.get(name)?;
        let accepted = c.default_params();
        let knob = match c.rate_control() {
            RateControl::Search { key, .. } | RateControl::SearchIncreasing { key, .. } => {
                Some(key)
            }
            RateControl::Native | RateControl::None => None,
        };
        for &key in keys {
            if !accepted.contains_key(key) {
                return Err(refused(format!(
                    "--param {key}: codec `{name}` does not take it; it takes {} \
                     (`study codecs` lists them)",
                    accepted.keys().cloned().collect::<Vec<_>>().join(", ")
                )));
            }
            if key == codec::keys::CR || Some(key) == knob {
                return Err(refused(format!(
                    "--param {key}: codec `{name}` sets {key} itself to reach each target; \
                     vary its other parameters"
                )));
            }
        }
        Ok(())
    }
}

impl CodecCatalog for Codecs {
    fn codec(&self, name: &str) -> Option<CodecInfo> {
        let c = codec::by_name_in(name, &self.ctx)?;
        Some(CodecInfo {
            params: c.default_params().into_keys().collect(),
            target_cr: c.rate_control() != RateControl::None,
            needs_database: c.name() == codec::primitive::NAME,
        })
    }

    fn names(&self) -> Vec<String> {
        self.all().iter().map(|c| c.name().to_string()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// protocols cannot name the codecs' keys (it does not depend on codecs): the two
    /// spellings of the target-ratio parameter must agree.
    #[test]
    fn protocols_and_codecs_name_the_target_ratio_alike() {
        assert_eq!(protocols::catalog::TARGET_CR_PARAM, codec::keys::CR);
        let spiht = Codecs::default().codec("spiht").unwrap();
        assert!(spiht.target_cr && spiht.params.iter().any(|p| p == codec::keys::CR));
        let raw = Codecs::default().codec("raw-f32").unwrap();
        assert!(!raw.target_cr);
        assert!(Codecs::default().codec("primitive").unwrap().needs_database);
        assert!(Codecs::default().codec("nope").is_none());
    }
}
