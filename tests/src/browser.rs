//! A real browser for the tests of `nerve ui`: headless Chromium driven
//! through chromedriver's WebDriver protocol (plain HTTP and JSON, spoken
//! here over a `TcpStream`), and a small HTTP client for the tests' own
//! requests to the server. `scripts/setup.sh --test` installs `chromium` and
//! `chromium-driver`; a machine without them fails the test with that hint.

use serde_json::{Value, json};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// One HTTP/1.1 request (`Host` is `addr` unless `headers` has one); returns
/// the status and the body. Panics when the server cannot be reached or
/// does not answer within 120 s.
pub fn http(addr: &str, method: &str, path: &str, headers: &[(&str, &str)], body: Option<&str>) -> (u16, String) {
    try_http(addr, method, path, headers, body).unwrap_or_else(|e| panic!("{method} {path} to {addr}: {e}"))
}

/// [`http`], with the failure returned.
pub fn try_http(
    addr: &str,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: Option<&str>,
) -> std::io::Result<(u16, String)> {
    let mut s = TcpStream::connect(addr)?;
    s.set_read_timeout(Some(Duration::from_secs(120)))?;
    let body = body.unwrap_or("");
    // a Host among `headers` replaces the default one (the address)
    let mut req = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\nContent-Length: {}\r\n", body.len());
    if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
        req.push_str(&format!("Host: {addr}\r\n"));
    }
    if !body.is_empty() {
        req.push_str("Content-Type: application/json\r\n");
    }
    for (k, v) in headers {
        req.push_str(&format!("{k}: {v}\r\n"));
    }
    req.push_str("\r\n");
    req.push_str(body);
    s.write_all(req.as_bytes())?;
    // read the head, then as much body as Content-Length says (a server may keep the connection open)
    let mut raw = Vec::new();
    let mut buf = [0u8; 65536];
    let head_end = loop {
        if let Some(i) = raw.windows(4).position(|w| w == b"\r\n\r\n") {
            break i + 4;
        }
        let n = s.read(&mut buf)?;
        if n == 0 {
            return Err(std::io::Error::other("the connection was closed before the answer"));
        }
        raw.extend_from_slice(&buf[..n]);
    };
    let head = String::from_utf8_lossy(&raw[..head_end]).to_ascii_lowercase();
    let status = head.split_whitespace().nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    let length =
        head.lines().find_map(|l| l.strip_prefix("content-length:")).and_then(|v| v.trim().parse::<usize>().ok());
    match length {
        Some(len) => {
            while raw.len() < head_end + len {
                let n = s.read(&mut buf)?;
                if n == 0 {
                    return Err(std::io::Error::other("the connection was closed in the middle of the answer"));
                }
                raw.extend_from_slice(&buf[..n]);
            }
        }
        None => {
            s.read_to_end(&mut raw)?;
        }
    }
    let body = String::from_utf8_lossy(&raw[head_end..]).into_owned();
    Ok((status, if head.contains("transfer-encoding: chunked") { dechunk(&body) } else { body }))
}

fn dechunk(mut s: &str) -> String {
    let mut out = String::new();
    while let Some((size, rest)) = s.split_once("\r\n") {
        let n = usize::from_str_radix(size.trim(), 16).unwrap_or(0);
        if n == 0 || rest.len() < n {
            break;
        }
        out.push_str(&rest[..n]);
        s = rest[n..].trim_start_matches("\r\n");
    }
    out
}

/// A headless Chromium with its chromedriver; both end when dropped.
#[derive(Debug)]
pub struct Browser {
    driver: Child,
    addr: String,
    session: String,
    profile: PathBuf,
}

const ELEMENT: &str = "element-6066-11e4-a52e-4f735466cecf";

