//! World files: the room the simulated robot lives in.
//!
//! A world is a TOML file, read strictly (unknown keys are errors, so a typo
//! never silently drops an obstacle). Lengths are metres, angles degrees
//! counter-clockwise, colours `[r, g, b]` 0–255. See `worlds/test-room.toml`
//! for a commented example and `docs/devices.md` for the full reference.
//!
//! ```toml
//! name = "test-room"
//! [robot]                       # start pose
//! x = 1.0
//! y = 1.0
//! heading_deg = 0.0
//! # wheel_bias = [0.0, -0.004]  # optional fixed drift (replaces the drawn bias)
//!
//! # or, for several robots in one world, one table per robot, in order
//! # (the first is the simulator's own robot, the next ones are named by
//! # `--extra-robot` on its command line):
//! # [[robot]]
//! # name = "robot 1"
//! # x = 0.0
//! # y = 0.0
//! # [[robot]]
//! # name = "robot 2"
//! # x = -4.0
//! # y = 0.0
//!
//! [[wall]]                      # a wall segment, optionally with door openings
//! from = [0.0, 0.0]
//! to = [6.0, 0.0]
//! doors = [{ at = 3.0, width = 0.9 }]   # centre `at` m from `from`
//!
//! [[box]]                       # a rectangular obstacle
//! center = [2.0, 2.0]
//! size = [0.6, 0.4]
//!
//! [[object]]                    # a coloured cylinder, fixed or moving
//! name = "red-object"
//! color = [220, 30, 30]
//! radius = 0.12
//! z = [0.5, 0.9]
//! path = { waypoints = [[4.0, 2.0], [5.0, 2.0]], speed = 0.3, mode = "pingpong" }
//!
//! [[checkpoint]]                # two-colour tube with four IR transmitters
//! id = 1
//! position = [5.5, 0.5]
//! target = false                # the target is a checkpoint upside down
//! ```

use std::path::{Path, PathBuf};

use serde::de::value::{MapAccessDeserializer, SeqAccessDeserializer};
use serde::{Deserialize, Deserializer};

use crate::geom::{Segment, Vec2};
use nerve_devices::Pose2;

/// Why a world file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The file could not be read.
    #[error("cannot read world file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The file is not valid TOML or does not match the schema.
    #[error("world file {path} is malformed: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What the parser said, with line and column.
        message: String,
    },
    /// The file parses but describes something impossible.
    #[error("world file {path}: {problem}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong and where.
        problem: String,
    },
}

