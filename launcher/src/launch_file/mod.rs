//! Launch files: a robot composed in one TOML file.
//!
//! ```toml
//! robot = "demo"                 # optional
//! [[agent]]
//! name = "t1"
//! kind = "ticker"                # or exe = "path/to/agent" (relative: to this file's folder)
//! period = "10ms"
//! params = { step = 1 }
//! restart = "on-failure"         # never | on-failure | always
//! cpu_latency = "off"            # PM QoS bound in µs, or "off" (also top-level, for all)
//! cpus = [0]                     # keep the agent on these CPUs (or "0-1")
//! poll = true                    # poll instead of sleeping, on those CPUs (needs cpus)
//! [[agent]]
//! name = "r1"
//! kind = "relay"
//! [[connect]]
//! from = "t1/tick"
//! to = "r1/in"
//! ```
//!
//! A file may also take arguments (`[args]`, `{arg.NAME}`), include other
//! files (`[[include]]`) and leave entries out with `if`/`unless`: those are
//! resolved first, in [`compose`] (docs/launch.md).
//!
//! Parsing is strict (unknown keys are refused) and the whole file is
//! checked before anything starts: syntax, names, unknown kinds, missing
//! executables, duplicate names, periods, connections to unknown agents or
//! ports, mismatched types, and one type name laid out differently at the
//! two ends (field by field, by the rule of the router and the agent,
//! [`shm_schemas::schema::compat`]). Ports, types and layouts come from each
//! agent executable's `--describe` (once per distinct executable, parameters
//! and arguments). Every problem is reported as `FILE:LINE: what, and what
//! to do`.

use crate::kinds::resolve_kind;
use agent_sdk::World;
use agent_sdk::cpu_latency::CpuLatencySetting;
use agent_sdk::rt::CpuList;
use serde::Deserialize;
use shm_schemas::control::agent_to_router::{PortSpec, TaskKind};
use shm_schemas::control::describe::Description;
use shm_schemas::schema::compat::{self, Declared};
use shm_schemas::{AgentName, PortRef, RobotName};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::time::Duration;
use toml::Spanned;

mod compose;
mod inputs;
use compose::Source;
pub use compose::parse_cli_args;

