//! The resource manager of the thesis (section 3.2.6) as a library: the
//! load level and the choice of whom to slow down, suspend or restore
//! ([`plan`]). The `resource` agent (`src/main.rs`) measures with `sysinfo`,
//! asks the router, and publishes `nerve::ResourceReport`.

pub mod plan;

pub use plan::{Action, AgentObs, Measures, Planner, level};
