//! A private network namespace for one run, so no other process can open its CAN
//! interfaces.
//!
//! E2E on the golf car bus proves integrity, not origin, and opening a raw CAN socket
//! needs no privilege: any local user can send on a vcan of the host. A run isolated
//! in a namespace of its own has its vcan interfaces there, invisible to every
//! process outside it; joining it takes CAP_SYS_ADMIN (root).
//!
//! [`NetNs::enter`] makes a *named* namespace, the way `ip netns add` does (a bind
//! mount of the namespace on `/run/netns/NAME`), so a user can look in with
//! `ip netns exec NAME candump vcan0`, and moves the **calling thread** into it:
//! sockets it opens and processes it spawns from then on (the controller) live there,
//! as do threads it starts. Dropping the [`NetNs`] moves the thread back and removes
//! the name; the namespace, with its vcan interfaces, goes when the last socket and
//! process in it are gone.
//!
//! ```no_run
//! # fn main() -> Result<(), vcan_setup::VcanError> {
//! let ns = vcan_setup::netns::NetNs::enter("ugv-run-42")?;
//! ns.add_vcan("vcan0")?;
//! println!("candump: {}", ns.exec_line("candump vcan0"));
//! // ... open sockets, spawn the controller ...
//! drop(ns);
//! # Ok(()) }
//! ```

use std::fs::File;
use std::path::{Path, PathBuf};

use nix::errno::Errno;
use nix::mount::{MntFlags, MsFlags, mount, umount2};
use nix::sched::{CloneFlags, setns, unshare};
use socketcan::CanInterface;

use crate::VcanError;

/// Where named network namespaces live (iproute2's `NETNS_RUN_DIR`).
pub const NETNS_RUN_DIR: &str = "/run/netns";

/// The calling thread's network namespace.
const THREAD_NS: &str = "/proc/thread-self/ns/net";

/// A named network namespace the calling thread is in (see the module).
#[derive(Debug)]
pub struct NetNs {
    name: String,
    path: PathBuf,
    /// The thread's namespace before, to go back to.
    original: File,
}

/// A namespace name: 1 to 64 of `[A-Za-z0-9._-]`, not starting with a dot.
fn valid_name(name: &str) -> bool {
    (1..=64).contains(&name.len())
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
}

/// `text` made into a valid namespace name: other characters become `-`, cut to 64.
pub fn name_for(text: &str) -> String {
    let mut name: String = text
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-') {
                c
            } else {
                '-'
            }
        })
        .take(64)
        .collect();
    if name.starts_with('.') || name.is_empty() {
        name.replace_range(..name.len().min(1), "n");
    }
    name
}

/// An I/O error of `action`, a permission error named as one.
fn io_error(name: &str, action: &'static str, source: std::io::Error) -> VcanError {
    if source.kind() == std::io::ErrorKind::PermissionDenied {
        VcanError::NetnsPermission {
            name: name.to_owned(),
            action,
        }
    } else {
        VcanError::Netns {
            name: name.to_owned(),
            action,
            source,
        }
    }
}

fn ns_error(name: &str, action: &'static str, errno: Errno) -> VcanError {
    match errno {
        Errno::EPERM | Errno::EACCES => VcanError::NetnsPermission {
            name: name.to_owned(),
            action,
        },
        _ => VcanError::Netns {
            name: name.to_owned(),
            action,
            source: std::io::Error::from(errno),
        },
    }
}

/// Make the run directory a shared mount point, as iproute2 does, so namespaces
/// mounted there are seen from other mount namespaces too.
fn prepare_run_dir(name: &str) -> Result<(), VcanError> {
    std::fs::create_dir_all(NETNS_RUN_DIR)
        .map_err(|e| io_error(name, "creating /run/netns for", e))?;
    let shared = || {
        mount(
            None::<&str>,
            NETNS_RUN_DIR,
            Some("none"),
            MsFlags::MS_SHARED | MsFlags::MS_REC,
            None::<&str>,
        )
    };
    match shared() {
        Ok(()) => Ok(()),
        // Not a mount point yet: bind it onto itself, then share it.
        Err(Errno::EINVAL) => {
            mount(
                Some(NETNS_RUN_DIR),
                NETNS_RUN_DIR,
                Some("none"),
                MsFlags::MS_BIND | MsFlags::MS_REC,
                None::<&str>,
            )
            .map_err(|e| ns_error(name, "mounting /run/netns for", e))?;
            shared().map_err(|e| ns_error(name, "sharing /run/netns for", e))
        }
        Err(e) => Err(ns_error(name, "sharing /run/netns for", e)),
    }
}

