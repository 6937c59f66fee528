//! `nerve record` and `nerve replay`, end to end: a robot with a built-in
//! type and a type nerve was not built with (`acme::Gripper`) is recorded to
//! MCAP; the file is read by the `mcap` package from PyPI (a reader nobody
//! here wrote, installed by this test into a virtual environment) and its
//! channels, schemas, message count and decoded contents are checked; then
//! the recording is exported as JSON for viewers and read back the same; then
//! the recording is replayed into the robot under the recorded agent's name
//! and recorded again: every sample comes back bit-exact and in order, with
//! the recorded spacing.
//!
//! A recording cut short (`kill -9` of the recorder, a full disk) is read up
//! to its last good record by replay, export and the PyPI reader, each
//! checked against a recording of the same ports that finished; a large
//! file is replayed in the memory of one message.

use nerve_tests::py::{messages, python_with_mcap, read_mcap, run_reader};
use nerve_tests::{Robot, wait_until};
use serde_json::Value;
use std::path::Path;
use std::time::Duration;

/// What `tests/py/read_mcap.py` finds in `file`.
fn read_with_python(file: &Path) -> Value {
    read_mcap(file)
}

/// What `tests/py/read_images.py` finds in `file`: every foxglove.RawImage,
/// decoded through the descriptor set in the file, with a count of the
/// pixels of `colour` in each.
fn images_with_python(file: &Path, colour: [u8; 3]) -> Value {
    run_reader("read_images.py", file, &[&format!("{},{},{}", colour[0], colour[1], colour[2])])
}

/// Equal JSON values, floats within a part in a million (f32 printed by
/// two decoders may differ in their last digits).
fn same(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) if x.is_f64() || y.is_f64() => {
            let (x, y) = (x.as_f64().unwrap_or(f64::NAN), y.as_f64().unwrap_or(f64::NAN));
            (x - y).abs() <= 1e-6 * x.abs().max(y.abs()).max(1.0)
        }
        (Value::Array(x), Value::Array(y)) => x.len() == y.len() && x.iter().zip(y).all(|(x, y)| same(x, y)),
        (Value::Object(x), Value::Object(y)) => {
            x.len() == y.len() && x.iter().all(|(k, v)| y.get(k).is_some_and(|w| same(v, w)))
        }
        _ => a == b,
    }
}

