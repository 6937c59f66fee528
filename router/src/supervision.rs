//! Supervision: which agents the router restarts when they exit, when, and
//! when it gives up on them.
//!
//! * **Policy**: `never`, `on-failure` (died without leaving cleanly) or
//!   `always` (any exit but one asked for by `nerve stop` or `nerve down`).
//! * **Back-off**: the first restart waits `backoff`, each further restart
//!   within the window twice as long, at most [`MAX_BACKOFF`]. More than
//!   `max_restarts` restarts within the window mark the agent `failed`.
//! * **Persisted** (reliability review R4, F1b): the list is saved in the
//!   robot's state directory (`supervision.json`, atomically, off the
//!   serving loop) whenever it changes, and loaded by the next router. A
//!   router killed and started again therefore keeps restarting agents. An
//!   agent that was expected to run when the router went away is given
//!   [`REREGISTER_GRACE`] to register with the new router; one that does
//!   not (it died meanwhile) is treated as failed and restarted by its
//!   policy. `nerve down` (a `Shutdown` request) removes the file: a robot
//!   brought down on purpose is not brought back by its next router.
//! * **Bounded**: at most [`MAX_SUPERVISED`] names; the names gone for
//!   [`crate::remembered::FORGET_AFTER`] are dropped.
//!
//! The logic here needs no router and no process: [`Supervisor::exited`]
//! and [`Supervisor::due`] take the time as an argument and are
//! unit-tested; the router's core asks for the file to be written
//! ([`Supervisor::encode`]) and for restarts, which the driver's
//! [`crate::spawner::Spawner`] starts.

use serde::{Deserialize, Serialize};
use shm_schemas::AgentName;
use shm_schemas::control::cli_to_router::{RestartPolicy, RouterError, Supervision};
use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The longest back-off between two restarts.
pub const MAX_BACKOFF: Duration = Duration::from_secs(10);
/// The most agents the router supervises at once.
pub const MAX_SUPERVISED: usize = 1024;
/// How long a router that loaded the supervision list waits for an agent
/// that was running to register again before it counts it as dead.
pub const REREGISTER_GRACE: Duration = Duration::from_secs(5);
/// The file's name in the robot's state directory.
pub const FILE_NAME: &str = "supervision.json";
/// Version of the file's layout.
pub const FILE_VERSION: u32 = 1;

/// Supervision state of one agent.
#[derive(Debug)]
pub struct Supervised {
    /// how to restart it
    pub spec: Supervision,
    /// restart times within the window
    recent: VecDeque<Instant>,
    /// restarts so far
    pub total: u32,
    /// too many restarts: no more
    pub failed: bool,
    /// when the next restart is due
    pub next_start: Option<Instant>,
    /// `nerve stop` asked it to leave: do not restart
    pub stopped_by_user: bool,
    /// when its agent was last live (or supervision was asked for)
    pub last_seen: Instant,
    /// loaded from the file of an earlier router: counted dead if it has
    /// not registered by then
    awaiting: Option<Instant>,
    /// the environment of the start that asked for this supervision
    /// (`nerve launch`'s), which restarts get too; kept in memory only (it
    /// may hold secrets): a router started again restarts with its own
    pub env: Option<Vec<(String, String)>>,
}

impl Supervised {
    fn new(spec: Supervision, now: Instant) -> Self {
        Supervised {
            spec,
            recent: VecDeque::new(),
            total: 0,
            failed: false,
            next_start: None,
            stopped_by_user: false,
            last_seen: now,
            awaiting: None,
            env: None,
        }
    }

    /// Whether it is restarting or failed while not running: shown by `ps`.
    pub fn is_pending(&self) -> bool {
        self.failed || self.next_start.is_some()
    }
}

/// What an exit leads to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Exit {
    /// Not supervised, or its policy does not restart it after this exit.
    Left,
    /// Restarted after this delay.
    Restart(Duration),
    /// Too many restarts within the window: marked failed.
    Failed {
        /// restarts within the window
        restarts: usize,
        /// the window
        window: Duration,
    },
}

#[derive(Debug, Serialize, Deserialize)]
struct SavedEntry {
    spec: Supervision,
    stopped_by_user: bool,
    failed: bool,
    total: u32,
}

