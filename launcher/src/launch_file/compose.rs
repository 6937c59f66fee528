//! Arguments, includes and conditions: a launch file and the files it
//! includes composed into one flat list of agents and connections, before
//! any of them is checked against its executable.
//!
//! ```toml
//! [args]
//! with_camera = "true"              # a default, overridden by `nerve launch FILE with_camera=false`
//! period = "10ms"
//! device = {}                       # no default: the command line (or the include) must set it
//!
//! [[include]]
//! file = "camera.toml"              # relative to this file's folder
//! args = { rate = "{arg.period}" }  # sets camera.toml's own [args]
//! prefix = "left_"                  # every agent of camera.toml is named left_NAME
//! if = "{arg.with_camera}"
//!
//! [[agent]]
//! name = "t1"
//! kind = "ticker"
//! period = "{arg.period}"
//! if = "{arg.with_camera}"          # "true" or "false" after substitution
//! ```
//!
//! `{arg.NAME}` is replaced in every string value of a file by the value of
//! that file's argument NAME. Every problem is collected with the file and
//! line it is in; nothing is checked further while any remains, so that an
//! unreplaced `{arg.x}` does not show up again as a bad period or name.

use super::{RawAgent, RawConnect, RawFile, line_of};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use toml::Spanned;

/// How deep includes may nest: a bound on the recursion, far above any real file.
const MAX_DEPTH: usize = 16;

/// One file read for a launch: the launch file itself (index 0) or one it includes.
#[derive(Debug)]
pub(super) struct Source {
    /// the file as named (relative to where nerve runs, or joined to its includer's folder)
    pub path: PathBuf,
    /// its text, for lines
    pub src: String,
    /// its folder, canonical when it can be: `{dir}` and relative `exe`
    pub dir: PathBuf,
    /// the file that includes it (None for the launch file)
    pub parent: Option<usize>,
    /// its top-level `cpu_latency`, after substitution
    pub cpu_latency: Option<Spanned<toml::Value>>,
}

/// An agent of one of the files, arguments replaced and name prefixed.
#[derive(Debug)]
pub(super) struct FlatAgent {
    /// the index of its file in [`Composed::sources`]
    pub file: usize,
    pub raw: RawAgent,
}

/// A connection of one of the files, arguments replaced and agent names prefixed.
#[derive(Debug)]
pub(super) struct FlatConnect {
    pub file: usize,
    pub raw: RawConnect,
}

/// A launch file and its includes as one.
#[derive(Debug, Default)]
pub(super) struct Composed {
    pub sources: Vec<Source>,
    /// the launch file's `robot`, arguments replaced
    pub robot: Option<Spanned<String>>,
    /// the launch file's `sim_time` and `time_scale`, arguments replaced
    /// (an included file's are ignored, as its `robot` is)
    pub sim_time: Option<Spanned<toml::Value>>,
    pub time_scale: Option<Spanned<toml::Value>>,
    pub agents: Vec<FlatAgent>,
    pub connections: Vec<FlatConnect>,
    /// (file, line, message)
    pub errors: Vec<(usize, usize, String)>,
}

/// Where the values of a file's arguments come from.
enum Given<'a> {
    /// `nerve launch FILE key=value ...`
    CommandLine(&'a [(String, String)]),
    /// an `[[include]]`: its values (already replaced in the including
    /// file), and where it is, for the errors that belong there
    Include { values: BTreeMap<String, Spanned<String>>, file: usize, at: Spanned<String> },
}

/// A file's arguments: name -> value; None for one that was never given
/// (already reported).
type Values = BTreeMap<String, Option<String>>;

/// Reads `path` and every file it includes.
pub(super) fn compose(path: &Path, cli: &[(String, String)]) -> Result<Composed, String> {
    let mut c = Composed::default();
    let mut dropped = BTreeSet::new();
    let src = std::fs::read_to_string(path).map_err(|e| format!("cannot read launch file {}: {e}", path.display()))?;
    c.file(path.to_path_buf(), src, None, Given::CommandLine(cli), "", &mut Vec::new(), &mut dropped);
    // a connection to an agent its condition left out goes with it (unless
    // another agent of that name, e.g. the other branch, is kept)
    let kept: BTreeSet<String> = c.agents.iter().map(|a| a.raw.name.get_ref().clone()).collect();
    let gone = |p: &Spanned<String>| {
        let agent = p.get_ref().split('/').next().unwrap_or_default();
        dropped.contains(agent) && !kept.contains(agent)
    };
    c.connections.retain(|k| {
        let keep = !gone(&k.raw.from) && !gone(&k.raw.to);
        if !keep {
            tracing::debug!(from = %k.raw.from.get_ref(), to = %k.raw.to.get_ref(), "connection left out with its agent");
        }
        keep
    });
    Ok(c)
}

