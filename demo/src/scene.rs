//! The world as the analysis sees it: what is solid (for clearance), where
//! the doors are (for `reached_doorway`), which object is the target and
//! where it is at any time (for `reached_target`).
//!
//! Walls, boxes, checkpoints and objects come from `nerve_sim::World`, the
//! very loader the simulator uses, so both agree on the geometry. The door
//! openings are read from the same file a second time (leniently: only
//! `[[wall]]` `from`, `to` and `doors` matter), because `World` keeps the
//! walls already cut around them.

use crate::DemoError;
use nerve_sim::world::{Motion, PathMode};
use nerve_sim::{RobotModel, Segment, Vec2, World};
use serde::Deserialize;
use std::path::Path;

/// A door opening: the gap a robot drives through.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Door {
    /// The opening, from one jamb to the other, on the wall's line.
    pub opening: Segment,
    /// Which `[[wall]]` of the file it belongs to (1-based, as in the simulator's messages).
    pub wall: usize,
}

#[derive(Debug, Deserialize)]
struct RawWorld {
    #[serde(default)]
    wall: Vec<RawWall>,
}

#[derive(Debug, Deserialize)]
struct RawWall {
    from: [f64; 2],
    to: [f64; 2],
    #[serde(default)]
    doors: Vec<RawDoor>,
}

#[derive(Debug, Deserialize)]
struct RawDoor {
    at: f64,
    width: f64,
}

/// The world of a run, with the target picked out.
#[derive(Debug, Clone)]
pub struct Scene {
    /// The validated world.
    pub world: World,
    /// Every door opening, in file order.
    pub doors: Vec<Door>,
    /// Index in `world.objects` of the target: the object named
    /// `red-object`, else the first red one (red > 150, green and blue < 90).
    pub target: Option<usize>,
    /// Robot disc radius, m (H1).
    pub robot_radius: f64,
    /// Height of the robot's body, m: objects starting above it are not bumped into.
    pub body_height: f64,
}

impl Scene {
    /// Loads a world file.
    pub fn load(path: &Path) -> Result<Scene, DemoError> {
        let text = std::fs::read_to_string(path).map_err(|source| DemoError::Io {
            what: "cannot read world file",
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text, path)
    }

    /// Parses world text; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &Path) -> Result<Scene, DemoError> {
        let world = World::from_toml_str(text, origin)?;
        let raw: RawWorld = toml::from_str(text)
            .map_err(|e| DemoError::Format { path: origin.to_path_buf(), problem: e.to_string() })?;
        let mut doors = Vec::new();
        for (i, w) in raw.wall.iter().enumerate() {
            let (a, b) = (Vec2::new(w.from[0], w.from[1]), Vec2::new(w.to[0], w.to[1]));
            let len = a.dist(b);
            if len <= 0.0 {
                continue;
            }
            let dir = (b - a) * (1.0 / len);
            for d in &w.doors {
                doors.push(Door {
                    opening: Segment::new(a + dir * (d.at - d.width / 2.0), a + dir * (d.at + d.width / 2.0)),
                    wall: i + 1,
                });
            }
        }
        let target = world
            .objects
            .iter()
            .position(|o| o.name == "red-object")
            .or_else(|| world.objects.iter().position(|o| o.color[0] > 150 && o.color[1] < 90 && o.color[2] < 90));
        let model = RobotModel::h1();
        Ok(Scene { world, doors, target, robot_radius: model.radius, body_height: model.body_height })
    }

    /// Where the target is at simulated time `t`.
    pub fn target_at(&self, t: f64) -> Option<Vec2> {
        self.target.map(|i| self.world.objects[i].position_at(t))
    }

    /// When the target has finished moving: the end of a `once` path, 0 for
    /// a fixed object, `None` for a path that never ends (loop, ping-pong)
    /// or when there is no target.
    pub fn target_settles_at(&self) -> Option<f64> {
        let o = &self.world.objects[self.target?];
        match &o.motion {
            Motion::Fixed(_) => Some(0.0),
            Motion::Path { waypoints, speed, mode, start_after } => match mode {
                PathMode::Once => {
                    let len: f64 = waypoints.windows(2).map(|w| w[0].dist(w[1])).sum();
                    Some(start_after + len / speed)
                }
                PathMode::Loop | PathMode::Pingpong => None,
            },
        }
    }

