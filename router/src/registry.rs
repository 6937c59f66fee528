//! The registry: the agents live now, as they registered (name, pid, kind,
//! task, ports, log file) and the state the router last set (running or
//! suspended). It holds live agents only: a dead agent is removed by the
//! liveness check (run by the router's driver) and its supervision decides what
//! follows.
//!
//! A registration's pid is checked before it is believed ([`check_process`],
//! run by the router's driver): a buggy or hostile client could otherwise
//! register another process's pid, which `nerve kill` and `nerve down` would
//! then signal (reliability review R10). Each entry keeps the
//! [`ProcessHandle`] (pid and start time) taken at registration, so that the
//! driver's liveness checks and `nerve kill` follow that process, not
//! whatever has its pid later (R6). The registry itself never looks at a
//! process: it is told.
//!
//! The schemas a registration carries (one per payload type of its ports)
//! must be valid ([`shm_schemas::Schema::validate`]): tools decode samples
//! and open ports through them, so a damaged or hostile one is refused
//! with the registration, saying what is wrong.

use agent_sdk::World;
use agent_sdk::process::ProcessHandle;
use shm_schemas::control::agent_to_router::{PortSpec, Registration};
use shm_schemas::control::cli_to_router::{AgentState, RouterError};
use shm_schemas::{AgentName, PortRef};
use std::collections::BTreeMap;

/// One live agent.
#[derive(Debug)]
pub struct Entry {
    /// what it told the router at registration (its period follows `nerve rate`)
    pub reg: Registration,
    /// its process, as it was when it registered
    pub process: ProcessHandle,
    /// running or suspended, as last set
    pub state: AgentState,
}

/// The live agents, by name.
#[derive(Debug, Default)]
pub struct Registry {
    agents: BTreeMap<String, Entry>,
}

impl Registry {
    /// Adds `reg` (of the process `process`, see [`check_process`]),
    /// replacing an earlier instance of the same name that is dead; refuses
    /// a bad name or a name a live process holds (`holder_alive`: the
    /// registered instance of this name, if its pid is another, still runs).
    pub fn register(
        &mut self,
        reg: Registration,
        process: ProcessHandle,
        holder_alive: bool,
    ) -> Result<(), RouterError> {
        AgentName::new(&reg.name).map_err(|e| RouterError::InvalidName(e.to_string()))?;
        for schema in &reg.schemas {
            schema.validate().map_err(|e| RouterError::RegistrationRefused {
                name: reg.name.clone(),
                pid: reg.pid,
                reason: format!("its {e}"),
            })?;
        }
        if let Some(existing) = self.agents.get(&reg.name)
            && existing.reg.pid != reg.pid
            && holder_alive
        {
            return Err(RouterError::DuplicateName { name: reg.name, pid: existing.reg.pid });
        }
        let state = if reg.suspended { AgentState::Suspended } else { AgentState::Running };
        self.agents.insert(reg.name.clone(), Entry { reg, process, state });
        Ok(())
    }

    /// Removes `name` if its pid is `pid` (an agent leaving); whether it did.
    pub fn unregister(&mut self, name: &str, pid: u32) -> bool {
        if self.agents.get(name).is_some_and(|e| e.reg.pid == pid) {
            self.agents.remove(name);
            return true;
        }
        false
    }

    /// Removes `name` if its pid is `pid` (an agent found dead); whether it did.
    pub fn remove_dead(&mut self, name: &str, pid: u32) -> bool {
        self.unregister(name, pid)
    }

    /// The live agent `name`.
    pub fn get(&self, name: &str) -> Option<&Entry> {
        self.agents.get(name)
    }

    /// The live agent `name`, to change.
    pub fn get_mut(&mut self, name: &str) -> Option<&mut Entry> {
        self.agents.get_mut(name)
    }

    /// Whether `name` is live.
    pub fn contains(&self, name: &str) -> bool {
        self.agents.contains_key(name)
    }

    /// The live agents, by name.
    pub fn iter(&self) -> impl Iterator<Item = (&String, &Entry)> {
        self.agents.iter()
    }

    /// The live agent `name`, or the error that lists the live ones.
    pub fn live(&self, name: &str) -> Result<&Entry, RouterError> {
        self.agents.get(name).ok_or_else(|| self.unknown(name))
    }