#[derive(Debug, Serialize, Deserialize)]
struct SavedFile {
    version: u32,
    agents: Vec<SavedEntry>,
}

/// The supervised agents of one robot.
#[derive(Debug)]
pub struct Supervisor {
    entries: BTreeMap<String, Supervised>,
    path: PathBuf,
    /// the router is stopping: nothing is restarted any more
    stopping: bool,
}

/// A supervision spec the router can act on: a valid agent name (it names
/// the log file the router opens, so `../x` would write outside the robot's
/// logs: reliability review R10) and a command line.
pub fn check(spec: &Supervision) -> Result<(), RouterError> {
    AgentName::new(&spec.name).map_err(|e| RouterError::InvalidName(format!("{:?}: {e}", spec.name)))?;
    if spec.argv.is_empty() {
        return Err(RouterError::NotApplicable("supervision needs a command line".into()));
    }
    Ok(())
}

impl Supervisor {
    /// An empty supervisor that saves into `state_dir`.
    pub fn new(state_dir: &Path) -> Self {
        Supervisor { entries: BTreeMap::new(), path: state_dir.join(FILE_NAME), stopping: false }
    }

    /// The supervisor with what an earlier router of this robot saved. A file
    /// that cannot be used is logged and ignored (the next `nerve launch`
    /// supervises again).
    pub fn load(state_dir: &Path, now: Instant) -> Self {
        let mut sup = Supervisor::new(state_dir);
        let bytes = match std::fs::read(&sup.path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return sup,
            Err(e) => {
                tracing::error!(file = %sup.path.display(), "cannot read the supervision list: {e}; supervising nothing until the next launch");
                return sup;
            }
        };
        let file = match serde_json::from_slice::<SavedFile>(&bytes) {
            Ok(f) if f.version == FILE_VERSION => f,
            Ok(f) => {
                tracing::error!(file = %sup.path.display(), version = f.version, "the supervision list was written by another nerve; supervising nothing until the next launch");
                return sup;
            }
            Err(e) => {
                tracing::error!(file = %sup.path.display(), "the supervision list cannot be read: {e}; supervising nothing until the next launch");
                return sup;
            }
        };
        for saved in file.agents.into_iter().take(MAX_SUPERVISED) {
            if let Err(e) = check(&saved.spec) {
                tracing::warn!(file = %sup.path.display(), "skipping a supervision entry: {e}");
                continue;
            }
            let mut s = Supervised::new(saved.spec, now);
            s.stopped_by_user = saved.stopped_by_user;
            s.failed = saved.failed;
            s.total = saved.total;
            if !s.stopped_by_user && !s.failed {
                s.awaiting = Some(now + REREGISTER_GRACE);
            }
            sup.entries.insert(s.spec.name.clone(), s);
        }
        tracing::info!(file = %sup.path.display(), agents = sup.entries.len(), "supervision resumed from the previous router");
        sup
    }

    /// The file the list is saved in.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file's bytes.
    pub fn encode(&self) -> Vec<u8> {
        let agents = self
            .entries
            .values()
            .map(|s| SavedEntry {
                spec: s.spec.clone(),
                stopped_by_user: s.stopped_by_user,
                failed: s.failed,
                total: s.total,
            })
            .collect();
        serde_json::to_vec_pretty(&SavedFile { version: FILE_VERSION, agents }).unwrap_or_default()
    }

    /// Restarts nothing more: the robot is being brought down on purpose
    /// (the caller removes the saved list, [`Supervisor::path`]).
    pub fn stop_all(&mut self) {
        self.stopping = true;
    }

    /// One agent's state.
    pub fn get(&self, name: &str) -> Option<&Supervised> {
        self.entries.get(name)
    }

    /// Every supervised agent, by name.
    pub fn iter(&self) -> impl Iterator<Item = (&String, &Supervised)> {
        self.entries.iter()
    }

