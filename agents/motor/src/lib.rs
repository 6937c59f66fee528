//! The actuator-agent pattern of the thesis (Fig. 2-4) as a library: a
//! **filter** that refuses impractical commands, a **fuzzy rule base** that
//! turns linguistic commands into numbers, a **weighted fusion** of the
//! sources, and a **safety stop** that always wins. The `motor` agent (the
//! "foot") and the `head` agent are thin shells around it.
//!
//! * [`filter`]: what makes a command impractical (not finite, over the
//!   limits, an acceleration over the limit, stale, from the future, an
//!   unknown term).
//! * [`fuzzy`]: triangular memberships, clipped and weighted, aggregated by
//!   sum and defuzzified by centroid.
//! * [`weights`]: per-sender weights, from text such as `safety:2,wall-follow:1`.
//! * [`fusion`]: the base's decision each control cycle.
//! * [`drive`]: from (v, ω) to wheel speeds.
//! * [`refusals`]: refused commands counted per sender, bounded.

pub mod drive;
pub mod filter;
pub mod fusion;
pub mod fuzzy;
pub mod refusals;
pub mod weights;

pub use filter::{Limits, Refusal};
pub use fusion::{Decision, Fusion};
pub use weights::Weights;
