//! Real-time scheduling for the loops that keep deadlines: the simulator's tick, the
//! controller's 10 ms command loop, a standalone ECU.
//!
//! A loop that misses its deadline on a busy machine trips a watchdog (the ECUs' 100
//! ms command timeout, the controller's 250 ms laser silence) although nothing is
//! wrong with the code under test: in a loaded VM the planner thread, the recorder and
//! the test harness share two CPUs with it. [`promote`] moves the calling thread to
//! `SCHED_FIFO` at a priority, so it preempts every ordinary thread, with
//! `SCHED_RESET_ON_FORK`: threads and processes it starts afterwards begin as ordinary
//! ones (a controller child, a planner thread) and choose for themselves. The loops
//! sleep to absolute deadlines between ticks, and the kernel's real-time throttling
//! (95 % of each second by default) bounds what a runaway could take.
//!
//! Needs root or CAP_SYS_NICE (or an RLIMIT_RTPRIO); without, the loop runs as an
//! ordinary thread and the caller says so ([`Promotion::describe`]).
//!
//! The workspace denies unsafe code; this module is the one exception, for three libc
//! calls nix does not wrap (sched_setscheduler, sched_getscheduler, sched_getparam),
//! each on the calling thread with a parameter that lives across the call.
#![allow(unsafe_code)]

/// The priority the binaries use when not told otherwise: above the kernel's
/// threaded interrupt handlers' default of 50 would starve the CAN and network
/// softirqs the loops depend on, so below it.
pub const DEFAULT_PRIORITY: u8 = 40;

/// The highest SCHED_FIFO priority Linux accepts.
pub const MAX_PRIORITY: u8 = 99;

/// What became of a request for real-time scheduling.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Promotion {
    /// Not asked for (priority 0).
    Off,
    /// The thread runs SCHED_FIFO at this priority.
    Fifo(u8),
    /// The kernel refused (the reason): the thread runs as before.
    Refused(String),
}

impl Promotion {
    /// One line for the log: what the loop runs at.
    pub fn describe(&self, what: &str) -> String {
        match self {
            Promotion::Off => format!("{what}: ordinary scheduling (real-time priority 0)"),
            Promotion::Fifo(p) => format!("{what}: SCHED_FIFO priority {p}"),
            Promotion::Refused(why) => format!(
                "{what}: ordinary scheduling, real-time priority refused ({why}; needs root or CAP_SYS_NICE)"
            ),
        }
    }
}

/// The command-line value of a real-time priority: 0 (off) to [`MAX_PRIORITY`].
pub fn parse_priority(text: &str) -> Result<u8, String> {
    match text.trim().parse::<u8>() {
        Ok(p) if p <= MAX_PRIORITY => Ok(p),
        _ => Err(format!(
            "{text:?} is not a real-time priority: a whole number from 0 (off) to {MAX_PRIORITY}"
        )),
    }
}

/// The calling thread at real-time priority until this is dropped, when it gets its
/// scheduling back (a suite's worker thread goes on to its next item as before).
#[derive(Debug)]
#[must_use = "the thread returns to its scheduling when this is dropped"]
pub struct Realtime {
    pub promotion: Promotion,
    previous: (i32, i32),
}

impl Drop for Realtime {
    fn drop(&mut self) {
        if let Promotion::Fifo(_) = self.promotion {
            let param = libc::sched_param {
                sched_priority: self.previous.1,
            };
            // SAFETY: as in `promote`; restoring the policy the thread had.
            unsafe { libc::sched_setscheduler(0, self.previous.0, &param) };
        }
    }
}

/// Run the calling thread SCHED_FIFO at `priority` (0: leave it as it is), threads
/// and processes it starts from now on reset to ordinary scheduling.
pub fn promote(priority: u8) -> Realtime {
    let previous = current();
    let promotion = if priority == 0 {
        Promotion::Off
    } else if priority > MAX_PRIORITY {
        Promotion::Refused(format!("priority {priority} is above {MAX_PRIORITY}"))
    } else {
        let param = libc::sched_param {
            sched_priority: i32::from(priority),
        };
        // SAFETY: sched_setscheduler reads the sched_param we pass by reference for
        // the duration of the call; pid 0 is the calling thread.
        let rc = unsafe {
            libc::sched_setscheduler(0, libc::SCHED_FIFO | libc::SCHED_RESET_ON_FORK, &param)
        };
        if rc == 0 {
            Promotion::Fifo(priority)
        } else {
            Promotion::Refused(std::io::Error::last_os_error().to_string())
        }
    };
    Realtime {
        promotion,
        previous,
    }
}

/// The calling thread's scheduling policy and priority, as the kernel reports them
/// (`SCHED_RESET_ON_FORK` masked off).
pub fn current() -> (i32, i32) {
    // SAFETY: both calls only read the calling thread's attributes; `param` outlives
    // the call that fills it.
    unsafe {
        let policy = libc::sched_getscheduler(0) & !libc::SCHED_RESET_ON_FORK;
        let mut param = libc::sched_param { sched_priority: 0 };
        libc::sched_getparam(0, &mut param);
        (policy, param.sched_priority)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn priorities_are_bounded_with_a_clear_error() {
        assert_eq!(parse_priority("0"), Ok(0));
        assert_eq!(parse_priority("99"), Ok(99));
        for bad in ["100", "-1", "1e3", "", "forty"] {
            let e = parse_priority(bad).unwrap_err();
            assert!(e.contains("0 (off) to 99"), "{bad}: {e}");
        }
    }

    #[test]
    fn priority_zero_leaves_the_thread_alone() {
        let before = current();
        let (p, now) = std::thread::spawn(|| {
            let rt = promote(0);
            (rt.promotion.clone(), current())
        })
        .join()
        .unwrap();
        assert_eq!(p, Promotion::Off);
        assert_eq!(now, before);
    }

    /// As root (this machine's tests run as root, CI too) the thread goes SCHED_FIFO,
    /// a thread it starts meanwhile is ordinary, and the thread is ordinary again once
    /// the guard is dropped; unprivileged, the refusal is reported and the thread is
    /// unchanged. Either way in a thread of its own.
    #[test]
    fn a_promoted_thread_runs_fifo_its_children_start_ordinary_and_it_returns() {
        let (promotion, before, during, child, after) = std::thread::spawn(|| {
            let before = current();
            let rt = promote(DEFAULT_PRIORITY);
            let during = current();
            let child = std::thread::spawn(current).join().unwrap();
            let promotion = rt.promotion.clone();
            drop(rt);
            (promotion, before, during, child, current())
        })
        .join()
        .unwrap();
        assert_eq!(after, before, "the thread did not get its scheduling back");
        match promotion {
            Promotion::Fifo(p) => {
                assert_eq!(during, (libc::SCHED_FIFO, i32::from(p)));
                assert_eq!(child, (libc::SCHED_OTHER, 0));
            }
            // Refused without the privilege (or, for root too, in a container or
            // cgroup without a real-time budget): the thread runs on unchanged.
            Promotion::Refused(why) => {
                assert_eq!(during, before, "a refused promotion changed the thread");
                assert_eq!(child, before, "a refused promotion changed the child");
                assert!(!why.is_empty(), "a refusal says why");
            }
            Promotion::Off => panic!("asked for {DEFAULT_PRIORITY}, got Off"),
        }
    }
}
