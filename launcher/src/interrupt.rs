//! Ctrl-C for the commands that run until told to stop (`nerve logs
//! --follow`, `nerve launch --foreground`, `nerve demo`, `nerve calibrate`,
//! `nerve echo`, `nerve record`, `nerve plot`): [`catch`] routes SIGINT and
//! SIGTERM to a flag that their loops poll with [`requested`], so that they
//! end cleanly (bring the robot down, write what they recorded) instead of
//! dying.
//!
//! The flag is [`agent_sdk::termination`]'s, the agents' and the router's:
//! iceoryx2, which catches the same signals into a record any later signal
//! overwrites, installs its handlers first, so that a command that makes
//! ports after `catch` keeps its own.

/// Routes SIGINT and SIGTERM to the flag [`requested`] reads.
pub fn catch() {
    if let Err(e) = agent_sdk::termination::install() {
        tracing::warn!("{e}; Ctrl-C ends the command at once");
    }
}

/// Whether SIGINT or SIGTERM came since [`catch`].
pub fn requested() -> bool {
    agent_sdk::termination::requested()
}
