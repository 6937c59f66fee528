//! Tests of the control channel through real iceoryx2 services: the
//! router's reserved client slot, errors that name their operation, size
//! limits, a request carried out once, clients sleeping until the reply.

use super::*;
use crate::world::test_support::Cleanup;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// The size of the tests' services.
const SMALL: ControlSize =
    ControlSize { max_clients: 2, max_nodes: 4, max_message: Some(128), reserved_clients: 0, reply_wake: false };

/// A robot of the test's own (removed when the guard drops) and the
/// name of its test service.
fn test_robot(tag: &str) -> (World, Cleanup, String) {
    let world = World::new(&format!("{tag}{}", std::process::id())).expect("world");
    let service = format!("nerve/{}/test/ctl", world.robot());
    (world.clone(), Cleanup(world), service)
}

#[test]
fn tools_leave_the_reserved_client_slot_for_the_router() {
    let (world, _cleanup, service) = test_robot("slot");
    let size =
        ControlSize { max_clients: 3, max_nodes: 8, max_message: Some(128), reserved_clients: 1, reply_wake: false };
    let node = world.node("server").expect("node");
    let _server: ControlServer<String, String> = ControlServer::create(&node, &service, size).expect("server");
    let tools = world.node("tools").expect("node");
    let a = ControlClient::<String, String>::open(&tools, &service, size).expect("first tool");
    let b = ControlClient::<String, String>::open(&tools, &service, size).expect("second tool");
    let e = ControlClient::<String, String>::open(&tools, &service, size).expect_err("the router's slot");
    assert!(matches!(e, ControlError::Full { taken: 2, max: 2, .. }), "{e}");
    assert!(e.to_string().contains("try again"), "{e}");
    let router = world.node("router").expect("node");
    let r = ControlClient::<String, String>::open_reserved(&router, &service, size).expect("the router gets in");
    drop((a, b, r));
}

/// A server of `String`s on its own thread.
struct ServerThread {
    done: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<()>,
}

impl ServerThread {
    /// Stops the server and waits for its thread.
    fn stop(self) {
        self.done.store(true, Ordering::Relaxed);
        self.thread.join().expect("server thread");
    }
}

