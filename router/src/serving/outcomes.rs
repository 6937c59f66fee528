//! A job's end: when the last outcome of its commands is in, what the
//! router records from what the agents did (not from what was asked), and
//! the reply the caller gets.

use super::*;

impl State {
    pub(super) fn finish(&mut self, job: Job) {
        let Job { reply, mut outcomes, work, since, .. } = job;
        let label = work.label();
        let now = self.now;
        tracing::debug!(job = label, us = now.saturating_duration_since(since).as_micros() as u64, "job ready");
        let mut single = || {
            outcomes
                .pop()
                .map_or_else(|| Err(RouterError::Internal("a command without an outcome".into())), |o| o.result)
        };
        let result = match work {
            Work::Views { graph, asked } => {
                let mut stats: BTreeMap<String, AgentStats> = BTreeMap::new();
                for o in outcomes {
                    let name = asked.get(&o.ticket).cloned().unwrap_or(o.agent);
                    if let Ok(AgentReply::Stats(s)) = o.result {
                        stats.insert(name, s);
                    }
                }
                let agents = self.views(&stats);
                Ok(if graph {
                    let mut connections = self.wiring.views(&agents);
                    connections.extend(self.transient.connections().map(|c| wiring::view(c, &agents, true)));
                    RouterReply::Graph(GraphView { agents, connections })
                } else {
                    RouterReply::Agents(agents)
                })
            }
            Work::Connect { conn } => match single() {
                Ok(_) => {
                    tracing::info!(from = %conn.from, to = %conn.to, "connected {} -> {}", conn.from, conn.to);
                    let what = format!("connected {} -> {}", conn.from, conn.to);
                    let event = EventKind::Connected { from: conn.from.to_string(), to: conn.to.to_string() };
                    if self.wiring.add(conn) {
                        self.events.push(event);
                        let save = self.persist_wiring();
                        let job = Job { reply, since, ..self.when_saved(save, what) };
                        return self.jobs.push(job);
                    }
                    Ok(RouterReply::Ok)
                }
                // nothing was saved for it: the list stays as it is
                Err(e) => Err(e),
            },
            Work::AgentView { name } => match single() {
                // one view, not every agent's (`nerve cmd` asks every 20 ms); none if it left meanwhile
                Ok(AgentReply::Stats(s)) => Ok(RouterReply::Agents(
                    self.registry.get(&name).map(|e| self.live_view(&name, e, Some(s))).into_iter().collect(),
                )),
                Ok(other) => Err(RouterError::Internal(format!("unexpected reply {other:?}"))),
                Err(e) => Err(e),
            },
            Work::Attach { attached } => single().map(|_| {
                let (from, to) = (attached.conn.from.to_string(), attached.conn.to.to_string());
                let pid = attached.process.pid();
                tracing::info!(from = %from, to = %to, pid, "attached {from} -> {to} (a tool, pid {pid})");
                if self.transient.add(attached) {
                    self.events.push(EventKind::Connected { from, to });
                }
                RouterReply::Ok
            }),
            Work::Detach { conn } => {
                // it let go, or it did not have it: either way nothing flows
                match single() {
                    Ok(_) | Err(RouterError::AgentRefused { .. }) => {
                        tracing::info!(from = %conn.from, to = %conn.to, "detached {} -> {}", conn.from, conn.to);
                        Ok(RouterReply::Ok)
                    }
                    Err(e) => Err(e),
                }
            }
            Work::Disconnect { conn } => match single() {
                // it let go, or it did not have it: either way nothing flows
                Ok(_) | Err(RouterError::AgentRefused { .. }) => {
                    self.wiring.remove(&conn.from, &conn.to);
                    self.events.push(EventKind::Disconnected { from: conn.from.to_string(), to: conn.to.to_string() });
                    let save = self.persist_wiring();
                    tracing::info!(from = %conn.from, to = %conn.to, "disconnected {} -> {}", conn.from, conn.to);
                    let what = format!("disconnected {} -> {}", conn.from, conn.to);
                    let job = Job { reply, since, ..self.when_saved(save, what) };
                    return self.jobs.push(job);
                }
                Err(RouterError::AgentUnreachable { name, detail }) => Err(RouterError::AgentUnreachable {
                    detail: format!(
                        "{detail}; {} -> {} stays in the connection list since {name} may still read it: try again, or `nerve kill {name}` and disconnect then",
                        conn.from, conn.to
                    ),
                    name,
                }),
                Err(e) => Err(e),
            },
            Work::Command { name, what } => single().map(|reply| self.obeyed(&name, &what, reply)),
            Work::Kill { name, pid, over } => match over {
                Some(Ok(still_there)) => {
                    if still_there {
                        tracing::warn!(agent = %name, pid, "{name} (pid {pid}) is still there {KILL_WAIT:?} after SIGKILL");
                    }
                    Ok(RouterReply::Ok)
                }
                Some(Err(e)) => Err(e),
                None => Err(RouterError::Internal("a kill without an end".into())),
            },
            Work::Saved { what, done, .. } => match done {
                Some(Err(detail)) => {
                    Err(RouterError::NotSaved { what, file: self.list_file.display().to_string(), detail })
                }
                _ => Ok(RouterReply::Ok),
            },
            Work::WaitRegistered { names, .. } => {
                Ok(RouterReply::Waited { missing: names.into_iter().filter(|n| !self.there(n)).collect() })
            }
            Work::Start { order, mut results } => Ok(RouterReply::Started(
                order
                    .into_iter()
                    .map(|name| {
                        let result = results.remove(&name).unwrap_or_else(|| StartResult::Failed {
                            status: "unknown".into(),
                            said: "the router lost this start".into(),
                        });
                        StartOutcome { name, result }
                    })
                    .collect(),
            )),
            Work::Background { name, what, effect } => {
                match single() {
                    Ok(reply) => {
                        tracing::info!(agent = %name, "{what}");
                        self.obeyed(&name, &effect, reply);
                    }
                    Err(e) => tracing::warn!(agent = %name, "not done: {what}: {e}"),
                }
                return;
            }
        };
        if let Some(id) = reply {
            tracing::debug!(job = label, us = now.saturating_duration_since(since).as_micros() as u64, "answered");
            self.reply(id, result.unwrap_or_else(RouterReply::Error));
        }
    }

