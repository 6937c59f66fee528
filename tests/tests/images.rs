//! Short-term memory end to end: the camera agent (test pattern, simulator
//! ring, missing V4L2 device), the image agent, several readers of one ring,
//! and `nerve mem list` / `nerve mem dump` — real processes, real rings in
//! `/dev/shm`, and nothing left behind.
//!
//! Needs the binaries: `cargo build -p nerve -p nerve-camera -p nerve-image
//! -p nerve-tests --bins` into the same target directory as the tests.

use nerve_tests::{Robot, alive, wait_until};
use serde_json::Value;
use std::time::{Duration, Instant};

/// `nerve mem list --json`, as (ring name → entry).
fn rings(r: &Robot) -> Vec<Value> {
    match serde_json::from_str::<Value>(&r.ok(&["mem", "list", "--json"])) {
        Ok(Value::Array(v)) => v,
        other => panic!("mem list --json gave {other:?}"),
    }
}

fn ring(r: &Robot, name: &str) -> Option<Value> {
    rings(r).into_iter().find(|x| x["name"] == name)
}

fn last_seq(r: &Robot, name: &str) -> u64 {
    ring(r, name).and_then(|x| x["last_seq"].as_u64()).unwrap_or(0)
}

/// Waits until ring `name` holds at least `n` frames.
fn wait_frames(r: &Robot, name: &str, n: u64) {
    assert!(
        wait_until(Duration::from_secs(10), || last_seq(r, name) >= n),
        "ring {name} did not reach {n} frames; rings: {:#?}\nlogs:\n{}",
        rings(r),
        logs(r)
    );
}

/// Every agent log of the robot, for failure messages.
fn logs(r: &Robot) -> String {
    let dir = r.home.join(&r.name).join("logs");
    let mut out = String::new();
    for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        out += &format!("--- {}\n{}\n", e.path().display(), std::fs::read_to_string(e.path()).unwrap_or_default());
    }
    out
}

fn log_of(r: &Robot, agent: &str) -> String {
    std::fs::read_to_string(r.home.join(&r.name).join("logs").join(format!("{agent}.log"))).unwrap_or_default()
}

/// Decodes a PNG: (width, height, colour type, pixels).
fn read_png(path: &std::path::Path) -> (u32, u32, png::ColorType, Vec<u8>) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("open {}: {e}", path.display()));
    let mut reader = png::Decoder::new(std::io::BufReader::new(file)).read_info().expect("png header");
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("png frame");
    buf.truncate(info.buffer_size());
    (info.width, info.height, info.color_type, buf)
}

fn camera(r: &Robot, name: &str, extra: &[&str]) {
    let mut args = vec!["start", "camera", "--name", name, "--", "--source", "test-pattern"];
    args.extend_from_slice(extra);
    r.ok(&args);
}

/// camera (test pattern) → image agent: the HSI and red-mask rings fill, the
/// mask holds the red disc and nothing else, `nerve mem list` shows the rings
/// advancing, and `nerve down` removes the ring files.
#[test]
fn camera_to_image_fills_red_mask() {
    let r = Robot::new("mask");
    r.router();
    camera(&r, "cam", &[]);
    r.ok(&["start", "image", "--name", "img"]);
    r.ok(&["connect", "cam/frames", "img/frames"]);
    wait_frames(&r, "red", 5);

    // list: every ring with its geometry, advancing sequence numbers and a rate
    let before: Vec<(String, u64)> = rings(&r)
        .iter()
        .map(|x| (x["name"].as_str().unwrap_or("?").to_owned(), x["last_seq"].as_u64().unwrap_or(0)))
        .collect();
    for n in ["cam", "hsi", "red"] {
        assert!(before.iter().any(|(name, _)| name == n), "ring {n} missing: {before:?}");
    }
    std::thread::sleep(Duration::from_millis(600));
    let cam = ring(&r, "cam").expect("cam ring");
    assert!(cam["last_seq"].as_u64() > before.iter().find(|(n, _)| n == "cam").map(|(_, s)| *s), "{cam}");
    assert!(last_seq(&r, "red") > before.iter().find(|(n, _)| n == "red").map_or(0, |(_, s)| *s));
    assert_eq!(
        (cam["width"].as_u64(), cam["height"].as_u64(), cam["format"].as_str()),
        (Some(320), Some(240), Some("rgb8"))
    );
    assert_eq!(cam["slot_capacity"].as_u64(), Some(320 * 240 * 3));
    let rate = cam["rate_hz"].as_f64().unwrap_or(0.0);
    assert!((10.0..=20.0).contains(&rate), "camera at 15 fps, ring says {rate}");
    assert_eq!(cam["writer_alive"], true);
    let red = ring(&r, "red").expect("red ring");
    assert_eq!((red["format"].as_str(), red["width"].as_u64()), (Some("gray8"), Some(320)));
    assert_eq!(ring(&r, "hsi").expect("hsi")["format"].as_str(), Some("hsi8"));
    let table = r.ok(&["mem", "list"]);
    assert!(table.contains("RING") && table.contains("cam") && table.contains("320x240 rgb8"), "{table}");

    // the mask: a disc of radius 30 (area ~2830 px), everything else black
    let out = r.home.join("red.png");
    r.ok(&["mem", "dump", "red", "--out", out.to_str().expect("utf-8 path")]);
    let (w, h, color, px) = read_png(&out);
    assert_eq!((w, h, color), (320, 240, png::ColorType::Grayscale));
    assert!(px.iter().all(|&p| p == 0 || p == 255), "a mask is 0 or 255");
    let on = px.iter().filter(|&&p| p == 255).count() as f64;
    let area = std::f64::consts::PI * 30.0 * 30.0;
    assert!((on - area).abs() < area * 0.15, "red pixels {on}, disc area {area}");

    // the HSI ring dumps as a picture again (converted back to RGB)
    let out = r.home.join("hsi.png");
    r.ok(&["mem", "dump", "hsi", "--out", out.to_str().expect("utf-8 path")]);
    let (w, h, color, px) = read_png(&out);
    assert_eq!((w, h, color), (320, 240, png::ColorType::Rgb));
    assert!(px.chunks_exact(3).any(|p| p[0] > 180 && p[1] < 70 && p[2] < 70), "the red disc survives HSI and back");

    // the blob area is published too
    let area_samples = r.echo("img/red_area", 2);
    let a = area_samples[0]["data"]["value"].as_f64().unwrap_or(0.0);
    assert!((a - area).abs() < area * 0.15, "red_area {a}: {area_samples:?}");

    let ring_files: Vec<String> = r.shm_files().into_iter().filter(|f| f.contains("_stm_")).collect();
    assert_eq!(ring_files.len(), 3, "{ring_files:?}");
    r.down_and_check_clean();
}