/// When a supervised agent is restarted (`restart = "on-failure"`): the
/// router's own type, so that the file and the request cannot drift apart.
pub use shm_schemas::control::cli_to_router::RestartPolicy;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    robot: Option<Spanned<String>>,
    cpu_latency: Option<Spanned<toml::Value>>,
    /// `sim_time = true`: the robot on simulated time (docs/time.md)
    sim_time: Option<Spanned<toml::Value>>,
    /// `time_scale = K`: its speed on simulated time
    time_scale: Option<Spanned<toml::Value>>,
    /// the file's arguments: NAME = default, or NAME = { default = .., doc = .. }
    args: Option<Spanned<BTreeMap<String, Spanned<toml::Value>>>>,
    #[serde(default)]
    include: Vec<RawInclude>,
    #[serde(default)]
    agent: Vec<RawAgent>,
    #[serde(default)]
    connect: Vec<RawConnect>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInclude {
    file: Spanned<String>,
    #[serde(default)]
    args: BTreeMap<String, Spanned<toml::Value>>,
    prefix: Option<Spanned<String>>,
    #[serde(rename = "if")]
    cond: Option<Spanned<String>>,
    unless: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAgent {
    name: Spanned<String>,
    kind: Option<Spanned<String>>,
    exe: Option<Spanned<String>>,
    period: Option<Spanned<String>>,
    device: Option<Spanned<String>>,
    #[serde(default)]
    args: Vec<Spanned<String>>,
    #[serde(default)]
    params: BTreeMap<String, Spanned<toml::Value>>,
    /// each input's `{ depth = N, keep = "latest" | "all" }` (inputs.rs)
    #[serde(default)]
    inputs: BTreeMap<String, Spanned<toml::Value>>,
    restart: Option<Spanned<RestartPolicy>>,
    max_restarts: Option<u32>,
    restart_window: Option<Spanned<String>>,
    backoff: Option<Spanned<String>>,
    importance: Option<Spanned<u8>>,
    #[serde(default)]
    suspended: bool,
    log_level: Option<Spanned<String>>,
    cpu_latency: Option<Spanned<toml::Value>>,
    cpus: Option<Spanned<toml::Value>>,
    poll: Option<Spanned<bool>>,
    #[serde(rename = "if")]
    cond: Option<Spanned<String>>,
    unless: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawConnect {
    from: Spanned<String>,
    to: Spanned<String>,
    #[serde(default)]
    allow_cycle: bool,
    #[serde(rename = "if")]
    cond: Option<Spanned<String>>,
    unless: Option<Spanned<String>>,
}

/// One agent of a validated launch file.
#[derive(Debug, Clone)]
pub struct AgentSpec {
    /// name
    pub name: String,
    /// kind shown to the user
    pub kind: String,
    /// the executable
    pub exe: PathBuf,
    /// period, for periodic agents
    pub period: Option<String>,
    /// agent-specific arguments (after `--`), with `{state}`, `{robot}` and `{dir}` expanded
    pub args: Vec<String>,
    /// `KEY=VALUE` parameter settings
    pub params: Vec<String>,
    /// `NAME:depth=N,keep=WORD` input settings (`inputs`, docs/inputs.md)
    pub inputs: Vec<String>,
    /// restart policy
    pub restart: RestartPolicy,
    /// restarts allowed within `restart_window`
    pub max_restarts: u32,
    /// the window
    pub restart_window: Duration,
    /// first back-off delay (doubles per restart in the window)
    pub backoff: Duration,
    /// 1..10, for the resource manager
    pub importance: u8,
    /// start suspended
    pub suspended: bool,
    /// log filter
    pub log_level: Option<String>,
    /// PM QoS bound (`cpu_latency`, the agent's or the file's); None: the agent's default
    pub cpu_latency: Option<CpuLatencySetting>,
    /// CPUs the agent is kept on (`cpus`)
    pub cpus: Option<CpuList>,
    /// poll instead of sleeping (`poll`), on `cpus`
    pub poll: bool,
    /// the agent's own description
    pub description: Description,
}

impl AgentSpec {
    /// The command line that starts this agent as a daemon.
    pub fn argv(&self, robot: &str) -> Vec<String> {
        let mut v = vec![
            self.exe.display().to_string(),
            "--robot".into(),
            robot.into(),
            "--name".into(),
            self.name.clone(),
            "--daemon".into(),
        ];
        if let Some(p) = &self.period {
            v.extend(["--period".into(), p.clone()]);
        }
        if let Some(l) = &self.log_level {
            v.extend(["--log-level".into(), l.clone()]);
        }
        if let Some(c) = &self.cpu_latency {
            v.extend(["--cpu-latency".into(), c.to_string()]);
        }
        if let Some(c) = &self.cpus {
            v.extend(["--cpus".into(), c.to_string()]);
        }
        if self.poll {
            v.push("--poll".into());
        }
        if self.suspended {
            v.push("--suspended".into());
        }
        for p in &self.params {
            v.extend(["--param".into(), p.clone()]);
        }
        for i in &self.inputs {
            v.extend(["--input".into(), i.clone()]);
        }
        if !self.args.is_empty() {
            v.push("--".into());
            v.extend(self.args.iter().cloned());
        }
        v
    }
}

/// A validated launch file.
#[derive(Debug, Clone)]
pub struct LaunchFile {
    /// the file
    pub path: PathBuf,
    /// agents in file order
    pub agents: Vec<AgentSpec>,
    /// connections (from, to) in file order
    pub connections: Vec<(PortRef, PortRef)>,
    /// the connections marked `allow_cycle = true`: they may close a loop
    /// of event-driven agents ([`shm_schemas::cycles`])
    pub allow_cycle: Vec<(PortRef, PortRef)>,
    /// `sim_time = true`: the robot runs on simulated time (as with
    /// `nerve launch --sim-time`, docs/time.md)
    pub sim_time: bool,
    /// `time_scale = K`: how fast simulated time runs (`--time-scale` wins)
    pub time_scale: Option<f64>,
}

/// Every problem found in a launch file (and the files it includes), each with its line.
#[derive(Debug)]
pub struct LaunchErrors {
    /// the file
    pub path: PathBuf,
    /// (line, message) in `path`
    pub errors: Vec<(usize, String)>,
    /// (file, line, message) in the files `path` includes
    pub included: Vec<(PathBuf, usize, String)>,
}

impl std::fmt::Display for LaunchErrors {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (line, msg) in &self.errors {
            writeln!(f, "{}:{line}: {msg}", self.path.display())?;
        }
        for (path, line, msg) in &self.included {
            writeln!(f, "{}:{line}: {msg}", path.display())?;
        }
        let n = self.errors.len() + self.included.len();
        write!(f, "{n} problem(s) in {}; nothing was started", self.path.display())
    }
}

impl std::error::Error for LaunchErrors {}

impl LaunchErrors {
    /// From (file index, line, message) over `sources`, sorted by file then line.
    fn of(sources: &[Source], mut all: Vec<(usize, usize, String)>) -> Self {
        all.sort_by_key(|(f, l, _)| (*f, *l));
        let path = sources.first().map(|s| s.path.clone()).unwrap_or_default();
        let mut errors = Vec::new();
        let mut included = Vec::new();
        for (f, line, msg) in all {
            match sources.get(f) {
                Some(s) if f > 0 => included.push((s.path.clone(), line, msg)),
                _ => errors.push((line, msg)),
            }
        }
        LaunchErrors { path, errors, included }
    }
}

fn line_of(src: &str, offset: usize) -> usize {
    src[..offset.min(src.len())].bytes().filter(|b| *b == b'\n').count() + 1
}

/// The checks' errors, each in the file ([`Source`]) of the entry being checked.
struct Ctx<'a> {
    sources: &'a [Source],
    /// the file of the entry being checked
    cur: usize,
    errors: Vec<(usize, usize, String)>,
}

