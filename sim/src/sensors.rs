//! Range and landmark sensors: the sonar ring and the IR receiver.
//!
//! **Sonar**: each of the 12 transducers casts five rays across its beam
//! (±12.5°) at its mounting height; the nearest hit is the true range. A
//! round thing (a pole, a tube's stand, a person, another robot) echoes when
//! any part of it lies within the beam's cone — a convex surface always
//! turns a point squarely to the transducer — so a pole thinner than the
//! gap between two rays is not missed, and its echo is never specular. Noise
//! is normal with a constant and a range-proportional part. When the beam
//! meets the surface at a grazing angle (incidence beyond `specular_angle`),
//! the echo may be reflected away (specular reflection; the incidence is that
//! of the beam axis): with
//! `specular_prob` the reading is then wrong — no echo, or a longer
//! multipath range. Rarely (`sonar_spurious_prob`) any sonar reads a random
//! range. Readings below the minimum range read as the minimum; beyond the
//! maximum, as [`SONAR_NO_ECHO`].
//!
//! Each robot's sensors see the other robots' bodies (sonar echoes, IR
//! blocked) but not their own.
//!
//! **IR**: a checkpoint is received when its centre is within the receiver's
//! range (2 m), no wall, box or robot is in between, and the robot lies inside the
//! emission cone (±50°) of at least one of its four transmitters. The report
//! names the nearest such checkpoint and the bitmask of transmitters whose
//! cone holds the robot. A visible checkpoint is missed with
//! `ir_dropout_prob`.

use rand::Rng;

use nerve_devices::{IrSighting, SONAR_COUNT, SONAR_NO_ECHO, wrap_angle};

use crate::geom::Vec2;
use crate::sim::{RobotId, RobotMut, RobotRef, Shape, Simulation, Surface, gauss, ray_hit};

/// True range and angle of incidence along one ray at `height`.
fn sonar_ray(surfaces: &[Surface], origin: Vec2, dir: Vec2, height: f64) -> Option<(f64, f64)> {
    surfaces
        .iter()
        .filter(|s| s.z[0] <= height && height <= s.z[1])
        .filter_map(|s| ray_hit(origin, dir, &s.shape))
        .min_by(|a, b| a.dist.total_cmp(&b.dist))
        .map(|h| (h.dist, dir.dot(h.normal).abs().clamp(0.0, 1.0).acos()))
}

/// The nearest round surface at `height` any part of which lies within the
/// cone of half-angle `half_beam` around `axis` (a unit vector) from
/// `origin`: its range (to its near side along the line to its centre).
fn sonar_cone(surfaces: &[Surface], origin: Vec2, axis: Vec2, half_beam: f64, height: f64) -> Option<f64> {
    surfaces
        .iter()
        .filter(|s| s.z[0] <= height && height <= s.z[1])
        .filter_map(|s| match s.shape {
            Shape::Circle(c, r) => {
                let to = c - origin;
                let d = to.norm();
                if d <= r {
                    return Some(0.0);
                }
                let off = wrap_angle(to.angle() - axis.angle()).abs();
                (off <= half_beam + (r / d).asin()).then_some(d - r)
            }
            Shape::Seg(_) => None,
        })
        .min_by(f64::total_cmp)
}

/// The true range over one transducer's beam and the angle of incidence
/// that decides a specular loss: the rays' nearest hit (with the beam
/// axis' incidence), or a round thing in the cone if nearer (incidence 0).
fn sonar_beam(surfaces: &[Surface], origin: Vec2, heading: f64, half_beam: f64, height: f64) -> Option<(f64, f64)> {
    let rays = (-2..=2)
        .filter_map(|k| {
            let d = Vec2::from_angle(heading + f64::from(k) * half_beam / 2.0);
            sonar_ray(surfaces, origin, d, height)
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))
        // the angle of incidence that matters is the beam axis' one
        .map(|(r, _)| {
            let axis = Vec2::from_angle(heading);
            let inc = sonar_ray(surfaces, origin, axis, height).map_or(std::f64::consts::FRAC_PI_2, |(_, inc)| inc);
            (r, inc)
        });
    let cone = sonar_cone(surfaces, origin, Vec2::from_angle(heading), half_beam, height);
    match (rays, cone) {
        (Some((r, _)), Some(c)) if c < r => Some((c, 0.0)),
        (None, Some(c)) => Some((c, 0.0)),
        (rays, _) => rays,
    }
}

/// Whether an opaque surface blocks the straight line from `a` to `b`.
fn line_blocked(surfaces: &[Surface], a: Vec2, b: Vec2) -> bool {
    let d = b - a;
    let len = d.norm();
    if len == 0.0 {
        return false;
    }
    let dir = d * (1.0 / len);
    surfaces.iter().filter(|s| s.opaque).filter_map(|s| ray_hit(a, dir, &s.shape)).any(|h| h.dist < len)
}