    /// The error for an agent that is not live.
    pub fn unknown(&self, name: &str) -> RouterError {
        RouterError::UnknownAgent { name: name.into(), running: self.agents.keys().cloned().collect() }
    }

    /// Port `p` (an output when `output`) as its agent registered it, or why there is none.
    pub fn port(&self, p: &PortRef, output: bool) -> Result<&PortSpec, RouterError> {
        let entry = self.live(p.agent.as_str())?;
        // a service is wired like an output, a client like an input (docs/calls.md)
        let (ports, calls) =
            if output { (&entry.reg.outputs, &entry.reg.services) } else { (&entry.reg.inputs, &entry.reg.clients) };
        ports.iter().chain(calls).find(|s| s.name == p.port).ok_or_else(|| RouterError::UnknownPort {
            agent: p.agent.to_string(),
            port: p.port.clone(),
            direction: if output { "output" } else { "input" }.into(),
            available: ports.iter().chain(calls).map(|s| s.name.clone()).collect(),
        })
    }

    /// A call's wire in the router's order, service to client, also when
    /// it is written client first (`nerve connect a/planner b/plan`, as
    /// `ros2` users write it); any other pair as it is (docs/calls.md).
    pub fn wire_order(&self, from: PortRef, to: PortRef) -> (PortRef, PortRef) {
        let is_client = |p: &PortRef| {
            self.agents.get(p.agent.as_str()).is_some_and(|e| e.reg.clients.iter().any(|c| c.name == p.port))
        };
        if is_client(&from) { (to, from) } else { (from, to) }
    }

    /// The type output `from` would send to input `to`, or why they cannot
    /// be connected: another type, or the same type name laid out
    /// differently (the fields that differ listed, see [`Registry::check_input`]).
    pub fn check_compatible(&self, from: &PortRef, to: &PortRef) -> Result<String, RouterError> {
        let f = self.port(from, true)?;
        self.check_input(from, f, to)?;
        Ok(f.type_name.clone())
    }

    /// Whether input `to` takes what `from` sends (`f`: the spec of `from`,
    /// an agent's output or a tool's port); why not, if not. The rule is
    /// the one the launch file and the agent apply
    /// ([`shm_schemas::schema::compat::check`]): the same type name laid out
    /// the same way, compared field by field through the schemas the two
    /// agents registered (by fingerprint when one has none: a tool's port,
    /// a registration too large for its schemas).
    pub fn check_input(&self, from: &PortRef, f: &PortSpec, to: &PortRef) -> Result<(), RouterError> {
        use shm_schemas::schema::compat::{self, Declared, Incompatible};
        let t = self.port(to, false)?;
        /// `spec` of `agent`'s port, with its layout if the agent registered it.
        fn declared<'a>(registry: &'a Registry, agent: &PortRef, spec: &'a PortSpec) -> Declared<'a> {
            let schemas = registry.agents.get(agent.agent.as_str()).map(|e| e.reg.schemas.as_slice());
            Declared {
                type_name: &spec.type_name,
                fingerprint: Some(spec.fingerprint),
                schema: schemas
                    .unwrap_or_default()
                    .iter()
                    .find(|s| s.type_name == spec.type_name && s.fingerprint() == spec.fingerprint),
            }
        }
        let (from_text, to_text) = (from.to_string(), to.to_string());
        match compat::check(declared(self, from, f), declared(self, to, t)) {
            Ok(()) => Ok(()),
            Err(Incompatible::Type { output, input }) => {
                Err(RouterError::TypeMismatch { from: from_text, from_type: output, to: to_text, to_type: input })
            }
            Err(Incompatible::Layout { fields, .. }) => {
                let differ = match &fields {
                    Some(m) => format!("the fields differ:\n{}\n", m.list(&from_text, &to_text)),
                    None => String::new(),
                };
                Err(RouterError::LayoutMismatch {
                    from: from_text,
                    to: to_text,
                    type_name: f.type_name.clone(),
                    from_fingerprint: f.fingerprint,
                    to_fingerprint: t.fingerprint,
                    rebuild: format!(
                        "{differ}make both declare the same layout of {} (the same fields, types and order), \
                         then restart the one you changed",
                        f.type_name
                    ),
                })
            }
        }
    }
}