impl Composed {
    fn err<T>(&mut self, file: usize, at: &Spanned<T>, msg: impl Into<String>) {
        let line = self.sources.get(file).map(|s| line_of(&s.src, at.span().start)).unwrap_or(1);
        self.errors.push((file, line, msg.into()));
    }

    /// Reads one file (already read into `src`) with its arguments `given`,
    /// prefixing its agents' names with `prefix`; `stack` holds the
    /// canonical paths of the files including it, for loops.
    #[allow(clippy::too_many_arguments)]
    fn file(
        &mut self,
        path: PathBuf,
        src: String,
        parent: Option<usize>,
        given: Given,
        prefix: &str,
        stack: &mut Vec<PathBuf>,
        dropped: &mut BTreeSet<String>,
    ) {
        let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let dir = dir.canonicalize().unwrap_or_else(|_| dir.to_path_buf());
        let me = self.sources.len();
        self.sources.push(Source { path: path.clone(), src, dir: dir.clone(), parent, cpu_latency: None });
        let raw: RawFile = match toml::from_str(&self.sources[me].src) {
            Ok(r) => r,
            Err(e) => {
                let line = e.span().map(|s| line_of(&self.sources[me].src, s.start)).unwrap_or(1);
                let msg = e.message().to_owned();
                let hint = if msg.contains("unknown field") {
                    "; see the launch-file keys in README.md and docs/launch.md"
                } else {
                    ""
                };
                self.errors.push((me, line, format!("{msg}{hint}")));
                return;
            }
        };
        let values = self.values(me, &raw, given);
        let mut s = Subst { c: self, file: me, values: &values };
        if parent.is_none() {
            s.c.robot = raw.robot.as_ref().map(|r| s.string(r));
            s.c.sim_time = raw.sim_time.as_ref().map(|v| s.value(v));
            s.c.time_scale = raw.time_scale.as_ref().map(|v| s.value(v));
        }
        let cpu_latency = raw.cpu_latency.as_ref().map(|v| s.value(v));
        s.c.sources[me].cpu_latency = cpu_latency;

        for a in raw.agent {
            let mut s = Subst { c: self, file: me, values: &values };
            let name = s.string(&a.name);
            let name = Spanned::new(name.span(), format!("{prefix}{}", name.get_ref()));
            if !s.condition(&a.cond, &a.unless) {
                dropped.insert(name.get_ref().clone());
                continue;
            }
            let raw = RawAgent {
                name,
                kind: s.opt(&a.kind),
                exe: s.opt(&a.exe),
                period: s.opt(&a.period),
                device: s.opt(&a.device),
                args: a.args.iter().map(|v| s.string(v)).collect(),
                params: a.params.iter().map(|(k, v)| (k.clone(), s.value(v))).collect(),
                inputs: a.inputs.iter().map(|(k, v)| (k.clone(), s.value(v))).collect(),
                restart: a.restart.clone(),
                max_restarts: a.max_restarts,
                restart_window: s.opt(&a.restart_window),
                backoff: s.opt(&a.backoff),
                importance: a.importance,
                suspended: a.suspended,
                log_level: s.opt(&a.log_level),
                cpu_latency: a.cpu_latency.as_ref().map(|v| s.value(v)),
                cpus: a.cpus.as_ref().map(|v| s.value(v)),
                poll: a.poll.clone(),
                cond: None,
                unless: None,
            };
            self.agents.push(FlatAgent { file: me, raw });
        }

        let canonical = path.canonicalize().unwrap_or_else(|_| path.clone());
        stack.push(canonical);
        for inc in raw.include {
            let mut s = Subst { c: self, file: me, values: &values };
            if !s.condition(&inc.cond, &inc.unless) {
                continue;
            }
            let file = s.string(&inc.file);
            let inner = inc.prefix.as_ref().map(|p| s.string(p));
            if let Some(p) = &inner
                && let Err(e) = shm_schemas::AgentName::new(&format!("{prefix}{}x", p.get_ref()))
            {
                s.c.err(me, p, format!("prefix {:?} would not make agent names: {e}", p.get_ref()));
                continue;
            }
            let args: BTreeMap<String, Spanned<String>> =
                inc.args.iter().filter_map(|(k, v)| Some((k.clone(), s.include_arg(k, v)?))).collect();
            let target = dir.join(file.get_ref());
            let target_canon = target.canonicalize().unwrap_or_else(|_| target.clone());
            if let Some(i) = stack.iter().position(|p| *p == target_canon) {
                let chain: Vec<String> =
                    stack[i..].iter().chain([&target_canon]).map(|p| p.display().to_string()).collect();
                self.err(me, &inc.file, format!("include loop: {}; remove one of these includes", chain.join(" -> ")));
                continue;
            }
            if stack.len() >= MAX_DEPTH {
                self.err(me, &inc.file, format!("includes nest deeper than {MAX_DEPTH} files; flatten some of them"));
                continue;
            }
            let text = match std::fs::read_to_string(&target) {
                Ok(t) => t,
                Err(e) => {
                    self.err(
                        me,
                        &inc.file,
                        format!(
                            "cannot read included file {}: {e}; fix the path (it is relative to this file's folder)",
                            target.display()
                        ),
                    );
                    continue;
                }
            };
            let prefix = format!("{prefix}{}", inner.as_ref().map(|p| p.get_ref().as_str()).unwrap_or(""));
            let given = Given::Include { values: args, file: me, at: file };
            self.file(target, text, Some(me), given, &prefix, stack, dropped);
        }
        stack.pop();

        for k in raw.connect {
            let mut s = Subst { c: self, file: me, values: &values };
            if !s.condition(&k.cond, &k.unless) {
                continue;
            }
            let (from, to) = (s.string(&k.from), s.string(&k.to));
            let port = |p: Spanned<String>| Spanned::new(p.span(), format!("{prefix}{}", p.get_ref()));
            let raw =
                RawConnect { from: port(from), to: port(to), allow_cycle: k.allow_cycle, cond: None, unless: None };
            self.connections.push(FlatConnect { file: me, raw });
        }
    }

