//! The wall follower of the thesis (section 4.2.2.3: "keeps increasing the
//! speed of the robot and tries to maintain the distance between the robot
//! and the wall") as a library.
//!
//! Directions are those of `nerve::SonarScan` (`i × 30°` counter-clockwise
//! from ahead). For a wall on the left the sonars at 60°, 90° and 120°
//! (directions 2, 3, 4) see it; on the right those at -60°, -90°, -120°
//! (10, 9, 8).
//!
//! * **Distance** to the wall: the smallest of `r90`, `r60 × sin 60°` and
//!   `r120 × sin 60°` (perpendicular estimates), over valid echoes within
//!   `wall_range`.
//! * **Side** (`auto`): the side with the nearer wall; the current side is
//!   kept unless the other wall is nearer by 20 %.
//! * **Turn**: `ω = s × (kp × (d - target) + ka × (r60 - r120))` with `s` = +1
//!   for a left wall, -1 for a right one: too far turns toward the wall, a
//!   wall that opens ahead (r60 > r120: heading away) turns toward it too.
//!   A wall or obstacle ahead closer than `front_slow` adds a turn away
//!   from the wall (the inside corner) and scales the speed down.
//! * **Speed** rises by `accel × dt` every cycle up to `v_max` (from
//!   `v_min`), and is scaled by the front clearance.
//! * No wall within range: straight ahead, speed still rising.
//!
//! **Going round in circles** ([`SideSwitch`]). Following the nearest wall
//! never leaves a free-standing obstacle (an island): the robot circles it
//! for ever. The map builder says when the robot is back at a place it
//! passed long ago (its `revisit`); on such a *rising edge* the follower
//! switches to the other side and keeps that side for `hold_s`, whatever
//! the nearer wall, following only a wall that comes within `reach_m` on
//! it ([`revisit_settings`]): it leaves the island, drives straight on into
//! new space, and does not steer back toward the island, 2 m away on the
//! new side, once it has turned along another wall. Then the ordinary
//! choice takes over, keeping the new wall (its 20 % hysteresis). A
//! revisit less than `holdoff_s` after the last switch is ignored, so that
//! the robot does not flip back and forth while it crosses visited space.

use shm_schemas::payloads::{SONAR_DIRECTIONS, SonarScan};

/// Which wall to follow.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WallSide {
    /// The wall on the robot's left.
    Left,
    /// The wall on the robot's right.
    Right,
}

impl WallSide {
    fn sign(self) -> f32 {
        match self {
            WallSide::Left => 1.0,
            WallSide::Right => -1.0,
        }
    }

    /// Directions at 60°, 90° and 120° toward this side.
    fn dirs(self) -> [usize; 3] {
        match self {
            WallSide::Left => [2, 3, 4],
            WallSide::Right => [10, 9, 8],
        }
    }
}

/// The wall follower's settings (its run-time parameters).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    /// Distance to keep from the wall, m.
    pub target: f32,
    /// Gain on the distance error, rad/s per m.
    pub kp: f32,
    /// Gain on the alignment (r60 - r120), rad/s per m.
    pub ka: f32,
    /// Speed to start from, m/s.
    pub v_min: f32,
    /// Speed to rise to, m/s.
    pub v_max: f32,
    /// How fast the speed rises, m/s².
    pub accel: f32,
    /// Largest turn rate, rad/s.
    pub omega_max: f32,
    /// A wall ahead nearer than this slows down and turns away, m.
    pub front_slow: f32,
    /// Echoes further than this are not a wall, m.
    pub wall_range: f32,
    /// `None`: follow the nearer wall.
    pub side: Option<WallSide>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            target: 0.6,
            kp: 1.2,
            ka: 0.8,
            v_min: 0.1,
            v_max: 0.6,
            accel: 0.1,
            omega_max: 1.0,
            front_slow: 1.0,
            wall_range: 2.0,
            side: None,
        }
    }
}

fn range(scan: &SonarScan, i: usize, max: f32) -> Option<f32> {
    let r = scan.ranges_m[i % SONAR_DIRECTIONS];
    (scan.valid[i % SONAR_DIRECTIONS] == 1 && r.is_finite() && r >= 0.0 && r <= max).then_some(r)
}

