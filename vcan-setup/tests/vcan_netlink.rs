//! vcan interfaces over netlink on a real kernel. Needs vcan and CAP_NET_ADMIN (the
//! README's test command runs this natively or inside `vcan-setup vm`); fails loudly
//! without them.

use vcan_setup::{KernelCan, UpOutcome, VcanError};

/// A vcan interface name for one test, deleted with the guard: the interface a test
/// creates goes away even when the test fails half-way.
struct Scratch(String);

impl Scratch {
    fn new(tag: &str) -> Scratch {
        Scratch(format!("vn{tag}{}", std::process::id() % 100_000))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        // Already gone (the test deleted it) is fine; anything else cannot fail a test
        // that is unwinding, so it is said.
        if let Err(e) = vcan_setup::down(&self.0) {
            eprintln!("cleaning up {}: {e}", self.0);
        }
    }
}

#[test]
fn up_is_idempotent_and_down_deletes() {
    let scratch = Scratch::new("idem");
    let n = &scratch.0;
    assert_eq!(
        vcan_setup::up(n).expect("vcan must be available"),
        UpOutcome::Created
    );
    assert_eq!(vcan_setup::up(n).expect("second up"), UpOutcome::AlreadyUp);
    let link = vcan_setup::can_links()
        .into_iter()
        .find(|l| l.name == *n)
        .expect("status lists the new interface");
    assert!(link.up);
    assert_eq!(vcan_setup::kernel_can(), KernelCan::Ready);
    assert!(vcan_setup::down(n).expect("down"));
    assert!(!vcan_setup::down(n).expect("second down"));
    assert!(!vcan_setup::can_links().iter().any(|l| l.name == *n));
}

#[test]
fn up_raises_an_existing_interface_that_is_down() {
    let scratch = Scratch::new("rais");
    let n = &scratch.0;
    vcan_setup::up(n).expect("vcan must be available");
    socketcan::CanInterface::open(n)
        .expect("open")
        .bring_down()
        .expect("bring down");
    assert!(!vcan_setup::can_links().iter().any(|l| l.name == *n && l.up));
    assert_eq!(vcan_setup::up(n).expect("up"), UpOutcome::RaisedExisting);
    assert!(vcan_setup::can_links().iter().any(|l| l.name == *n && l.up));
}

#[test]
fn refuses_non_can_interfaces_and_bad_names() {
    assert!(matches!(
        vcan_setup::up("lo"),
        Err(VcanError::NotCan { link_type: 772, .. })
    ));
    assert!(matches!(
        vcan_setup::up("a-name-much-too-long"),
        Err(VcanError::BadName { .. })
    ));
    assert!(matches!(
        vcan_setup::up("a/b"),
        Err(VcanError::BadName { .. })
    ));
}