/// Log-time gaps between consecutive messages, ms.
fn gaps_ms(msgs: &[Value]) -> Vec<f64> {
    msgs.windows(2)
        .map(|w| (w[1]["log_time"].as_u64().unwrap_or(0) as f64 - w[0]["log_time"].as_u64().unwrap_or(0) as f64) / 1e6)
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

#[test]
fn a_recording_reads_in_an_independent_reader_and_replays_bit_exact() {
    let r = Robot::new("rec");
    r.router();
    r.ok(&["start", "gripper", "--name", "g"]);
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    let fp = r.agent("g").expect("g")["outputs"][0]["fingerprint"].as_u64().expect("fingerprint");
    let file = r.home.join("run.mcap");
    let file_s = file.display().to_string();
    let out = r.ok(&["record", "--all", "-o", &file_s, "--duration", "2", "-q"]);
    let total: u64 = out
        .split_whitespace()
        .zip(out.split_whitespace().skip(1))
        .find(|(_, w)| *w == "messages,")
        .and_then(|(n, _)| n.parse().ok())
        .unwrap_or_else(|| panic!("no message count in {out:?}"));
    assert!(out.contains(", 0 dropped"), "{out}");

    // the independent reader: channels, schemas, count, contents
    let got = read_with_python(&file);
    assert_eq!(got["message_count"].as_u64(), Some(total), "{out}");
    assert_eq!(got["channel_count"], 2);
    let g = &got["channels"]["g/state"];
    assert_eq!(g["message_encoding"], "nerve.raw");
    assert_eq!(g["schema_name"], "acme::Gripper");
    assert_eq!(g["schema_encoding"], "nerve.schema+json");
    assert_eq!(g["metadata"]["fingerprint"], format!("{fp:#018x}"));
    assert_eq!(g["metadata"]["agent"], "g");
    assert_eq!(got["channels"]["t1/tick"]["schema_name"], "nerve::Tick");
    let recorded = messages(&got, "g/state");
    assert!(recorded.len() >= 50, "2 s of a 20 ms agent: {}", recorded.len());
    for w in recorded.windows(2) {
        // in order, none lost: the agent counts each sample
        assert_eq!(w[1]["data"]["count"].as_u64(), w[0]["data"]["count"].as_u64().map(|c| c + 1));
        assert_eq!(w[1]["sequence"].as_u64(), w[0]["sequence"].as_u64().map(|s| s + 1));
    }
    assert_eq!(recorded[0]["data"]["tool"], "screwdriver");
    assert_eq!(recorded[0]["data"]["fingers"].as_array().map(Vec::len), Some(3));
    let ticks = messages(&got, "t1/tick");
    assert!(ticks.windows(2).all(|w| w[1]["data"]["seq"].as_u64() > w[0]["data"]["seq"].as_u64()));

    // exported for JSON viewers: the same samples, as the independent decoder read them
    let json_file = r.home.join("run-json.mcap");
    let said = r.ok(&["export", &file_s, "-o", &json_file.display().to_string()]);
    assert!(said.contains(&format!("{total} messages as JSON")), "{said}");
    let exported = read_with_python(&json_file);
    let g = &exported["channels"]["g/state"];
    assert_eq!(g["message_encoding"], "json");
    assert_eq!(g["schema_encoding"], "jsonschema");
    assert_eq!(g["json_schema"]["properties"]["fingers"]["items"]["properties"]["contact"]["type"], "boolean");
    assert_eq!(g["metadata"]["fingerprint"], format!("{fp:#018x}"));
    for topic in ["g/state", "t1/tick"] {
        let (raw, js) = (messages(&got, topic), messages(&exported, topic));
        assert_eq!(raw.len(), js.len(), "{topic}: every message");
        for (a, b) in raw.iter().zip(js) {
            assert!(same(&a["data"], &b["data"]), "{topic}: {} exported as {}", a["data"], b["data"]);
            assert_eq!((&a["sequence"], &a["log_time"]), (&b["sequence"], &b["log_time"]));
        }
    }

    // the replay, recorded again
    r.ok(&["stop", "g"]);
    assert!(wait_until(Duration::from_secs(5), || r.agent("g").is_none()), "g did not stop");
    let again = r.home.join("again.mcap");
    let again_s = again.display().to_string();
    let mut recorder = r
        .command("nerve")
        .args(["record", "--all", "-o", &again_s, "--duration", "7", "-q"])
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("recorder");
    std::thread::sleep(Duration::from_millis(300));
    let mut replay =
        r.command("nerve").args(["replay", &file_s, "--as", "g", "--delay", "2.5", "-q"]).spawn().expect("replay");
    // the replayed agent is in the robot under its recorded name
    assert!(
        wait_until(Duration::from_secs(5), || r.agent("g").is_some_and(|a| a["kind"] == "replay")),
        "ps does not list the replayed agent: {:?}",
        r.ps()
    );
    let e = r.fails(&["start", "gripper", "--name", "g"]);
    assert!(e.contains("g"), "a second g while the replay runs: {e}");
    assert!(replay.wait().expect("replay").success(), "the replay failed");
    assert!(recorder.wait().expect("recorder").success(), "the second recording failed");
    assert!(wait_until(Duration::from_secs(5), || r.agent("g").is_none()), "the replayed agent stayed registered");

    let back = read_with_python(&again);
    let replayed = messages(&back, "g/state");
    assert_eq!(replayed.len(), recorded.len(), "every sample, once");
    for (i, (a, b)) in recorded.iter().zip(replayed).enumerate() {
        assert_eq!(a["hex"], b["hex"], "sample {i} differs");
    }
    // the recorded spacing (20 ms), within what a loaded machine keeps
    let (orig, rep) = (gaps_ms(recorded), gaps_ms(replayed));
    let deviation = median(orig.iter().zip(&rep).map(|(a, b)| (a - b).abs()).collect());
    assert!(deviation < 5.0, "median spacing deviation {deviation:.2} ms: {orig:?} vs {rep:?}");
    let (span_o, span_r): (f64, f64) = (orig.iter().sum(), rep.iter().sum());
    assert!((span_r - span_o).abs() < 0.2 * span_o, "span {span_r:.0} ms vs recorded {span_o:.0} ms");
    r.down_and_check_clean();
}

/// A camera's ring notices are recorded with the frames they name, as
/// `foxglove.RawImage` on `cam/frames/image`, and the file decodes in
/// Google's protobuf through the schema it carries: the test pattern's
/// size, encoding and red disc are in every frame. A replay of the file
/// replays the notices and leaves the images aside.
#[test]
fn ring_frames_are_recorded_as_foxglove_images() {
    let r = Robot::new("recimg");
    r.router();
    r.ok(&[
        "start",
        "camera",
        "--name",
        "cam",
        "--",
        "--source",
        "test-pattern",
        "--width",
        "160",
        "--height",
        "120",
        "--fps",
        "25",
    ]);
    assert!(wait_until(Duration::from_secs(10), || r.agent("cam").is_some()), "camera did not start");
    let file = r.home.join("cam.mcap");
    let file_s = file.display().to_string();
    let out = r.ok(&["record", "cam/frames", "-o", &file_s, "--duration", "2", "-q"]);
    assert!(out.contains("cam/frames/image") && out.contains("foxglove.RawImage"), "{out}");
    let notices = messages(&read_with_python(&file), "cam/frames").len();
    assert!(notices >= 25, "2 s at 25 fps: {notices} notices\n{out}");

    let got = images_with_python(&file, [220, 30, 35]);
    let ch = &got["channels"]["cam/frames/image"];
    assert_eq!(ch["schema_name"], "foxglove.RawImage");
    assert_eq!(ch["schema_encoding"], "protobuf");
    assert_eq!(ch["metadata"]["agent"], "cam");
    let frames = ch["frames"].as_array().expect("frames");
    // every notice's frame, unless the camera overwrote it first (counted)
    let dropped = out
        .lines()
        .find(|l| l.contains("cam/frames/image"))
        .and_then(|l| {
            l.split(", ")
                .find_map(|p| p.strip_suffix(" dropped (overwritten in the ring before the recorder read them)"))
        })
        .map_or(0, |n| n.trim().parse::<usize>().unwrap_or(0));
    assert_eq!(frames.len() + dropped, notices, "{out}");
    assert!(frames.len() >= notices * 9 / 10, "{} of {notices} frames\n{out}", frames.len());
    for f in frames {
        assert_eq!((f["width"].as_u64(), f["height"].as_u64()), (Some(160), Some(120)), "{f}");
        assert_eq!(f["encoding"], "rgb8");
        assert_eq!(f["step"].as_u64(), Some(160 * 3));
        assert_eq!(f["len"].as_u64(), Some(160 * 120 * 3));
        assert_eq!(f["frame_id"], "cam/cam");
        assert!(f["colour"].as_u64().unwrap_or(0) > 100, "the red disc: {f}");
        assert!(f["sec"].as_u64().unwrap_or(0) > 1_700_000_000, "a wall-clock stamp: {f}");
    }
    let seqs: Vec<u64> = frames.iter().filter_map(|f| f["sequence"].as_u64()).collect();
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "frames in order: {seqs:?}");

    // a replay takes the notices and leaves the images
    r.ok(&["stop", "cam"]);
    assert!(wait_until(Duration::from_secs(5), || r.agent("cam").is_none()), "cam did not stop");
    let said = r.ok(&["replay", &file_s, "--fast", "-q"]);
    assert!(said.contains("cam"), "{said}");
    r.down_and_check_clean();
}