impl Ctx<'_> {
    fn err<T>(&mut self, at: &Spanned<T>, msg: impl Into<String>) {
        let line = self.sources.get(self.cur).map(|s| line_of(&s.src, at.span().start)).unwrap_or(1);
        self.errors.push((self.cur, line, msg.into()));
    }

    /// `FILE:LINE` of `at` in the current file, for messages that point elsewhere.
    fn place<T>(&self, at: &Spanned<T>) -> (usize, usize) {
        let line = self.sources.get(self.cur).map(|s| line_of(&s.src, at.span().start)).unwrap_or(1);
        (self.cur, line)
    }
}

/// Expands `{state}` and `{robot}` in a launch-file string.
pub fn expand(s: &str, world: &World) -> String {
    s.replace("{state}", &world.state_dir().display().to_string()).replace("{robot}", world.robot().as_str())
}

/// Expands `{state}`, `{robot}` and `{dir}` (the launch file's own folder,
/// so that a file can name its neighbours wherever it is launched from).
fn expand_in(s: &str, world: &World, dir: &Path) -> String {
    expand(s, world).replace("{dir}", &dir.display().to_string())
}

fn param_text(v: &toml::Value) -> Option<String> {
    match v {
        toml::Value::String(s) => Some(s.clone()),
        toml::Value::Integer(i) => Some(i.to_string()),
        toml::Value::Float(f) => Some(f.to_string()),
        toml::Value::Boolean(b) => Some(b.to_string()),
        _ => None,
    }
}

/// Runs `EXE --describe [--param ..] -- ARGS` and parses its description.
pub fn describe(exe: &Path, params: &[String], args: &[String]) -> Result<Description, String> {
    let mut cmd = std::process::Command::new(exe);
    cmd.arg("--describe").arg("--no-realtime");
    for p in params {
        cmd.arg("--param").arg(p);
    }
    if !args.is_empty() {
        cmd.arg("--").args(args);
    }
    let out = cmd.env_remove("NOTIFY_SOCKET").output().map_err(|e| format!("cannot run {}: {e}", exe.display()))?;
    if !out.status.success() {
        // the agent's last error, with the lines that follow it (a config
        // file's own problems, one per line)
        let err = String::from_utf8_lossy(&out.stderr);
        let lines: Vec<&str> = err.lines().collect();
        let msg = match lines.iter().rposition(|l| l.starts_with("error")) {
            Some(i) => lines[i..].join("\n"),
            None => err.trim().to_owned(),
        };
        return Err(msg.trim_start_matches("error: ").to_owned());
    }
    let d: Description = serde_json::from_slice(&out.stdout).map_err(|e| {
        format!("{} is not a nerve agent (its --describe output is not understood: {e})", exe.display())
    })?;
    if d.protocol != shm_schemas::PROTOCOL_VERSION {
        return Err(shm_schemas::ProtocolError::VersionMismatch {
            peer: d.protocol,
            ours: shm_schemas::PROTOCOL_VERSION,
        }
        .to_string());
    }
    Ok(d)
}