/// `nerve mem dump cam` writes a PNG of the camera's size; --seq and --at
/// pick frames; bad requests fail with a reason.
#[test]
fn mem_dump_writes_png_of_frame_size() {
    let r = Robot::new("dump");
    r.router();
    camera(&r, "cam", &["--width", "160", "--height", "120", "--fps", "25"]);
    wait_frames(&r, "cam", 4);
    let out = r.home.join("cam.png");
    let path = out.to_str().expect("utf-8 path");
    let said = r.ok(&["mem", "dump", "cam", "--out", path]);
    assert!(said.contains("160x120 rgb8"), "{said}");
    let (w, h, color, px) = read_png(&out);
    assert_eq!((w, h, color), (160, 120, png::ColorType::Rgb));
    assert!(px.chunks_exact(3).any(|p| p == [220, 30, 35]), "the red disc is in the picture");
    assert!(px.chunks_exact(3).filter(|p| *p != [220, 30, 35]).count() > 10_000, "and a background");

    // a given frame, and the frame nearest to a time
    let seq = last_seq(&r, "cam");
    let said = r.ok(&["mem", "dump", "cam", "--seq", &seq.to_string(), "--out", path]);
    assert!(said.contains(&format!("frame {seq} ")), "{said}");
    let said = r.ok(&["mem", "dump", "cam", "--at", "-100ms", "--out", path]);
    assert!(said.contains("frame "), "{said}");
    let stamp = ring(&r, "cam").and_then(|x| x["last_stamp_ns"].as_u64()).expect("stamp");
    let said = r.ok(&["mem", "dump", "cam", "--at", &stamp.to_string(), "--out", path]);
    assert!(said.contains("160x120"), "{said}");

    // refusals say why (frame 1 is gone once the 8 slots have been reused)
    wait_frames(&r, "cam", 12);
    let e = r.fails(&["mem", "dump", "cam", "--seq", "1", "--out", path]);
    assert!(e.contains("overwritten"), "{e}");
    let e = r.fails(&["mem", "dump", "nosuch", "--out", path]);
    assert!(e.contains("nosuch") && e.contains("does not exist"), "{e}");
    let e = r.fails(&["mem", "dump", "Bad-Name", "--out", path]);
    assert!(e.contains("ring"), "{e}");
    r.down_and_check_clean();
}

/// Two image agents read one camera ring; both get every recent frame, and
/// a third one on the same output rings is refused at start with a reason.
#[test]
fn several_readers_share_one_camera_ring() {
    let r = Robot::new("readers");
    r.router();
    camera(&r, "cam", &[]);
    r.ok(&["start", "image", "--name", "img1"]);
    r.ok(&["start", "image", "--name", "img2", "--", "--hsi-ring", "hsi2", "--red-ring", "red2"]);
    r.ok(&["connect", "cam/frames", "img1/frames"]);
    r.ok(&["connect", "cam/frames", "img2/frames"]);
    wait_frames(&r, "red", 10);
    wait_frames(&r, "red2", 10);
    // both keep up with the camera (15 fps): over a second, both rings advance alike
    let (a0, b0, c0) = (last_seq(&r, "red"), last_seq(&r, "red2"), last_seq(&r, "cam"));
    std::thread::sleep(Duration::from_millis(1500));
    let (a, b, c) = (last_seq(&r, "red") - a0, last_seq(&r, "red2") - b0, last_seq(&r, "cam") - c0);
    assert!(c >= 15, "camera stored {c} frames in 1.5 s");
    assert!(a + 3 >= c && b + 3 >= c, "readers processed {a} and {b} of {c} frames");
    // the camera's statistics do not depend on its readers: one write per frame
    let cam = r.agent("cam").expect("cam in ps");
    assert_eq!(cam["stats"]["overruns"].as_u64(), Some(0), "{cam}");

    // one writer per ring: a third image agent with the default rings is refused
    let out = r.nerve(&["start", "image", "--name", "img3"]);
    assert!(!out.status.success(), "img3 should be refused");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("hsi") && err.contains("already written") && err.contains("pid"), "{err}");
    r.down_and_check_clean();
}

