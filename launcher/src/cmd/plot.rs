//! `nerve plot`: numeric fields of output ports against time, as a PNG or
//! SVG figure, to look at a signal without writing a script.
//!
//! The samples come from a recording `nerve record` wrote (`--from`), or
//! from the live robot for `--duration` seconds (a subscriber like `nerve
//! echo`: zero copy, the publisher is never disturbed). Each sample is
//! decoded through its type's schema (the recording's channel schema, or
//! the one the agent registered with the router): the fields named with
//! `--field` must be numbers (any integer or float; a bool plots as 0 or
//! 1), so a string, an array or a struct is refused with the list of the
//! type's numeric fields. Each port and field is one line of the figure.
//!
//! A sequence port's samples (`Seq<T, H>`) are as long as their elements:
//! `--field header.x` plots a field of the header, `items[3].x` one of the
//! fourth element, and `items[-1].x` one of the last element, whichever
//! index that is in each sample. A sample without that element (fewer than
//! four, or none) has no point on that line; it is not an error.
//!
//! Time axis: seconds since the first plotted sample, by the samples' own
//! stamps (the sender's CLOCK_MONOTONIC; in a recording, the messages'
//! publish time), so a recording and a live run of the same port plot
//! alike and the recorder's own delays do not show. Lines of more than
//! [`MAX_POINTS`] samples are thinned to the lowest and highest value of
//! each run of samples, so that spikes stay visible.

use crate::client::cli_node;
use crate::cmd::echo::port_info;
use agent_sdk::World;
use agent_sdk::ports::port_event;
use agent_sdk::raw_port::RawPort;
use agent_sdk::world::Ipc;
use anyhow::{Context as _, Result, anyhow, bail};
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use nerve_plot_font::figure::{self, DrawResult, Figure, Format};
use nerve_recording::{MESSAGE_ENCODING, SCHEMA_ENCODING};
use plotters::coord::Shift;
use plotters::prelude::*;
use shm_schemas::schema::{Kind, Value};
use shm_schemas::{PortRef, Schema};
use std::collections::{BTreeMap, BTreeSet};
use std::io::{IsTerminal as _, Write as _};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// `nerve plot`
#[derive(Debug, clap::Args)]
pub struct PlotArgs {
    /// Output ports, AGENT/PORT (every --field is plotted for each).
    #[arg(required = true, value_name = "PORT")]
    pub ports: Vec<String>,
    /// A numeric field to plot (`seq`, `pose.x`, `ranges_m.3`); repeat it for several lines.
    #[arg(long = "field", required = true, value_name = "F")]
    pub fields: Vec<String>,
    /// Read the samples from this recording (written by `nerve record`) instead of the live robot.
    #[arg(long, value_name = "FILE.mcap")]
    pub from: Option<PathBuf>,
    /// Live: subscribe for this many seconds [default: 10].
    #[arg(long, value_name = "S", conflicts_with = "from", value_parser = agent_sdk::clock::parse_seconds)]
    pub duration: Option<f64>,
    /// The figure to write, OUT.png or OUT.svg (default: `PORT-FIELD.png` here).
    #[arg(short = 'o', long, value_name = "OUT")]
    pub output: Option<PathBuf>,
    /// The figure's title (default: `ROBOT AGENT/PORT`).
    #[arg(long, value_name = "T")]
    pub title: Option<String>,
    /// No progress line.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// The live subscription's length when `--duration` is not given, seconds.
const DEFAULT_DURATION_S: f64 = 10.0;
/// The figure's size, pixels.
pub const SIZE: (u32, u32) = (1000, 600);
/// At most this many points are drawn per line.
pub const MAX_POINTS: usize = 4000;
/// The lines' colours, in turn.
const COLOURS: [RGBColor; 8] = [
    RGBColor(30, 90, 200),
    RGBColor(210, 60, 30),
    RGBColor(20, 150, 60),
    RGBColor(150, 70, 170),
    RGBColor(230, 150, 20),
    RGBColor(20, 160, 170),
    RGBColor(120, 120, 120),
    RGBColor(190, 40, 120),
];

/// The figure's file format, by the output's extension.
fn format_of(path: &Path) -> Result<Format> {
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("png") => Ok(Format::Png),
        Some("svg") => Ok(Format::Svg),
        _ => bail!("-o {}: the figure's name must end in .png or .svg", path.display()),
    }
}