fn default_wall_height() -> f64 {
    2.5
}
fn default_wall_color() -> [u8; 3] {
    [175, 175, 170]
}
fn default_box_height() -> f64 {
    0.8
}
fn default_box_color() -> [u8; 3] {
    [140, 100, 60]
}
fn default_object_z() -> [f64; 2] {
    [0.0, 1.0]
}
fn default_upper() -> [u8; 3] {
    [230, 200, 20]
}
fn default_lower() -> [u8; 3] {
    [20, 70, 210]
}
fn default_tube_radius() -> f64 {
    0.05
}
fn default_tube_z() -> [f64; 2] {
    [0.6, 1.0]
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WorldFile {
    #[serde(default)]
    name: Option<String>,
    /// How many times as fast as real time the world runs on simulated time.
    #[serde(default)]
    time_scale: Option<f64>,
    robot: RobotStartsFile,
    #[serde(default)]
    wall: Vec<WallFile>,
    #[serde(default, rename = "box")]
    boxes: Vec<BoxFile>,
    #[serde(default)]
    object: Vec<ObjectFile>,
    #[serde(default)]
    checkpoint: Vec<CheckpointFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RobotStartFile {
    #[serde(default)]
    name: Option<String>,
    x: f64,
    y: f64,
    #[serde(default)]
    heading_deg: f64,
    #[serde(default)]
    wheel_bias: Option<[f64; 2]>,
}

/// `[robot]` (one robot, as world files always had) or `[[robot]]` (one
/// table per robot). Decided by what the file holds, so that the parser's
/// own errors — unknown key, line and column — come through unchanged.
#[derive(Debug)]
struct RobotStartsFile(Vec<RobotStartFile>);

impl<'de> Deserialize<'de> for RobotStartsFile {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct OneOrMany;
        impl<'de> serde::de::Visitor<'de> for OneOrMany {
            type Value = RobotStartsFile;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a [robot] table or one [[robot]] table per robot")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
                RobotStartFile::deserialize(MapAccessDeserializer::new(map)).map(|r| RobotStartsFile(vec![r]))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
                Vec::<RobotStartFile>::deserialize(SeqAccessDeserializer::new(seq)).map(RobotStartsFile)
            }
        }
        d.deserialize_any(OneOrMany)
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WallFile {
    from: [f64; 2],
    to: [f64; 2],
    #[serde(default)]
    doors: Vec<DoorFile>,
    #[serde(default = "default_wall_height")]
    height: f64,
    #[serde(default = "default_wall_color")]
    color: [u8; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DoorFile {
    at: f64,
    width: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct BoxFile {
    center: [f64; 2],
    size: [f64; 2],
    #[serde(default)]
    heading_deg: f64,
    #[serde(default = "default_box_height")]
    height: f64,
    #[serde(default = "default_box_color")]
    color: [u8; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ObjectFile {
    name: String,
    color: [u8; 3],
    radius: f64,
    #[serde(default = "default_object_z")]
    z: [f64; 2],
    #[serde(default)]
    position: Option<[f64; 2]>,
    #[serde(default)]
    path: Option<PathFile>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PathFile {
    waypoints: Vec<[f64; 2]>,
    speed: f64,
    #[serde(default)]
    mode: PathMode,
    #[serde(default)]
    start_after: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CheckpointFile {
    id: u8,
    position: [f64; 2],
    #[serde(default)]
    heading_deg: f64,
    #[serde(default)]
    target: bool,
    #[serde(default = "default_upper")]
    upper_color: [u8; 3],
    #[serde(default = "default_lower")]
    lower_color: [u8; 3],
    #[serde(default = "default_tube_radius")]
    radius: f64,
    #[serde(default = "default_tube_z")]
    z: [f64; 2],
}

/// How a moving object walks its waypoints.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PathMode {
    /// Walk to the last waypoint and stay there.
    #[default]
    Once,
    /// Walk back to the first waypoint and start over.
    Loop,
    /// Walk back and forth.
    Pingpong,
}

/// A wall piece (doors already cut out).
#[derive(Debug, Clone, PartialEq)]
pub struct Wall {
    /// Footprint.
    pub seg: Segment,
    /// Height, metres.
    pub height: f64,
    /// Base colour.
    pub color: [u8; 3],
}

/// A rectangular obstacle.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxObstacle {
    /// The four edges, counter-clockwise.
    pub edges: [Segment; 4],
    /// Height, metres.
    pub height: f64,
    /// Colour.
    pub color: [u8; 3],
}

/// How an object moves.
#[derive(Debug, Clone, PartialEq)]
pub enum Motion {
    /// It stays put.
    Fixed(Vec2),
    /// It walks waypoints at a speed.
    Path {
        /// At least two points.
        waypoints: Vec<Vec2>,
        /// m/s.
        speed: f64,
        /// Once, loop or ping-pong.
        mode: PathMode,
        /// Seconds of simulated time it waits at the first waypoint.
        start_after: f64,
    },
}

/// A coloured vertical cylinder (a ball on a stick, a person's red object).
#[derive(Debug, Clone, PartialEq)]
pub struct ColoredObject {
    /// Name, for logs.
    pub name: String,
    /// Colour.
    pub color: [u8; 3],
    /// Radius, metres.
    pub radius: f64,
    /// Bottom and top height, metres.
    pub z: [f64; 2],
    /// Fixed or moving.
    pub motion: Motion,
}

impl ColoredObject {
    /// Where the object is at simulated time `t` seconds.
    pub fn position_at(&self, t: f64) -> Vec2 {
        match &self.motion {
            Motion::Fixed(p) => *p,
            Motion::Path { waypoints, speed, mode, start_after } => {
                let mut pts = waypoints.clone();
                if *mode == PathMode::Loop {
                    pts.push(waypoints[0]);
                }
                let total: f64 = pts.windows(2).map(|w| w[0].dist(w[1])).sum();
                if total <= 0.0 {
                    return pts[0];
                }
                let s = ((t - start_after).max(0.0)) * speed;
                let s = match mode {
                    PathMode::Once => s.min(total),
                    PathMode::Loop => s % total,
                    PathMode::Pingpong => {
                        let m = s % (2.0 * total);
                        if m > total { 2.0 * total - m } else { m }
                    }
                };
                let mut left = s;
                for w in pts.windows(2) {
                    let l = w[0].dist(w[1]);
                    if left <= l && l > 0.0 {
                        return w[0] + (w[1] - w[0]) * (left / l);
                    }
                    left -= l;
                }
                pts[pts.len() - 1]
            }
        }
    }
}

/// A checkpoint landmark: a two-colour tube with four IR transmitters.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    /// IR identification code.
    pub id: u8,
    /// Centre of the tube.
    pub position: Vec2,
    /// Direction transmitter 0 faces, radians; transmitter `i` faces
    /// `heading + i·90°`.
    pub heading: f64,
    /// Whether this is the target (tube upside down).
    pub target: bool,
    /// Colour of the upper half as mounted (already swapped for the target).
    pub upper_color: [u8; 3],
    /// Colour of the lower half as mounted.
    pub lower_color: [u8; 3],
    /// Tube radius, metres.
    pub radius: f64,
    /// Bottom and top height of the tube, metres.
    pub z: [f64; 2],
}

impl Checkpoint {
    /// Heights of the centres of the lower and the upper colour band,
    /// metres: the tube is two bands of equal height, stacked.
    pub fn band_centres(&self) -> (f64, f64) {
        let h = (self.z[1] - self.z[0]) / 4.0;
        (self.z[0] + h, self.z[1] - h)
    }

    /// Distance between the centres of the two colour bands, metres: the
    /// known length `D` of the thesis' Appendix A.
    pub fn band_spacing(&self) -> f64 {
        (self.z[1] - self.z[0]) / 2.0
    }
}

/// Where one robot starts, and its fixed odometry drift if the world sets one.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotStart {
    /// A label for logs (`[[robot]] name`), if given.
    pub name: Option<String>,
    /// Start pose.
    pub pose: Pose2,
    /// Relative error of each wheel's effective radius, `[left, right]`:
    /// the ground moves by the counted travel × (1 + bias). Replaces the
    /// bias drawn per run; `None` keeps the drawn one.
    pub wheel_bias: Option<[f64; 2]>,
}

/// A validated world.
#[derive(Debug, Clone, PartialEq)]
pub struct World {
    /// Name for logs.
    pub name: String,
    /// Where it was loaded from (for messages).
    pub source: PathBuf,
    /// Wall pieces.
    pub walls: Vec<Wall>,
    /// Boxes.
    pub boxes: Vec<BoxObstacle>,
    /// Coloured objects.
    pub objects: Vec<ColoredObject>,
    /// Checkpoints and the target.
    pub checkpoints: Vec<Checkpoint>,
    /// Start pose of the first robot (`robots[0].pose`).
    pub start: Pose2,
    /// Every robot's start, in file order; never empty. The first is the
    /// simulator's own robot.
    pub robots: Vec<RobotStart>,
    /// `time_scale = 4.0`: the scale of simulated time this world runs at
    /// when the robot runs on simulated time and no `--time-scale` is
    /// given (`docs/time.md`); 1 when absent.
    pub time_scale: Option<f64>,
}

fn v(p: [f64; 2]) -> Vec2 {
    Vec2::new(p[0], p[1])
}

impl World {
    /// Reads and validates a world file.
    pub fn load(path: &Path) -> Result<World, WorldError> {
        let text =
            std::fs::read_to_string(path).map_err(|source| WorldError::Read { path: path.to_path_buf(), source })?;
        Self::from_toml_str(&text, path)
    }

    /// Parses and validates world text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<World, WorldError> {
        let file: WorldFile = toml::from_str(text).map_err(|e| WorldError::Parse {
            path: origin.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        let bad = |problem: String| WorldError::Invalid { path: origin.to_path_buf(), problem };
        let finite = |what: &str, xs: &[f64]| {
            if xs.iter().all(|x| x.is_finite()) {
                Ok(())
            } else {
                Err(bad(format!("{what} has a value that is not a finite number")))
            }
        };

        if let Some(k) = file.time_scale {
            let (lo, hi) = agent_sdk::simclock::SCALE_RANGE;
            if !(k.is_finite() && (lo..=hi).contains(&k)) {
                return Err(bad(format!(
                    "time_scale = {k}: give how many times as fast as real time the world runs, from {lo} to {hi}"
                )));
            }
        }
        if file.robot.0.is_empty() {
            return Err(bad("no robot: add a [robot] table (or [[robot]] tables) with its start x and y".into()));
        }
        let mut robots = Vec::new();
        for (i, r) in file.robot.0.iter().enumerate() {
            let who = match &r.name {
                Some(name) => format!("robot {} (\"{name}\")", i + 1),
                None => format!("robot {}", i + 1),
            };
            finite(&who, &[r.x, r.y, r.heading_deg])?;
            if let Some(b) = r.wheel_bias {
                finite(&who, &b)?;
                if b.iter().any(|x| x.abs() >= 0.5) {
                    return Err(bad(format!(
                        "{who}: wheel_bias {b:?} is a relative error of each wheel's radius; \
                         use small values such as [0.0, -0.004] (each within ±0.5)"
                    )));
                }
            }
            let pose = Pose2 { x: r.x, y: r.y, theta: nerve_devices::wrap_angle(r.heading_deg.to_radians()) };
            robots.push(RobotStart { name: r.name.clone(), pose, wheel_bias: r.wheel_bias });
        }
        let start = robots[0].pose;

        let mut walls = Vec::new();
        for (i, w) in file.wall.iter().enumerate() {
            let n = i + 1;
            finite(&format!("wall {n}"), &[w.from[0], w.from[1], w.to[0], w.to[1], w.height])?;
            let seg = Segment::new(v(w.from), v(w.to));
            let len = seg.len();
            if len < 1e-6 {
                return Err(bad(format!("wall {n} has zero length (from == to)")));
            }
            if w.height <= 0.0 {
                return Err(bad(format!("wall {n} has height {} m; it must be > 0", w.height)));
            }
            let mut doors: Vec<(f64, f64)> = Vec::new();
            for (j, d) in w.doors.iter().enumerate() {
                finite(&format!("door {} of wall {n}", j + 1), &[d.at, d.width])?;
                let (lo, hi) = (d.at - d.width / 2.0, d.at + d.width / 2.0);
                if d.width <= 0.0 || lo < 0.0 || hi > len + 1e-9 {
                    return Err(bad(format!(
                        "door {} of wall {n} (at {} m, width {} m) does not fit on the wall, \
                         which is {len:.3} m long; `at` is the door centre measured from `from`",
                        j + 1,
                        d.at,
                        d.width
                    )));
                }
                doors.push((lo, hi));
            }
            doors.sort_by(|a, b| a.0.total_cmp(&b.0));
            if doors.windows(2).any(|p| p[1].0 < p[0].1) {
                return Err(bad(format!("doors of wall {n} overlap")));
            }
            let dir = (seg.b - seg.a) * (1.0 / len);
            let mut pos = 0.0;
            for (lo, hi) in doors.iter().copied().chain(std::iter::once((len, len))) {
                if lo - pos > 1e-6 {
                    walls.push(Wall {
                        seg: Segment::new(seg.a + dir * pos, seg.a + dir * lo),
                        height: w.height,
                        color: w.color,
                    });
                }
                pos = hi;
            }
        }

        let mut boxes = Vec::new();
        for (i, b) in file.boxes.iter().enumerate() {
            let n = i + 1;
            finite(&format!("box {n}"), &[b.center[0], b.center[1], b.size[0], b.size[1], b.heading_deg, b.height])?;
            if b.size[0] <= 0.0 || b.size[1] <= 0.0 || b.height <= 0.0 {
                return Err(bad(format!("box {n} needs a positive size and height")));
            }
            let (c, h) = (v(b.center), b.heading_deg.to_radians());
            let (ux, uy) = (Vec2::from_angle(h), Vec2::from_angle(h + std::f64::consts::FRAC_PI_2));
            let (hx, hy) = (b.size[0] / 2.0, b.size[1] / 2.0);
            let k = [c - ux * hx - uy * hy, c + ux * hx - uy * hy, c + ux * hx + uy * hy, c - ux * hx + uy * hy];
            boxes.push(BoxObstacle {
                edges: [
                    Segment::new(k[0], k[1]),
                    Segment::new(k[1], k[2]),
                    Segment::new(k[2], k[3]),
                    Segment::new(k[3], k[0]),
                ],
                height: b.height,
                color: b.color,
            });
        }

        let mut objects = Vec::new();
        for (i, o) in file.object.iter().enumerate() {
            let who = format!("object {} (\"{}\")", i + 1, o.name);
            finite(&who, &[o.radius, o.z[0], o.z[1]])?;
            if o.radius <= 0.0 || o.z[0] < 0.0 || o.z[1] <= o.z[0] {
                return Err(bad(format!("{who} needs radius > 0 and z = [bottom, top] with 0 <= bottom < top")));
            }
            let motion = match (&o.position, &o.path) {
                (Some(p), None) => {
                    finite(&who, p)?;
                    Motion::Fixed(v(*p))
                }
                (None, Some(p)) => {
                    if p.waypoints.len() < 2 || p.speed <= 0.0 || p.start_after < 0.0 {
                        return Err(bad(format!(
                            "{who}: a path needs at least two waypoints, speed > 0 and \
                             start_after >= 0"
                        )));
                    }
                    for w in &p.waypoints {
                        finite(&who, w)?;
                    }
                    finite(&who, &[p.speed, p.start_after])?;
                    Motion::Path {
                        waypoints: p.waypoints.iter().map(|w| v(*w)).collect(),
                        speed: p.speed,
                        mode: p.mode,
                        start_after: p.start_after,
                    }
                }
                _ => {
                    return Err(bad(format!("{who} needs exactly one of `position` (fixed) or `path` (moving)")));
                }
            };
            objects.push(ColoredObject { name: o.name.clone(), color: o.color, radius: o.radius, z: o.z, motion });
        }

        let mut checkpoints: Vec<Checkpoint> = Vec::new();
        for (i, c) in file.checkpoint.iter().enumerate() {
            let who = format!("checkpoint {} (id {})", i + 1, c.id);
            finite(&who, &[c.position[0], c.position[1], c.heading_deg, c.radius, c.z[0], c.z[1]])?;
            if checkpoints.iter().any(|o| o.id == c.id) {
                return Err(bad(format!("{who}: id {} is used twice; ids must be unique", c.id)));
            }
            if c.radius <= 0.0 || c.z[0] < 0.0 || c.z[1] <= c.z[0] {
                return Err(bad(format!("{who} needs radius > 0 and z = [bottom, top] with 0 <= bottom < top")));
            }
            let (upper, lower) = if c.target { (c.lower_color, c.upper_color) } else { (c.upper_color, c.lower_color) };
            checkpoints.push(Checkpoint {
                id: c.id,
                position: v(c.position),
                heading: c.heading_deg.to_radians(),
                target: c.target,
                upper_color: upper,
                lower_color: lower,
                radius: c.radius,
                z: c.z,
            });
        }

        Ok(World {
            name: file.name.unwrap_or_else(|| {
                origin.file_stem().map_or_else(|| "world".into(), |s| s.to_string_lossy().into_owned())
            }),
            source: origin.to_path_buf(),
            walls,
            boxes,
            objects,
            checkpoints,
            start,
            robots,
            time_scale: file.time_scale,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<World, WorldError> {
        World::from_toml_str(s, Path::new("t.toml"))
    }

    #[test]
    fn doors_cut_walls() {
        let w =
            parse("[robot]\nx=1\ny=1\n[[wall]]\nfrom=[0,0]\nto=[4,0]\ndoors=[{at=2.0,width=1.0}]\n").expect("valid");
        assert_eq!(w.walls.len(), 2);
        assert!((w.walls[0].seg.b.x - 1.5).abs() < 1e-9);
        assert!((w.walls[1].seg.a.x - 2.5).abs() < 1e-9);
    }

    #[test]
    fn a_world_names_its_time_scale_within_range() {
        assert_eq!(parse("time_scale = 4.0\n[robot]\nx=1\ny=1\n").expect("valid").time_scale, Some(4.0));
        assert_eq!(parse("[robot]\nx=1\ny=1\n").expect("valid").time_scale, None);
        for bad in ["0", "-2", "1000", "nan"] {
            let e = parse(&format!("time_scale = {bad}\n[robot]\nx=1\ny=1\n")).expect_err(bad);
            assert!(e.to_string().contains("time_scale"), "{e}");
        }
    }

    #[test]
    fn errors_name_file_and_problem() {
        let e = parse("[robot]\nx=1\ny=1\nspeed=3\n").expect_err("unknown key");
        let msg = e.to_string();
        assert!(msg.contains("t.toml") && msg.contains("speed"), "{msg}");
        let e = parse("[robot]\nx=1\ny=1\n[[wall]]\nfrom=[0,0]\nto=[1,0]\ndoors=[{at=0.9,width=1}]\n")
            .expect_err("door too wide");
        assert!(e.to_string().contains("door 1 of wall 1"), "{e}");
        let e =
            parse("[robot]\nx=1\ny=1\n[[checkpoint]]\nid=1\nposition=[0,0]\n[[checkpoint]]\nid=1\nposition=[1,0]\n")
                .expect_err("dup id");
        assert!(e.to_string().contains("used twice"), "{e}");
        let e =
            parse("[robot]\nx=1\ny=1\n[[object]]\nname=\"r\"\ncolor=[1,2,3]\nradius=0.1\n").expect_err("no position");
        assert!(e.to_string().contains("exactly one of"), "{e}");
    }

    #[test]
    fn one_robot_or_several() {
        let w = parse("[robot]\nx=1\ny=2\nheading_deg=90\nwheel_bias=[0.0,-0.004]\n").expect("valid");
        assert_eq!(w.robots.len(), 1);
        assert_eq!(w.robots[0].wheel_bias, Some([0.0, -0.004]));
        assert_eq!(w.start, w.robots[0].pose);
        let w = parse("[[robot]]\nname=\"r1\"\nx=0\ny=0\n[[robot]]\nx=-4\ny=0\nheading_deg=180\n").expect("valid");
        assert_eq!(w.robots.len(), 2);
        assert_eq!(w.robots[0].name.as_deref(), Some("r1"));
        assert!((w.robots[1].pose.x + 4.0).abs() < 1e-12 && w.robots[1].wheel_bias.is_none());
        assert_eq!((w.start.x, w.start.y), (0.0, 0.0));
        // the parser's own message, with the line, for a misspelt key in the second robot
        let e = parse("[[robot]]\nx=0\ny=0\n[[robot]]\nx=1\ny=0\nheadng_deg=3\n").expect_err("typo");
        let msg = e.to_string();
        assert!(msg.contains("t.toml") && msg.contains("headng_deg") && msg.contains("line 7"), "{msg}");
        let e = parse("[robot]\nx=0\ny=0\nwheel_bias=[0.0,0.7]\n").expect_err("bias");
        assert!(e.to_string().contains("robot 1") && e.to_string().contains("wheel_bias"), "{e}");
        let e = parse("robot=[]\n").expect_err("no robot");
        assert!(e.to_string().contains("no robot"), "{e}");
    }

    #[test]
    fn band_centres_are_a_quarter_in() {
        let w = parse("[robot]\nx=0\ny=0\n[[checkpoint]]\nid=1\nposition=[1,1]\nz=[0.6,1.0]\n").expect("valid");
        let c = &w.checkpoints[0];
        let (lo, hi) = c.band_centres();
        assert!((lo - 0.7).abs() < 1e-12 && (hi - 0.9).abs() < 1e-12);
        assert!((c.band_spacing() - 0.2).abs() < 1e-12);
    }

    #[test]
    fn target_swaps_colours_and_paths_move() {
        let w = parse(
            "[robot]\nx=0\ny=0\n[[checkpoint]]\nid=9\nposition=[0,0]\ntarget=true\n\
             [[object]]\nname=\"p\"\ncolor=[200,0,0]\nradius=0.1\n\
             path={waypoints=[[0,0],[1,0]],speed=0.5,mode=\"pingpong\"}\n",
        )
        .expect("valid");
        assert_eq!(w.checkpoints[0].upper_color, default_lower());
        let o = &w.objects[0];
        assert!((o.position_at(1.0).x - 0.5).abs() < 1e-9);
        assert!((o.position_at(3.0).x - 0.5).abs() < 1e-9);
        assert!((o.position_at(4.0).x - 0.0).abs() < 1e-9);
    }
}