/// The perpendicular distance to the wall on `side`, if one is within `max`.
pub fn wall_distance(scan: &SonarScan, side: WallSide, max: f32) -> Option<f32> {
    let [d60, d90, d120] = side.dirs();
    let sin60 = 60f32.to_radians().sin();
    [range(scan, d90, max), range(scan, d60, max).map(|r| r * sin60), range(scan, d120, max).map(|r| r * sin60)]
        .into_iter()
        .flatten()
        .reduce(f32::min)
}

/// The side to follow: the nearer wall, keeping `previous` unless the other is nearer by 20 %.
pub fn choose_wall(scan: &SonarScan, s: &Settings, previous: Option<WallSide>) -> Option<WallSide> {
    if let Some(fixed) = s.side {
        return Some(fixed);
    }
    let l = wall_distance(scan, WallSide::Left, s.wall_range);
    let r = wall_distance(scan, WallSide::Right, s.wall_range);
    match (l, r, previous) {
        (None, None, _) => None,
        (Some(_), None, _) => Some(WallSide::Left),
        (None, Some(_), _) => Some(WallSide::Right),
        (Some(l), Some(r), Some(WallSide::Left)) => Some(if r < 0.8 * l { WallSide::Right } else { WallSide::Left }),
        (Some(l), Some(r), Some(WallSide::Right)) => Some(if l < 0.8 * r { WallSide::Left } else { WallSide::Right }),
        (Some(l), Some(r), None) => Some(if l <= r { WallSide::Left } else { WallSide::Right }),
    }
}

/// One cycle's command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Command {
    /// Forward speed, m/s.
    pub v: f32,
    /// Turn rate, rad/s.
    pub omega: f32,
    /// The wall followed.
    pub side: Option<WallSide>,
    /// The speed before scaling by the front clearance (the rising speed).
    pub rising: f32,
}

/// The command for `scan`, `dt` seconds after the last one whose rising speed was `rising`.
pub fn follow(scan: &SonarScan, s: &Settings, previous: Option<WallSide>, rising: f32, dt: f32) -> Command {
    let rising = (rising.max(s.v_min) + s.accel * dt.max(0.0)).min(s.v_max);
    let side = choose_wall(scan, s, previous);
    let mut omega = 0.0;
    if let Some(side) = side {
        let [d60, _, d120] = side.dirs();
        if let Some(d) = wall_distance(scan, side, s.wall_range) {
            omega += side.sign() * s.kp * (d - s.target);
        }
        if let (Some(a), Some(b)) = (range(scan, d60, s.wall_range), range(scan, d120, s.wall_range)) {
            omega += side.sign() * s.ka * (a - b);
        }
    }
    let front = [11usize, 0, 1].iter().filter_map(|&i| range(scan, i, f32::INFINITY)).fold(f32::INFINITY, f32::min);
    let mut scale = 1.0;
    if front < s.front_slow {
        let c = (1.0 - front / s.front_slow).clamp(0.0, 1.0);
        scale = 1.0 - c;
        // inside corner: turn away from the wall (or left when none is followed)
        let away = side.map_or(1.0, |w| -w.sign());
        omega += away * s.omega_max * c;
    }
    Command { v: rising * scale, omega: omega.clamp(-s.omega_max, s.omega_max), side, rising }
}

/// How the follower answers a revisit (the map builder's `revisit`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RevisitSettings {
    /// How long the other side is kept after a switch, s: long enough to
    /// leave the obstacle circled and find a wall on that side.
    pub hold_s: f32,
    /// A revisit sooner than this after the last switch is ignored, s.
    pub holdoff_s: f32,
    /// While the hold lasts, only a wall this near on the new side is followed, m.
    pub reach_m: f32,
}

impl Default for RevisitSettings {
    fn default() -> Self {
        RevisitSettings { hold_s: 20.0, holdoff_s: 40.0, reach_m: 1.2 }
    }
}

/// The settings of one cycle: `base`, or while a switch holds (`forced`),
/// the side switched to with a wall range of at most `r.reach_m`.
pub fn revisit_settings(base: &Settings, forced: Option<WallSide>, r: &RevisitSettings) -> Settings {
    match forced {
        Some(side) => Settings { side: Some(side), wall_range: base.wall_range.min(r.reach_m), ..*base },
        None => *base,
    }
}

