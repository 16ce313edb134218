//! Study definitions and the protocol engines that decide what a subject sees next.
//!
//! Holds (protocols issue): the versioned study file (TOML), trial plans, the MOS, DSCQS and
//! 2AFC-staircase engines as deterministic state machines (study + seed + responses so far fix
//! the next trial), and simulated observers for dry runs. It knows stimuli only as ids and
//! parameters from the [`manifest`]; it never draws anything and never touches result files.

pub mod manifest;