/// Serves `service` on a thread of its own, taking each request with
/// `take`, until [`ServerThread::stop`].
fn server_thread(
    world: &World,
    service: &str,
    size: ControlSize,
    mut take: impl FnMut(Result<String, ProtocolError>, Responder<String>) + Send + 'static,
) -> ServerThread {
    let done = Arc::new(AtomicBool::new(false));
    let (world, service, stop) = (world.clone(), service.to_owned(), done.clone());
    let thread = std::thread::spawn(move || {
        let node = world.node("server").expect("node");
        let server: ControlServer<String, String> = ControlServer::create(&node, &service, size).expect("server");
        while !stop.load(Ordering::Relaxed) {
            while let Some((req, responder)) = server.receive().expect("receive") {
                take(req, responder);
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    });
    ServerThread { done, thread }
}

/// A client of `service`, once its server is up (at most 5 s).
fn client_of(node: &Node<Ipc>, service: &str, size: ControlSize) -> ControlClient<String, String> {
    let t0 = Instant::now();
    loop {
        match ControlClient::<String, String>::open(node, service, size) {
            Ok(c) => return c,
            Err(_) if t0.elapsed() < Duration::from_secs(5) => std::thread::sleep(Duration::from_millis(10)),
            Err(e) => panic!("no server: {e}"),
        }
    }
}

#[test]
fn an_iceoryx2_error_says_which_operation_failed_and_keeps_its_cause() {
    let (world, _cleanup, _) = test_robot("op");
    let node = world.node("tools").expect("node");
    let service = format!("nerve/{}/{}", world.robot(), "x".repeat(1000));
    let e = ControlClient::<String, String>::open(&node, &service, SMALL).expect_err("a name iceoryx2 refuses");
    let ControlError::Ipc { op, source, .. } = &e else { panic!("not an iceoryx2 error: {e}") };
    assert_eq!(*op, IpcOp::Name);
    assert!(!source.to_string().is_empty());
    assert!(std::error::Error::source(&e).is_some(), "the cause is kept");
    assert!(e.to_string().contains("could not name the service"), "{e}");
}

#[test]
fn oversized_messages_are_refused_or_answered_with_an_error() {
    let (world, _cleanup, service) = test_robot("ctl");
    let handler = |req: Result<String, ProtocolError>| match req {
        Ok(r) if r == "big" => "x".repeat(500),
        Ok(r) => format!("echo {r}"),
        Err(e) => format!("error: {e}"),
    };
    let server = server_thread(&world, &service, SMALL, move |req, responder| {
        responder.respond_or(&handler(req), |e| handler(Err(e)))
    });
    let node = world.node("client").expect("node");
    let client = client_of(&node, &service, SMALL);
    let timeout = Duration::from_secs(5);
    assert_eq!(client.call(&"hi".to_owned(), timeout).expect("small call"), "echo hi");
    // a request over the limit never leaves the client
    let e = client.call(&"y".repeat(300), timeout).expect_err("too large a request");
    assert!(matches!(e, ControlError::TooLarge { max: 128, .. }), "{e}");
    // a reply over the limit comes back as the handler's error reply, not as a time-out
    let reply = client.call(&"big".to_owned(), timeout).expect("an answer");
    assert!(reply.starts_with("error: the reply (") && reply.contains("128 bytes"), "{reply}");
    server.stop();
}

/// A request the server took is never sent twice: one it lets go
/// unanswered says so at once (it used to look untaken and was sent
/// three times), and one answered just before the server let go is
/// read, not mistaken for a server gone.
#[test]
fn a_taken_request_is_carried_out_once() {
    let (world, _cleanup, service) = test_robot("once");
    let taken = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let server = {
        let taken = taken.clone();
        server_thread(&world, &service, SMALL, move |req, responder| {
            taken.fetch_add(1, Ordering::SeqCst);
            if req.as_deref() != Ok("drop") {
                responder.respond_or(&"ok".to_owned(), |e| e.to_string());
            }
        })
    };
    let node = world.node("client").expect("node");
    let client = client_of(&node, &service, SMALL);
    let timeout = Duration::from_secs(5);
    let t0 = Instant::now();
    let e = client.call(&"drop".to_owned(), timeout).expect_err("an unanswered request");
    assert!(matches!(e, ControlError::Protocol(ProtocolError::Unanswered)), "{e}");
    assert!(t0.elapsed() < Duration::from_secs(4), "the caller waited for its time-out");
    assert_eq!(taken.load(Ordering::SeqCst), 1, "the request was sent again");
    const CALLS: usize = 2000;
    for i in 0..CALLS {
        assert_eq!(client.call(&format!("{i}"), timeout).expect("an answer"), "ok");
    }
    assert_eq!(taken.load(Ordering::SeqCst), 1 + CALLS, "a request was carried out twice");
    server.stop();
}

/// This thread's voluntary context switches (each sleep that ended).
fn own_wakeups() -> u64 {
    std::fs::read_to_string("/proc/thread-self/status")
        .ok()
        .and_then(|s| {
            s.lines().find_map(|l| l.strip_prefix("voluntary_ctxt_switches:").and_then(|v| v.trim().parse().ok()))
        })
        .expect("voluntary_ctxt_switches")
}

/// A server's handling that answers "re: REQUEST" `after` it took the request.
fn answer_after(after: Duration) -> impl FnMut(Result<String, ProtocolError>, Responder<String>) + Send + 'static {
    move |req, responder| {
        std::thread::sleep(after);
        responder.respond_or(&format!("re: {}", req.unwrap_or_default()), |e| e.to_string());
    }
}

#[test]
fn a_client_of_a_service_with_reply_wakes_sleeps_until_the_reply() {
    let late = Duration::from_millis(20);
    let (world, _cleanup, service) = test_robot("wake");
    let woken = ControlSize { reply_wake: true, ..SMALL };
    let server = server_thread(&world, &service, woken, answer_after(late));
    let node = world.node("client").expect("node");
    let client = client_of(&node, &service, woken);
    assert!(client.replies.is_some(), "the client listens for replies");
    let before = own_wakeups();
    assert_eq!(client.call(&"a".to_owned(), Duration::from_secs(5)).expect("reply"), "re: a");
    let woke = own_wakeups() - before;
    // the reply came well within REPLY_WAIT_BOUND: its wake-up ended the wait
    assert!(client.reply_wakes.get() >= 1, "the reply did not wake the client");
    // polling every 200 µs at most would have woken some 100 times
    assert!(woke < 12, "the client woke {woke} times waiting {late:?} for its reply");
    server.stop();
    drop(client);
    // without the wake-ups the same call polls
    let (world, _cleanup, service) = test_robot("poll");
    let server = server_thread(&world, &service, SMALL, answer_after(late));
    let node = world.node("client").expect("node");
    let client = client_of(&node, &service, SMALL);
    assert!(client.replies.is_none());
    let before = own_wakeups();
    assert_eq!(client.call(&"b".to_owned(), Duration::from_secs(5)).expect("reply"), "re: b");
    let polled = own_wakeups() - before;
    assert!(polled > 30, "a polling client woke only {polled} times: the test cannot tell the two apart");
    server.stop();
}