impl Simulation {
    /// The first robot's noise-free sonar ranges; see [`RobotRef::sonar_true_ranges`].
    pub fn sonar_true_ranges(&self) -> Vec<Option<f64>> {
        self.robot(RobotId::FIRST).sonar_true_ranges()
    }
    /// One noisy scan of the first robot's ring; see [`RobotMut::sonar_scan`].
    pub fn sonar_scan(&mut self) -> [u16; SONAR_COUNT] {
        self.robot_mut(RobotId::FIRST).sonar_scan()
    }
    /// The first robot's noise-free IR sighting; see [`RobotRef::ir_true_sighting`].
    pub fn ir_true_sighting(&self) -> Option<IrSighting> {
        self.robot(RobotId::FIRST).ir_true_sighting()
    }
    /// One IR reading of the first robot, with dropouts.
    pub fn ir_sighting(&mut self) -> Option<IrSighting> {
        self.robot_mut(RobotId::FIRST).ir_sighting()
    }
}

impl RobotRef<'_> {
    /// The noise-free range of each sonar, metres (`None`: nothing within
    /// the beam at any distance). Empty for a robot without sonar.
    pub fn sonar_true_ranges(&self) -> Vec<Option<f64>> {
        let r = self.r();
        let Some(spec) = &r.model.sonar else {
            return Vec::new();
        };
        let surfaces = self.sim.surfaces(Some(self.i));
        let p = Vec2::new(r.pose.x, r.pose.y);
        spec.angles
            .iter()
            .map(|a| {
                let heading = r.pose.theta + a;
                let origin = p + Vec2::from_angle(heading) * r.model.radius;
                sonar_beam(&surfaces, origin, heading, spec.half_beam, spec.height).map(|(r, _)| r)
            })
            .collect()
    }

    /// The noise-free IR sighting: nearest checkpoint in range, in sight,
    /// with the transmitters facing the robot.
    pub fn ir_true_sighting(&self) -> Option<IrSighting> {
        let r = self.r();
        let surfaces = self.sim.surfaces(Some(self.i));
        let p = Vec2::new(r.pose.x, r.pose.y);
        let mut best: Option<(f64, IrSighting)> = None;
        for c in &self.sim.world.checkpoints {
            let d = c.position.dist(p);
            if d > r.model.ir_range || line_blocked(&surfaces, p, c.position) {
                continue;
            }
            let bearing = (p - c.position).angle() - c.heading;
            let mut mask = 0u8;
            for i in 0..4 {
                let facing = f64::from(i) * std::f64::consts::FRAC_PI_2;
                if wrap_angle(bearing - facing).abs() <= r.model.ir_half_angle {
                    mask |= 1 << i;
                }
            }
            if mask != 0 && best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, IrSighting { checkpoint_id: c.id, transmitters: mask }));
            }
        }
        best.map(|(_, s)| s)
    }
}

impl RobotMut<'_> {
    /// One noisy scan of the ring, in mm as the sonar module reports it.
    /// All [`SONAR_NO_ECHO`] for a robot without sonar.
    pub fn sonar_scan(&mut self) -> [u16; SONAR_COUNT] {
        let mut out = [SONAR_NO_ECHO; SONAR_COUNT];
        let Some(spec) = self.r().model.sonar.clone() else {
            return out;
        };
        let surfaces = self.sim.surfaces(Some(self.i));
        let n = self.sim.cfg.noise;
        let (pose, radius) = (self.r().pose, self.r().model.radius);
        let p = Vec2::new(pose.x, pose.y);
        let rng = &mut self.r().rng;
        for (i, a) in spec.angles.iter().enumerate().take(SONAR_COUNT) {
            let heading = pose.theta + a;
            let origin = p + Vec2::from_angle(heading) * radius;
            // Nearest echo over the beam.
            let best = sonar_beam(&surfaces, origin, heading, spec.half_beam, spec.height);
            // Fixed number of draws per sonar keeps runs reproducible.
            let (g, u_spec, u_kind, u_mult, u_spur, u_rand) = (
                gauss(rng),
                rng.random::<f64>(),
                rng.random::<f64>(),
                rng.random::<f64>(),
                rng.random::<f64>(),
                rng.random::<f64>(),
            );
            let mut range = match best {
                None => None,
                Some((r, incidence)) => {
                    if incidence > n.specular_angle && u_spec < n.specular_prob {
                        if u_kind < 0.5 { None } else { Some(r * (1.3 + 1.2 * u_mult)) }
                    } else {
                        Some(r + g * (n.sonar_sd + n.sonar_sd_rel * r))
                    }
                }
            };
            if u_spur < n.sonar_spurious_prob {
                range = Some(spec.min_range + u_rand * (spec.max_range - spec.min_range));
            }
            out[i] = match range {
                Some(r) if r <= spec.max_range => {
                    (r.max(spec.min_range) * 1000.0).round().min(f64::from(SONAR_NO_ECHO - 1)) as u16
                }
                _ => SONAR_NO_ECHO,
            };
        }
        out
    }

    /// One IR receiver reading, with dropouts.
    pub fn ir_sighting(&mut self) -> Option<IrSighting> {
        let dropout = self.sim.cfg.noise.ir_dropout_prob;
        let u: f64 = self.r().rng.random();
        if u < dropout {
            return None;
        }
        self.as_ref().ir_true_sighting()
    }
}