    /// How many agents are supervised.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether none is.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Supervises `spec.name` (again: a new spec replaces the old one,
    /// clears `failed` and starts a new restart window). When the list is full, names neither live nor
    /// restarting are dropped to make room.
    pub fn supervise(
        &mut self,
        spec: Supervision,
        now: Instant,
        live: impl Fn(&str) -> bool,
    ) -> Result<(), RouterError> {
        check(&spec)?;
        let name = spec.name.clone();
        if let Some(s) = self.entries.get_mut(&name) {
            s.spec = spec;
            s.failed = false;
            s.recent.clear();
            s.last_seen = now;
            s.env = None;
            return Ok(());
        }
        if self.entries.len() >= MAX_SUPERVISED {
            let gone = self.forget_gone(now, Duration::ZERO, |n| live(n) || n == name);
            if !gone.is_empty() {
                tracing::info!("stopped supervising {} agent(s) no longer running", gone.len());
            }
            if self.entries.len() >= MAX_SUPERVISED {
                return Err(RouterError::NotApplicable(format!(
                    "the router supervises {MAX_SUPERVISED} agents at most and all are running or restarting; stop some with `nerve stop NAME`, or restart the router with `nerve down`"
                )));
            }
        }
        self.entries.insert(name, Supervised::new(spec, now));
        Ok(())
    }

    /// Restarts of `name` get `env` (the environment its launch started it with).
    pub fn set_env(&mut self, name: &str, env: Option<Vec<(String, String)>>) {
        if let Some(s) = self.entries.get_mut(name) {
            s.env = env;
        }
    }

    /// An agent of this name registered: it runs, whatever was pending.
    pub fn registered(&mut self, name: &str) {
        if let Some(s) = self.entries.get_mut(name) {
            s.stopped_by_user = false;
            s.next_start = None;
            s.awaiting = None;
        }
    }

    /// `nerve stop` was obeyed (or asked for an agent that is not running):
    /// no restart, and none pending. Returns whether it is supervised.
    pub fn stopped_by_user(&mut self, name: &str) -> bool {
        let Some(s) = self.entries.get_mut(name) else { return false };
        s.stopped_by_user = true;
        s.next_start = None;
        s.awaiting = None;
        true
    }

    /// An agent exited at `now` (`failure`: died without leaving cleanly);
    /// decides whether and when it is restarted.
    pub fn exited(&mut self, name: &str, failure: bool, now: Instant) -> Exit {
        let stopping = self.stopping;
        let Some(sup) = self.entries.get_mut(name) else { return Exit::Left };
        sup.awaiting = None;
        let wanted = match sup.spec.policy {
            RestartPolicy::Never => false,
            RestartPolicy::OnFailure => failure,
            RestartPolicy::Always => true,
        };
        if !wanted || sup.stopped_by_user || sup.failed || stopping {
            return Exit::Left;
        }
        let window = Duration::from_nanos(sup.spec.window_ns);
        while sup.recent.front().is_some_and(|t| now.saturating_duration_since(*t) > window) {
            sup.recent.pop_front();
        }
        if sup.recent.len() as u32 >= sup.spec.max_restarts {
            sup.failed = true;
            return Exit::Failed { restarts: sup.recent.len(), window };
        }
        let exp = sup.recent.len().min(16) as u32;
        let delay = Duration::from_nanos(sup.spec.backoff_ns).saturating_mul(1 << exp).min(MAX_BACKOFF);
        sup.next_start = Some(now + delay);
        Exit::Restart(delay)
    }

    /// The agents loaded from an earlier router that have not registered
    /// within the grace: they died while no router watched.
    pub fn missing(&self, now: Instant, live: impl Fn(&str) -> bool) -> Vec<String> {
        self.entries
            .iter()
            .filter(|(n, s)| s.awaiting.is_some_and(|t| t <= now) && !live(n))
            .map(|(n, _)| n.clone())
            .collect()
    }

    /// The agents whose restart is due at `now` and that are not live;
    /// each is counted as restarted, and its command line returned.
    pub fn due(&mut self, now: Instant, live: impl Fn(&str) -> bool) -> Vec<(String, Vec<String>, u32)> {
        if self.stopping {
            return Vec::new();
        }
        let mut out = Vec::new();
        for (name, sup) in self.entries.iter_mut() {
            if sup.next_start.is_none_or(|t| t > now) || live(name) {
                continue;
            }
            sup.next_start = None;
            sup.recent.push_back(now);
            sup.total = sup.total.saturating_add(1);
            out.push((name.clone(), sup.spec.argv.clone(), sup.total));
        }
        out
    }

