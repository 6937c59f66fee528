//! `nerve ui`: a running robot's live graph in a browser, to watch and to
//! rewire it (the thesis' future work, section 5.2).
//!
//! This crate is the web side: an HTTP server ([`serve`]) that hands out one
//! page built into the binary (`assets/`: plain HTML, CSS and JavaScript,
//! nothing fetched from the internet), streams the graph to it as
//! server-sent events, and turns the page's requests into calls of a
//! [`Robot`]. The robot side, which talks to the router exactly as the
//! command line does, is the `nerve ui` command's (`launcher/src/cmd/ui.rs`);
//! it answers on the thread that called [`serve`], so a router session (not
//! `Send`) never leaves that thread.
//!
//! Every `/api/*` route needs a token (as Jupyter's, `nerve ui` prints the
//! address with it): the read token to watch, the edit token to act (it
//! also lets its holder watch). `--read-only` refuses every action. The
//! server checks `Host` and `Origin` and bounds every request (see
//! `server.rs` and `http.rs`, and `docs/ui.md`).

mod action;
mod assets;
mod http;
mod server;
mod token;

pub use action::Action;
pub use server::{Options, UiError, WRITE_TIMEOUT, serve};
pub use token::{matches as token_matches, new_token, token_problem};

/// What the page asks of the robot. `nerve ui` implements it with a router
/// session; every call is made on the thread that called [`serve`].
pub trait Robot {
    /// The graph as `nerve graph --json` prints it: `{"agents": [...],
    /// "connections": [...]}`; an error says why there is none (no router).
    fn graph(&mut self) -> Result<serde_json::Value, String>;
    /// Carries out an action through the router; the error is the router's
    /// refusal as the command line would print it.
    fn act(&mut self, action: Action) -> Result<serde_json::Value, String>;
    /// The latest samples of output port `port` (`agent/port`), decoded,
    /// with sequence numbers above `after`. A sequence port's samples carry
    /// their length, their last element and only their first elements, so
    /// that the answer stays bounded however long they are (`docs/ui.md`).
    fn samples(&mut self, port: &str, after: u64) -> Result<serde_json::Value, String>;
    /// The image of the latest ring notice on `port`, as PNG.
    fn image(&mut self, port: &str) -> Result<Vec<u8>, String>;
    /// The agent kinds that can be started by name.
    fn kinds(&mut self) -> Vec<String>;
    /// Called once per update interval, before the graph is read (to let go
    /// of subscriptions nobody looks at any more).
    fn tick(&mut self) {}
}
