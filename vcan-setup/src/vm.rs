//! Run a command inside a throwaway VM whose stock distribution kernel has CAN.
//!
//! virtme-ng (`vng`) boots the kernel under QEMU with the host's root filesystem
//! shared read-only, the working directory writable (`--rwdir`), and the same working
//! directory. Inside, this same binary (`vcan-setup vm-guest`) brings up the vcan
//! interfaces and runs the command; its exit code is written to a host directory
//! shared with the guest, so a VM that failed to boot is told apart from a command
//! that failed.
//!
//! Quirks of vng handled here: stdin must be open (it is /dev/null), stdout and
//! stderr must be pipes (QEMU reopens file descriptors with truncation), and the
//! guest does not inherit the environment (the toolchain's variables are passed).
//! Some hosts offer /dev/kvm and then hang the guest at boot: a KVM boot that has not
//! reached the guest within [`KVM_BOOT_LIMIT`] is stopped and the software-emulated
//! boot follows.

use std::ffi::OsString;
use std::io::{Read, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::VcanError;

/// How to install the prerequisites on Debian/Ubuntu.
pub const INSTALL_HINT: &str = "bash scripts/install-deps.sh installs all of it; by hand: apt-get install linux-image-amd64 qemu-system-x86 busybox-static can-utils, pip install virtme-ng";

/// Environment variables passed into the guest (exact names, or prefixes ending in `*`).
const PASS_ENV: &[&str] = &[
    "PATH",
    "HOME",
    "USER",
    "LANG",
    "LC_*",
    "TERM",
    "CARGO*",
    "RUST*",
    "NEXTEST*",
    "CI",
    "PYENV*",
    "PYTHON*",
    "VIRTUAL_ENV",
    "UGV_*",
];

/// Whether to use KVM.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Accel {
    /// KVM when /dev/kvm is usable, falling back to software emulation if the VM
    /// does not come up with it.
    Auto,
    /// Hardware virtualisation only.
    Kvm,
    /// Software emulation (QEMU TCG): slower, works everywhere.
    Tcg,
}

/// Arguments of `vcan-setup vm`.
#[derive(Debug, Clone, clap::Args)]
pub struct VmArgs {
    /// Kernel image to boot; default: the newest /boot/vmlinuz-* that has a vcan module.
    #[arg(long, value_name = "VMLINUZ")]
    pub kernel: Option<PathBuf>,
    /// CAN interfaces to create and bring up inside (vcan0 always).
    #[arg(long = "iface", value_name = "NAME")]
    pub ifaces: Vec<String>,
    /// Guest memory: a size with a unit (512M, 2G), 128M to 1024G.
    #[arg(long, default_value = "2G", value_parser = memory_size)]
    pub memory: String,
    /// Guest CPUs, 1 to 256; default: as many as the host has.
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=256))]
    pub cpus: Option<usize>,
    /// Further host directories the guest may write (the working directory always).
    #[arg(long, value_name = "DIR")]
    pub rwdir: Vec<PathBuf>,
    /// Hardware virtualisation.
    #[arg(long, value_enum, default_value_t = Accel::Auto)]
    pub accel: Accel,
    /// The niceness QEMU runs at on the host, -20 to 19: below 0 its vCPUs keep
    /// their share while the host is busy (a build, a fuzzer), which the guest's
    /// real-time runs need, above all under software emulation. Raising priority
    /// needs root or CAP_SYS_NICE; without, `nice` says so and the VM runs at 0.
    #[arg(long, default_value_t = -10, allow_hyphen_values = true,
          value_parser = clap::value_parser!(i8).range(-20..=19))]
    pub host_nice: i8,
    /// The round-robin real-time priority QEMU runs at on the host (SCHED_RR, 1-99;
    /// 0 leaves it to `--host-nice`). A busy host cannot then take a vCPU away for
    /// longer than the kernel's real-time throttling allows (50 ms a second while
    /// the guest keeps its CPUs busy), where a niceness still loses slices to every
    /// runnable process. Needs root or CAP_SYS_NICE; without, the VM runs at
    /// `--host-nice` and says so.
    #[arg(long, default_value_t = 10,
          value_parser = clap::value_parser!(u8).range(0..=99))]
    pub host_rt: u8,
    /// The command and its arguments.
    #[arg(last = true, required = true, value_name = "CMD")]
    pub command: Vec<OsString>,
}

