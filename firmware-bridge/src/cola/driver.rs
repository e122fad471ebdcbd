//! The driver loop: a scanner's scans, read with a [`ColaClient`], published as
//! [`LaserFrame`](crate::laser::LaserFrame)s on an iceoryx2 laser service with a
//! [`LaserPublisher`] until told to stop, a dropped connection retried once a second.
//! `ugv-sick` runs it on its main thread, the simulator on a thread of its own when a
//! run's laser is a CoLa-A device; each follows it through the [`DriverEvent`]s it
//! reports (`ugv-sick` logs them, the simulator keeps counts).
//!
//! The stop is a [`Receiver`]: a message, or its sender dropped, ends the loop (within
//! [`DriverConfig::poll`], or at once while waiting to reconnect).

use std::fmt;
use std::sync::mpsc::{Receiver, RecvTimeoutError};
use std::time::{Duration, Instant};

use super::{ClientStats, ColaClient, ColaError};
use crate::laser::{LaserError, LaserPublisher};

/// Between two connection attempts.
pub const RETRY_INTERVAL: Duration = Duration::from_secs(1);

/// How the loop runs.
#[derive(Clone, Debug, PartialEq)]
pub struct DriverConfig {
    /// The longest one wait for a scan blocks.
    pub poll: Duration,
    /// Reconnect a dropped connection (at once, then every [`RETRY_INTERVAL`] until it
    /// succeeds); `false`: end with the error.
    pub reconnect: bool,
    /// A silence this long is reported, once ([`DriverEvent::Silent`]).
    pub frame_timeout: Duration,
    /// Stop after publishing this many scans.
    pub count: Option<u64>,
}

impl Default for DriverConfig {
    fn default() -> Self {
        DriverConfig {
            poll: Duration::from_millis(100),
            reconnect: true,
            frame_timeout: Duration::from_secs(2),
            count: None,
        }
    }
}

/// Counts since the loop started, and the client's own.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DriverStats {
    /// Scans published.
    pub published: u64,
    /// Scans the publisher refused or could not deliver.
    pub publish_errors: u64,
    /// Telegrams that did not parse or convert (skipped).
    pub bad: u64,
    /// The client's counters (lost scans, connections, ...).
    pub client: ClientStats,
}

/// What one turn of the loop did.
#[derive(Debug)]
pub enum DriverEvent<'a> {
    /// A scan was published.
    Published { sequence: u64 },
    /// A scan could not be published; the loop goes on.
    PublishFailed { sequence: u64, error: LaserError },
    /// No scan within [`DriverConfig::poll`].
    Idle,
    /// No scan for [`DriverConfig::frame_timeout`] (said once per silence).
    Silent { since: Duration },
    /// A telegram that did not parse or convert; the loop goes on with the next.
    Bad(ColaError),
    /// The connection dropped; reconnecting.
    Lost(&'a ColaError),
    /// A reconnect failed; the next attempt after [`RETRY_INTERVAL`].
    ReconnectFailed(&'a ColaError),
    /// Connected again.
    Reconnected,
}

impl DriverEvent<'_> {
    /// The error this event reports, if any.
    pub fn error(&self) -> Option<&dyn fmt::Display> {
        match self {
            DriverEvent::PublishFailed { error, .. } => Some(error),
            DriverEvent::Bad(e) => Some(e),
            DriverEvent::Lost(e) | DriverEvent::ReconnectFailed(e) => Some(*e),
            DriverEvent::Published { .. }
            | DriverEvent::Idle
            | DriverEvent::Silent { .. }
            | DriverEvent::Reconnected => None,
        }
    }
}

/// Whether `stop` says stop within `wait`: a message, or its sender gone.
pub fn stopped(stop: &Receiver<()>, wait: Duration) -> bool {
    match stop.recv_timeout(wait) {
        Ok(()) | Err(RecvTimeoutError::Disconnected) => true,
        Err(RecvTimeoutError::Timeout) => false,
    }
}

/// Run `attempt` (a connect or reconnect) until it succeeds: at once, then every
/// [`RETRY_INTERVAL`], each failure given to `failed`. `false`: stopped first.
pub fn retry(
    stop: &Receiver<()>,
    mut attempt: impl FnMut() -> Result<(), ColaError>,
    mut failed: impl FnMut(&ColaError),
) -> bool {
    loop {
        match attempt() {
            Ok(()) => return true,
            Err(e) => failed(&e),
        }
        if stopped(stop, RETRY_INTERVAL) {
            return false;
        }
    }
}

/// Publish `client`'s scans with `publisher` until `stop` (or [`DriverConfig::count`]
/// scans), telling `watch` what each turn did. The error is a dropped connection
/// when [`DriverConfig::reconnect`] is off; otherwise it ends with the counts.
pub fn drive(
    client: &mut ColaClient,
    publisher: &LaserPublisher,
    config: &DriverConfig,
    stop: &Receiver<()>,
    mut watch: impl FnMut(&DriverEvent<'_>, &DriverStats),
) -> Result<DriverStats, ColaError> {
    let mut stats = DriverStats::default();
    let mut last_frame = Instant::now();
    let mut silent = false;
    while !stopped(stop, Duration::ZERO) {
        let event = match client.next_frame(config.poll) {
            Ok(Some(frame)) => {
                last_frame = Instant::now();
                silent = false;
                match publisher.publish(&frame) {
                    Ok(_) => {
                        stats.published += 1;
                        DriverEvent::Published {
                            sequence: frame.sequence,
                        }
                    }
                    Err(error) => {
                        stats.publish_errors += 1;
                        DriverEvent::PublishFailed {
                            sequence: frame.sequence,
                            error,
                        }
                    }
                }
            }
            Ok(None) if !silent && last_frame.elapsed() >= config.frame_timeout => {
                silent = true;
                DriverEvent::Silent {
                    since: last_frame.elapsed(),
                }
            }
            Ok(None) => DriverEvent::Idle,
            Err(e @ (ColaError::ConnectionLost { .. } | ColaError::Io { .. })) => {
                if !config.reconnect {
                    return Err(e);
                }
                stats.client = client.stats();
                watch(&DriverEvent::Lost(&e), &stats);
                let now = stats;
                if !retry(
                    stop,
                    || client.reconnect(),
                    |e| watch(&DriverEvent::ReconnectFailed(e), &now),
                ) {
                    break;
                }
                last_frame = Instant::now();
                silent = false;
                DriverEvent::Reconnected
            }
            Err(e) => {
                stats.bad += 1;
                DriverEvent::Bad(e)
            }
        };
        stats.client = client.stats();
        watch(&event, &stats);
        if config.count.is_some_and(|n| stats.published >= n) {
            break;
        }
    }
    stats.client = client.stats();
    Ok(stats)
}