    /// Notes that `name` is live at `now`.
    pub fn seen(&mut self, name: &str, now: Instant) {
        if let Some(s) = self.entries.get_mut(name) {
            s.last_seen = now;
        }
    }

    /// Drops the supervision of names that are not live, not waiting for a
    /// restart, and gone for more than `forget_after` before `now`; returns them.
    pub fn forget_gone(&mut self, now: Instant, forget_after: Duration, live: impl Fn(&str) -> bool) -> Vec<String> {
        let gone: Vec<String> = self
            .entries
            .iter()
            .filter(|(n, s)| {
                !live(n)
                    && s.next_start.is_none()
                    && s.awaiting.is_none()
                    && now.saturating_duration_since(s.last_seen) > forget_after
            })
            .map(|(n, _)| n.clone())
            .collect();
        for n in &gone {
            self.entries.remove(n);
        }
        gone
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::remembered::FORGET_AFTER;
    use crate::store::Writer;

    fn spec(name: &str, policy: RestartPolicy) -> Supervision {
        Supervision {
            name: name.into(),
            argv: vec!["nerve-ticker".into()],
            policy,
            max_restarts: 3,
            window_ns: 10_000_000_000,
            backoff_ns: 100_000_000,
            importance: 5,
            cwd: None,
        }
    }

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("nerve-sup-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_supervision_name_that_is_not_an_agent_name_is_refused() {
        assert!(check(&spec("t1", RestartPolicy::Always)).is_ok());
        for bad in ["../../x", "a/b", "", ".hidden"] {
            match check(&spec(bad, RestartPolicy::Always)) {
                Err(RouterError::InvalidName(m)) => assert!(m.contains(&format!("{bad:?}")), "{m}"),
                other => panic!("{bad:?} accepted: {other:?}"),
            }
        }
        let mut no_argv = spec("t1", RestartPolicy::Always);
        no_argv.argv.clear();
        assert!(matches!(check(&no_argv), Err(RouterError::NotApplicable(_))));
    }

    #[test]
    fn back_off_doubles_within_the_window_then_the_agent_fails() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(&dir("backoff"));
        s.supervise(spec("a", RestartPolicy::OnFailure), t0, |_| false).expect("supervised");
        let mut now = t0;
        for expected_ms in [100, 200, 400] {
            assert_eq!(s.exited("a", true, now), Exit::Restart(Duration::from_millis(expected_ms)));
            now += Duration::from_millis(expected_ms);
            assert_eq!(s.due(now - Duration::from_millis(1), |_| false), vec![], "not due before its back-off");
            let due = s.due(now, |_| false);
            assert_eq!(due.len(), 1);
            assert_eq!(due[0].0, "a");
        }
        assert!(matches!(s.exited("a", true, now), Exit::Failed { restarts: 3, .. }));
        assert!(s.get("a").is_some_and(|x| x.failed && x.is_pending()));
        assert_eq!(s.exited("a", true, now), Exit::Left, "a failed agent is not restarted");
        // supervising it again (a new launch) clears the failure
        s.supervise(spec("a", RestartPolicy::OnFailure), now, |_| false).expect("again");
        assert!(matches!(s.exited("a", true, now), Exit::Restart(_)));
    }