/// `PORT-FIELD.png`, with `/` and `.` made `-` (several ports and fields: all of them, in turn).
fn default_output(ports: &[PortRef], fields: &[String]) -> PathBuf {
    let parts: Vec<String> = ports.iter().map(ToString::to_string).chain(fields.iter().cloned()).collect();
    PathBuf::from(format!("{}.png", parts.join("-").replace(['/', '.'], "-")))
}

/// A value as a number to plot: integers and floats as they are, a bool as
/// 0 or 1; `None` for a string, an array or a struct.
pub fn numeric(v: &Value) -> Option<f64> {
    match v {
        Value::Bool(b) => Some(f64::from(u8::from(*b))),
        Value::Unsigned(u) => Some(*u as f64),
        Value::Signed(i) => Some(*i as f64),
        Value::F32(f) => Some(f64::from(*f)),
        Value::Float(f) => Some(*f),
        Value::String(_) | Value::Array(_) | Value::Struct(_) => None,
    }
}

/// Every numeric field path of `schema`: `pose.x`, and `ranges_m.<i>` or
/// `fingers.<i>.force_n` for the elements of an array (with the indices it has).
pub fn numeric_paths(schema: &Schema) -> Vec<String> {
    let mut out = Vec::new();
    schema.visit_fields(|path, s, lens| {
        if matches!(s.kind, Kind::Primitive { .. }) {
            let note: Vec<String> = lens.iter().map(|len| format!("<i> < {len}")).collect();
            out.push(if note.is_empty() { path.to_string() } else { format!("{path} ({})", note.join(", ")) });
        }
    });
    out
}

/// Where field `path` of `schema` lies in a sample, if it is a number;
/// else an error that lists the numeric fields.
pub fn numeric_field(schema: &Schema, port: &PortRef, path: &str) -> Result<Field> {
    let list = || {
        let paths = numeric_paths(schema);
        if paths.is_empty() { "none".to_string() } else { paths.join(", ") }
    };
    let not_a_number = |s: &Schema| {
        anyhow!(
            "field {path:?} of {port} ({}) is a {}, not a number; the numeric fields of {}: {}",
            schema.type_name,
            s.type_name,
            schema.type_name,
            list()
        )
    };
    // the last element of a sequence: where it lies depends on the sample
    if let (Kind::Sequence { element, .. }, Some(rest)) = (&schema.kind, last_element_path(path)) {
        let found = if rest.is_empty() { Some((0, element.as_ref())) } else { element.field(rest) };
        return match found {
            Some((offset, s)) if matches!(s.kind, Kind::Primitive { .. }) => {
                Ok(Field::LastItem { offset, schema: s.clone(), items_at: schema.size, element: element.size })
            }
            Some((_, s)) => Err(not_a_number(s)),
            None => bail!(
                "{port} ({}) has no field {path:?}; the numeric fields of {}: {}",
                schema.type_name,
                schema.type_name,
                list()
            ),
        };
    }
    match schema.field(path) {
        Some((offset, s)) if matches!(s.kind, Kind::Primitive { .. }) => {
            Ok(Field::At { offset, schema: s.clone(), sequence: schema.sequence_shape().is_some() })
        }
        Some((_, s)) => Err(not_a_number(s)),
        None => bail!(
            "{port} ({}) has no field {path:?}; the numeric fields of {}: {}",
            schema.type_name,
            schema.type_name,
            list()
        ),
    }
}

/// `items[-1].x` (or `items.-1.x`): the rest of the path inside the last
/// element (`x`; empty for a sequence of numbers), else `None`.
fn last_element_path(path: &str) -> Option<&str> {
    let rest = path.strip_prefix(shm_schemas::seq::ITEMS_FIELD)?;
    let rest = rest.strip_prefix("[-1]").or_else(|| rest.strip_prefix(".-1"))?;
    if rest.is_empty() {
        return Some(rest);
    }
    rest.strip_prefix('.')
}