/// What one revisit reading did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RevisitEvent {
    /// No rising edge (still in new space, still on the same visited stretch, or no reading).
    Nothing,
    /// Back at a place passed before: now following the other side.
    Switched {
        /// The side followed until now.
        from: WallSide,
        /// The side followed from now on.
        to: WallSide,
    },
    /// Back at a place passed before, but the last switch was only `since_s` ago.
    TooSoon {
        /// Seconds since the last switch.
        since_s: f32,
    },
    /// Back at a place passed before, but no wall was ever followed: nothing to switch.
    NoWall,
}

/// The side switch on revisits: an edge detector on the map builder's
/// `revisit`, a hold on the new side and a hold-off between switches.
/// Without readings (input not connected, or silent) it never switches.
#[derive(Debug, Clone, Default)]
pub struct SideSwitch {
    was: bool,
    last_side: Option<WallSide>,
    forced: Option<(WallSide, u64)>,
    last_switch_ns: Option<u64>,
    switches: u64,
}

impl WallSide {
    /// The other side.
    pub fn other(self) -> WallSide {
        match self {
            WallSide::Left => WallSide::Right,
            WallSide::Right => WallSide::Left,
        }
    }

    /// `"left"` or `"right"`.
    pub fn name(self) -> &'static str {
        match self {
            WallSide::Left => "left",
            WallSide::Right => "right",
        }
    }
}

impl SideSwitch {
    /// The wall followed this cycle (the last one followed is remembered).
    pub fn followed(&mut self, side: Option<WallSide>) {
        if side.is_some() {
            self.last_side = side;
        }
    }

    /// A reading of `revisit` at `now_ns`: `Some(true)` back at a place
    /// passed before, `Some(false)` in new space, `None` no fresh reading
    /// (the edge detector keeps its state). A rising edge switches sides.
    pub fn revisit(&mut self, back: Option<bool>, now_ns: u64, s: &RevisitSettings) -> RevisitEvent {
        let Some(back) = back else { return RevisitEvent::Nothing };
        let rising = back && !self.was;
        self.was = back;
        if !rising {
            return RevisitEvent::Nothing;
        }
        if let Some(t) = self.last_switch_ns {
            let since_s = now_ns.saturating_sub(t) as f32 / 1e9;
            if since_s < s.holdoff_s {
                return RevisitEvent::TooSoon { since_s };
            }
        }
        let Some(from) = self.last_side else { return RevisitEvent::NoWall };
        let to = from.other();
        let hold_ns = (f64::from(s.hold_s.max(0.0)) * 1e9) as u64;
        self.forced = Some((to, now_ns.saturating_add(hold_ns)));
        self.last_switch_ns = Some(now_ns);
        self.last_side = Some(to);
        self.switches = self.switches.saturating_add(1);
        RevisitEvent::Switched { from, to }
    }

    /// The side to keep at `now_ns`: the side switched to, while its hold lasts.
    pub fn forced(&self, now_ns: u64) -> Option<WallSide> {
        self.forced.filter(|(_, until)| now_ns < *until).map(|(side, _)| side)
    }

