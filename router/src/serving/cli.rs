//! The router's answer to a command-line request (`nerve connect`, `start`,
//! `stop`, `rate`, `ps`, ...): answered at once from what the router knows,
//! or turned into a job of commands to agents.

use super::*;

impl State {
    /// A command-line request, from a registry without dead agents (the
    /// driver's liveness check comes first).
    pub(super) fn cli(
        &mut self,
        req: CliRequest,
        tool: Option<Result<ProcessHandle, String>>,
    ) -> Result<Started, RouterError> {
        let command = |s: &mut Self, name: String, cmd: AgentCommand, what: Asked| -> Result<Started, RouterError> {
            let ticket = s.submit(&name, cmd, AGENT_TIMEOUT)?;
            Ok(s.waiting(vec![ticket], Work::Command { name, what }))
        };
        match req {
            CliRequest::Ps | CliRequest::Graph => {
                let graph = matches!(req, CliRequest::Graph);
                let names: Vec<String> = self.registry.iter().map(|(n, _)| n.clone()).collect();
                let mut asked = BTreeMap::new();
                for name in names {
                    let ticket = self.send(&name, AgentCommand::Stats, STATS_TIMEOUT);
                    asked.insert(ticket, name);
                }
                Ok(self.waiting(asked.keys().copied().collect(), Work::Views { graph, asked }))
            }
            CliRequest::Agent { name } => {
                self.registry.live(&name)?;
                let ticket = self.send(&name, AgentCommand::Stats, STATS_TIMEOUT);
                Ok(self.waiting(vec![ticket], Work::AgentView { name }))
            }
            CliRequest::Attach { from, pid, type_name, fingerprint, to } => {
                if self.registry.contains(from.agent.as_str()) {
                    return Err(RouterError::NotApplicable(format!(
                        "{from} is an agent's port: connect it with `nerve connect {from} {to}`"
                    )));
                }
                let process = match tool {
                    Some(Ok(p)) if p.pid() == pid => p,
                    Some(Err(e)) => {
                        return Err(RouterError::NotApplicable(format!(
                            "cannot attach {from}: its process {pid} is not there ({e})"
                        )));
                    }
                    _ => {
                        return Err(RouterError::NotApplicable(format!(
                            "cannot attach {from}: its process {pid} was not looked at"
                        )));
                    }
                };
                let spec = PortSpec { name: from.port.clone(), type_name, fingerprint };
                self.registry.check_input(&from, &spec, &to)?;
                let conn = Connection { from, to, type_name: spec.type_name, allow_cycle: false };
                let (agent, cmd) = Wiring::connect_command(&conn);
                let ticket = self.submit(&agent, cmd, AGENT_TIMEOUT)?;
                Ok(self.waiting(vec![ticket], Work::Attach { attached: Attached { conn, process } }))
            }
            CliRequest::Detach { from, to } => {
                if self.registry.contains(from.agent.as_str()) {
                    return Err(RouterError::NotConnected { from: from.to_string(), to: to.to_string() });
                }
                let conn = match self.transient.remove(&from, &to) {
                    Some(a) => {
                        self.events.push(EventKind::Disconnected { from: from.to_string(), to: to.to_string() });
                        a.conn
                    }
                    // attached under an earlier router: the agent may still hold it
                    None => Connection { from, to, type_name: String::new(), allow_cycle: false },
                };
                let (agent, cmd) = Wiring::disconnect_command(&conn);
                let ticket = self.submit(&agent, cmd, AGENT_TIMEOUT)?;
                Ok(self.waiting(vec![ticket], Work::Detach { conn }))
            }
            CliRequest::Events { after } => Ok(Started::Answer(RouterReply::Events {
                epoch: self.epoch,
                next: self.events.next(),
                events: self.events.after(after),
            })),
            CliRequest::Connect { from, to, allow_cycle } => {
                let (from, to) = self.registry.wire_order(from, to);
                let from_type = self.registry.check_compatible(&from, &to)?;
                if !allow_cycle {
                    let registry = &self.registry;
                    let event_driven = |n: &str| registry.get(n).is_some_and(|e| e.reg.task == TaskKind::EventDriven);
                    // a loop through an edge allowed to close one is allowed;
                    // connects still waiting for their agent count too, so
                    // that requests sent side by side (`nerve launch`) cannot
                    // close a loop between them unseen
                    let edges = self.wiring.loop_edges().chain(self.pending_loop_edges());
                    if let Some(cycle) = event_cycle(edges, from.agent.as_str(), to.agent.as_str(), event_driven) {
                        return Err(RouterError::Cycle { from: from.to_string(), to: to.to_string(), cycle });
                    }
                }
                let conn = Connection { from, to, type_name: from_type, allow_cycle };
                let (agent, cmd) = Wiring::connect_command(&conn);
                let ticket = self.submit(&agent, cmd, AGENT_TIMEOUT)?;
                // saved once the agent has subscribed (the list on disk
                // never holds an edge an agent refused)
                Ok(self.waiting(vec![ticket], Work::Connect { conn }))
            }
            CliRequest::Disconnect { from, to } => {
                // a call's wire, written client first, is listed service to client
                let (from, to) = if self.wiring.find(&from, &to).is_none() && self.wiring.find(&to, &from).is_some() {
                    (to, from)
                } else {
                    (from, to)
                };
                let (f, t) = (from.to_string(), to.to_string());
                let Some(conn) = self.wiring.find(&from, &to).cloned() else {
                    return Err(RouterError::NotConnected { from: f, to: t });
                };
                if !self.registry.contains(to.agent.as_str()) {
                    // nobody reads it: the list is the whole truth
                    self.wiring.remove(&from, &to);
                    self.events.push(EventKind::Disconnected { from: f.clone(), to: t.clone() });
                    let save = self.persist_wiring();
                    tracing::info!(from = %f, to = %t, "disconnected {f} -> {t}");
                    return Ok(Started::Job(Box::new(self.when_saved(save, format!("disconnected {f} -> {t}")))));
                }
                let (agent, cmd) = Wiring::disconnect_command(&conn);
                let ticket = self.submit(&agent, cmd, AGENT_TIMEOUT)?;
                // saved once the agent has let go
                Ok(self.waiting(vec![ticket], Work::Disconnect { conn }))
            }
            CliRequest::Rate { name, period_ns } => {
                command(self, name, AgentCommand::SetPeriod { period_ns }, Asked::Rate(period_ns))
            }
            CliRequest::Suspend { name } => command(self, name, AgentCommand::Suspend, Asked::Suspend),
            CliRequest::Resume { name } => command(self, name, AgentCommand::Resume, Asked::Resume),
            CliRequest::ParamGet { name, key } => command(self, name, AgentCommand::ParamGet { key }, Asked::ParamGet),
            CliRequest::ParamList { name } => command(self, name, AgentCommand::ParamList, Asked::ParamList),
            CliRequest::ParamSet { name, key, value } => {
                let cmd = AgentCommand::ParamSet { key: key.clone(), value: value.clone() };
                command(self, name, cmd, Asked::ParamSet { key, value })
            }
            CliRequest::Stop { name } => {
                if !self.registry.contains(&name) {
                    // a supervised agent waiting for its restart: stopping it
                    // cancels the restart (there is no process to disagree)
                    if self.supervisor.stopped_by_user(&name) {
                        self.persist_supervision();
                    }
                    return Err(self.registry.unknown(&name));
                }
                command(self, name, AgentCommand::Stop, Asked::Stop)
            }
            CliRequest::Supervise(spec) => {
                tracing::info!(
                    agent = %spec.name,
                    "supervising {}: restart {:?}, at most {} restarts in {:?}",
                    spec.name,
                    spec.policy,
                    spec.max_restarts,
                    Duration::from_nanos(spec.window_ns)
                );
                let registry = &self.registry;
                self.supervisor.supervise(spec, self.now, |n| registry.contains(n))?;
                self.persist_supervision();
                Ok(Started::Answer(RouterReply::Ok))
            }
            CliRequest::Kill { name } => {
                // through the handle taken at registration: a pid reused since
                // the agent died (and before the liveness check saw it) is not signalled
                let process = self.registry.live(&name)?.process.clone();
                let pid = process.pid();
                self.ticket = self.ticket.wrapping_add(1);
                let ticket = self.ticket;
                self.out.push(Effect::Kill { ticket, name: name.clone(), process });
                Ok(self.waiting(vec![ticket], Work::Kill { name, pid, over: None }))
            }
            CliRequest::WaitRegistered { names, timeout_ns } => {
                let wait = Duration::from_nanos(timeout_ns).min(MAX_WAIT_REGISTERED);
                let until = self.now.checked_add(wait).unwrap_or(self.now);
                Ok(self.waiting(Vec::new(), Work::WaitRegistered { names, until }))
            }
            CliRequest::Start { agents } => self.start(agents),
            CliRequest::Shutdown => {
                self.shutdown = true;
                self.supervisor.stop_all();
                self.out.push(Effect::Remove { path: self.supervisor.path().to_owned() });
                Ok(Started::Answer(RouterReply::Ok))
            }
        }
    }
}