/// One plotted field of a type.
#[derive(Debug, Clone)]
pub enum Field {
    /// At `offset` in every sample; in a sequence's sample (`sequence`),
    /// past the end of a short one, which then has no value.
    At { offset: usize, schema: Schema, sequence: bool },
    /// At `offset` inside a sequence's last element (elements of `element`
    /// bytes from `items_at`); a sample without elements has no value.
    LastItem { offset: usize, schema: Schema, items_at: usize, element: usize },
}

impl Field {
    /// The value in the sample `bytes`: `None` when a sequence's sample has
    /// no such element.
    fn value(&self, bytes: &[u8]) -> Result<Option<f64>, String> {
        let (at, schema) = match self {
            Field::At { offset, schema, sequence } => {
                if *sequence && offset.checked_add(schema.size).is_none_or(|end| end > bytes.len()) {
                    return Ok(None);
                }
                (*offset, schema)
            }
            Field::LastItem { offset, schema, items_at, element } => {
                let n = bytes.len().saturating_sub(*items_at).checked_div(*element).unwrap_or(0);
                let Some(last) = n.checked_sub(1) else { return Ok(None) };
                let at = last
                    .checked_mul(*element)
                    .and_then(|b| b.checked_add(*items_at))
                    .and_then(|b| b.checked_add(*offset));
                (at.ok_or_else(|| format!("a {}-byte sample is too long to index", bytes.len()))?, schema)
            }
        };
        let b = bytes.get(at..).ok_or_else(|| format!("a {}-byte sample is shorter than its schema", bytes.len()))?;
        let v = schema.decode(b).map_err(|e| e.to_string())?;
        numeric(&v).map(Some).ok_or_else(|| format!("{} is not a number", schema.type_name))
    }
}

/// The plotted fields of a type, in the order of `--field`.
#[derive(Debug, Clone)]
pub struct Fields(Vec<Field>);

impl Fields {
    /// The fields `paths` of `schema` (each must be a number).
    pub fn of(schema: &Schema, port: &PortRef, paths: &[String]) -> Result<Self> {
        paths.iter().map(|p| numeric_field(schema, port, p)).collect::<Result<_>>().map(Fields)
    }

    /// The values of the fields in the sample `bytes` (`None`: a
    /// sequence's sample without that element).
    pub fn values(&self, bytes: &[u8]) -> Result<Vec<Option<f64>>, String> {
        self.0.iter().map(|f| f.value(bytes)).collect()
    }
}

/// The samples of one port: each one's stamp (CLOCK_MONOTONIC ns) and its fields' values.
#[derive(Debug)]
struct Samples {
    port: PortRef,
    stamps: Vec<u64>,
    /// per field, in the order of `--field` (`None`: that sample has no such element)
    values: Vec<Vec<Option<f64>>>,
}

impl Samples {
    fn new(port: &PortRef, fields: usize) -> Self {
        Samples { port: port.clone(), stamps: Vec::new(), values: vec![Vec::new(); fields] }
    }

    fn push(&mut self, stamp_ns: u64, values: Vec<Option<f64>>) {
        self.stamps.push(stamp_ns);
        for (line, v) in self.values.iter_mut().zip(values) {
            line.push(v);
        }
    }
}

/// One line of the figure.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// `PORT field`
    pub label: String,
    /// (seconds since the first plotted sample, value)
    pub points: Vec<(f64, f64)>,
}

/// The lines of `samples`, with the time axis starting at the first sample of any port.
fn lines(samples: &[Samples], fields: &[String]) -> Vec<Line> {
    let t0 = samples.iter().filter_map(|s| s.stamps.iter().min()).min().copied().unwrap_or(0);
    let mut out = Vec::new();
    for s in samples.iter().filter(|s| !s.stamps.is_empty()) {
        for (field, values) in fields.iter().zip(&s.values) {
            let mut points: Vec<(f64, f64)> = s
                .stamps
                .iter()
                .zip(values)
                .filter_map(|(t, v)| v.map(|v| (t.saturating_sub(t0) as f64 / 1e9, v)))
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            out.push(Line { label: format!("{} {field}", s.port), points: thin(&points, MAX_POINTS) });
        }
    }
    out
}