/// A `cpu_latency` value: `"off"`, a number of µs, or a string such as `"20us"`.
fn cpu_latency_of(cx: &mut Ctx, v: &Spanned<toml::Value>) -> Option<CpuLatencySetting> {
    let parsed = match v.get_ref() {
        toml::Value::String(s) => s.parse(),
        toml::Value::Integer(i) => i.to_string().parse(),
        other => Err(format!("{other} is neither \"off\" nor a number of microseconds")),
    };
    parsed.map_err(|e| cx.err(v, format!("cpu_latency: {e}"))).ok()
}

/// A `sim_time` value: `true` or `false`, or a string that is one of them
/// (`sim_time = "{arg.sim}"`, so that the command line can choose).
fn sim_time_of(cx: &mut Ctx, v: &Spanned<toml::Value>) -> Option<bool> {
    match v.get_ref() {
        toml::Value::Boolean(b) => Some(*b),
        toml::Value::String(s) => match s.trim() {
            "true" => Some(true),
            "false" => Some(false),
            other => {
                cx.err(v, format!("sim_time is {other:?}; an argument that sets it must be \"true\" or \"false\""));
                None
            }
        },
        other => {
            cx.err(v, format!("sim_time is {other}; write sim_time = true or sim_time = false"));
            None
        }
    }
}

/// A `time_scale` value: a number (or a string of one) from 0.01 to 100, by
/// the rule of `--time-scale`.
fn time_scale_of(cx: &mut Ctx, v: &Spanned<toml::Value>) -> Option<f64> {
    let text = match v.get_ref() {
        toml::Value::String(s) => s.clone(),
        toml::Value::Integer(i) => i.to_string(),
        toml::Value::Float(f) => f.to_string(),
        other => other.to_string(),
    };
    crate::sim_time::parse_scale(&text).map_err(|e| cx.err(v, format!("time_scale: {e}"))).ok()
}

/// A `poll` value: polling is only allowed on a placement (`cpus`), as
/// the agent's `--poll` needs `--cpus` (`agent_sdk::runtime::PollError`).
fn poll_of(cx: &mut Ctx, v: Option<&Spanned<bool>>, placed: bool) -> bool {
    let Some(v) = v else { return false };
    if *v.get_ref() && !placed {
        cx.err(
            v,
            "poll = true needs a placement: a polling agent takes its CPU whole; add `cpus = [1]` (a CPU nothing else runs on) to this agent",
        );
    }
    *v.get_ref()
}

/// A `cpus` value: `[0, 1]`, `0` or a string such as `"0-1"`; a CPU this
/// machine lacks is refused here, before anything starts.
fn cpus_of(cx: &mut Ctx, v: &Spanned<toml::Value>) -> Option<CpuList> {
    let text = match v.get_ref() {
        toml::Value::String(s) => Ok(s.clone()),
        toml::Value::Integer(i) => Ok(i.to_string()),
        toml::Value::Array(a) => a
            .iter()
            .map(|x| x.as_integer().map(|i| i.to_string()).ok_or(()))
            .collect::<Result<Vec<_>, _>>()
            .map(|v| v.join(","))
            .map_err(|()| "a list of CPU numbers".to_string()),
        _ => Err("a list of CPU numbers such as [0, 1], or a string such as \"0-1\"".to_string()),
    };
    let parsed = text.and_then(|t| t.parse::<CpuList>());
    // the CPUs this process may use: a container's or `taskset`'s, not 0..nproc
    let allowed = agent_sdk::rt::allowed_cpus();
    match parsed {
        Ok(c) if allowed.as_ref().is_some_and(|a| c.0.iter().any(|k| !a.0.contains(k))) => {
            let a = allowed.map(|a| a.to_string()).unwrap_or_default();
            cx.err(v, format!("cpus: nerve may use CPUs {a} here (`taskset -p $$`, `nproc`); {c} is not among them"));
            None
        }
        Ok(c) => Some(c),
        Err(e) => {
            cx.err(v, format!("cpus: {e}"));
            None
        }
    }
}