/// `nerve record --all` follows the robot: an agent started while it
/// records joins the file, from soon after it registered.
#[test]
fn record_all_follows_agents_started_while_it_records() {
    let r = Robot::new("recall");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    let file = r.home.join("all.mcap");
    let recorder = r
        .command("nerve")
        .args(["record", "--all", "-o", &file.display().to_string(), "--duration", "4", "-q"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("recorder");
    std::thread::sleep(Duration::from_millis(1500));
    let started = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64);
    r.ok(&["start", "gripper", "--name", "g"]);
    let out = recorder.wait_with_output().expect("recorder");
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stderr.contains("recording g/state too"), "{stderr}");
    let got = read_with_python(&file);
    let g = messages(&got, "g/state");
    assert!(g.len() >= 50, "about 2.5 s of a 20 ms agent: {}\n{stdout}", g.len());
    let first_ms = (g[0]["log_time"].as_u64().unwrap_or(0) as f64 - started as f64) / 1e6;
    assert!(first_ms < 1500.0, "g/state recorded from {first_ms:.0} ms after g was started");
    assert!(messages(&got, "t1/tick").len() >= 200, "and t1 throughout");
    r.down_and_check_clean();
}

#[test]
fn replay_refuses_what_it_cannot_do() {
    let r = Robot::new("recbad");
    let junk = nerve_tests::write_file(&r.home, "junk.mcap", "not an mcap file");
    let e = r.fails(&["replay", &junk.display().to_string()]);
    assert!(e.contains("junk.mcap") && e.contains("not a readable MCAP file"), "{e}");
    let e = r.fails(&["replay", "/nonexistent.mcap"]);
    assert!(e.contains("cannot read /nonexistent.mcap"), "{e}");
    let e = r.fails(&["record", "--all", "--duration", "1"]);
    assert!(e.contains("recording needs the router"), "{e}");
    let e = r.fails(&["record"]);
    assert!(e.contains("--all"), "{e}");
}