    /// The values of file `me`'s arguments: given, else the default; every
    /// argument given but not declared, or declared without a default and
    /// not given, is an error.
    fn values(&mut self, me: usize, raw: &RawFile, given: Given) -> Values {
        let mut declared: BTreeMap<String, (Option<String>, Spanned<()>)> = BTreeMap::new();
        let table_at = raw.args.as_ref().map(|t| t.span()).unwrap_or(0..0);
        if let Some(table) = &raw.args {
            for (name, v) in table.get_ref() {
                let at = Spanned::new(v.span(), ());
                if !valid_name(name) {
                    self.err(me, v, format!("argument name {name:?}: use letters, digits and _ only"));
                    continue;
                }
                let default = match v.get_ref() {
                    toml::Value::Table(t) => {
                        if let Some(k) = t.keys().find(|k| !["default", "doc"].contains(&k.as_str())) {
                            self.err(
                                me,
                                v,
                                format!("argument {name}: unknown key {k:?}; an argument takes `default` and `doc`"),
                            );
                        }
                        match t.get("default") {
                            None => None,
                            Some(d) => match scalar(d) {
                                Some(d) => Some(d),
                                None => {
                                    self.err(
                                        me,
                                        v,
                                        format!("argument {name}: its default must be a string, number or boolean"),
                                    );
                                    continue;
                                }
                            },
                        }
                    }
                    other => {
                        match scalar(other) {
                            Some(d) => Some(d),
                            None => {
                                self.err(me, v, format!("argument {name}: give a default (a string, number or boolean) or `{{}}` for none"));
                                continue;
                            }
                        }
                    }
                };
                declared.insert(name.clone(), (default, at));
            }
        }
        let names = || {
            let v: Vec<&str> = declared.keys().map(String::as_str).collect();
            if v.is_empty() { "none".to_owned() } else { v.join(", ") }
        };
        let path = self.sources[me].path.display().to_string();
        let mut values = Values::new();
        match given {
            Given::CommandLine(cli) => {
                let at = Spanned::new(table_at, ());
                for (k, v) in cli {
                    if declared.contains_key(k) {
                        values.insert(k.clone(), Some(v.clone()));
                    } else {
                        let msg = format!(
                            "the command line sets {k}={v} but this file declares no argument {k:?} (its [args]: {}); fix the name or declare it under [args]",
                            names()
                        );
                        self.err(me, &at, msg);
                    }
                }
                for (name, (default, at)) in &declared {
                    if values.contains_key(name) {
                        continue;
                    }
                    if default.is_none() {
                        self.err(me, at, format!("argument {name} has no default and is not given: add {name}=VALUE to `nerve launch {path}`"));
                    }
                    values.insert(name.clone(), default.clone());
                }
            }
            Given::Include { values: set, file, at } => {
                for (k, v) in set {
                    if declared.contains_key(&k) {
                        values.insert(k, Some(v.into_inner()));
                    } else {
                        let msg = format!(
                            "include of {path}: it declares no argument {k:?} (its [args]: {}); fix the name or declare it there",
                            names()
                        );
                        self.err(file, &v, msg);
                    }
                }
                for (name, (default, decl)) in &declared {
                    if values.contains_key(name) {
                        continue;
                    }
                    if default.is_none() {
                        let line = line_of(&self.sources[me].src, decl.span().start);
                        let msg = format!(
                            "include of {path}: argument {name} (declared on its line {line}) has no default and is not given; add it to this include's `args`"
                        );
                        self.err(file, &at, msg);
                    }
                    values.insert(name.clone(), default.clone());
                }
            }
        }
        values
    }
}