/// Reads and checks a launch file for `world` (the robot the file runs on):
/// `cli_robot` when it was named explicitly (`--robot`, `NERVE_ROBOT`), else
/// the file's `robot`, else `cli_robot` (the default), with the command
/// line's launch arguments (`NAME=VALUE`, see [`parse_cli_args`]; the others
/// take their defaults): the file's includes read, its arguments replaced
/// and its conditions applied, then every agent and connection checked.
pub fn load_with_args(
    path: &Path,
    cli_robot: &str,
    explicit: bool,
    cli_args: &[(String, String)],
) -> Result<(LaunchFile, World), Box<dyn std::error::Error + Send + Sync>> {
    let default_robot = cli_robot;
    let composed = compose::compose(path, cli_args)?;
    if !composed.errors.is_empty() {
        return Err(Box::new(LaunchErrors::of(&composed.sources, composed.errors)));
    }
    let compose::Composed {
        sources,
        robot: file_robot,
        sim_time,
        time_scale,
        agents: flat_agents,
        connections: flat_connections,
        ..
    } = composed;
    let mut cx = Ctx { sources: &sources, cur: 0, errors: Vec::new() };
    let sim_time = sim_time.as_ref().and_then(|v| sim_time_of(&mut cx, v)).unwrap_or(false);
    let time_scale = time_scale.as_ref().and_then(|v| time_scale_of(&mut cx, v));
    let robot = match &file_robot {
        Some(r) if explicit => {
            if r.get_ref() != cli_robot {
                eprintln!(
                    "note: {} names robot {:?}; launching on robot {cli_robot:?} as the command line says",
                    path.display(),
                    r.get_ref()
                );
            }
            cli_robot.to_owned()
        }
        Some(r) => match RobotName::new(r.get_ref()) {
            Ok(_) => r.get_ref().clone(),
            Err(e) => {
                cx.err(r, e.to_string());
                default_robot.to_owned()
            }
        },
        None => default_robot.to_owned(),
    };
    let world = World::new(&robot)?;

    // each file's `cpu_latency`, else its includer's
    let mut file_cpu_latency: Vec<Option<CpuLatencySetting>> = Vec::with_capacity(sources.len());
    for (i, s) in sources.iter().enumerate() {
        cx.cur = i;
        let own = s.cpu_latency.as_ref().and_then(|v| cpu_latency_of(&mut cx, v));
        let inherited = s.parent.and_then(|p| file_cpu_latency.get(p).cloned().flatten());
        file_cpu_latency.push(own.or(inherited));
    }
    let mut agents = Vec::new();
    // name -> (file, line) where it is first defined
    let mut seen: HashMap<String, (usize, usize)> = HashMap::new();
    // one `--describe` per distinct (executable, parameters, arguments)
    type DescribeKey = (PathBuf, Vec<String>, Vec<String>);
    let mut descriptions: HashMap<DescribeKey, Result<Description, String>> = HashMap::new();
    if flat_agents.is_empty() {
        cx.errors.push((
            0,
            1,
            "no [[agent]] in the file (or every one's condition is false); add at least one agent".into(),
        ));
    }
    for flat in &flat_agents {
        let a = &flat.raw;
        cx.cur = flat.file;
        let dir = sources.get(flat.file).map(|s| s.dir.clone()).unwrap_or_else(|| PathBuf::from("."));
        let name = a.name.get_ref().clone();
        if let Err(e) = AgentName::new(&name) {
            cx.err(&a.name, e.to_string());
            continue;
        }
        let here = cx.place(&a.name);
        if let Some((file, line)) = seen.get(&name).copied() {
            let first = if file == here.0 {
                format!("line {line}")
            } else {
                format!("{}:{line}", sources.get(file).map(|s| s.path.display().to_string()).unwrap_or_default())
            };
            cx.err(&a.name, format!("duplicate agent name {name:?} (first defined on {first}); names must be unique (an include's `prefix` keeps its agents apart)"));
            continue;
        }
        seen.insert(name.clone(), here);
        let (kind, exe) = match (&a.kind, &a.exe) {
            (Some(k), None) => match resolve_kind(k.get_ref()) {
                Ok(exe) => (k.get_ref().clone(), exe),
                Err(e) => {
                    cx.err(k, format!("{e:#}"));
                    continue;
                }
            },
            (None, Some(x)) => {
                // a relative path is the launch file's, wherever nerve runs from
                let p = dir.join(expand_in(x.get_ref(), &world, &dir));
                match resolve_kind(&p.display().to_string()) {
                    Ok(exe) => (p.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default(), exe),
                    Err(_) => {
                        cx.err(
                            x,
                            format!(
                                "executable {} is missing or not executable; build it or fix the path",
                                p.display()
                            ),
                        );
                        continue;
                    }
                }
            }
            (Some(k), Some(_)) => {
                cx.err(k, format!("agent {name:?} has both `kind` and `exe`; give one"));
                continue;
            }
            (None, None) => {
                cx.err(&a.name, format!("agent {name:?} needs `kind = \"...\"` (e.g. ticker) or `exe = \"path\"`"));
                continue;
            }
        };
        let mut args: Vec<String> = a.args.iter().map(|s| expand_in(s.get_ref(), &world, &dir)).collect();
        if let Some(d) = &a.device {
            args.push("--device".into());
            args.push(expand_in(d.get_ref(), &world, &dir));
        }
        let mut params = Vec::new();
        for (k, v) in &a.params {
            match param_text(v.get_ref()) {
                Some(t) => params.push(format!("{k}={t}")),
                None => cx.err(v, format!("parameter {k:?} of {name:?} must be a string, number or boolean")),
            }
        }
        let dur = |cx: &mut Ctx, s: &Option<Spanned<String>>, default: Duration| match s {
            Some(s) => agent_sdk::clock::parse_duration(s.get_ref()).unwrap_or_else(|e| {
                cx.err(s, e);
                default
            }),
            None => default,
        };
        if let Some(p) = &a.period
            && let Err(e) = agent_sdk::clock::parse_duration(p.get_ref())
        {
            cx.err(p, format!("period: {e}"));
        }
        if let Some(l) = &a.log_level
            && let Err(e) = agent_sdk::daemon::parse_log_level(l.get_ref())
        {
            cx.err(l, format!("log_level: {e}"));
        }
        let restart_window = dur(&mut cx, &a.restart_window, Duration::from_secs(60));
        let backoff = dur(&mut cx, &a.backoff, Duration::from_millis(250));
        let importance = match &a.importance {
            Some(i) if !(1..=10).contains(i.get_ref()) => {
                cx.err(i, "importance must be between 1 and 10");
                5
            }
            Some(i) => *i.get_ref(),
            None => 5,
        };
        let key = (exe.clone(), params.clone(), args.clone());
        let description = descriptions.entry(key).or_insert_with(|| describe(&exe, &params, &args)).clone();
        let description = match description {
            Ok(d) => d,
            Err(e) => {
                cx.err(a.kind.as_ref().or(a.exe.as_ref()).unwrap_or(&a.name), format!("agent {name:?}: {e}"));
                continue;
            }
        };
        if a.period.is_some()
            && description.task == TaskKind::EventDriven
            && let Some(p) = &a.period
        {
            cx.err(p, format!("agent {name:?} ({kind}) is event-driven; remove `period`"));
        }
        let inputs = inputs::inputs_of(&mut cx, &name, &a.inputs, &description);
        agents.push(AgentSpec {
            name,
            kind,
            exe,
            period: a.period.as_ref().map(|p| p.get_ref().clone()),
            args,
            params,
            inputs,
            restart: a.restart.as_ref().map(|r| *r.get_ref()).unwrap_or(RestartPolicy::OnFailure),
            max_restarts: a.max_restarts.unwrap_or(5),
            restart_window,
            backoff,
            importance,
            suspended: a.suspended,
            log_level: a.log_level.as_ref().map(|l| l.get_ref().clone()),
            cpu_latency: a
                .cpu_latency
                .as_ref()
                .and_then(|v| cpu_latency_of(&mut cx, v))
                .or(file_cpu_latency.get(flat.file).cloned().flatten()),
            cpus: a.cpus.as_ref().and_then(|v| cpus_of(&mut cx, v)),
            poll: poll_of(&mut cx, a.poll.as_ref(), a.cpus.is_some()),
            description,
        });
    }

    let mut connections = Vec::new();
    let mut allow_cycle = Vec::new();
    for flat in &flat_connections {
        let c = &flat.raw;
        cx.cur = flat.file;
        let from: PortRef = match c.from.get_ref().parse() {
            Ok(p) => p,
            Err(e) => {
                cx.err(&c.from, e.to_string());
                continue;
            }
        };
        let to: PortRef = match c.to.get_ref().parse() {
            Ok(p) => p,
            Err(e) => {
                cx.err(&c.to, e.to_string());
                continue;
            }
        };
        let find = |p: &PortRef| agents.iter().find(|a| a.name == p.agent.as_str());
        // a call's wire may be written client first (docs/calls.md): service to client from here on
        let (from, to) = match find(&from) {
            Some(a) if a.description.clients.iter().any(|c| c.name == from.port) => (to, from),
            _ => (from, to),
        };
        let from_type = match find(&from) {
            None => {
                if !seen.contains_key(from.agent.as_str()) {
                    cx.err(&c.from, format!("no agent named {:?} in this file or its includes", from.agent.as_str()));
                }
                None
            }
            Some(a) => {
                match a.description.outputs.iter().chain(&a.description.services).find(|o| o.name == from.port) {
                    Some(o) => Some(declared(a, o)),
                    None => {
                        let names: Vec<&str> = a
                            .description
                            .outputs
                            .iter()
                            .chain(&a.description.services)
                            .map(|o| o.name.as_str())
                            .collect();
                        cx.err(
                            &c.from,
                            format!(
                                "agent {:?} ({}) has no output port {:?}; its outputs: {}",
                                a.name,
                                a.kind,
                                from.port,
                                list(&names)
                            ),
                        );
                        None
                    }
                }
            }
        };
        let to_type = match find(&to) {
            None => {
                if !seen.contains_key(to.agent.as_str()) {
                    cx.err(&c.to, format!("no agent named {:?} in this file or its includes", to.agent.as_str()));
                }
                None
            }
            Some(a) => match a.description.inputs.iter().chain(&a.description.clients).find(|i| i.name == to.port) {
                Some(i) => Some(declared(a, i)),
                None => {
                    let names: Vec<&str> =
                        a.description.inputs.iter().chain(&a.description.clients).map(|i| i.name.as_str()).collect();
                    cx.err(
                        &c.to,
                        format!(
                            "agent {:?} ({}) has no input port {:?}; its inputs: {}",
                            a.name,
                            a.kind,
                            to.port,
                            list(&names)
                        ),
                    );
                    None
                }
            },
        };
        // the rule of the router and the agent, on the layouts the agents
        // described: a difference is refused here, before anything starts
        if let (Some(fd), Some(td)) = (from_type, to_type)
            && let Err(e) = compat::check(fd, td)
        {
            cx.err(&c.from, e.refusal(&from.to_string(), &to.to_string()));
            continue;
        }
        if from_type.is_some() && to_type.is_some() {
            if connections.iter().any(|(f, t)| f == &from && t == &to) {
                cx.err(&c.from, format!("connection {from} -> {to} is listed twice"));
                continue;
            }
            let event_driven = |n: &str| {
                agents.iter().find(|a| a.name == n).is_some_and(|a| a.description.task == TaskKind::EventDriven)
            };
            // a loop through an edge allowed to close one is allowed, whatever the order
            let edges = connections
                .iter()
                .filter(|e| !allow_cycle.contains(*e))
                .map(|(f, t): &(PortRef, PortRef)| (f.agent.as_str(), t.agent.as_str()));
            if c.allow_cycle {
                allow_cycle.push((from.clone(), to.clone()));
            } else if let Some(cycle) =
                shm_schemas::cycles::event_cycle(edges, from.agent.as_str(), to.agent.as_str(), event_driven)
            {
                cx.err(
                    &c.from,
                    format!(
                        "connection {from} -> {to} closes a loop of event-driven agents ({}): each sample would wake the next agent at once, forever; if an agent on it breaks the loop, add `allow_cycle = true` to this [[connect]]",
                        cycle.join(" -> ")
                    ),
                );
                continue;
            }
            connections.push((from, to));
        }
    }
    if !cx.errors.is_empty() {
        let errors = std::mem::take(&mut cx.errors);
        return Err(Box::new(LaunchErrors::of(&sources, errors)));
    }
    Ok((LaunchFile { path: path.to_path_buf(), agents, connections, allow_cycle, sim_time, time_scale }, world))
}

