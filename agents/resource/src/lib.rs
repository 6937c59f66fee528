//! The resource manager of the thesis (section 3.2.6) as a library: the
//! load level and the choice of whom to slow down, suspend or restore
//! ([`plan`]), and the report of what it measured and did ([`report`]).
//! The `resource` agent (`src/main.rs`) measures with `sysinfo`, asks the
//! router, and publishes `nerve::ResourceReport` (`Seq<AgentLoad,
//! ResourceHeader>`: every agent, any count).

pub mod plan;
pub mod report;

pub use plan::{Action, AgentObs, Measures, Planner, level};
pub use report::{Machine, report};
