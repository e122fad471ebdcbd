//! vcan tooling: create, raise, delete and inspect virtual CAN interfaces over
//! netlink, and ([`vm`]) run a command inside a throwaway VM whose stock kernel has
//! CAN, for hosts whose kernel has none (WSL2, most CI runners, this project's own);
//! ([`netns`]) a private network namespace for a run's interfaces.

pub mod netns;
pub mod vm;

use std::path::{Path, PathBuf};
use std::process::Command;

use socketcan::CanInterface;

/// `ARPHRD_CAN`, the link type of CAN interfaces in /sys/class/net/*/type.
const ARPHRD_CAN: u32 = 280;

/// Errors of vcan management.
#[derive(Debug, thiserror::Error)]
pub enum VcanError {
    #[error("{name:?} is not a valid interface name (1 to 15 characters, no '/', ':' or spaces)")]
    BadName { name: String },
    #[error(
        "{action} {iface} needs CAP_NET_ADMIN: run as root (sudo vcan-setup ...) or give the binary cap_net_admin"
    )]
    PermissionDenied { action: &'static str, iface: String },
    #[error(
        "this kernel ({release}) has no vcan support ({detail}); on such a host run the command in a VM: vcan-setup vm -- <command>"
    )]
    NoKernelCan { release: String, detail: String },
    #[error("{iface} exists but is not a CAN interface (link type {link_type})")]
    NotCan { iface: String, link_type: u32 },
    #[error("{action} {iface}: {source}")]
    Netlink {
        action: &'static str,
        iface: String,
        #[source]
        source: socketcan::Error,
    },
    #[error(
        "{name:?} is not a valid network namespace name (1 to 64 of A-Z a-z 0-9 . _ -, not starting with a dot)"
    )]
    BadNetnsName { name: String },
    #[error(
        "{action} network namespace {name} needs CAP_SYS_ADMIN: run as root (sudo), or run without isolation"
    )]
    NetnsPermission { name: String, action: &'static str },
    #[error(
        "network namespace {name} exists already (another run, or one that did not clean up: sudo ip netns delete {name})"
    )]
    NetnsExists { name: String },
    #[error("{action} network namespace {name}: {source}")]
    Netns {
        name: String,
        action: &'static str,
        #[source]
        source: std::io::Error,
    },
    #[error("{0}")]
    Vm(String),
    #[error("{what}: {source}")]
    Io {
        what: String,
        #[source]
        source: std::io::Error,
    },
}

/// How the running kernel supports CAN.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KernelCan {
    /// The vcan driver is loaded or built in: interfaces can be created.
    Ready,
    /// The vcan module exists and will be loaded on demand.
    Module(PathBuf),
    /// Neither loaded, built in, nor installed as a module.
    Missing(String),
}

/// One CAN interface of the host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CanLink {
    pub name: String,
    pub up: bool,
    /// `vcan`, `can` (a real controller), `vxcan`, ... from the link's driver.
    pub kind: String,
}

/// What `status` reports.
#[derive(Debug, Clone)]
pub struct Status {
    pub release: String,
    pub kernel: KernelCan,
    pub links: Vec<CanLink>,
    pub net_admin: bool,
}

fn validate(name: &str) -> Result<(), VcanError> {
    let ok = !name.is_empty()
        && name.len() < 16
        && !name.contains(['/', ':', ' ', '\t', '\n'])
        && name != "."
        && name != "..";
    if ok {
        Ok(())
    } else {
        Err(VcanError::BadName {
            name: name.to_owned(),
        })
    }
}

/// The running kernel's release (`uname -r`).
pub fn kernel_release() -> String {
    std::fs::read_to_string("/proc/sys/kernel/osrelease")
        .map(|s| s.trim().to_owned())
        .unwrap_or_else(|_| "unknown".to_owned())
}

pub(crate) fn find_module(dir: &Path, stem: &str) -> Option<PathBuf> {
    let entries = std::fs::read_dir(dir).ok()?;
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            if let Some(found) = find_module(&path, stem) {
                return Some(found);
            }
        } else if path
            .file_name()
            .and_then(|n| n.to_str())
            .is_some_and(|n| n == format!("{stem}.ko") || n.starts_with(&format!("{stem}.ko.")))
        {
            return Some(path);
        }
    }
    None
}

/// Whether and how the running kernel supports vcan.
pub fn kernel_can() -> KernelCan {
    if Path::new("/sys/module/vcan").exists() {
        return KernelCan::Ready;
    }
    let release = kernel_release();
    let modules = PathBuf::from("/lib/modules").join(&release);
    let builtin = std::fs::read_to_string(modules.join("modules.builtin")).unwrap_or_default();
    if builtin.lines().any(|l| l.ends_with("/vcan.ko")) {
        return KernelCan::Ready;
    }
    match find_module(&modules.join("kernel/drivers/net/can"), "vcan") {
        Some(path) => KernelCan::Module(path),
        None if modules.exists() => KernelCan::Missing(format!(
            "no vcan module under {} and not built in",
            modules.display()
        )),
        None => KernelCan::Missing(format!(
            "no modules installed for it ({} is missing) and vcan is not loaded",
            modules.display()
        )),
    }
}

/// Whether this process holds CAP_NET_ADMIN (bit 12 of CapEff).
pub fn has_net_admin() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("CapEff:"))
                .and_then(|hex| u64::from_str_radix(hex.trim(), 16).ok())
        })
        .is_some_and(|caps| caps & (1 << 12) != 0)
}