    /// Distance from `p` to the nearest solid thing at time `t` (walls, box
    /// sides, checkpoint tubes, objects low enough to bump into), as the
    /// simulator computes it for collisions.
    pub fn clearance(&self, p: Vec2, t: f64) -> f64 {
        let w = &self.world;
        let walls = w.walls.iter().map(|wl| wl.seg.distance_to(p));
        let boxes = w.boxes.iter().flat_map(|b| b.edges.iter().map(move |e| e.distance_to(p)));
        let tubes = w.checkpoints.iter().map(|c| c.position.dist(p) - c.radius);
        let objects =
            w.objects.iter().filter(|o| o.z[0] < self.body_height).map(|o| o.position_at(t).dist(p) - o.radius);
        walls.chain(boxes).chain(tubes).chain(objects).fold(f64::INFINITY, f64::min)
    }

    /// The bounding box of the walls, boxes, checkpoints and object paths: (min, max).
    pub fn bounds(&self) -> (Vec2, Vec2) {
        let mut pts: Vec<Vec2> = Vec::new();
        for wl in &self.world.walls {
            pts.extend([wl.seg.a, wl.seg.b]);
        }
        for b in &self.world.boxes {
            pts.extend(b.edges.iter().map(|e| e.a));
        }
        pts.extend(self.world.checkpoints.iter().map(|c| c.position));
        for o in &self.world.objects {
            match &o.motion {
                Motion::Fixed(p) => pts.push(*p),
                Motion::Path { waypoints, .. } => pts.extend(waypoints.iter().copied()),
            }
        }
        pts.push(Vec2::new(self.world.start.x, self.world.start.y));
        let mut lo = Vec2::new(f64::INFINITY, f64::INFINITY);
        let mut hi = Vec2::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
        for p in pts {
            lo = Vec2::new(lo.x.min(p.x), lo.y.min(p.y));
            hi = Vec2::new(hi.x.max(p.x), hi.y.max(p.y));
        }
        if !lo.is_finite() || !hi.is_finite() {
            return (Vec2::new(0.0, 0.0), Vec2::new(1.0, 1.0));
        }
        (lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn doors_targets_and_clearance() {
        let s = Scene::from_toml_str(
            "[robot]\nx=1\ny=1\n[[wall]]\nfrom=[4,0]\nto=[4,4]\ndoors=[{at=2.0,width=1.0}]\n\
             [[object]]\nname=\"p\"\ncolor=[200,30,30]\nradius=0.2\n\
             path={waypoints=[[6,2],[6,4]],speed=0.5,start_after=2}\n",
            Path::new("w.toml"),
        )
        .expect("valid");
        assert_eq!(s.doors.len(), 1);
        let d = s.doors[0].opening;
        assert!((d.a.y - 1.5).abs() < 1e-9 && (d.b.y - 2.5).abs() < 1e-9 && (d.a.x - 4.0).abs() < 1e-9);
        assert_eq!(s.target, Some(0));
        assert_eq!(s.target_settles_at(), Some(6.0));
        // the wall piece below the door is 1 m from (3, 1); the door gap is free
        assert!((s.clearance(Vec2::new(3.0, 1.0), 0.0) - 1.0).abs() < 1e-9);
        assert!((s.clearance(Vec2::new(6.0, 1.0), 0.0) - 0.8).abs() < 1e-9);
    }
}

#[cfg(test)]
mod world_files {
    use super::*;
    use nerve_sim::{SimConfig, Simulation};

    /// The demo's worlds load, the robot fits at its start, and each has one
    /// door and a target whose path ends.
    #[test]
    fn explore_worlds_are_valid() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join("worlds");
        for f in ["explore.toml", "explore-2.toml"] {
            let s = Scene::load(&root.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
            assert_eq!(s.doors.len(), 1, "{f}");
            assert!(s.target.is_some() && s.target_settles_at().is_some(), "{f}");
            Simulation::new(s.world.clone(), RobotModel::h1(), SimConfig::new(1))
                .unwrap_or_else(|e| panic!("{f}: {e}"));
        }
    }
}
