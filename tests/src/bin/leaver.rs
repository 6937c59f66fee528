//! `leaver`: a process that serves the router's service of robot
//! `NERVE_ROBOT` and then leaves slowly, as a router killed while one of its
//! threads is still busy (finishing a write to disk, say) does: its main
//! thread ends at once (the process shows as a zombie in
//! `/proc/<pid>/stat`), while another thread holds the server, and with it
//! a live iceoryx2 node, for `HOLD_MS` more milliseconds (`test-leaver
//! HOLD_MS`; not named `nerve-*`, which would make it an agent kind).
//! Prints `serving` once it serves.

use agent_sdk::World;
use agent_sdk::control::{ControlServer, ControlSize};
use shm_schemas::control::cli_to_router::{RouterReply, RouterRequest};
use std::io::Write as _;
use std::time::Duration;

fn main() {
    let hold_ms: u64 = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(500);
    let robot = std::env::var("NERVE_ROBOT").unwrap_or_else(|_| "default".into());
    let (serving_tx, serving) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let world = World::new(&robot).unwrap_or_else(|e| panic!("leaver: {e}"));
        let node = world.node("router").unwrap_or_else(|e| panic!("leaver: {e}"));
        let service = world.robot().router_service();
        let server = ControlServer::<RouterRequest, RouterReply>::create(&node, &service, ControlSize::ROUTER)
            .unwrap_or_else(|e| panic!("leaver: {e}"));
        println!("serving");
        let _ = std::io::stdout().flush();
        let _ = serving_tx.send(());
        std::thread::sleep(Duration::from_millis(hold_ms));
        drop(server);
        drop(node);
        std::process::exit(0);
    });
    if serving.recv().is_err() {
        std::process::exit(1);
    }
    // The raw `exit` system call ends the calling thread only (`exit_group`
    // ends them all), without unwinding: `pthread_exit` unwinds by force
    // through Rust frames, which aborted the whole process.
    // SAFETY: the thread ends without returning; nothing on its stack is
    // used again, and the other thread owns everything the process needs.
    unsafe { libc::syscall(libc::SYS_exit, 0) };
    unreachable!("the main thread has ended");
}