/// The `sequence` of each message of `topic` in [`read_mcap`]'s answer.
fn sequences(got: &Value, topic: &str) -> Vec<u64> {
    messages(got, topic).iter().map(|m| m["sequence"].as_u64().expect("sequence")).collect()
}

/// What `tests/py/read_cut.py` (the PyPI reader, front to back, up to the
/// first record it cannot read) finds of `topic` in `file`: its sequences,
/// and how the reading ended.
fn read_cut_with_python(file: &Path, topic: &str) -> (Vec<u64>, String) {
    let got = run_reader("read_cut.py", file, &[]);
    let seqs = got["channels"][topic]["sequences"]
        .as_array()
        .map(|a| a.iter().filter_map(Value::as_u64).collect())
        .unwrap_or_default();
    (seqs, got["ended"].as_str().unwrap_or("").to_string())
}

fn consecutive(seqs: &[u64]) -> bool {
    seqs.windows(2).all(|w| w[1] == w[0] + 1)
}

/// The sequence numbers missing between the first and the last of `seqs`
/// (which must rise).
fn gaps(seqs: &[u64]) -> u64 {
    seqs.windows(2).map(|w| w[1].checked_sub(w[0] + 1).expect("sequences rise")).sum()
}

/// The drops `nerve record`'s summary (its stdout) reports for `port`: 0
/// when its line says none; a missing line fails.
fn reported_drops(summary: &str, port: &str) -> u64 {
    let line = summary
        .lines()
        .find(|l| l.split_whitespace().next() == Some(port))
        .unwrap_or_else(|| panic!("no line for {port} in the recorder's summary:\n{summary}"));
    match line.split_once(", ") {
        Some((_, rest)) => rest.split_whitespace().next().and_then(|n| n.parse().ok()).expect("a count of drops"),
        None => 0,
    }
}