fn read_u32(path: &Path) -> Option<u32> {
    std::fs::read_to_string(path).ok()?.trim().parse().ok()
}

fn link_kind(dir: &Path) -> String {
    std::fs::read_link(dir.join("device/driver"))
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .or_else(|| {
            // Virtual links have no device; uevent names the kind.
            std::fs::read_to_string(dir.join("uevent"))
                .ok()
                .and_then(|u| {
                    u.lines()
                        .find_map(|l| l.strip_prefix("DEVTYPE=").map(str::to_owned))
                })
        })
        .unwrap_or_else(|| "can".to_owned())
}

/// The CAN interfaces of the host.
pub fn can_links() -> Vec<CanLink> {
    let Ok(entries) = std::fs::read_dir("/sys/class/net") else {
        return Vec::new();
    };
    let mut links: Vec<CanLink> = entries
        .flatten()
        .filter(|e| read_u32(&e.path().join("type")) == Some(ARPHRD_CAN))
        .map(|e| {
            let dir = e.path();
            let flags = std::fs::read_to_string(dir.join("flags"))
                .ok()
                .and_then(|f| u32::from_str_radix(f.trim().trim_start_matches("0x"), 16).ok())
                .unwrap_or(0);
            CanLink {
                name: e.file_name().to_string_lossy().into_owned(),
                up: flags & 1 != 0,
                kind: link_kind(&dir),
            }
        })
        .collect();
    links.sort_by(|a, b| a.name.cmp(&b.name));
    links
}

/// The whole picture: kernel support, interfaces, privileges.
pub fn status() -> Status {
    Status {
        release: kernel_release(),
        kernel: kernel_can(),
        links: can_links(),
        net_admin: has_net_admin(),
    }
}

fn netlink_error(action: &'static str, iface: &str, source: socketcan::Error) -> VcanError {
    let errno = match &source {
        socketcan::Error::Nl(nl) => nl.errno(),
        socketcan::Error::Io(io) => io.raw_os_error(),
        _ => None,
    };
    match errno {
        Some(libc::EPERM) | Some(libc::EACCES) => VcanError::PermissionDenied {
            action,
            iface: iface.to_owned(),
        },
        _ => VcanError::Netlink {
            action,
            iface: iface.to_owned(),
            source,
        },
    }
}

fn existing(name: &str) -> Option<PathBuf> {
    let dir = PathBuf::from("/sys/class/net").join(name);
    dir.exists().then_some(dir)
}

/// What `up` did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpOutcome {
    Created,
    RaisedExisting,
    AlreadyUp,
}

/// Make sure the kernel can create vcan links, loading the module where needed.
fn ensure_vcan_driver() -> Result<(), VcanError> {
    match kernel_can() {
        KernelCan::Ready => Ok(()),
        KernelCan::Missing(detail) => Err(VcanError::NoKernelCan {
            release: kernel_release(),
            detail,
        }),
        KernelCan::Module(path) => {
            let out = Command::new("modprobe")
                .arg("vcan")
                .output()
                .map_err(|source| VcanError::Io {
                    what: "running modprobe vcan".to_owned(),
                    source,
                })?;
            if out.status.success() {
                // Raw CAN sockets need can and can-raw; the kernel loads them on the
                // first socket() too, this just makes it explicit.
                let _ = Command::new("modprobe").arg("can-raw").output();
                Ok(())
            } else if !has_net_admin() {
                Err(VcanError::PermissionDenied {
                    action: "loading the vcan module for",
                    iface: "vcan".to_owned(),
                })
            } else {
                Err(VcanError::NoKernelCan {
                    release: kernel_release(),
                    detail: format!(
                        "modprobe vcan failed for {}: {}",
                        path.display(),
                        String::from_utf8_lossy(&out.stderr).trim()
                    ),
                })
            }
        }
    }
}

/// Create `name` as a vcan interface if it does not exist, and bring it up.
/// Idempotent; loads the vcan module where needed.
pub fn up(name: &str) -> Result<UpOutcome, VcanError> {
    validate(name)?;
    let outcome = match existing(name) {
        Some(dir) => {
            let link_type = read_u32(&dir.join("type")).unwrap_or(0);
            if link_type != ARPHRD_CAN {
                return Err(VcanError::NotCan {
                    iface: name.to_owned(),
                    link_type,
                });
            }
            if can_links().iter().any(|l| l.name == name && l.up) {
                return Ok(UpOutcome::AlreadyUp);
            }
            UpOutcome::RaisedExisting
        }
        None => {
            ensure_vcan_driver()?;
            CanInterface::create_vcan(name, None)
                .map_err(|e| netlink_error("creating", name, e))?;
            UpOutcome::Created
        }
    };
    let iface = CanInterface::open(name).map_err(|e| netlink_error("opening", name, e))?;
    iface
        .bring_up()
        .map_err(|e| netlink_error("bringing up", name, e))?;
    Ok(outcome)
}

/// Delete the interface `name`; `Ok(false)` when it did not exist.
pub fn down(name: &str) -> Result<bool, VcanError> {
    validate(name)?;
    if existing(name).is_none() {
        return Ok(false);
    }
    let iface = CanInterface::open(name).map_err(|e| netlink_error("opening", name, e))?;
    iface
        .delete()
        .map_err(|(_, e)| netlink_error("deleting", name, e))?;
    Ok(true)
}
