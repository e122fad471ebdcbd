//! Waiting for a child process with a deadline, shared by sim/tests/cli_bounds.rs and
//! sim/tests/live_view.rs.
#![allow(dead_code, clippy::unwrap_used, clippy::panic)]

use std::io::Read;
use std::process::Child;
use std::time::{Duration, Instant};

/// Wait for `child` at most `limit`, then read its piped stderr: its exit code and
/// stderr. Past `limit` it is killed and the test fails, naming `what`.
pub fn exit_and_stderr(child: &mut Child, limit: Duration, what: &str) -> (Option<i32>, String) {
    let deadline = Instant::now() + limit;
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{what}: still running after {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let mut stderr = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    (status.code(), stderr)
}