/// The process of a registration, if the router can believe it: the pid
/// names a live process, of the router's own effective uid, that is one of
/// nerve's in `world` ([`ProcessHandle::is_nerve`]: a `nerve-*` executable,
/// or a process holding a live iceoryx2 node of this robot). Anything else
/// is refused, saying which check failed.
pub fn check_process(reg: &Registration, world: &World) -> Result<ProcessHandle, RouterError> {
    let refused = |reason: String| RouterError::RegistrationRefused { name: reg.name.clone(), pid: reg.pid, reason };
    let process = ProcessHandle::take(reg.pid).map_err(|_| {
        refused("no process has this pid (a wrong pid, or an agent that ended right after it asked)".into())
    })?;
    let ours = nix::unistd::geteuid().as_raw();
    match process.uid() {
        Some(uid) if uid == ours => {}
        Some(uid) => return Err(refused(format!("the process runs as uid {uid}, the router as uid {ours}"))),
        None => return Err(refused("the process exited while it was checked".into())),
    }
    if !process.is_nerve(world) {
        // an agent that died in its own `start` (which runs beside the
        // registration) is gone before its executable can be read
        if !process.is_alive() {
            return Err(refused("the process ended while its registration was checked".into()));
        }
        let exe = process.exe().map_or_else(|| "unknown".to_owned(), |e| e.display().to_string());
        return Err(refused(format!(
            "the process is not a nerve agent: its executable {exe} is not `nerve-*` and it has no iceoryx2 node of robot {}",
            world.robot()
        )));
    }
    Ok(process)
}

#[cfg(test)]
mod tests {
    use super::{Registry, check_process};
    use agent_sdk::World;
    use agent_sdk::process::ProcessHandle;
    use shm_schemas::Described as _;
    use shm_schemas::control::agent_to_router::{Registration, TaskKind};
    use shm_schemas::control::cli_to_router::RouterError;
    use std::process::Command;

    fn registration(pid: u32) -> Registration {
        Registration {
            name: "t1".into(),
            pid,
            kind: "ticker".into(),
            executable: String::new(),
            task: TaskKind::Periodic,
            period_ns: None,
            inputs: vec![],
            outputs: vec![],
            log_file: None,
            suspended: false,
            schemas: vec![],
            services: vec![],
            clients: vec![],
        }
    }

    #[test]
    fn a_registration_with_an_invalid_schema_is_refused_saying_what_is_wrong() {
        let mut registry = Registry::default();
        let me = || ProcessHandle::take(std::process::id()).expect("this process");
        let mut reg = registration(std::process::id());
        let mut bad = shm_schemas::payloads::Tick::schema();
        bad.align = 0;
        reg.schemas = vec![shm_schemas::payloads::Scalar::schema(), bad];
        match registry.register(reg.clone(), me(), false) {
            Err(e @ RouterError::RegistrationRefused { .. }) => {
                let text = e.to_string();
                assert!(text.contains("schema nerve::Tick: align 0 is not a power of two"), "{text}");
            }
            other => panic!("registered with align 0: {other:?}"),
        }
        assert!(!registry.contains("t1"));
        reg.schemas.pop();
        registry.register(reg, me(), false).expect("valid schemas register");
        assert!(registry.contains("t1"));
    }