    /// Records what an agent obeyed; the reply to give.
    pub(super) fn obeyed(&mut self, name: &str, what: &Asked, reply: AgentReply) -> RouterReply {
        let now = self.now;
        match what {
            Asked::Rate(period_ns) => {
                if let Some(e) = self.registry.get_mut(name) {
                    e.reg.period_ns = Some(*period_ns);
                }
                self.remembered.set_period(name, *period_ns, now);
            }
            Asked::Suspend | Asked::Resume => {
                let suspended = matches!(what, Asked::Suspend);
                if let Some(e) = self.registry.get_mut(name) {
                    e.state = if suspended { AgentState::Suspended } else { AgentState::Running };
                }
                self.remembered.set_suspended(name, suspended, now);
            }
            Asked::ParamGet => {
                return match reply {
                    AgentReply::Param(v) => RouterReply::Param(v),
                    other => RouterReply::Error(RouterError::Internal(format!("unexpected reply {other:?}"))),
                };
            }
            Asked::ParamList => {
                return match reply {
                    AgentReply::Params(v) => RouterReply::Params(v),
                    other => RouterReply::Error(RouterError::Internal(format!("unexpected reply {other:?}"))),
                };
            }
            Asked::ParamSet { key, value } => {
                if !self.remembered.set_param(name, key, value, now) {
                    tracing::warn!(
                        agent = name,
                        "{name}: {key} = {value} is set but not remembered for a restart: {} other parameters of it are",
                        remembered::MAX_PARAMS
                    );
                }
            }
            Asked::Stop => {
                if self.supervisor.stopped_by_user(name) {
                    self.persist_supervision();
                }
            }
            Asked::Nothing => {}
        }
        RouterReply::Ok
    }
}