    #[test]
    fn restarts_outside_the_window_do_not_count_and_the_delay_is_capped() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(&dir("window"));
        let mut sp = spec("a", RestartPolicy::Always);
        sp.max_restarts = 100;
        sp.backoff_ns = 4_000_000_000;
        s.supervise(sp, t0, |_| false).expect("supervised");
        let mut now = t0;
        for _ in 0..3 {
            let Exit::Restart(d) = s.exited("a", false, now) else { panic!("restarted") };
            assert!(d <= MAX_BACKOFF, "{d:?}");
            now += d;
            s.due(now, |_| false);
        }
        assert_eq!(s.exited("a", false, now), Exit::Restart(MAX_BACKOFF));
        // an hour later the window is empty again: the first back-off
        now += Duration::from_secs(3600);
        s.due(now, |_| false);
        assert_eq!(s.exited("a", false, now + Duration::from_secs(3600)), Exit::Restart(Duration::from_secs(4)));
    }

    #[test]
    fn policies_and_stop_decide_whether_an_exit_restarts() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(&dir("policy"));
        for (n, p) in
            [("never", RestartPolicy::Never), ("fail", RestartPolicy::OnFailure), ("always", RestartPolicy::Always)]
        {
            s.supervise(spec(n, p), t0, |_| false).expect("supervised");
        }
        assert_eq!(s.exited("never", true, t0), Exit::Left);
        assert_eq!(s.exited("fail", false, t0), Exit::Left, "a clean exit is not a failure");
        assert!(matches!(s.exited("fail", true, t0), Exit::Restart(_)));
        assert!(s.stopped_by_user("always"));
        assert_eq!(s.exited("always", false, t0), Exit::Left, "stopped by the user");
        s.registered("always");
        assert!(matches!(s.exited("always", false, t0), Exit::Restart(_)), "a new start clears the stop");
        // a stop obeyed after the exit was seen cancels the pending restart
        assert!(s.stopped_by_user("always"));
        assert!(s.due(t0 + Duration::from_secs(60), |_| false).iter().all(|(n, _, _)| n != "always"));
        assert_eq!(s.exited("unknown", true, t0), Exit::Left);
    }

    #[test]
    fn the_list_survives_a_router_restart_and_missing_agents_are_restarted() {
        let d = dir("persist");
        let t0 = Instant::now();
        let mut w = Writer::start().expect("writer");
        let mut s = Supervisor::new(&d);
        for n in ["up", "died", "stopped"] {
            s.supervise(spec(n, RestartPolicy::Always), t0, |_| false).expect("supervised");
        }
        s.stopped_by_user("stopped");
        w.write(s.path(), s.encode());
        w.flush();
        let mut again = Supervisor::load(&d, t0);
        assert_eq!(again.len(), 3);
        assert!(again.get("stopped").is_some_and(|x| x.stopped_by_user));
        // "up" registers with the new router; "died" does not
        again.registered("up");
        assert!(again.missing(t0 + Duration::from_secs(1), |_| false).is_empty(), "still within the grace");
        let later = t0 + REREGISTER_GRACE;
        assert_eq!(again.missing(later, |_| false), vec!["died".to_owned()]);
        assert!(matches!(again.exited("died", true, later), Exit::Restart(_)));
        assert!(again.missing(later, |_| false).is_empty(), "counted once");
        // `nerve down` removes the file and restarts nothing more
        let mut w = Writer::start().expect("writer");
        again.stop_all();
        w.remove(again.path());
        w.flush();
        assert!(!d.join(FILE_NAME).exists());
        assert!(again.due(later + Duration::from_secs(60), |_| false).is_empty());
        assert!(Supervisor::load(&d, later).is_empty());
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_damaged_list_is_ignored() {
        let d = dir("damaged");
        std::fs::create_dir_all(&d).expect("dir");
        for bad in [&b"{ nope"[..], br#"{"version": 7, "agents": []}"#] {
            std::fs::write(d.join(FILE_NAME), bad).expect("write");
            assert!(Supervisor::load(&d, Instant::now()).is_empty());
        }
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn supervision_of_names_gone_for_long_is_dropped_unless_live_or_restarting() {
        let t0 = Instant::now();
        let mut s = Supervisor::new(&dir("gone"));
        for n in ["gone", "live", "restarting"] {
            s.supervise(spec(n, RestartPolicy::Always), t0, |_| false).expect("supervised");
        }
        assert!(matches!(s.exited("restarting", true, t0), Exit::Restart(_)));
        assert!(s.forget_gone(t0 + Duration::from_secs(60), FORGET_AFTER, |n| n == "live").is_empty());
        let later = t0 + FORGET_AFTER + Duration::from_secs(1);
        assert_eq!(s.forget_gone(later, FORGET_AFTER, |n| n == "live"), vec!["gone".to_owned()]);
        assert_eq!(
            s.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>(),
            vec!["live".to_owned(), "restarting".to_owned()]
        );
    }
}