/// At most about `max` of `points`: each run of consecutive points becomes
/// its lowest and its highest (in their order), so that spikes stay visible.
pub fn thin(points: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if points.len() <= max || max < 2 {
        return points.to_vec();
    }
    let run = points.len().div_ceil(max / 2);
    let mut out = Vec::with_capacity(max + 2);
    for chunk in points.chunks(run) {
        let lo = chunk.iter().enumerate().min_by(|a, b| a.1.1.total_cmp(&b.1.1));
        let hi = chunk.iter().enumerate().max_by(|a, b| a.1.1.total_cmp(&b.1.1));
        if let (Some((i, lo)), Some((j, hi))) = (lo, hi) {
            match i.cmp(&j) {
                std::cmp::Ordering::Less => out.extend([*lo, *hi]),
                std::cmp::Ordering::Greater => out.extend([*hi, *lo]),
                std::cmp::Ordering::Equal => out.push(*lo),
            }
        }
    }
    out
}

pub fn plot(world: &World, a: PlotArgs) -> Result<ExitCode> {
    let ports: Vec<PortRef> =
        a.ports.iter().map(|p| p.parse::<PortRef>().with_context(|| format!("port {p:?}"))).collect::<Result<_>>()?;
    let output = a.output.clone().unwrap_or_else(|| default_output(&ports, &a.fields));
    let format = format_of(&output)?;
    let (samples, robot) = match &a.from {
        Some(file) => from_recording(file, &ports, &a.fields)?,
        None => {
            let duration = a.duration.unwrap_or(DEFAULT_DURATION_S);
            if duration <= 0.0 {
                bail!("--duration must be a positive number of seconds");
            }
            // a subscriber maps a connection segment: on a full /dev/shm, SIGBUS (review R14)
            crate::cmd::shm_space::ensure_shm_space("plot")?;
            (live(world, &ports, &a.fields, duration, a.quiet)?, world.robot().to_string())
        }
    };
    let total: usize = samples.iter().map(|s| s.stamps.len()).sum();
    let names = ports.iter().map(ToString::to_string).collect::<Vec<_>>().join(", ");
    if total == 0 {
        match &a.from {
            Some(file) => bail!("{} has no samples of {names}: nothing to plot", file.display()),
            None => bail!("no sample arrived on {names}: nothing to plot (is the agent running and publishing?)"),
        }
    }
    for s in samples.iter().filter(|s| s.stamps.is_empty()) {
        eprintln!("no sample of {}: it has no line in the figure", s.port);
    }
    let title = a.title.clone().unwrap_or_else(|| format!("{robot} {names}"));
    let lines = lines(&samples, &a.fields);
    draw_to(&output, format, &lines, &title, &a.fields.join(", "))?;
    println!("plotted {total} samples of {names} (fields {}) to {}", a.fields.join(", "), output.display());
    Ok(ExitCode::SUCCESS)
}