impl NetNs {
    /// Create the network namespace `name` (`/run/netns/NAME`), move the calling
    /// thread into it and bring its loopback up. Needs CAP_SYS_ADMIN (root).
    pub fn enter(name: &str) -> Result<NetNs, VcanError> {
        if !valid_name(name) {
            return Err(VcanError::BadNetnsName {
                name: name.to_owned(),
            });
        }
        let original = File::open(THREAD_NS).map_err(|source| VcanError::Netns {
            name: name.to_owned(),
            action: "opening the thread's namespace before entering",
            source,
        })?;
        prepare_run_dir(name)?;
        let path = Path::new(NETNS_RUN_DIR).join(name);
        // The mount point: a new empty file (an existing one is another run's).
        match std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(_) => {}
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                return Err(VcanError::NetnsExists {
                    name: name.to_owned(),
                });
            }
            Err(e) => return Err(io_error(name, "creating the mount point of", e)),
        }
        let undo_file = |e: VcanError| {
            let _ = std::fs::remove_file(&path);
            e
        };
        unshare(CloneFlags::CLONE_NEWNET).map_err(|e| undo_file(ns_error(name, "creating", e)))?;
        let ns = NetNs {
            name: name.to_owned(),
            path: path.clone(),
            original,
        };
        // From here on dropping `ns` undoes everything (an unmounted path is fine).
        mount(
            Some(THREAD_NS),
            &path,
            Some("none"),
            MsFlags::MS_BIND,
            None::<&str>,
        )
        .map_err(|e| ns_error(name, "naming (bind-mounting)", e))?;
        // Loopback, for what a run serves on 127.0.0.1 (a CoLa-A laser).
        CanInterface::open("lo")
            .and_then(|lo| lo.bring_up())
            .map_err(|e| crate::netlink_error("bringing up the loopback of", name, e))?;
        Ok(ns)
    }

    /// The namespace's name (`ip netns exec NAME ...`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Its mount point, `/run/netns/NAME`.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The command line that runs `command` inside the namespace.
    pub fn exec_line(&self, command: &str) -> String {
        format!("sudo ip netns exec {} {command}", self.name)
    }

    /// Create the vcan interface `iface` in this namespace and bring it up. The
    /// calling thread must still be the one that entered it.
    pub fn add_vcan(&self, iface: &str) -> Result<(), VcanError> {
        crate::validate(iface)?;
        crate::ensure_vcan_driver()?;
        // Not through /sys/class/net: sysfs shows the namespace it was mounted in.
        let link = match CanInterface::create_vcan(iface, None) {
            Ok(link) => link,
            Err(e) => return Err(crate::netlink_error("creating", iface, e)),
        };
        link.bring_up()
            .map_err(|e| crate::netlink_error("bringing up", iface, e))
    }
}

impl Drop for NetNs {
    fn drop(&mut self) {
        let _ = setns(&self.original, CloneFlags::CLONE_NEWNET);
        let _ = umount2(&self.path, MntFlags::MNT_DETACH);
        let _ = std::fs::remove_file(&self.path);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_checked_and_made_valid() {
        assert!(valid_name("ugv-paper-1234"));
        assert!(valid_name("a.b_c-9"));
        for bad in ["", ".hidden", "a/b", "a b", "x".repeat(65).as_str(), "ü"] {
            assert!(!valid_name(bad), "{bad:?}");
        }
        assert_eq!(name_for("ugv-suite/paper 1"), "ugv-suite-paper-1");
        assert_eq!(name_for(".x"), "nx");
        assert_eq!(name_for(""), "n");
        assert!(valid_name(&name_for(&"é".repeat(100))));
        assert_eq!(name_for(&"a".repeat(100)).len(), 64);
    }

    #[test]
    fn a_bad_name_is_refused_before_anything_is_touched() {
        let err = NetNs::enter("../etc").err().map(|e| e.to_string());
        assert!(
            err.as_deref()
                .is_some_and(|e| e.contains("not a valid network namespace name")),
            "{err:?}"
        );
    }
}