/// A camera that is not there is reported with its path and what to do, the
/// agent keeps running and retries with backoff, without spinning.
#[test]
fn missing_camera_is_reported_and_retried_without_spinning() {
    let r = Robot::new("nocam");
    r.router();
    // the start itself succeeds: devices are opened in the task, and retried
    r.ok(&["start", "camera", "--name", "cam", "--", "--source", "v4l", "--device", "/dev/video9"]);
    let pid = r.pid("cam");
    let t0 = Instant::now();
    assert!(
        wait_until(Duration::from_secs(5), || log_of(&r, "cam").contains("/dev/video9")),
        "log: {}",
        log_of(&r, "cam")
    );
    std::thread::sleep(Duration::from_millis(3200).saturating_sub(t0.elapsed()));
    let log = log_of(&r, "cam");
    let first = log.lines().find(|l| l.contains("/dev/video9")).expect("a line naming the device");
    assert!(first.contains("no camera at /dev/video9") && first.contains("--source test-pattern"), "{first}");
    assert!(first.contains("retrying in"), "{first}");
    // backoff 0.5, 1, 2 s: at most 4 attempts in ~3 s, not hundreds
    let attempts = log.lines().filter(|l| l.contains("retrying in")).count();
    assert!((2..=5).contains(&attempts), "{attempts} attempts in 3 s:\n{log}");
    assert!(alive(pid), "the camera agent keeps running");
    let a = r.agent("cam").expect("cam in ps");
    let cpu = a["stats"]["cpu_percent"].as_f64().expect("cpu_percent");
    assert!(cpu < 5.0, "waiting for a camera costs {cpu}% CPU: {a}");
    // the ring exists (readers can map it), empty
    assert_eq!(ring(&r, "cam").and_then(|x| x["last_seq"].as_u64()), Some(0));
    r.down_and_check_clean();
}

/// `--source sim` forwards the frames the simulator writes into its ring
/// (here a second camera writes ring `simcam`, standing in for the
/// simulator), and says clearly when there is no such ring.
#[test]
fn sim_source_forwards_the_simulator_ring() {
    let r = Robot::new("simsrc");
    r.router();
    r.ok(&["start", "camera", "--name", "cam", "--", "--source", "sim"]);
    assert!(
        wait_until(Duration::from_secs(5), || log_of(&r, "cam").contains("ring simcam")),
        "log: {}",
        log_of(&r, "cam")
    );
    let log = log_of(&r, "cam");
    assert!(log.contains("no simulator camera") && log.contains("--sim-ring"), "{log}");
    assert_eq!(last_seq(&r, "cam"), 0);

    // a "simulator" appears: the camera picks it up at its next attempt (backoff <= 8 s)
    camera(&r, "simulator", &["--ring", "simcam"]);
    assert!(
        wait_until(Duration::from_secs(15), || last_seq(&r, "cam") >= 5),
        "cam ring: {:?}\n{}",
        ring(&r, "cam"),
        logs(&r)
    );
    let cam = ring(&r, "cam").expect("cam");
    assert_eq!((cam["width"].as_u64(), cam["format"].as_str()), (Some(320), Some("rgb8")));
    // forwarded frames keep the simulator's stamps and pixels
    let out = r.home.join("fwd.png");
    r.ok(&["mem", "dump", "cam", "--out", out.to_str().expect("utf-8 path")]);
    let (w, h, _, px) = read_png(&out);
    assert_eq!((w, h), (320, 240));
    assert!(px.chunks_exact(3).any(|p| p == [220, 30, 35]));
    r.down_and_check_clean();
}

/// `--describe` runs `Agent::new` in a throw-away world: no device is
/// opened and no ring file is left behind.
#[test]
fn describe_opens_nothing() {
    let r = Robot::new("descr");
    for (exe, args) in [
        ("nerve-camera", vec!["--describe", "--", "--source", "v4l", "--device", "/dev/video9"]),
        ("nerve-image", vec!["--describe"]),
    ] {
        let out = r.command(exe).args(&args).output().expect("run");
        assert!(out.status.success(), "{exe}: {}", String::from_utf8_lossy(&out.stderr));
        let d: Value = serde_json::from_slice(&out.stdout).expect("describe json");
        let outputs = d["outputs"].to_string();
        assert!(outputs.contains("nerve::RingNotice"), "{d}");
    }
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("nerve_describe-") && n.contains("_stm_"))
        .collect();
    assert!(left.is_empty(), "describe left rings: {left:?}");
}
