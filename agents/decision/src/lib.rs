//! The global decision maker of the thesis (sections 3.2.5 and 4.2.2.4) as a
//! library: the knowledge base ([`kb`]), read from a strict TOML file, and
//! the decision ([`decide`]): the situation from the agents' reports, the
//! table look-up, the hysteresis, and the actions a mode asks for; and
//! [`apply`], which carries the actions out through the router from a
//! worker thread.
//!
//! The `decision` agent (`src/main.rs`) is a thin shell around it; the
//! resource manager reads the same knowledge base through [`kb`]. The
//! format and the modes of `kb/explore.toml` are described in
//! `docs/decision.md`.

pub mod apply;
pub mod decide;
pub mod kb;

pub use decide::{Action, Arbiter, Change, Facts, Reports, actions, lookup};
pub use kb::{KbError, KnowledgeBase, ModeSpec, ResourcePolicy, Thresholds};