/// Replaces `{arg.NAME}` in the strings of one file.
struct Subst<'c, 'v> {
    c: &'c mut Composed,
    file: usize,
    values: &'v Values,
}

impl Subst<'_, '_> {
    /// An include's argument value: a string (replaced), number or boolean.
    fn include_arg(&mut self, name: &str, v: &Spanned<toml::Value>) -> Option<Spanned<String>> {
        match v.get_ref() {
            toml::Value::String(t) => Some(self.string(&Spanned::new(v.span(), t.clone()))),
            other => match scalar(other) {
                Some(t) => Some(Spanned::new(v.span(), t)),
                None => {
                    self.c.err(self.file, v, format!("argument {name}: give a string, number or boolean"));
                    None
                }
            },
        }
    }

    fn opt(&mut self, v: &Option<Spanned<String>>) -> Option<Spanned<String>> {
        v.as_ref().map(|v| self.string(v))
    }

    /// `s` with every `{arg.NAME}` replaced, at the same place in the file.
    fn string(&mut self, s: &Spanned<String>) -> Spanned<String> {
        match substitute(s.get_ref(), self.values) {
            Ok(v) => Spanned::new(s.span(), v),
            Err(e) => {
                self.c.err(self.file, s, e);
                Spanned::new(s.span(), s.get_ref().clone())
            }
        }
    }

    /// A value with its strings (also in lists and tables) replaced.
    fn value(&mut self, v: &Spanned<toml::Value>) -> Spanned<toml::Value> {
        fn walk(v: &toml::Value, values: &Values, errors: &mut Vec<String>) -> toml::Value {
            match v {
                toml::Value::String(s) => toml::Value::String(substitute(s, values).unwrap_or_else(|e| {
                    errors.push(e);
                    s.clone()
                })),
                toml::Value::Array(a) => toml::Value::Array(a.iter().map(|x| walk(x, values, errors)).collect()),
                toml::Value::Table(t) => {
                    toml::Value::Table(t.iter().map(|(k, x)| (k.clone(), walk(x, values, errors))).collect())
                }
                other => other.clone(),
            }
        }
        let mut errors = Vec::new();
        let out = walk(v.get_ref(), self.values, &mut errors);
        for e in errors {
            self.c.err(self.file, v, e);
        }
        Spanned::new(v.span(), out)
    }

