//! `nerve plot`, end to end: a ticker and an agent with a type of its own
//! (`acme::Gripper`) are recorded with `nerve record`; the recording is
//! plotted to PNG (a real PNG of the figure's size, with the line drawn,
//! and exactly the samples the recorder counted), fields that are not
//! numbers, unknown fields and ports the file lacks are refused with what
//! there is; and a port is plotted live to SVG.

use nerve_tests::Robot;
use std::path::Path;

/// The figure's size in pixels (`nerve plot` draws every figure this size).
const SIZE: (u32, u32) = (1000, 600);

/// The count `nerve record` printed for `port` (`  t1/tick   nerve::Tick   123 messages`).
fn recorded_count(out: &str, port: &str) -> u64 {
    out.lines()
        .map(str::split_whitespace)
        .find_map(|mut w| (w.next() == Some(port)).then(|| w.nth(1).and_then(|n| n.parse().ok())).flatten())
        .unwrap_or_else(|| panic!("no count of {port} in {out:?}"))
}

/// The sample count in `plotted N samples of ...`.
fn plotted_count(out: &str) -> u64 {
    out.strip_prefix("plotted ")
        .and_then(|s| s.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no `plotted N samples` in {out:?}"))
}

/// Width and height from the IHDR chunk of a PNG file, after checking its signature.
fn png_size(file: &Path) -> (u32, u32) {
    let b = std::fs::read(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    assert!(b.len() > 33, "{} is too short for a PNG", file.display());
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "PNG signature of {}", file.display());
    assert_eq!(&b[8..16], b"\0\0\0\x0dIHDR", "the first chunk of {} is IHDR", file.display());
    let be = |i: usize| u32::from_be_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
    (be(16), be(20))
}

/// Pixels of the first line's colour (RGB 30, 90, 200) in the PNG `file`.
fn line_pixels(file: &Path) -> usize {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(file).expect("open png")));
    let mut reader = decoder.read_info().expect("png header");
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("png frame");
    assert_eq!(info.color_type, png::ColorType::Rgb, "an RGB figure");
    buf[..info.buffer_size()].chunks_exact(3).filter(|p| p == &[30, 90, 200]).count()
}

#[test]
fn a_recording_is_plotted_sample_for_sample() {
    let r = Robot::new("plot");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    r.ok(&["start", "gripper", "--name", "g"]);
    let file = r.home.join("run.mcap");
    let file_s = file.display().to_string();
    let rec = r.ok(&["record", "t1/tick", "g/state", "-o", &file_s, "--duration", "2", "-q"]);
    let ticks = recorded_count(&rec, "t1/tick");
    assert!(ticks >= 50, "2 s of a 10 ms ticker: {rec}");

    // one field, to PNG: every recorded sample, a figure of the set size with the line drawn
    let png = r.home.join("seq.png");
    let out = r.ok(&["plot", "t1/tick", "--field", "seq", "--from", &file_s, "-o", &png.display().to_string()]);
    assert_eq!(plotted_count(&out), ticks, "the samples the recorder counted: {out} / {rec}");
    assert!(out.contains("of t1/tick (fields seq) to ") && out.trim_end().ends_with("seq.png"), "{out}");
    assert_eq!(png_size(&png), SIZE);
    assert!(line_pixels(&png) > 200, "the line of seq is not drawn in {}", png.display());

    // two fields, the default name in the current directory, a title
    let out = r
        .command("nerve")
        .current_dir(&r.home)
        .args(["plot", "t1/tick", "--field", "seq", "--field", "stamp_ns", "--from", &file_s, "--title", "ticks"])
        .output()
        .expect("nerve plot");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout} {}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(plotted_count(&stdout), ticks, "{stdout}");
    assert!(stdout.contains("(fields seq, stamp_ns)"), "{stdout}");
    assert_eq!(png_size(&r.home.join("t1-tick-seq-stamp_ns.png")), SIZE);

    // a type nerve was not built with, by the recording's schema: a nested numeric field
    let out =
        r.ok(&["plot", "g/state", "--field", "fingers.1.force_n", "--from", &file_s, "-o", &png.display().to_string()]);
    assert_eq!(plotted_count(&out), recorded_count(&rec, "g/state"), "{out}");

    // what cannot be plotted, and what there is instead
    let gripper_fields = "count, opening_m, fingers.<i>.force_n (<i> < 3), fingers.<i>.contact (<i> < 3), temp_cdeg";
    for (field, says) in [("tool", "is a "), ("fingers", "is a "), ("fingers.3.force_n", "has no field")] {
        let e = r.fails(&["plot", "g/state", "--field", field, "--from", &file_s, "-o", "x.png"]);
        assert!(e.contains(says) && e.contains(gripper_fields), "--field {field}: {e}");
    }
    let e = r.fails(&["plot", "t1/tick", "--field", "nope", "--from", &file_s, "-o", "x.png"]);
    assert!(e.contains("has no field \"nope\"") && e.contains("numeric fields of nerve::Tick: seq, stamp_ns"), "{e}");
    let e = r.fails(&["plot", "t9/tick", "--field", "seq", "--from", &file_s, "-o", "x.png"]);
    assert!(e.contains("has no port t9/tick; its topics: g/state, t1/tick"), "{e}");
    let e = r.fails(&["plot", "t1/tick", "--field", "seq", "--from", &file_s, "-o", "x.jpg"]);
    assert!(e.contains(".png or .svg"), "{e}");
    let junk = nerve_tests::write_file(&r.home, "junk.mcap", "not an mcap file");
    let e = r.fails(&["plot", "t1/tick", "--field", "seq", "--from", &junk.display().to_string(), "-o", "x.png"]);
    assert!(e.contains("not a readable MCAP file"), "{e}");
    assert!(!r.home.join("x.png").exists() && !Path::new("x.png").exists(), "a refused plot writes nothing");
    r.down_and_check_clean();
}

#[test]
fn a_live_port_is_plotted_to_svg() {
    let r = Robot::new("plotlive");
    r.router();
    r.ok(&["start", "ticker", "--name", "t1", "--period", "10ms"]);
    let svg = r.home.join("live.svg");
    let out = r.ok(&["plot", "t1/tick", "--field", "seq", "--duration", "2", "-o", &svg.display().to_string()]);
    let n = plotted_count(&out);
    assert!(n >= 50, "2 s of a 10 ms ticker: {out}");
    let text = std::fs::read_to_string(&svg).expect("the SVG");
    assert!(text.contains("<svg"), "not an SVG: {}", &text[..text.len().min(200)]);
    // the mesh is drawn with polylines too: the data line is the one in the first line colour with the most points
    let points = text
        .split("<polyline")
        .skip(1)
        .filter(|p| p.contains("stroke=\"#1E5AC8\""))
        .filter_map(|p| p.split("points=\"").nth(1)?.split('"').next().map(|pts| pts.split_whitespace().count()))
        .max()
        .unwrap_or(0);
    assert!(points as u64 >= n * 9 / 10, "the line of {n} samples has {points} points");
    assert!(text.contains(&format!("{} t1/tick", r.name)), "the default title names robot and port");
    assert!(text.contains("t1/tick seq") && text.contains("time (s)"), "legend and axis label");

    let e = r.fails(&["plot", "t1/tick", "--field", "stamp", "--duration", "1", "-o", "x.svg"]);
    assert!(e.contains("has no field \"stamp\"") && e.contains("seq, stamp_ns"), "{e}");
    let e = r.fails(&["plot", "t1/nothing", "--field", "seq", "--duration", "1", "-o", "x.svg"]);
    assert!(e.contains("nothing"), "{e}");
    r.down_and_check_clean();
}