/// The samples of `ports` in the recording `file`, and the robot it was made on.
fn from_recording(file: &Path, ports: &[PortRef], fields: &[String]) -> Result<(Vec<Samples>, String)> {
    let bytes = std::fs::read(file).with_context(|| format!("cannot read {}", file.display()))?;
    let name = file.display().to_string();
    let not_ours = |what: String| anyhow!("{name}: {what}; is it a file `nerve record` wrote?");
    let mut samples: Vec<Samples> = ports.iter().map(|p| Samples::new(p, fields.len())).collect();
    // per channel: the port it records (index in `ports`) and its fields
    let mut channels: BTreeMap<u16, Option<(usize, Fields)>> = BTreeMap::new();
    let mut topics: BTreeSet<String> = BTreeSet::new();
    let mut robot = None;
    let stream = mcap::MessageStream::new(&bytes).map_err(|e| not_ours(format!("not a readable MCAP file ({e})")))?;
    for m in stream {
        let m = m.map_err(|e| not_ours(format!("not a readable MCAP file, or a damaged one ({e})")))?;
        let ch = &m.channel;
        let entry = match channels.entry(ch.id) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(slot) => {
                topics.insert(ch.topic.clone());
                let wanted = match ports.iter().position(|p| p.to_string() == ch.topic) {
                    Some(i) => {
                        let schema = channel_schema(ch).map_err(not_ours)?;
                        robot = robot.or_else(|| ch.metadata.get("robot").cloned());
                        Some((i, Fields::of(&schema, &ports[i], fields)?))
                    }
                    None => None,
                };
                slot.insert(wanted)
            }
        };
        let Some((i, f)) = entry else { continue };
        let values = f.values(&m.data).map_err(|e| anyhow!("{name}: a sample of {}: {e}", ch.topic))?;
        samples[*i].push(m.publish_time, values);
    }
    // the topics of channels without messages are in the summary only
    if let Ok(Some(summary)) = mcap::Summary::read(&bytes) {
        topics.extend(summary.channels.values().map(|c| c.topic.clone()));
    }
    for p in ports {
        if !topics.contains(&p.to_string()) {
            bail!(
                "{name} has no port {p}; its topics: {}",
                if topics.is_empty() {
                    "none".to_string()
                } else {
                    topics.iter().cloned().collect::<Vec<_>>().join(", ")
                }
            );
        }
    }
    Ok((samples, robot.unwrap_or_else(|| "recording".to_string())))
}

/// The schema of a recorded channel, or what makes it not one of nerve's.
fn channel_schema(ch: &mcap::Channel<'_>) -> Result<Schema, String> {
    if ch.message_encoding != MESSAGE_ENCODING {
        return Err(format!("channel {} is encoded {:?}, not {MESSAGE_ENCODING:?}", ch.topic, ch.message_encoding));
    }
    let Some(s) = ch.schema.as_ref().filter(|s| s.encoding == SCHEMA_ENCODING) else {
        return Err(format!("channel {} has no {SCHEMA_ENCODING} schema", ch.topic));
    };
    serde_json::from_slice(&s.data).map_err(|e| format!("the schema of channel {} does not read ({e})", ch.topic))
}

/// A port subscribed to for the live plot.
struct Watched {
    raw: RawPort,
    listener: iceoryx2::port::listener::Listener<Ipc>,
    fields: Fields,
}

/// The samples of `ports` in the live robot for `duration` seconds (less on Ctrl-C).
fn live(world: &World, ports: &[PortRef], fields: &[String], duration: f64, quiet: bool) -> Result<Vec<Samples>> {
    let node = cli_node(world)?;
    let mut watched = Vec::new();
    for port in ports {
        let info = port_info(world, &node, port)?;
        let schema = info.schema_or_why(port)?;
        let fields = Fields::of(schema, port, fields)?;
        let service = world.robot().port_service(port.agent.as_str(), &port.port);
        let raw = RawPort::open(&node, &service).with_context(|| format!("cannot subscribe to {port}"))?;
        let listener = port_event(&node, &service)?
            .listener_builder()
            .create()
            .map_err(|e| anyhow!("cannot wait for the samples of {port}: {e:?}"))?;
        watched.push(Watched { raw, listener, fields });
    }
    let mut samples: Vec<Samples> = ports.iter().map(|p| Samples::new(p, fields.len())).collect();
    crate::interrupt::catch();
    let ws = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
        .create::<Ipc>()
        .map_err(|e| anyhow!("{e:?}"))?;
    let mut guards = Vec::new();
    for w in &watched {
        guards.push(ws.attach_notification(&w.listener).map_err(|e| anyhow!("{e:?}"))?);
    }
    let _tick = ws.attach_interval(Duration::from_millis(100)).map_err(|e| anyhow!("{e:?}"))?;
    let start = Instant::now();
    let until = start + Duration::from_secs_f64(duration);
    let tty = std::io::stderr().is_terminal();
    let mut next_progress = start + Duration::from_secs(1);
    let mut interrupted = false;
    loop {
        match ws.wait_and_process_once(|_| CallbackProgression::Continue) {
            Ok(WaitSetRunResult::TerminationRequest | WaitSetRunResult::Interrupt) => interrupted = true,
            Ok(_) if crate::interrupt::requested() => interrupted = true,
            Ok(_) => {}
            Err(e) => bail!("wait failed: {e:?}"),
        }
        for ((w, s), port) in watched.iter().zip(&mut samples).zip(ports) {
            let _ = w.listener.try_wait(|_| {});
            let mut failed = None;
            w.raw.receive(|h, bytes| match w.fields.values(bytes) {
                Ok(v) => {
                    s.push(h.stamp_ns, v);
                    true
                }
                Err(e) => {
                    failed = Some(anyhow!("port {port}: {e}"));
                    false
                }
            })?;
            if let Some(e) = failed {
                return Err(e);
            }
        }
        let now = Instant::now();
        if interrupted || now >= until {
            break;
        }
        if now >= next_progress && !quiet {
            next_progress = now + Duration::from_secs(1);
            let n: usize = samples.iter().map(|s| s.stamps.len()).sum();
            let line = format!("plotting: {n} samples ({:.0} of {duration} s)", start.elapsed().as_secs_f64());
            let mut err = std::io::stderr().lock();
            let _ = if tty { write!(err, "\r{line}   ") } else { writeln!(err, "{line}") };
            let _ = err.flush();
        }
    }
    if !quiet && tty {
        eprintln!();
    }
    if interrupted {
        eprintln!("interrupted after {:.1} s: plotting what arrived", start.elapsed().as_secs_f64());
    }
    Ok(samples)
}

