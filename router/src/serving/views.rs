//! The agents as `nerve ps` and `nerve graph` show them: the live ones
//! with the figures they answered, then the supervised ones restarting or
//! failed.

use super::*;

impl State {
    /// The agents as `ps` shows them: the live ones with the statistics
    /// they answered (`unresponsive` when they did not), then the supervised
    /// ones that are restarting or failed.
    pub(super) fn views(&self, stats: &BTreeMap<String, AgentStats>) -> Vec<AgentView> {
        let mut out = Vec::new();
        for (name, e) in self.registry.iter() {
            out.push(self.live_view(name, e, stats.get(name).cloned()));
        }
        for (name, sup) in self.supervisor.iter() {
            if self.registry.contains(name) || !sup.is_pending() {
                continue;
            }
            out.push(AgentView {
                name: name.clone(),
                pid: 0,
                kind: sup.spec.argv[0].rsplit('/').next().unwrap_or("").trim_start_matches("nerve-").to_owned(),
                state: if sup.failed { AgentState::Failed } else { AgentState::Restarting },
                task: TaskKind::Periodic,
                period_ns: None,
                inputs: vec![],
                outputs: vec![],
                log_file: Some(self.logs_dir.join(format!("{name}.log")).display().to_string()),
                stats: None,
                restarts: sup.total,
                importance: Some(sup.spec.importance),
                schemas: vec![],
                services: vec![],
                clients: vec![],
            });
        }
        out.sort_by(|a, b| a.name.cmp(&b.name));
        out
    }

    /// Live agent `name` as `ps` shows it, with the statistics it answered
    /// (`None`: it did not, and shows as unresponsive).
    pub(super) fn live_view(&self, name: &str, e: &Entry, stats: Option<AgentStats>) -> AgentView {
        let sup = self.supervisor.get(name);
        AgentView {
            name: name.to_owned(),
            pid: e.reg.pid,
            kind: e.reg.kind.clone(),
            state: if stats.is_some() { e.state } else { AgentState::Unresponsive },
            task: e.reg.task,
            period_ns: if e.reg.task == TaskKind::Periodic { e.reg.period_ns } else { None },
            inputs: e.reg.inputs.clone(),
            outputs: e.reg.outputs.clone(),
            log_file: e.reg.log_file.clone(),
            stats,
            restarts: sup.map(|s| s.total).unwrap_or(0),
            importance: sup.map(|s| s.spec.importance),
            schemas: e.reg.schemas.clone(),
            services: e.reg.services.clone(),
            clients: e.reg.clients.clone(),
        }
    }
}