/// Port `spec` of agent `a`, with its layout when the agent described it.
fn declared<'a>(a: &'a AgentSpec, spec: &'a PortSpec) -> Declared<'a> {
    Declared {
        type_name: &spec.type_name,
        fingerprint: Some(spec.fingerprint),
        schema: a
            .description
            .schemas
            .iter()
            .find(|s| s.type_name == spec.type_name && s.fingerprint() == spec.fingerprint),
    }
}

fn list(v: &[&str]) -> String {
    if v.is_empty() { "none".into() } else { v.join(", ") }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A launch file of this test, removed when dropped (also when the test fails).
    struct TempFile(PathBuf);

    impl TempFile {
        fn new(tag: &str, body: &str) -> Self {
            let p = std::env::temp_dir().join(format!("nerve-launch-{}-{tag}.toml", std::process::id()));
            std::fs::write(&p, body).expect("write a launch file");
            TempFile(p)
        }
    }

    impl Drop for TempFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    /// The file's `sim_time` and `time_scale` as [`load_with_args`] reads
    /// them, and the errors as (line, message).
    fn time_keys(f: &TempFile, cli: &[&str]) -> (Option<bool>, Option<f64>, Vec<(usize, String)>) {
        let cli: Vec<String> = cli.iter().map(|s| s.to_string()).collect();
        let c = compose::compose(&f.0, &parse_cli_args(&cli).expect("NAME=VALUE")).expect("read");
        assert!(c.errors.is_empty(), "{:?}", c.errors);
        let mut cx = Ctx { sources: &c.sources, cur: 0, errors: Vec::new() };
        let sim = c.sim_time.as_ref().and_then(|v| sim_time_of(&mut cx, v));
        let scale = c.time_scale.as_ref().and_then(|v| time_scale_of(&mut cx, v));
        (sim, scale, cx.errors.into_iter().map(|(_, l, m)| (l, m)).collect())
    }

    #[test]
    fn sim_time_and_time_scale_are_read_from_the_file_and_its_arguments() {
        let agent = "[[agent]]\nname = \"t1\"\nkind = \"ticker\"\n";
        let f = TempFile::new("sim", &format!("sim_time = true\ntime_scale = 4\n{agent}"));
        assert_eq!(time_keys(&f, &[]), (Some(true), Some(4.0), vec![]));
        let f = TempFile::new(
            "half",
            &format!("sim_time = \"{{arg.sim}}\"\ntime_scale = 0.5\n[args]\nsim = \"false\"\n{agent}"),
        );
        assert_eq!(time_keys(&f, &[]), (Some(false), Some(0.5), vec![]));
        assert_eq!(time_keys(&f, &["sim=true"]), (Some(true), Some(0.5), vec![]));
        let f = TempFile::new("none", agent);
        assert_eq!(time_keys(&f, &[]), (None, None, vec![]));
    }

    #[test]
    fn bad_sim_time_and_time_scale_are_refused_at_their_lines() {
        let f = TempFile::new(
            "bad",
            "robot = \"x\"\nsim_time = \"yes\"\ntime_scale = 1000\n[[agent]]\nname = \"t1\"\nexe = \"./nowhere\"\n",
        );
        let (sim, scale, errors) = time_keys(&f, &[]);
        assert_eq!((sim, scale), (None, None));
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(errors[0].0 == 2 && errors[0].1.contains("sim_time is \"yes\""), "{errors:?}");
        assert!(
            errors[1].0 == 3 && errors[1].1.contains("time_scale") && errors[1].1.contains("from 0.01"),
            "{errors:?}"
        );
        // the whole load says where, and starts nothing
        let e = load_with_args(&f.0, "x", false, &[]).expect_err("refused").to_string();
        let at = |line: usize| format!("{}:{line}: ", f.0.display());
        assert!(e.contains(&format!("{}sim_time", at(2))), "{e}");
        assert!(e.contains(&format!("{}time_scale", at(3))), "{e}");
        assert!(e.contains("nothing was started"), "{e}");
        let f =
            TempFile::new("word", "sim_time = 1\ntime_scale = \"fast\"\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\n");
        let (_, _, errors) = time_keys(&f, &[]);
        assert!(errors.iter().any(|(l, m)| *l == 1 && m.contains("write sim_time = true")), "{errors:?}");
        assert!(errors.iter().any(|(l, m)| *l == 2 && m.contains("is not a number")), "{errors:?}");
    }

    #[test]
    fn lines_are_counted_from_one() {
        assert_eq!(line_of("a\nb\nc", 0), 1);
        assert_eq!(line_of("a\nb\nc", 2), 2);
        assert_eq!(line_of("a\nb\nc", 4), 3);
    }
}
