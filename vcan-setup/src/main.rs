//! `vcan-setup`: virtual CAN interfaces on this host, or a VM with CAN when the host
//! kernel has none.
//!
//! ```text
//! vcan-setup up [vcan0 ...]     create (loading the module) and raise; idempotent
//! vcan-setup down [vcan0 ...]   delete
//! vcan-setup status             kernel support, interfaces, what to do
//! vcan-setup vm -- CMD ...      run CMD in a throwaway VM with vcan0 up
//! ```

use std::process::ExitCode;

use anyhow::Result;
use clap::{Parser, Subcommand};
use vcan_setup::{KernelCan, UpOutcome};

#[derive(Parser, Debug)]
#[command(
    name = "vcan-setup",
    version,
    about = "Virtual CAN interfaces, natively or in a VM"
)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// Create vcan interfaces (loading the vcan module where needed) and bring them up.
    Up {
        #[arg(default_value = "vcan0")]
        names: Vec<String>,
    },
    /// Delete vcan interfaces.
    Down {
        #[arg(default_value = "vcan0")]
        names: Vec<String>,
    },
    /// Whether this kernel has CAN, which CAN interfaces exist, and what to do if none can.
    Status,
    /// Run a command inside a throwaway VM booted from a stock kernel with CAN modules,
    /// with the host filesystem visible, the same working directory, and vcan0 (plus
    /// any --iface) up. The command's output and exit code pass through.
    Vm(vcan_setup::vm::VmArgs),
    /// Inside the VM: bring up the interfaces and run the command (used by `vm`).
    #[command(hide = true)]
    VmGuest(vcan_setup::vm::GuestArgs),
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("vcan-setup: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> Result<ExitCode> {
    match cli.command {
        Cmd::Up { names } => {
            for name in names {
                let what = match vcan_setup::up(&name)? {
                    UpOutcome::Created => "created and up",
                    UpOutcome::RaisedExisting => "existed, now up",
                    UpOutcome::AlreadyUp => "already up",
                };
                println!("{name}: {what}");
            }
            Ok(ExitCode::SUCCESS)
        }
        Cmd::Down { names } => {
            for name in names {
                let what = if vcan_setup::down(&name)? {
                    "deleted"
                } else {
                    "did not exist"
                };
                println!("{name}: {what}");
            }
            Ok(ExitCode::SUCCESS)
        }
        Cmd::Status => {
            let s = vcan_setup::status();
            let kernel = match &s.kernel {
                KernelCan::Ready => "vcan ready".to_owned(),
                KernelCan::Module(p) => format!("vcan available as a module ({})", p.display()),
                KernelCan::Missing(why) => format!("no vcan: {why}"),
            };
            println!("kernel {}: {kernel}", s.release);
            if s.links.is_empty() {
                println!("CAN interfaces: none");
            } else {
                for l in &s.links {
                    println!(
                        "CAN interface {}: {} ({})",
                        l.name,
                        if l.up { "up" } else { "down" },
                        l.kind
                    );
                }
            }
            println!(
                "CAP_NET_ADMIN: {}",
                if s.net_admin {
                    "yes"
                } else {
                    "no (run as root to create interfaces)"
                }
            );
            match s.kernel {
                KernelCan::Missing(_) => {
                    println!(
                        "To use CAN here, run the command in a VM with a CAN-capable kernel:\n  vcan-setup vm -- <command>\nPrerequisites: {}",
                        vcan_setup::vm::INSTALL_HINT
                    );
                    Ok(ExitCode::from(1))
                }
                _ => {
                    if !s.links.iter().any(|l| l.up) {
                        println!("To create vcan0: vcan-setup up vcan0");
                    }
                    Ok(ExitCode::SUCCESS)
                }
            }
        }
        Cmd::Vm(args) => Ok(ExitCode::from(vcan_setup::vm::run(&args)?)),
        Cmd::VmGuest(args) => Ok(ExitCode::from(vcan_setup::vm::guest(&args)?)),
    }
}