    /// `nerve connect` of one type laid out two ways is refused by the
    /// shared rule (`schema::compat`): the fields that differ are listed
    /// from the registered schemas, or the fingerprints named when a side
    /// registered none, and no side is called the older build.
    #[test]
    fn a_connection_of_one_type_laid_out_two_ways_is_refused_listing_the_fields() {
        use shm_schemas::control::agent_to_router::PortSpec;
        use shm_schemas::payloads::Tick;
        use shm_schemas::schema::{Field, Kind};
        let mut wide = Tick::schema();
        let Kind::Struct { fields } = &mut wide.kind else { panic!("Tick is a struct") };
        fields.push(Field { name: "spread".into(), offset: 16, schema: f64::schema() });
        wide.size = 24;
        let me = || ProcessHandle::take(std::process::id()).expect("this process");
        let mut registry = Registry::default();
        let mut t1 = registration(std::process::id());
        t1.outputs = vec![PortSpec::of::<Tick>("tick")];
        t1.schemas = vec![Tick::schema()];
        let mut w = registration(std::process::id());
        w.name = "w".into();
        w.inputs =
            vec![PortSpec { name: "tick".into(), type_name: "nerve::Tick".into(), fingerprint: wide.fingerprint() }];
        w.schemas = vec![wide];
        registry.register(t1.clone(), me(), false).expect("t1 registers");
        registry.register(w.clone(), me(), false).expect("w registers");
        let port = |p: &str| p.parse::<shm_schemas::PortRef>().expect("a port");
        let text = match registry.check_compatible(&port("t1/tick"), &port("w/tick")) {
            Err(e @ RouterError::LayoutMismatch { .. }) => e.to_string(),
            other => panic!("connected one type of two layouts: {other:?}"),
        };
        assert!(text.contains("field `spread` (f64, 8 bytes at offset 16): only in w/tick"), "{text}");
        assert!(text.contains("make both declare the same layout of nerve::Tick") && !text.contains("older"), "{text}");
        // registered without its schemas (too large for the service): told by fingerprint
        w.schemas.clear();
        registry.register(w, me(), false).expect("w registers again");
        let text = match registry.check_compatible(&port("t1/tick"), &port("w/tick")) {
            Err(e @ RouterError::LayoutMismatch { .. }) => e.to_string(),
            other => panic!("connected one type of two fingerprints: {other:?}"),
        };
        assert!(!text.contains("fields differ") && text.contains("make both declare the same layout"), "{text}");
        // the same layout connects
        let mut r = registration(std::process::id());
        r.name = "r".into();
        r.inputs = vec![PortSpec::of::<Tick>("in")];
        registry.register(r, me(), false).expect("r registers");
        assert_eq!(registry.check_compatible(&port("t1/tick"), &port("r/in")).expect("one layout"), "nerve::Tick");
    }

    fn refusal(pid: u32, world: &World) -> String {
        match check_process(&registration(pid), world) {
            Err(e @ RouterError::RegistrationRefused { .. }) => e.to_string(),
            other => panic!("pid {pid} was not refused: {other:?}"),
        }
    }

    #[test]
    fn a_registration_naming_a_process_that_is_not_a_nerve_agent_is_refused() {
        let world = World::new(&format!("regchk{}", std::process::id())).expect("world");
        // any process of ours that is not an agent: `nerve kill t1` would kill it
        let mut sleep = Command::new("sleep").arg("30").spawn().expect("start sleep");
        let e = refusal(sleep.id(), &world);
        assert!(e.contains("not a nerve agent") && e.contains("sleep") && e.contains("t1"), "{e}");
        let _ = sleep.kill();
        // dead and not yet reaped, as an agent that died in its `start`
        // while its registration was on the way
        let zombie = (0..200).any(|_| {
            std::thread::sleep(std::time::Duration::from_millis(5));
            std::fs::read_to_string(format!("/proc/{}/stat", sleep.id())).is_ok_and(|s| s.contains(") Z "))
        });
        assert!(zombie, "sleep did not end");
        let e = refusal(sleep.id(), &world);
        assert!(e.contains("no process has this pid") && e.contains("ended right after"), "{e}");
        let _ = sleep.wait();
        // a pid nobody has (any more)
        let e = refusal(sleep.id(), &world);
        assert!(e.contains("no process has this pid"), "{e}");
        // this test's own executable is `nerve_router-...`: believed
        assert!(check_process(&registration(std::process::id()), &world).is_ok());
    }

    #[test]
    fn a_registration_of_another_users_process_is_refused() {
        if !nix::unistd::geteuid().is_root() {
            eprintln!("skipped: needs root to start a process of another uid");
            return;
        }
        let world = World::new(&format!("reguid{}", std::process::id())).expect("world");
        let mut other = std::os::unix::process::CommandExt::uid(&mut Command::new("sleep"), 65534)
            .arg("30")
            .spawn()
            .expect("start sleep as nobody");
        let e = refusal(other.id(), &world);
        let _ = other.kill();
        let _ = other.wait();
        assert!(e.contains("uid 65534"), "{e}");
    }
}