/// `--memory`: digits and a unit (K, M, G or T, as QEMU takes them), 128 MiB to
/// 1 TiB; the text as given.
fn memory_size(text: &str) -> Result<String, String> {
    let refuse = || "give a size with a unit (512M, 2G) from 128M to 1024G".to_owned();
    let split = text
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(text.len());
    let (digits, unit) = text.split_at(split);
    let shift = match unit {
        "K" | "k" => 10,
        "M" | "m" => 20,
        "G" | "g" => 30,
        "T" | "t" => 40,
        _ => return Err(refuse()),
    };
    let bytes = digits
        .parse::<u64>()
        .ok()
        .and_then(|n| n.checked_mul(1u64 << shift))
        .ok_or_else(refuse)?;
    if ((128u64 << 20)..=(1u64 << 40)).contains(&bytes) {
        Ok(text.to_owned())
    } else {
        Err(refuse())
    }
}

/// Arguments of the hidden `vcan-setup vm-guest` (what runs inside the VM).
#[derive(Debug, Clone, clap::Args)]
pub struct GuestArgs {
    #[arg(long = "iface", value_name = "NAME")]
    pub ifaces: Vec<String>,
    /// Host directory (shared) to write the exit code into.
    #[arg(long)]
    pub status_dir: PathBuf,
    #[arg(long)]
    pub cwd: PathBuf,
    #[arg(last = true, required = true)]
    pub command: Vec<OsString>,
}

fn find_in_path(tool: &str) -> Option<PathBuf> {
    std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|p| p.join(tool))
            .find(|p| p.is_file())
    })
}

fn missing(tool: &str, package: &str) -> VcanError {
    VcanError::Vm(format!(
        "{tool} not found on PATH: install {package} ({INSTALL_HINT})"
    ))
}

/// The newest installed kernel image whose modules include vcan.
pub fn default_kernel() -> Result<PathBuf, VcanError> {
    let mut candidates: Vec<(String, PathBuf)> = std::fs::read_dir("/boot")
        .map_err(|source| VcanError::Io {
            what: "listing /boot".to_owned(),
            source,
        })?
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let release = name.strip_prefix("vmlinuz-")?.to_owned();
            let modules = PathBuf::from("/lib/modules").join(&release);
            crate::find_module(&modules.join("kernel/drivers/net/can"), "vcan")?;
            Some((release, e.path()))
        })
        .collect();
    candidates.sort_by_key(|c| version_key(&c.0));
    candidates.pop().map(|(_, p)| p).ok_or_else(|| {
        VcanError::Vm(format!(
            "no kernel image in /boot with a vcan module under /lib/modules: install linux-image-amd64 ({INSTALL_HINT})"
        ))
    })
}

/// "6.1.0-56-amd64" -> [6, 1, 0, 56]: numeric parts for ordering releases.
fn version_key(release: &str) -> Vec<u64> {
    release
        .split(|c: char| !c.is_ascii_digit())
        .filter_map(|p| p.parse().ok())
        .collect()
}

/// The file the guest leaves in the status directory once it runs (before the command).
const BOOTED: &str = "booted";

/// How long a KVM boot may take to reach the guest before it counts as hung; the
/// software-emulated attempt follows. KVM boots in seconds, where it works at all.
const KVM_BOOT_LIMIT: Duration = Duration::from_secs(60);

fn kvm_usable() -> bool {
    std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open("/dev/kvm")
        .is_ok()
}

fn guest_env() -> Vec<OsString> {
    std::env::vars_os()
        .filter(|(k, v)| {
            let k = k.to_string_lossy();
            let v = v.to_string_lossy();
            !v.contains('\n')
                && PASS_ENV.iter().any(|p| match p.strip_suffix('*') {
                    Some(prefix) => k.starts_with(prefix),
                    None => k == *p,
                })
        })
        .map(|(k, v)| {
            let mut kv = k;
            kv.push("=");
            kv.push(v);
            kv
        })
        .collect()
}

/// Copy a child's pipe to ours as it comes.
fn forward(mut from: impl Read + Send + 'static, to_stderr: bool) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let mut buf = [0u8; 8192];
        while let Ok(n) = from.read(&mut buf) {
            if n == 0 {
                break;
            }
            let written = if to_stderr {
                std::io::stderr().write_all(&buf[..n])
            } else {
                std::io::stdout().write_all(&buf[..n])
            };
            if written.is_err() {
                break;
            }
        }
    })
}