/// Writes the figure to `path`.
fn draw_to(path: &Path, format: Format, lines: &[Line], title: &str, y_desc: &str) -> Result<()> {
    Ok(figure::write(path, format, SIZE, &Plot { lines, title, y_desc })?)
}

/// The figure: one line per field against time.
struct Plot<'a> {
    lines: &'a [Line],
    title: &'a str,
    y_desc: &'a str,
}

impl Figure for Plot<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult
    where
        DB::ErrorType: 'static,
    {
        Ok(draw(root, self.lines, self.title, self.y_desc)?)
    }
}

/// (low, high) of `values`, padded by 5 % (a flat line: by 1, or 5 % of its value).
fn padded(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) =
        values.filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| (l.min(v), h.max(v)));
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = if hi > lo { (hi - lo) * 0.05 } else { (lo.abs() * 0.05).max(1.0) };
    (lo - pad, hi + pad)
}

/// A value axis' label for `v`, with the digits ticks `step` apart need:
/// `0.25`, `480`, `7.4741e12` (large or tiny magnitudes in scientific form).
fn tick_label(v: f64, step: f64) -> String {
    if v == 0.0 || !v.is_finite() || !step.is_finite() || step <= 0.0 {
        return format!("{v}");
    }
    let magnitude = v.abs().max(step);
    if !(1e-3..1e6).contains(&magnitude) {
        let digits = (magnitude / step).log10().floor().clamp(0.0, 15.0) as usize;
        format!("{v:.digits$e}")
    } else {
        let decimals = (-step.log10().floor()).clamp(0.0, 9.0) as usize;
        format!("{v:.decimals$}")
    }
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    lines: &[Line],
    title: &str,
    y_desc: &str,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let t1 = lines.iter().flat_map(|l| l.points.iter().map(|p| p.0)).fold(0.0, f64::max);
    let (y0, y1) = padded(lines.iter().flat_map(|l| l.points.iter().map(|p| p.1)));
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(90)
        .build_cartesian_2d(0.0..if t1 > 0.0 { t1 } else { 1.0 }, y0..y1)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(y_desc)
        .light_line_style(RGBColor(238, 238, 238))
        .y_label_formatter(&|v| tick_label(*v, (y1 - y0) / 10.0))
        .draw()
        .map_err(e)?;
    for (i, line) in lines.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        chart
            .draw_series(LineSeries::new(line.points.iter().copied(), colour.stroke_width(2)))
            .map_err(e)?
            .label(line.label.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2)));
        // a few samples: marked, so that a single one shows too
        if line.points.len() <= 50 {
            chart.draw_series(line.points.iter().map(|p| Circle::new(*p, 3, colour.filled()))).map_err(e)?;
        }
    }
    figure::legend(&mut chart, SeriesLabelPosition::UpperLeft, 14).map_err(e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use shm_schemas::payloads::Tick;
    use shm_schemas::{Described, FixedName};

    /// `{ x: f64, ok: bool, n: i16, ranges: [u16; 3], name: FixedName }`, laid out by hand.
    fn schema() -> Schema {
        let field = |name: &str, offset, schema| shm_schemas::schema::Field { name: name.into(), offset, schema };
        let name = FixedName::schema();
        let fields = vec![
            field("x", 0, f64::schema()),
            field("ok", 8, bool::schema()),
            field("n", 10, i16::schema()),
            field("ranges", 12, <[u16; 3]>::schema()),
            field("name", 20, name.clone()),
        ];
        Schema { type_name: "test::S".into(), size: 20 + name.size, align: 8, kind: Kind::Struct { fields } }
    }

    fn bytes() -> Vec<u8> {
        let s = schema();
        let mut b = vec![0u8; s.size];
        b[0..8].copy_from_slice(&2.5f64.to_le_bytes());
        b[8] = 1;
        b[10..12].copy_from_slice(&(-7i16).to_le_bytes());
        b[14..16].copy_from_slice(&300u16.to_le_bytes());
        b
    }

    fn port() -> PortRef {
        PortRef::new("a", "p").expect("port")
    }

    #[test]
    fn numbers_of_every_kind_plot_and_the_rest_does_not() {
        assert_eq!(numeric(&Value::Bool(true)), Some(1.0));
        assert_eq!(numeric(&Value::Bool(false)), Some(0.0));
        assert_eq!(numeric(&Value::Unsigned(u64::from(u32::MAX))), Some(4_294_967_295.0));
        assert_eq!(numeric(&Value::Signed(-3)), Some(-3.0));
        assert_eq!(numeric(&Value::F32(0.5)), Some(0.5));
        assert_eq!(numeric(&Value::Float(-1e300)), Some(-1e300));
        assert_eq!(numeric(&Value::String("x".into())), None);
        assert_eq!(numeric(&Value::Array(vec![Value::Unsigned(1)])), None);
        assert_eq!(numeric(&Value::Struct(vec![])), None);
    }

    #[test]
    fn fields_are_read_from_the_sample_bytes() {
        let paths: Vec<String> = ["x", "ok", "n", "ranges.1", "ranges.0"].map(String::from).to_vec();
        let f = Fields::of(&schema(), &port(), &paths).expect("numeric fields");
        assert_eq!(f.values(&bytes()), Ok(vec![Some(2.5), Some(1.0), Some(-7.0), Some(300.0), Some(0.0)]));
        assert!(f.values(&bytes()[..10]).is_err(), "a short sample is an error, not a zero");

        let tick = Tick::schema();
        let f = Fields::of(&tick, &port(), &["stamp_ns".into(), "seq".into()]).expect("tick fields");
        let mut b = 42u64.to_le_bytes().to_vec();
        b.extend(7u64.to_le_bytes());
        assert_eq!(f.values(&b), Ok(vec![Some(7.0), Some(42.0)]));
    }

    /// `Seq<Tick, Tick>` with `n` elements: header `{seq: 9, stamp_ns: 8}`,
    /// element `i` `{seq: i, stamp_ns: 10 * i}`.
    fn sequence_sample(n: u64) -> Vec<u8> {
        let mut b = [9u64, 8].map(u64::to_le_bytes).concat();
        for i in 0..n {
            b.extend(i.to_le_bytes());
            b.extend((10 * i).to_le_bytes());
        }
        b
    }

    #[test]
    fn a_sequence_plots_its_header_one_element_and_the_last_one() {
        let schema = shm_schemas::seq::Seq::<Tick, Tick>::schema();
        let paths: Vec<String> =
            ["header.seq", "items[2].stamp_ns", "items[-1].seq", "items.-1.stamp_ns"].map(String::from).to_vec();
        let f = Fields::of(&schema, &port(), &paths).expect("numeric fields of a sequence");
        assert_eq!(f.values(&sequence_sample(4)), Ok(vec![Some(9.0), Some(20.0), Some(3.0), Some(30.0)]));
        // a sample without the third element, or without any, has no point there
        assert_eq!(f.values(&sequence_sample(1)), Ok(vec![Some(9.0), None, Some(0.0), Some(0.0)]));
        assert_eq!(f.values(&sequence_sample(0)), Ok(vec![Some(9.0), None, None, None]));
        // the last element of a sequence of numbers
        let bytes = shm_schemas::seq::Seq::<f32>::schema();
        let f = Fields::of(&bytes, &port(), &["items[-1]".into()]).expect("the last number");
        assert_eq!(f.values(&[1f32, 2.5].map(f32::to_le_bytes).concat()), Ok(vec![Some(2.5)]));
        for (path, says) in
            [("items[-1]", "not a number"), ("items[-1].nope", "has no field"), ("items[-2].seq", "has no field")]
        {
            let e = numeric_field(&schema, &port(), path).map(|_| ()).expect_err(path).to_string();
            assert!(e.contains(says) && e.contains("items.<i>.seq"), "{path}: {e}");
        }
        // points of samples without the element are left out of the line
        let samples = Samples {
            port: port(),
            stamps: vec![0, 1_000_000_000, 2_000_000_000],
            values: vec![vec![Some(1.0), None, Some(3.0)]],
        };
        assert_eq!(lines(&[samples], &["items[5].seq".into()])[0].points, vec![(0.0, 1.0), (2.0, 3.0)]);
    }

    #[test]
    fn a_field_that_is_not_a_number_is_refused_with_the_numeric_ones() {
        let list = "x, ok, n, ranges.<i> (<i> < 3)";
        assert_eq!(numeric_paths(&schema()).join(", "), list);
        for (path, says) in [
            ("name", "not a number"),
            ("ranges", "not a number"),
            ("", "not a number"),
            ("nope", "has no field \"nope\""),
            ("ranges.3", "has no field"),
            ("x.y", "has no field"),
        ] {
            let e = numeric_field(&schema(), &port(), path).map(|_| ()).expect_err(path).to_string();
            assert!(e.contains(says) && e.ends_with(list), "{path}: {e}");
        }
    }

    #[test]
    fn long_lines_are_thinned_to_their_extremes() {
        let points: Vec<(f64, f64)> =
            (0..10_000).map(|i| (f64::from(i), if i == 5_003 { 99.0 } else { 0.0 })).collect();
        let thin = thin(&points, 100);
        assert!(thin.len() <= 102, "{}", thin.len());
        assert!(thin.contains(&(5_003.0, 99.0)), "the spike stays");
        assert!(thin.windows(2).all(|w| w[0].0 < w[1].0), "in time order");
        assert_eq!(super::thin(&points[..50], 100).len(), 50);
    }

    #[test]
    fn axis_labels_have_the_digits_their_ticks_need() {
        assert_eq!(tick_label(480.0, 20.0), "480");
        assert_eq!(tick_label(0.25, 0.05), "0.25");
        assert_eq!(tick_label(-1.5, 0.5), "-1.5");
        assert_eq!(tick_label(0.0, 3e8), "0");
        assert_eq!(tick_label(7_474_123_456_789.0, 3e8), "7.4741e12");
        assert_eq!(tick_label(2e-5, 1e-6), "2.0e-5");
    }

    #[test]
    fn outputs_are_named_after_port_and_field() {
        let p = PortRef::new("t1", "tick").expect("port");
        assert_eq!(default_output(std::slice::from_ref(&p), &["pose.x".into()]), PathBuf::from("t1-tick-pose-x.png"));
        assert_eq!(format_of(Path::new("a.SVG")).ok(), Some(Format::Svg));
        assert_eq!(format_of(Path::new("a.png")).ok(), Some(Format::Png));
        assert!(format_of(Path::new("a.jpg")).is_err());
    }
}