    /// Whether an `if` / `unless` pair keeps its entry: each must be "true"
    /// or "false" after substitution. A bad one is an error (and keeps the
    /// entry, so that its other problems are found too).
    fn condition(&mut self, cond: &Option<Spanned<String>>, unless: &Option<Spanned<String>>) -> bool {
        let mut keep = true;
        for (c, key, want) in [(cond, "if", true), (unless, "unless", false)] {
            let Some(c) = c else { continue };
            let before = self.c.errors.len();
            let v = self.string(c);
            if self.c.errors.len() > before {
                continue;
            }
            match v.get_ref().trim() {
                // an argument never given: already reported where it is declared
                "" if c.get_ref().contains("{arg.") => {}
                "true" => keep &= want,
                "false" => keep &= !want,
                other => self.c.err(
                    self.file,
                    c,
                    format!("`{key}` is {other:?} (from {:?}); it must be \"true\" or \"false\"", c.get_ref()),
                ),
            }
        }
        keep
    }
}

/// `s` with every `{arg.NAME}` replaced by NAME's value; other braces
/// (`{state}`, `{robot}`, `{dir}`) are left for later.
pub(super) fn substitute(s: &str, values: &Values) -> Result<String, String> {
    const OPEN: &str = "{arg.";
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(i) = rest.find(OPEN) {
        out.push_str(&rest[..i]);
        let after = &rest[i + OPEN.len()..];
        let Some(end) = after.find('}') else {
            return Err(format!("{:?}: `{{arg.` is not closed by `}}`; write {{arg.NAME}}", s));
        };
        let name = &after[..end];
        match values.get(name) {
            Some(Some(v)) => out.push_str(v),
            // never given: reported where it is declared
            Some(None) => {}
            None => {
                let known: Vec<&str> = values.keys().map(String::as_str).collect();
                let known = if known.is_empty() { "none".to_owned() } else { known.join(", ") };
                return Err(format!(
                    "unknown argument {name:?} in {s:?} (this file's arguments: {known}); declare it under [args]"
                ));
            }
        }
        rest = &after[end + 1..];
    }
    out.push_str(rest);
    Ok(out)
}