/// The SCHED_RR priority to start QEMU at: `None` when asked for none, or when the
/// host refuses it (no CAP_SYS_NICE, no chrt), which is said on stderr.
fn host_rt(prio: u8) -> Option<u8> {
    if prio == 0 {
        return None;
    }
    let probe = Command::new("chrt")
        .args(["--rr", &prio.to_string(), "true"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .output();
    let refused = match probe {
        Ok(out) if out.status.success() => return Some(prio),
        Ok(out) => String::from_utf8_lossy(&out.stderr).trim().to_owned(),
        Err(e) => format!("chrt: {e}"),
    };
    eprintln!(
        "vcan-setup: QEMU cannot run at SCHED_RR {prio} on this host ({refused}); it runs at its niceness"
    );
    None
}

/// One boot: `Ok(Some(code))` when the guest ran the command, `Ok(None)` when the VM
/// did not get that far.
fn boot(
    args: &VmArgs,
    vng: &Path,
    kernel: &Path,
    kvm: bool,
    status_dir: &Path,
) -> Result<Option<u8>, VcanError> {
    let mut cmd = vng_command(args, vng, kernel, kvm, status_dir)?;
    let mut child = cmd.spawn().map_err(|source| VcanError::Io {
        what: format!("starting {} through chrt and nice", vng.display()),
        source,
    })?;
    let out = child.stdout.take().map(|o| forward(o, false));
    let err = child.stderr.take().map(|e| forward(e, true));
    let status = wait_for_vm(&mut child, kvm, status_dir)?;
    for handle in [out, err].into_iter().flatten() {
        let _ = handle.join();
    }
    let recorded = std::fs::read_to_string(status_dir.join("exit-code"))
        .ok()
        .and_then(|s| s.trim().parse::<u8>().ok());
    if recorded.is_none() {
        eprintln!(
            "vcan-setup: the VM exited ({status}) without running the command{}",
            if kvm { " (with KVM)" } else { "" }
        );
    }
    Ok(recorded)
}

/// The command that boots the VM: vng (under chrt and nice) running `kernel` with
/// the working directory, the `--rwdir`s and `status_dir` writable, and this binary's
/// `vm-guest` inside, which sets up the interfaces and runs the command.
fn vng_command(
    args: &VmArgs,
    vng: &Path,
    kernel: &Path,
    kvm: bool,
    status_dir: &Path,
) -> Result<Command, VcanError> {
    let cwd = std::env::current_dir().map_err(|source| VcanError::Io {
        what: "reading the working directory".to_owned(),
        source,
    })?;
    let me = std::env::current_exe().map_err(|source| VcanError::Io {
        what: "locating vcan-setup itself".to_owned(),
        source,
    })?;
    let mut cmd = prioritised(args);
    cmd.arg(vng);
    cmd.arg("--run").arg(kernel);
    if !kvm {
        cmd.arg("--disable-kvm");
    }
    cmd.args(["--memory", &args.memory]);
    let cpus = args
        .cpus
        .or_else(|| std::thread::available_parallelism().ok().map(|n| n.get()))
        .unwrap_or(1);
    cmd.args(["--cpus", &cpus.to_string()]);
    for dir in std::iter::once(&cwd)
        .chain(&args.rwdir)
        .chain(std::iter::once(&status_dir.to_path_buf()))
    {
        cmd.arg("--rwdir").arg(dir);
    }
    cmd.arg("--")
        .arg("env")
        .args(guest_env())
        .arg(me)
        .arg("vm-guest");
    let mut ifaces = vec!["vcan0".to_owned()];
    ifaces.extend(args.ifaces.iter().filter(|i| *i != "vcan0").cloned());
    for iface in &ifaces {
        cmd.args(["--iface", iface]);
    }
    cmd.arg("--status-dir")
        .arg(status_dir)
        .arg("--cwd")
        .arg(&cwd)
        .arg("--")
        .args(&args.command);
    // vng's own bin directory must be on PATH (it executes virtme-run beside it).
    if let Some(dir) = vng.parent() {
        let mut paths = vec![dir.to_path_buf()];
        if let Some(p) = std::env::var_os("PATH") {
            paths.extend(std::env::split_paths(&p));
        }
        if let Ok(joined) = std::env::join_paths(paths) {
            cmd.env("PATH", joined);
        }
    }
    cmd.stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    // A group of its own: a hung boot is stopped with vng's QEMU and all.
    cmd.process_group(0);
    Ok(cmd)
}

/// `nice -n HOST_NICE`, through util-linux's chrt when the host lets us, then
/// coreutils' nice, which runs the command even when it may not set the niceness
/// (and says why).
fn prioritised(args: &VmArgs) -> Command {
    let mut cmd = match host_rt(args.host_rt) {
        Some(prio) => {
            let mut c = Command::new("chrt");
            c.args(["--rr", &prio.to_string(), "nice"]);
            c
        }
        None => Command::new("nice"),
    };
    cmd.args(["-n", &args.host_nice.to_string()]);
    cmd
}

/// Wait for the VM to exit; with KVM, stop it when the guest has not started the
/// command within [`KVM_BOOT_LIMIT`] (some hosts offer /dev/kvm and hang the guest).
fn wait_for_vm(
    child: &mut std::process::Child,
    kvm: bool,
    status_dir: &Path,
) -> Result<std::process::ExitStatus, VcanError> {
    let waited = |e| VcanError::Io {
        what: "waiting for the VM".to_owned(),
        source: e,
    };
    let started = Instant::now();
    loop {
        if !kvm || status_dir.join(BOOTED).exists() {
            return child.wait().map_err(waited);
        }
        if let Some(status) = child.try_wait().map_err(waited)? {
            return Ok(status);
        }
        if started.elapsed() > KVM_BOOT_LIMIT {
            eprintln!(
                "vcan-setup: the KVM guest did not start the command within {} s (some hosts offer /dev/kvm and hang the guest); stopping it",
                KVM_BOOT_LIMIT.as_secs()
            );
            if let Ok(pid) = i32::try_from(child.id()) {
                let _ = nix::sys::signal::killpg(
                    nix::unistd::Pid::from_raw(pid),
                    nix::sys::signal::Signal::SIGKILL,
                );
            }
            return child.wait().map_err(waited);
        }
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// Boot the VM, run the command inside, and return its exit code.
pub fn run(args: &VmArgs) -> Result<u8, VcanError> {
    let vng = find_in_path("vng").ok_or_else(|| missing("vng", "virtme-ng (pip)"))?;
    find_in_path("qemu-system-x86_64")
        .ok_or_else(|| missing("qemu-system-x86_64", "qemu-system-x86"))?;
    find_in_path("busybox").ok_or_else(|| missing("busybox", "busybox-static"))?;
    let kernel = match &args.kernel {
        Some(k) if k.is_file() => k.clone(),
        Some(k) => {
            return Err(VcanError::Vm(format!(
                "kernel image {} does not exist",
                k.display()
            )));
        }
        None => default_kernel()?,
    };
    let status_dir = std::env::temp_dir().join(format!("vcan-setup-vm-{}", std::process::id()));
    std::fs::create_dir_all(&status_dir).map_err(|source| VcanError::Io {
        what: format!("creating {}", status_dir.display()),
        source,
    })?;
    let attempts: &[bool] = match args.accel {
        Accel::Kvm => &[true],
        Accel::Tcg => &[false],
        Accel::Auto if kvm_usable() => &[true, false],
        Accel::Auto => &[false],
    };
    let started = Instant::now();
    let mut result = None;
    for &kvm in attempts {
        result = boot(args, &vng, &kernel, kvm, &status_dir)?;
        if result.is_some() {
            break;
        }
    }
    let _ = std::fs::remove_dir_all(&status_dir);
    match result {
        Some(code) => {
            eprintln!(
                "vcan-setup: VM ({}) finished in {:.1} s, command exit code {code}",
                kernel.display(),
                started.elapsed().as_secs_f64()
            );
            Ok(code)
        }
        None => Err(VcanError::Vm(format!(
            "the VM booted from {} did not run the command; see its output above",
            kernel.display()
        ))),
    }
}

/// The guest's input backlog per CPU, frames (`net.core.netdev_max_backlog`, 1000 by
/// default). vcan hands every frame to the local sockets through this backlog, which
/// softirqs empty; in an emulated guest they fall behind while real-time loops catch
/// up after a stall, and a full backlog drops the frame for every reader at once.
pub const GUEST_BACKLOG: u32 = 10_000;

/// Inside the VM: say it booted, deepen the input backlog ([`GUEST_BACKLOG`]), bring
/// up the interfaces, run the command, record its exit code.
pub fn guest(args: &GuestArgs) -> Result<u8, VcanError> {
    std::fs::write(args.status_dir.join(BOOTED), b"").map_err(|source| VcanError::Io {
        what: format!("writing {} to {}", BOOTED, args.status_dir.display()),
        source,
    })?;
    let backlog = "/proc/sys/net/core/netdev_max_backlog";
    if let Err(e) = std::fs::write(backlog, GUEST_BACKLOG.to_string()) {
        // The tests still run; frames may be lost under load, as the verdicts say.
        eprintln!("vcan-setup: could not set {backlog} to {GUEST_BACKLOG}: {e}");
    }
    for iface in &args.ifaces {
        crate::up(iface)?;
    }
    let Some((program, rest)) = args.command.split_first() else {
        return Err(VcanError::Vm("no command to run in the VM".to_owned()));
    };
    let status = Command::new(program)
        .args(rest)
        .current_dir(&args.cwd)
        .status()
        .map_err(|source| VcanError::Io {
            what: format!("running {program:?} in the VM"),
            source,
        })?;
    // A command killed by a signal reports 128 + signal, as a shell would.
    let code = status.code().unwrap_or_else(|| {
        use std::os::unix::process::ExitStatusExt;
        128 + status.signal().unwrap_or(0)
    });
    let code = u8::try_from(code).unwrap_or(1);
    std::fs::write(args.status_dir.join("exit-code"), code.to_string()).map_err(|source| {
        VcanError::Io {
            what: format!("writing the exit code to {}", args.status_dir.display()),
            source,
        }
    })?;
    Ok(code)
}