impl Browser {
    /// Starts chromedriver and a headless Chromium window of 1400x900.
    pub fn start() -> Browser {
        let port = crate::free_port();
        let driver = Command::new("chromedriver")
            .arg(format!("--port={port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!(
                    "cannot run chromedriver ({e}): install chromium and chromium-driver (scripts/setup.sh --test does)"
                )
            });
        let addr = format!("127.0.0.1:{port}");
        let up = crate::wait_until(Duration::from_secs(20), || TcpStream::connect(&addr).is_ok());
        let profile = std::env::temp_dir().join(format!("nerve-test-chromium-{}-{port}", std::process::id()));
        let mut b = Browser { driver, addr, session: String::new(), profile };
        assert!(up, "chromedriver did not listen on port {port} within 20 s");
        let caps = json!({ "capabilities": { "alwaysMatch": {
            "browserName": "chrome",
            // navigation returns once the document is parsed; the tests wait for what they need
            "pageLoadStrategy": "eager",
            "goog:chromeOptions": {
                "binary": "/usr/bin/chromium",
                "args": ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                         "--window-size=1400,900", "--hide-scrollbars",
                         format!("--user-data-dir={}", b.profile.display())],
            },
        }}});
        let v = b.call("POST", "/session", Some(&caps));
        b.session = v["sessionId"].as_str().unwrap_or_else(|| panic!("no WebDriver session: {v}")).to_owned();
        b
    }

    /// A WebDriver command; returns its `value`, panics on an error.
    fn call(&self, method: &str, path: &str, body: Option<&Value>) -> Value {
        let text = body.map(Value::to_string);
        let (status, answer) = http(&self.addr, method, path, &[], text.as_deref().or(Some("")));
        let v: Value = serde_json::from_str(&answer).unwrap_or(Value::Null);
        assert!(status == 200, "WebDriver {method} {path} answered {status}: {answer}");
        v["value"].clone()
    }

    fn session_call(&self, method: &str, path: &str, body: Option<&Value>) -> Value {
        self.call(method, &format!("/session/{}{path}", self.session), body)
    }

    /// Loads `url`.
    pub fn open(&self, url: &str) {
        self.session_call("POST", "/url", Some(&json!({ "url": url })));
    }

    /// Runs `script` (a function body; `return` gives the result) in the page.
    pub fn eval(&self, script: &str) -> Value {
        self.session_call("POST", "/execute/sync", Some(&json!({ "script": script, "args": [] })))
    }

    /// Evaluates `script` until it gives something truthy, for up to `timeout`.
    pub fn wait_for(&self, what: &str, timeout: Duration, script: &str) -> Value {
        let t0 = Instant::now();
        loop {
            let v = self.eval(script);
            let truthy = !matches!(&v, Value::Null | Value::Bool(false))
                && v.as_array().is_none_or(|a| !a.is_empty())
                && v.as_str().is_none_or(|s| !s.is_empty());
            if truthy {
                return v;
            }
            assert!(t0.elapsed() < timeout, "the page did not show {what} within {timeout:?}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// The element matching `css`.
    pub fn element(&self, css: &str) -> Value {
        let v = self.session_call("POST", "/element", Some(&json!({ "using": "css selector", "value": css })));
        let mut reference = serde_json::Map::new();
        reference.insert(ELEMENT.to_owned(), v[ELEMENT].clone());
        Value::Object(reference)
    }

    /// Runs a sequence of mouse `steps`; `release` lets go of every input
    /// state afterwards (a drag that goes on keeps it).
    fn mouse(&self, steps: Value, release: bool) {
        let actions = json!({ "actions": [{
            "type": "pointer", "id": "mouse", "parameters": { "pointerType": "mouse" }, "actions": steps,
        }]});
        self.session_call("POST", "/actions", Some(&actions));
        if release {
            self.session_call("DELETE", "/actions", None);
        }
    }

    /// Presses the mouse on `from`, moves it in steps onto `to` and releases it there.
    pub fn drag(&self, from: &str, to: &str) {
        let (a, b) = (self.element(from), self.element(to));
        self.mouse(json!([move_to(&a, 0, 0, 0), down(), move_to(&a, 30, 10, 150), move_to(&b, 0, 0, 150), up()]), true);
    }

    /// Presses the mouse on `css`, moves it by (`dx`, `dy`) pixels and releases it.
    pub fn drag_by(&self, css: &str, dx: i64, dy: i64) {
        let a = self.element(css);
        let by = json!({ "type": "pointerMove", "duration": 200, "origin": "pointer", "x": dx, "y": dy });
        self.mouse(json!([move_to(&a, 0, 0, 0), down(), by, up()]), true);
    }

    /// Presses the mouse on `css` and moves it a little, holding it (a drag
    /// begun; [`Browser::release_on`] ends it).
    pub fn press_on(&self, css: &str) {
        let a = self.element(css);
        self.mouse(json!([move_to(&a, 0, 0, 0), down(), move_to(&a, 40, 15, 100)]), false);
    }

    /// Moves the held mouse onto `css` and releases it there.
    pub fn release_on(&self, css: &str) {
        let b = self.element(css);
        self.mouse(json!([move_to(&b, 0, 0, 100), up()]), true);
    }

    /// Clicks the element matching `css` (in its centre).
    pub fn click(&self, css: &str) {
        let e = self.element(css);
        self.mouse(json!([move_to(&e, 0, 0, 0), down(), up()]), true);
    }

    /// Presses a key (a WebDriver key code such as `"\u{E017}"`, Delete).
    pub fn key(&self, key: &str) {
        let actions = json!({ "actions": [{
            "type": "key", "id": "keyboard",
            "actions": [{ "type": "keyDown", "value": key }, { "type": "keyUp", "value": key }],
        }]});
        self.session_call("POST", "/actions", Some(&actions));
    }

    /// The window as PNG.
    pub fn screenshot(&self) -> Vec<u8> {
        let v = self.session_call("GET", "/screenshot", None);
        base64_decode(v.as_str().expect("a base64 screenshot"))
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        if !self.session.is_empty() {
            let _ = try_http(&self.addr, "DELETE", &format!("/session/{}", self.session), &[], None);
        }
        let _ = self.driver.kill();
        let _ = self.driver.wait();
        // a browser whose session could not be ended (the test failed mid-command) is found by its profile
        kill_processes_using(&self.profile.display().to_string());
        let _ = std::fs::remove_dir_all(&self.profile);
    }
}

/// A WebDriver step: the mouse moves to (`x`, `y`) from the centre of `element` in `ms`.
fn move_to(element: &Value, x: i64, y: i64, ms: u64) -> Value {
    json!({ "type": "pointerMove", "duration": ms, "origin": element, "x": x, "y": y })
}

/// A WebDriver step: the left button pressed.
fn down() -> Value {
    json!({ "type": "pointerDown", "button": 0 })
}

/// A WebDriver step: the left button released.
fn up() -> Value {
    json!({ "type": "pointerUp", "button": 0 })
}

/// SIGKILLs every process whose command line contains `needle`.
fn kill_processes_using(needle: &str) {
    let Ok(entries) = std::fs::read_dir("/proc") else { return };
    for pid in entries.filter_map(|e| e.ok()?.file_name().to_str()?.parse::<i32>().ok()) {
        let Ok(cmdline) = std::fs::read(format!("/proc/{pid}/cmdline")) else { continue };
        if String::from_utf8_lossy(&cmdline).contains(needle) {
            let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), nix::sys::signal::Signal::SIGKILL);
        }
    }
}

fn base64_decode(s: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => Some(c - b'A'),
        b'a'..=b'z' => Some(c - b'a' + 26),
        b'0'..=b'9' => Some(c - b'0' + 52),
        b'+' => Some(62),
        b'/' => Some(63),
        _ => None,
    };
    let mut out = Vec::with_capacity(s.len() * 3 / 4);
    let (mut acc, mut bits) = (0u32, 0);
    for v in s.bytes().filter_map(value) {
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn base64_and_chunks_are_decoded() {
        assert_eq!(super::base64_decode("aGVsbG8gd29ybGQ="), b"hello world");
        assert_eq!(super::dechunk("5\r\nhello\r\n6\r\n world\r\n0\r\n\r\n"), "hello world");
    }
}