fn valid_name(name: &str) -> bool {
    !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// A string, number or boolean as the text it stands for (a parameter's
/// own rule, `param_text`).
fn scalar(v: &toml::Value) -> Option<String> {
    super::param_text(v)
}

/// Parses the command line's `NAME=VALUE` launch arguments.
pub fn parse_cli_args(args: &[String]) -> Result<Vec<(String, String)>, String> {
    let mut out: Vec<(String, String)> = Vec::new();
    for a in args {
        let Some((k, v)) = a.split_once('=') else {
            return Err(format!("launch argument {a:?} is not NAME=VALUE (e.g. with_camera=false)"));
        };
        if out.iter().any(|(o, _)| o == k) {
            return Err(format!("launch argument {k} is given twice; give it once"));
        }
        out.push((k.to_owned(), v.to_owned()));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A folder of this test, removed when dropped (also when the test fails).
    struct Folder(PathBuf);

    impl Folder {
        fn new(tag: &str) -> Self {
            let p = std::env::temp_dir().join(format!("nerve-compose-{}-{tag}", std::process::id()));
            let _ = std::fs::remove_dir_all(&p);
            std::fs::create_dir_all(&p).expect("a temporary folder");
            Folder(p)
        }

        fn write(&self, name: &str, body: &str) -> PathBuf {
            let p = self.0.join(name);
            std::fs::write(&p, body).expect("write a launch file");
            p
        }
    }

    impl Drop for Folder {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    fn cli(pairs: &[&str]) -> Vec<(String, String)> {
        parse_cli_args(&pairs.iter().map(|s| s.to_string()).collect::<Vec<_>>()).expect("NAME=VALUE")
    }

    /// (file name, line, message) of every error.
    fn errors(c: &Composed) -> Vec<(String, usize, String)> {
        c.errors
            .iter()
            .map(|(f, l, m)| {
                let name = c.sources[*f].path.file_name().map(|n| n.to_string_lossy().into_owned());
                (name.unwrap_or_default(), *l, m.clone())
            })
            .collect()
    }

    fn has(c: &Composed, file: &str, line: usize, text: &str) -> bool {
        errors(c).iter().any(|(f, l, m)| f == file && *l == line && m.contains(text))
    }

    fn names(c: &Composed) -> Vec<String> {
        c.agents.iter().map(|a| a.raw.name.get_ref().clone()).collect()
    }

    const PERIODIC: &str = "[args]\nperiod = \"10ms\"\nstep = 1\n\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nperiod = \"{arg.period}\"\nparams = { step = \"{arg.step}\" }\nargs = [\"--every\", \"{arg.period}\"]\n";

    #[test]
    fn arguments_are_replaced_in_strings_and_left_braces_stay() {
        let values: Values = [("a".to_owned(), Some("x".to_owned())), ("b".to_owned(), Some("2".to_owned()))].into();
        assert_eq!(substitute("{arg.a}-{arg.b}/{state}", &values).as_deref(), Ok("x-2/{state}"));
        assert_eq!(substitute("no args", &values).as_deref(), Ok("no args"));
        let e = substitute("{arg.c}", &values).expect_err("unknown");
        assert!(e.contains("unknown argument \"c\"") && e.contains("a, b"), "{e}");
        let e = substitute("{arg.a", &values).expect_err("unclosed");
        assert!(e.contains("not closed"), "{e}");
    }

    #[test]
    fn defaults_apply_and_the_command_line_overrides_them() {
        let d = Folder::new("defaults");
        let p = d.write("robot.toml", PERIODIC);
        let c = compose(&p, &[]).expect("read");
        assert!(c.errors.is_empty(), "{:?}", errors(&c));
        let a = &c.agents[0].raw;
        assert_eq!(a.period.as_ref().map(|p| p.get_ref().as_str()), Some("10ms"));
        assert_eq!(a.params["step"].get_ref().as_str(), Some("1"));
        assert_eq!(a.args[1].get_ref(), "10ms");
        let c = compose(&p, &cli(&["period=25ms", "step=3"])).expect("read");
        assert!(c.errors.is_empty(), "{:?}", errors(&c));
        let a = &c.agents[0].raw;
        assert_eq!(a.period.as_ref().map(|p| p.get_ref().as_str()), Some("25ms"));
        assert_eq!(a.params["step"].get_ref().as_str(), Some("3"));
    }

    #[test]
    fn bad_arguments_are_refused_with_their_lines() {
        let d = Folder::new("badargs");
        let p = d.write("robot.toml", PERIODIC);
        let c = compose(&p, &cli(&["perod=5ms"])).expect("read");
        assert!(has(&c, "robot.toml", 1, "declares no argument \"perod\""), "{:?}", errors(&c));
        let p = d.write(
            "need.toml",
            "[args]\ndevice = {}\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nargs = [\"{arg.device}\"]\n",
        );
        let c = compose(&p, &[]).expect("read");
        assert!(has(&c, "need.toml", 2, "argument device has no default"), "{:?}", errors(&c));
        assert_eq!(c.errors.len(), 1, "reported once, not again where it is used: {:?}", errors(&c));
        let p = d.write("unknown.toml", "[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nperiod = \"{arg.period}\"\n");
        let c = compose(&p, &[]).expect("read");
        assert!(has(&c, "unknown.toml", 4, "unknown argument \"period\""), "{:?}", errors(&c));
        assert!(parse_cli_args(&["novalue".to_owned()]).is_err());
        assert!(parse_cli_args(&["a=1".to_owned(), "a=2".to_owned()]).is_err());
    }

    #[test]
    fn conditions_drop_agents_with_their_connections_and_refuse_other_values() {
        let d = Folder::new("cond");
        let body = "[args]\ncam = \"true\"\n[[agent]]\nname = \"t1\"\nkind = \"ticker\"\n[[agent]]\nname = \"cam\"\nkind = \"relay\"\nif = \"{arg.cam}\"\n[[agent]]\nname = \"fake\"\nkind = \"relay\"\nunless = \"{arg.cam}\"\n[[connect]]\nfrom = \"t1/tick\"\nto = \"cam/in\"\n";
        let p = d.write("robot.toml", body);
        let c = compose(&p, &[]).expect("read");
        assert_eq!(names(&c), ["t1", "cam"]);
        assert_eq!(c.connections.len(), 1);
        let c = compose(&p, &cli(&["cam=false"])).expect("read");
        assert_eq!(names(&c), ["t1", "fake"]);
        assert!(c.connections.is_empty(), "the connection to the dropped agent goes with it");
        let c = compose(&p, &cli(&["cam=yes"])).expect("read");
        assert!(has(&c, "robot.toml", 9, "must be \"true\" or \"false\""), "{:?}", errors(&c));
        let p = d.write("unknown.toml", "[[agent]]\nname = \"t1\"\nkind = \"ticker\"\nif = \"{arg.cam}\"\n");
        let c = compose(&p, &[]).expect("read");
        assert!(has(&c, "unknown.toml", 4, "unknown argument \"cam\""), "{:?}", errors(&c));
    }

    #[test]
    fn includes_take_arguments_and_prefix_names_and_report_in_their_own_file() {
        let d = Folder::new("include");
        d.write("part.toml", "[args]\nrate = {}\n[[agent]]\nname = \"t\"\nkind = \"ticker\"\nperiod = \"{arg.rate}\"\n[[agent]]\nname = \"r\"\nkind = \"relay\"\n[[connect]]\nfrom = \"t/tick\"\nto = \"r/in\"\n");
        let p = d.write("top.toml", "[args]\np = \"20ms\"\n[[include]]\nfile = \"part.toml\"\nargs = { rate = \"{arg.p}\" }\nprefix = \"left_\"\n[[agent]]\nname = \"r\"\nkind = \"relay\"\n[[connect]]\nfrom = \"left_t/tick\"\nto = \"r/in\"\n");
        let c = compose(&p, &[]).expect("read");
        assert!(c.errors.is_empty(), "{:?}", errors(&c));
        assert_eq!(names(&c), ["r", "left_t", "left_r"]);
        assert_eq!(c.agents[1].raw.period.as_ref().map(|p| p.get_ref().as_str()), Some("20ms"));
        let links: Vec<(String, String)> =
            c.connections.iter().map(|k| (k.raw.from.get_ref().clone(), k.raw.to.get_ref().clone())).collect();
        assert_eq!(links, [("left_t/tick".into(), "left_r/in".into()), ("left_t/tick".into(), "r/in".into())]);

        // an argument the include does not set, one it does not declare, an error inside
        d.write("bad.toml", "[args]\nrate = {}\n[[agent]]\nname = \"t\"\nkind = \"ticker\"\nperiod = \"{arg.rte}\"\n");
        let p = d.write("top2.toml", "[[include]]\nfile = \"bad.toml\"\nargs = { speed = \"1\" }\n");
        let c = compose(&p, &[]).expect("read");
        assert!(has(&c, "top2.toml", 2, "argument rate (declared on its line 2) has no default"), "{:?}", errors(&c));
        assert!(has(&c, "top2.toml", 3, "declares no argument \"speed\""), "{:?}", errors(&c));
        assert!(has(&c, "bad.toml", 6, "unknown argument \"rte\""), "{:?}", errors(&c));

        // a number as an include's argument, and a prefix that makes no names
        let p = d.write("num.toml", "[[include]]\nfile = \"part.toml\"\nargs = { rate = 5 }\nprefix = \"L\"\n");
        let c = compose(&p, &[]).expect("read");
        assert!(has(&c, "num.toml", 4, "prefix \"L\" would not make agent names"), "{:?}", errors(&c));
        assert_eq!(c.errors.len(), 1, "{:?}", errors(&c));

        // a loop, and a missing file
        d.write("a.toml", "[[include]]\nfile = \"b.toml\"\n");
        d.write("b.toml", "[[agent]]\nname = \"x\"\nkind = \"relay\"\n[[include]]\nfile = \"a.toml\"\n");
        let c = compose(&d.0.join("a.toml"), &[]).expect("read");
        assert!(has(&c, "b.toml", 5, "include loop"), "{:?}", errors(&c));
        let p = d.write("missing.toml", "[[include]]\nfile = \"nowhere.toml\"\n");
        let c = compose(&p, &[]).expect("read");
        assert!(has(&c, "missing.toml", 2, "cannot read included file"), "{:?}", errors(&c));
    }
}
