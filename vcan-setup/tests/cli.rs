//! The `vcan-setup` binary on its command line: the numbers of `vm` (memory, CPUs, the
//! host niceness and real-time priority) are bounded and refused with the argument named, before any VM is
//! started (issue 11, item 8).

// Helpers outside #[test] functions unwrap and panic as the tests do.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use std::process::Command;

#[test]
fn vm_memory_and_cpus_out_of_range_are_refused_naming_the_argument() {
    let cases: [(&[&str], &str); 13] = [
        (&["--host-rt", "100"], "--host-rt"),
        (&["--host-rt=-1"], "--host-rt"),
        (&["--host-nice", "-21"], "--host-nice"),
        (&["--host-nice", "20"], "--host-nice"),
        (&["--host-nice", "nice"], "--host-nice"),
        (&["--cpus", "0"], "--cpus"),
        (&["--cpus", "18446744073709551616"], "--cpus"),
        (&["--cpus", "100000"], "--cpus"),
        (&["--memory", "99999999999999999999G"], "--memory"),
        (&["--memory", "18014398509481984T"], "--memory"),
        (&["--memory", "1M"], "--memory"),
        (&["--memory", "2X"], "--memory"),
        (&["--memory=-2G"], "--memory"),
    ];
    for (extra, argument) in cases {
        let out = Command::new(env!("CARGO_BIN_EXE_vcan-setup"))
            .arg("vm")
            .args(extra)
            .args(["--", "true"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{extra:?}: {stderr}");
        assert!(stderr.contains(argument), "{extra:?}: {stderr}");
    }
}