/// The ports the crash tests record: a ticker (sequences to compare) and a
/// camera (enough bytes that chunks fill and the write buffer goes to disk
/// between the recorder's flushes).
fn crash_robot(tag: &str, width: &str, height: &str) -> Robot {
    let r = Robot::new(tag);
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "camera", "--name", "cam", "--", "--source", "test-pattern", "--width", width, "--height", height]);
    assert!(wait_until(Duration::from_secs(10), || r.agent("cam").is_some()), "camera did not start");
    r
}

/// `nerve export` of a file cut short: it succeeds with a warning naming
/// the file; returns the ticker's sequences in the (whole) export.
fn export_cut(r: &Robot, cut: &Path, what: &str) -> Vec<u64> {
    let exported = r.home.join("exported.mcap");
    let out = r.nerve(&["export", &cut.display().to_string(), "-o", &exported.display().to_string()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "export of the cut file failed: {stderr}");
    assert!(stderr.contains("warning: ") && stderr.contains(&cut.display().to_string()), "no warning: {stderr}");
    assert!(stderr.contains(what), "{stderr}");
    sequences(&read_mcap(&exported), "t1/tick")
}

/// `kill -9` of `nerve record` in the middle of a chunk: replay, export and
/// the PyPI reader read everything before the cut. A second recorder of the
/// same ports that finishes is what was published: the cut file's ticks are
/// a run of it, none missing; nerve's reader reads at least what the PyPI
/// reader does (it also reads the chunk the recorder never closed).
#[test]
fn a_recorder_killed_mid_chunk_leaves_everything_before_the_cut_readable() {
    let r = crash_robot("reckil", "160", "120");
    let (full, cut) = (r.home.join("full.mcap"), r.home.join("cut.mcap"));
    let ports = ["t1/tick", "cam/frames"];
    let mut whole = r
        .command("nerve")
        .args(["record", ports[0], ports[1], "-o", &full.display().to_string(), "--duration", "5", "-q"])
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("recorder");
    std::thread::sleep(Duration::from_millis(500));
    let mut killed = r
        .command("nerve")
        .args(["record", ports[0], ports[1], "-o", &cut.display().to_string(), "-q"])
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("recorder");
    std::thread::sleep(Duration::from_millis(2600));
    killed.kill().expect("SIGKILL");
    let _ = killed.wait();
    assert!(whole.wait().expect("recorder").success(), "the whole recording failed");

    let published = sequences(&read_mcap(&full), "t1/tick");
    let (py, ended) = read_cut_with_python(&cut, "t1/tick");
    assert_ne!(ended, "complete", "the PyPI reader read a killed recording as whole");
    assert!(py.len() >= 100, "at least the chunks closed in the first 2 s: {} ticks ({ended})", py.len());
    let ours = export_cut(&r, &cut, "read ");
    assert!(ours.len() >= py.len(), "nerve read {} ticks, the PyPI reader {}", ours.len(), py.len());
    assert_eq!(&ours[..py.len()], &py[..], "both read the same ticks from the start");
    assert!(consecutive(&ours), "a tick before the cut is missing: {ours:?}");
    let start = published.iter().position(|s| *s == ours[0]).expect("the first tick was published");
    assert_eq!(&published[start..start + ours.len()], &ours[..], "the cut file holds what was published");

    // replay reads it too, up to the same message, with the same warning
    let out = r.nerve(&["replay", &cut.display().to_string(), "--fast", "--as", "t1=t1r", "-q"]);
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{stdout}{stderr}");
    assert!(stdout.contains(&format!("replayed {} messages", ours.len())), "{stdout}{stderr}");
    assert!(stderr.contains("warning: ") && stderr.contains("cut.mcap"), "{stderr}");
    r.down_and_check_clean();
}

/// A tmpfs of `mb` MB mounted at `dir` (root only), unmounted on drop.
struct SmallDisk(std::path::PathBuf);

impl SmallDisk {
    fn mount(dir: &Path, mb: u32) -> Option<SmallDisk> {
        std::fs::create_dir_all(dir).expect("dir");
        let st = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={mb}m"), "tmpfs", &dir.display().to_string()])
            .stderr(std::process::Stdio::null())
            .status();
        st.is_ok_and(|s| s.success()).then(|| SmallDisk(dir.to_path_buf()))
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(&self.0).status();
    }
}

/// A full disk (a 4 MB tmpfs; where mounting is not allowed, a file size
/// limit, `ulimit -f`, which fails writes the same way) stops `nerve
/// record` with an error naming the file and what to do, and leaves a file
/// that export and the PyPI reader read up to the last message written.
#[test]
fn a_full_disk_stops_the_recorder_with_a_clear_error_and_a_readable_file() {
    let r = crash_robot("recful", "320", "240");
    let small = r.home.join("small");
    // NERVE_TEST_NO_TMPFS=1 takes the path of a machine where mounting is refused
    let disk = if std::env::var_os("NERVE_TEST_NO_TMPFS").is_some() {
        std::fs::create_dir_all(&small).expect("dir");
        None
    } else {
        SmallDisk::mount(&small, 4)
    };
    let file = small.join("run.mcap");
    let nerve = nerve_tests::bin_dir().join("nerve");
    let record = format!("{} record t1/tick cam/frames -o {} --duration 30 -q", nerve.display(), file.display());
    // without the tmpfs: writes past 4 MB fail with EFBIG (SIGXFSZ ignored, as a shell's trap leaves it)
    let script =
        if disk.is_some() { format!("exec {record}") } else { format!("trap '' XFSZ; ulimit -f 4096; exec {record}") };
    let out = std::process::Command::new("bash")
        .args(["-c", &script])
        .env("NERVE_ROBOT", &r.name)
        .env("NERVE_HOME", &r.home)
        .output()
        .expect("bash");
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!("the recorder said: {stderr}");
    assert!(!out.status.success(), "the recorder went on past a full disk: {stderr}");
    assert!(stderr.contains(&format!("cannot write {}", file.display())), "{stderr}");
    let what = if disk.is_some() { "the disk is full" } else { "size limit" };
    assert!(stderr.contains(what) && stderr.contains("MB on disk") && stderr.contains("readable"), "{stderr}");

    let (py, ended) = read_cut_with_python(&file, "t1/tick");
    assert_ne!(ended, "complete", "{ended}");
    let ours = export_cut(&r, &file, "read ");
    // what the recorder could not keep up with (a stall of the loaded
    // machine longer than the port's buffer) is a gap it counts and says
    let stdout = String::from_utf8_lossy(&out.stdout);
    let said_dropped = reported_drops(&stdout, "t1/tick");
    assert!(!ours.is_empty() && gaps(&ours) <= said_dropped, "the ticks before the disk filled: {ours:?}\n{stdout}");
    assert!(ours.len() >= py.len() && ours[..py.len()] == py[..], "nerve {ours:?}\nPyPI {py:?}");
    drop(disk);
    r.down_and_check_clean();
}

/// The nerve schema of a port whose samples are `size` bytes.
fn blob_schema(size: usize) -> shm_schemas::Schema {
    use shm_schemas::schema::{Field, Kind};
    use shm_schemas::{Described, Schema};
    let bytes = Schema {
        type_name: format!("[u8; {size}]"),
        size,
        align: 1,
        kind: Kind::Array { len: size, element: Box::new(u8::schema()) },
    };
    Schema {
        type_name: "test::Blob".into(),
        size,
        align: 1,
        kind: Kind::Struct { fields: vec![Field { name: "data".into(), offset: 0, schema: bytes }] },
    }
}

/// Replays a file of `mb` MB of 1 MiB samples (written by the PyPI writer)
/// as fast as it can and returns the replay's peak RSS in MB (`wait4`'s
/// `ru_maxrss`, the process alone). The file is removed, even on failure.
fn replay_peak_rss_mb(tag: &str, mb: u32) -> f64 {
    struct Remove(std::path::PathBuf);
    impl Drop for Remove {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }
    let r = Robot::new(tag);
    let schema_file = r.home.join("blob.json");
    std::fs::write(&schema_file, serde_json::to_vec(&blob_schema(1 << 20)).expect("json")).expect("schema");
    let big = Remove(r.home.join("big.mcap"));
    let out = std::process::Command::new(python_with_mcap())
        .arg(std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("py").join("write_big.py"))
        .args([&big.0, &schema_file])
        .arg(mb.to_string())
        .output()
        .expect("python");
    assert!(out.status.success(), "write_big.py: {}", String::from_utf8_lossy(&out.stderr));
    let count: u64 = String::from_utf8_lossy(&out.stdout).trim().parse().expect("count");
    // waited for below with wait4, which gives the process's own peak RSS
    #[allow(clippy::zombie_processes)]
    let child = r
        .command("nerve")
        .args(["replay", &big.0.display().to_string(), "--fast", "-q"])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("replay");
    let pid = child.id() as libc::pid_t;
    let mut stdout = child.stdout.expect("stdout");
    let mut said = String::new();
    std::io::Read::read_to_string(&mut stdout, &mut said).expect("replay's output");
    let mut status = 0;
    // SAFETY: an all-zero rusage is valid; wait4 writes into the two
    // locals, which outlive the call. The child is not waited for elsewhere
    // (its Child handle was consumed above).
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: as above
    let waited = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    assert_eq!(waited, pid, "wait4: {}", std::io::Error::last_os_error());
    assert!(libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0, "replay failed ({status}): {said}");
    assert!(said.contains(&format!("replayed {count} messages")), "{said}");
    usage.ru_maxrss as f64 / 1024.0
}

/// Replay streams a 300 MB file: its memory stays far below the file's size.
#[test]
fn replay_streams_a_large_file_in_bounded_memory() {
    let rss = replay_peak_rss_mb("recbig", 300);
    eprintln!("replay of a 300 MB file: peak RSS {rss:.0} MB");
    assert!(rss < 100.0, "replay of a 300 MB file peaked at {rss:.0} MB");
}

/// The figure: a 2 GB file under 200 MB of RSS (about 9 s here,
/// most of it writing the file; the file is 2 GB in the temp folder while
/// it runs).
#[test]
fn replay_of_a_2_gb_file_stays_under_200_mb() {
    let rss = replay_peak_rss_mb("recgb", 2048);
    eprintln!("replay of a 2 GB file: peak RSS {rss:.0} MB");
    assert!(rss < 200.0, "replay of a 2 GB file peaked at {rss:.0} MB");
}

/// A schema from a file is outside input: one that iceoryx2 must not be
/// handed (an alignment of 3) is refused by replay and export, with the
/// file and the channel named, before any port is made.
#[test]
fn a_bad_schema_in_a_recording_is_refused_with_the_file_and_channel() {
    let r = Robot::new("recsch");
    let mut schema = serde_json::to_value(blob_schema(1024)).expect("json");
    schema["align"] = serde_json::json!(3);
    let schema_file = r.home.join("bad.json");
    std::fs::write(&schema_file, serde_json::to_vec(&schema).expect("json")).expect("schema");
    let file = r.home.join("bad.mcap");
    let out = std::process::Command::new(python_with_mcap())
        .arg(std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("py").join("write_big.py"))
        .args([&file, &schema_file])
        .arg("1")
        .output()
        .expect("python");
    assert!(out.status.success(), "write_big.py: {}", String::from_utf8_lossy(&out.stderr));
    let file_s = file.display().to_string();
    for args in [vec!["replay", &file_s, "--fast"], vec!["export", &file_s]] {
        let e = r.fails(&args);
        assert!(e.contains(&file_s) && e.contains("big/blob") && e.contains("align 3"), "{args:?}: {e}");
    }
    assert!(r.shm_files().is_empty(), "replay made shared memory for a refused schema: {:?}", r.shm_files());
}