    /// Switches so far.
    pub fn switches(&self) -> u64 {
        self.switches
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan(pairs: &[(usize, f32)]) -> SonarScan {
        let mut s = SonarScan::default();
        for &(i, r) in pairs {
            s.ranges_m[i] = r;
            s.valid[i] = 1;
        }
        s
    }

    /// A straight wall on the left, parallel, at `d` metres.
    fn left_wall(d: f32) -> SonarScan {
        let k = 1.0 / 60f32.to_radians().sin();
        scan(&[(2, d * k), (3, d), (4, d * k)])
    }

    #[test]
    fn keeps_the_distance() {
        let s = Settings::default();
        let at = follow(&left_wall(0.6), &s, None, 0.2, 0.1);
        assert_eq!(at.side, Some(WallSide::Left));
        assert!(at.omega.abs() < 1e-4, "on target, parallel: {at:?}");
        assert!(follow(&left_wall(1.0), &s, None, 0.2, 0.1).omega > 0.0, "too far: toward the wall (left)");
        assert!(follow(&left_wall(0.3), &s, None, 0.2, 0.1).omega < 0.0, "too near: away");
        // mirrored for a right wall
        let k = 1.0 / 60f32.to_radians().sin();
        let right = scan(&[(10, 1.0 * k), (9, 1.0), (8, 1.0 * k)]);
        let c = follow(&right, &s, None, 0.2, 0.1);
        assert_eq!(c.side, Some(WallSide::Right));
        assert!(c.omega < 0.0, "too far from a right wall: turn right");
    }

    #[test]
    fn heading_away_turns_back() {
        let s = Settings::default();
        // at the right distance, but the wall opens ahead (r60 > r120)
        let sc = scan(&[(2, 0.9), (3, 0.6), (4, 0.6)]);
        assert!(follow(&sc, &s, None, 0.2, 0.1).omega > 0.0);
    }

    #[test]
    fn speed_rises_to_the_limit_and_slows_at_a_corner() {
        let s = Settings::default();
        let mut v = 0.0;
        for _ in 0..100 {
            v = follow(&left_wall(0.6), &s, None, v, 0.1).rising;
        }
        assert!((v - s.v_max).abs() < 1e-6);
        let mut corner = left_wall(0.6);
        corner.ranges_m[0] = 0.5;
        corner.valid[0] = 1;
        let c = follow(&corner, &s, Some(WallSide::Left), v, 0.1);
        assert!(c.v < v * 0.6, "slower: {c:?}");
        assert!(c.omega < 0.0, "turns away from the left wall: {c:?}");
        // nothing around: straight, rising from v_min
        let c = follow(&SonarScan::default(), &s, None, 0.0, 0.1);
        assert_eq!((c.side, c.omega), (None, 0.0));
        assert!((c.v - (s.v_min + s.accel * 0.1)).abs() < 1e-6);
    }

    #[test]
    fn side_choice_has_hysteresis() {
        let s = Settings::default();
        let sc = scan(&[(3, 0.9), (9, 0.8)]);
        assert_eq!(choose_wall(&sc, &s, None), Some(WallSide::Right));
        assert_eq!(choose_wall(&sc, &s, Some(WallSide::Left)), Some(WallSide::Left));
        let sc = scan(&[(3, 0.9), (9, 0.5)]);
        assert_eq!(choose_wall(&sc, &s, Some(WallSide::Left)), Some(WallSide::Right));
        let fixed = Settings { side: Some(WallSide::Left), ..s };
        assert_eq!(choose_wall(&sc, &fixed, None), Some(WallSide::Left));
    }

    const S: u64 = 1_000_000_000;

    #[test]
    fn unconnected_or_silent_revisit_never_switches() {
        let r = RevisitSettings::default();
        let mut sw = SideSwitch::default();
        sw.followed(Some(WallSide::Right));
        for t in 0..1000 {
            assert_eq!(sw.revisit(None, t * S, &r), RevisitEvent::Nothing);
            assert_eq!(sw.forced(t * S), None);
        }
        assert_eq!(sw.switches(), 0);
    }

    #[test]
    fn a_rising_edge_switches_to_the_other_side_for_the_hold() {
        let r = RevisitSettings { hold_s: 20.0, holdoff_s: 40.0, ..RevisitSettings::default() };
        let mut sw = SideSwitch::default();
        sw.followed(Some(WallSide::Right));
        sw.followed(None); // lost the wall for a cycle: the last one counts
        assert_eq!(sw.revisit(Some(false), 10 * S, &r), RevisitEvent::Nothing);
        assert_eq!(
            sw.revisit(Some(true), 50 * S, &r),
            RevisitEvent::Switched { from: WallSide::Right, to: WallSide::Left }
        );
        assert_eq!(sw.switches(), 1);
        // held, whatever else happens, for 20 s; no edge while it stays 1
        for t in 50..70 {
            assert_eq!(sw.revisit(Some(true), t * S, &r), RevisitEvent::Nothing);
            assert_eq!(sw.forced(t * S), Some(WallSide::Left), "at {t} s");
        }
        assert_eq!(sw.forced(70 * S), None, "the hold ends: the ordinary choice again");
        // silence keeps the edge detector's state: 1 -> silent -> 1 is no new edge
        assert_eq!(sw.revisit(None, 100 * S, &r), RevisitEvent::Nothing);
        assert_eq!(sw.revisit(Some(true), 101 * S, &r), RevisitEvent::Nothing);
        assert_eq!(sw.switches(), 1);
    }

    #[test]
    fn switches_have_a_hold_off_and_alternate() {
        let r = RevisitSettings { hold_s: 20.0, holdoff_s: 40.0, ..RevisitSettings::default() };
        let mut sw = SideSwitch::default();
        sw.followed(Some(WallSide::Left));
        assert!(matches!(sw.revisit(Some(true), 100 * S, &r), RevisitEvent::Switched { to: WallSide::Right, .. }));
        sw.followed(Some(WallSide::Right));
        // crossing visited space: 1, 0, 1 within the hold-off does not flip back
        assert_eq!(sw.revisit(Some(false), 110 * S, &r), RevisitEvent::Nothing);
        assert_eq!(sw.revisit(Some(true), 120 * S, &r), RevisitEvent::TooSoon { since_s: 20.0 });
        assert_eq!(sw.forced(119 * S), Some(WallSide::Right));
        assert_eq!(sw.switches(), 1);
        // a new edge after the hold-off switches back
        assert_eq!(sw.revisit(Some(false), 130 * S, &r), RevisitEvent::Nothing);
        assert_eq!(
            sw.revisit(Some(true), 141 * S, &r),
            RevisitEvent::Switched { from: WallSide::Right, to: WallSide::Left }
        );
        assert_eq!(sw.switches(), 2);
    }

    #[test]
    fn no_wall_followed_yet_is_nothing_to_switch() {
        let r = RevisitSettings::default();
        let mut sw = SideSwitch::default();
        assert_eq!(sw.revisit(Some(true), 5 * S, &r), RevisitEvent::NoWall);
        assert_eq!(sw.forced(5 * S), None);
        assert_eq!(sw.switches(), 0);
    }

    #[test]
    fn the_forced_side_leaves_an_island_on_the_other_side() {
        // an island 0.6 m on the right, nothing on the left: auto keeps to the
        // island; the side switched to (left, no wall) drives straight on
        let s = Settings::default();
        let k = 1.0 / 60f32.to_radians().sin();
        let island = scan(&[(10, 1.0 * k), (9, 1.0), (8, 0.6 * k)]);
        let auto = follow(&island, &s, Some(WallSide::Right), 0.5, 0.1);
        assert_eq!(auto.side, Some(WallSide::Right));
        assert!(auto.omega < -0.1, "auto turns back toward the island: {auto:?}");
        let r = RevisitSettings::default();
        let left = revisit_settings(&s, Some(WallSide::Left), &r);
        let away = follow(&island, &left, Some(WallSide::Right), 0.5, 0.1);
        assert_eq!((away.side, away.omega), (Some(WallSide::Left), 0.0), "straight on: {away:?}");
        assert_eq!(revisit_settings(&s, None, &r), s, "no switch: the settings unchanged");
    }

    #[test]
    fn while_held_a_far_wall_on_the_new_side_does_not_pull() {
        // along a wall on the right at 0.6 m, the island 1.9 m away on the
        // left (the side switched to): the robot goes straight on instead of
        // steering back across the room to the island
        let s = Settings::default();
        let k = 1.0 / 60f32.to_radians().sin();
        let sc = scan(&[(2, 1.9 * k), (3, 1.9), (4, 1.9 * k), (10, 0.6 * k), (9, 0.6), (8, 0.6 * k)]);
        let plain_left = Settings { side: Some(WallSide::Left), ..s };
        assert!(follow(&sc, &plain_left, None, 0.5, 0.1).omega > 0.5, "a plain left follower turns to the island");
        let held = revisit_settings(&s, Some(WallSide::Left), &RevisitSettings::default());
        let c = follow(&sc, &held, None, 0.5, 0.1);
        assert_eq!(c.omega, 0.0, "{c:?}");
        // a wall within reach on the new side is followed as usual
        let near = scan(&[(2, 1.0 * k), (3, 1.0), (4, 1.0 * k)]);
        assert!(follow(&near, &held, None, 0.5, 0.1).omega > 0.0);
    }
}
