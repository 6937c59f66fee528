//! Sonar ranges against known geometry, specular errors, IR sightings.

mod common;

use common::{h1, room};
use nerve_devices::{IrSighting, SONAR_NO_ECHO};
use nerve_sim::{NoiseModel, RobotModel, SimConfig, Simulation};

/// Analytic range of sonar `i` in an axis-aligned square room of side `s`
/// for a robot at (x, y) heading 0: nearest wall over the beam's five rays.
fn expected_mm(i: usize, s: f64, x: f64, y: f64) -> f64 {
    let spec = RobotModel::h1().sonar.expect("H1 has sonar");
    let a = spec.angles[i];
    let (ox, oy) = (x + 0.25 * a.cos(), y + 0.25 * a.sin());
    (-2..=2)
        .map(|k| {
            let t = a + f64::from(k) * spec.half_beam / 2.0;
            let (dx, dy) = (t.cos(), t.sin());
            let tx = if dx > 1e-12 {
                (s - ox) / dx
            } else if dx < -1e-12 {
                -ox / dx
            } else {
                f64::INFINITY
            };
            let ty = if dy > 1e-12 {
                (s - oy) / dy
            } else if dy < -1e-12 {
                -oy / dy
            } else {
                f64::INFINITY
            };
            tx.min(ty)
        })
        .fold(f64::INFINITY, f64::min)
        * 1000.0
}

#[test]
fn sonar_matches_room_geometry_without_noise() {
    let mut sim = h1(room(4.0, 1.5, 2.2, 0.0, ""), 1, NoiseModel::none());
    let scan = sim.sonar_scan();
    for (i, r) in scan.iter().enumerate() {
        let want = expected_mm(i, 4.0, 1.5, 2.2);
        assert!((f64::from(*r) - want).abs() <= 1.0, "sonar {i}: {r} mm, expected {want:.0}");
    }
    assert_eq!(scan[0], 2250); // 4 - 1.5 - 0.25
    assert_eq!(scan[6], 1250); // 1.5 - 0.25
}

#[test]
fn sonar_with_noise_is_close_most_of_the_time() {
    // robot square in the middle: every beam meets a wall within 40°, so
    // specular errors stay rare; readings are within noise of the geometry
    let mut sim = h1(room(4.0, 2.0, 2.0, 0.0, ""), 11, NoiseModel::default());
    let mut good = 0;
    let mut total = 0;
    for _ in 0..50 {
        for (i, r) in sim.sonar_scan().iter().enumerate() {
            let want = expected_mm(i, 4.0, 2.0, 2.0);
            total += 1;
            if r != &SONAR_NO_ECHO && (f64::from(*r) - want).abs() < 0.05 * want + 30.0 {
                good += 1;
            }
        }
    }
    assert!(good as f64 > 0.9 * total as f64, "{good}/{total} within noise");
}

#[test]
fn grazing_beams_give_occasional_wrong_readings() {
    // long corridor, 1.2 m wide: the 30° sonars meet the side walls at 60°
    let text = "[robot]\nx = 2.0\ny = 0.6\n\
                [[wall]]\nfrom = [0.0, 0.0]\nto = [40.0, 0.0]\n\
                [[wall]]\nfrom = [0.0, 1.2]\nto = [40.0, 1.2]\n";
    let world = nerve_sim::World::from_toml_str(text, std::path::Path::new("corridor.toml")).expect("valid");
    let mut sim = h1(world, 5, NoiseModel::default());
    let truth = sim.sonar_true_ranges()[1].expect("sonar 1 sees the wall");
    let n = 400;
    let wrong = (0..n)
        .filter(|_| {
            let r = sim.sonar_scan()[1];
            r == SONAR_NO_ECHO || (f64::from(r) / 1000.0 - truth).abs() > 0.25 * truth
        })
        .count();
    assert!(wrong > n / 20 && wrong < n / 2, "{wrong}/{n} wrong readings");
}

#[test]
fn h2_has_no_sonar() {
    let sim = Simulation::new(
        room(4.0, 2.0, 2.0, 0.0, ""),
        RobotModel::h2(),
        SimConfig::new(1).with_noise(NoiseModel::none()),
    );
    let mut sim = sim.expect("valid");
    assert_eq!(sim.sonar_scan(), [SONAR_NO_ECHO; 12]);
    assert!(sim.sonar_true_ranges().is_empty());
}

fn ir_at(x: f64, y: f64, extra: &str) -> Option<IrSighting> {
    let cp = "[[checkpoint]]\nid = 3\nposition = [5.0, 5.0]\nheading_deg = 0.0\n";
    let sim = h1(room(10.0, x, y, 0.0, &format!("{cp}{extra}")), 1, NoiseModel::none());
    sim.ir_true_sighting()
}

#[test]
fn ir_is_seen_within_two_metres_only() {
    // east of the checkpoint: transmitter 0 faces the robot
    assert_eq!(ir_at(6.5, 5.0, ""), Some(IrSighting { checkpoint_id: 3, transmitters: 0b0001 }));
    // north: transmitter 1
    assert_eq!(ir_at(5.0, 6.9, ""), Some(IrSighting { checkpoint_id: 3, transmitters: 0b0010 }));
    // on the diagonal between 0 and 1 both are received
    let d = 1.5 / 2f64.sqrt();
    assert_eq!(ir_at(5.0 + d, 5.0 + d, ""), Some(IrSighting { checkpoint_id: 3, transmitters: 0b0011 }));
    // west and south
    assert_eq!(ir_at(3.5, 5.0, "").map(|s| s.transmitters), Some(0b0100));
    assert_eq!(ir_at(5.0, 3.5, "").map(|s| s.transmitters), Some(0b1000));
    // beyond 2 m: nothing
    assert_eq!(ir_at(7.1, 5.0, ""), None);
    assert_eq!(ir_at(5.0, 2.5, ""), None);
    // a wall in between blocks the light
    assert_eq!(ir_at(6.5, 5.0, "[[wall]]\nfrom = [5.8, 4.0]\nto = [5.8, 6.0]\n"), None);
}

#[test]
fn ir_dropouts_are_occasional() {
    let cp = "[[checkpoint]]\nid = 3\nposition = [5.0, 5.0]\n";
    let mut sim = h1(room(10.0, 6.0, 5.0, 0.0, cp), 2, NoiseModel::default());
    let seen = (0..500).filter(|_| sim.ir_sighting().is_some()).count();
    assert!(seen > 450 && seen < 500, "{seen}/500 seen");
}

#[test]
fn a_thin_pole_between_two_rays_of_a_beam_echoes() {
    // a checkpoint tube (radius 5 cm, on a stand as wide) 1.5 m ahead and
    // 8.5° to the left of sonar 0's axis: between its rays at 6.25° and
    // 12.5°, 1.5 m away the rays are 16 cm apart; the cone holds it
    let (x, y) = (1.0, 2.0);
    let a = 8.5f64.to_radians();
    let (px, py) = (x + 0.25 + 1.5 * a.cos(), y + 1.5 * a.sin());
    let pole = format!("[[checkpoint]]\nid = 1\nposition = [{px}, {py}]\n");
    let mut sim = h1(room(6.0, x, y, 0.0, &pole), 1, NoiseModel::none());
    let r = sim.sonar_true_ranges()[0].expect("an echo");
    assert!((r - 1.45).abs() < 0.01, "the pole's near side, 1.45 m: {r}");
    let scan = sim.sonar_scan();
    assert!((f64::from(scan[0]) - 1450.0).abs() <= 10.0, "{}", scan[0]);
    // 30° off the axis it is outside the cone: the wall behind is seen
    let b = 30f64.to_radians();
    let pole = format!("[[checkpoint]]\nid = 1\nposition = [{}, {}]\n", x + 1.5 * b.cos(), y + 1.5 * b.sin());
    let sim = h1(room(6.0, x, y, 0.0, &pole), 1, NoiseModel::none());
    assert!(sim.sonar_true_ranges()[0].expect("the wall") > 4.0);
}

/// The ring's blind spots, which the safety monitor must live with
/// (agents/safety, "release after clear scans in a row"): twelve beams of
/// ±12.5° every 30° leave gaps, and near the rim, where the transducers sit
/// 13 cm apart, the gaps are wide. A tube (radius 5 cm) whose centre is
/// 0.31-0.40 m from the robot's centre (within 0.15 m of the rim) at ±15° or
/// ±45° echoes in no front beam; at 0°, ±30° and ±60° it does, and at 0.5 m
/// only the gaps' middle (±15°, ±45°) stays blind. Should the beams change,
/// this says what the safety monitor was tuned against.
#[test]
fn a_tube_close_to_the_rim_between_two_beams_echoes_in_none() {
    let (x, y) = (3.0, 3.0);
    let seen = |d: f64, bearing_deg: f64| {
        let b = bearing_deg.to_radians();
        let tube = format!("[[checkpoint]]\nid = 1\nposition = [{}, {}]\n", x + d * b.cos(), y + d * b.sin());
        let sim = h1(room(6.0, x, y, 0.0, &tube), 1, NoiseModel::none());
        let r = sim.sonar_true_ranges();
        // the front sector and the flanks (the safety monitor's front clearance)
        [10usize, 11, 0, 1, 2].iter().any(|&i| r[i].is_some_and(|m| m < d))
    };
    for d in [0.31, 0.35, 0.40] {
        for b in [-45.0, -15.0, 15.0, 45.0] {
            assert!(!seen(d, b), "a tube {d} m away at {b}° was seen: the ring has no blind spot there any more");
        }
        for b in [-60.0, -30.0, 0.0, 30.0, 60.0] {
            assert!(seen(d, b), "a tube {d} m away at {b}° was not seen");
        }
    }
    for b in [-48.0, -42.0, -18.0, -12.0, 12.0, 18.0, 42.0, 48.0] {
        assert!(seen(0.5, b), "a tube 0.5 m away at {b}° was not seen");
    }
}
