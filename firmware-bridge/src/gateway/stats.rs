//! What the gateway counts: per direction, per message, per reason a frame stayed
//! local, transmit retries, and the per-frame latency as a histogram.

use std::collections::BTreeMap;
use std::time::Duration;

use super::routing::{LocalReason, RoutingTable, Side};

/// Sub-buckets per power of two (relative resolution 1/32, about 3 %).
const SUB_BITS: u32 = 5;
const SUB: usize = 1 << SUB_BITS;
/// Values below this many nanoseconds get a bucket each.
const LINEAR: u64 = 2 * SUB as u64;
const BUCKETS: usize = LINEAR as usize + (64 - SUB_BITS as usize - 1) * SUB;

/// A latency histogram with about 3 % resolution over the whole u64 nanosecond range
/// (fixed size, no allocation per sample).
#[derive(Debug, Clone)]
pub struct Histogram {
    counts: Vec<u64>,
    samples: u64,
    sum_ns: u128,
    max_ns: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            counts: vec![0; BUCKETS],
            samples: 0,
            sum_ns: 0,
            max_ns: 0,
        }
    }
}

fn bucket_of(ns: u64) -> usize {
    if ns < LINEAR {
        return ns as usize;
    }
    let exp = 63 - ns.leading_zeros(); // >= SUB_BITS + 1
    let sub = (ns >> (exp - SUB_BITS)) as usize & (SUB - 1);
    LINEAR as usize + (exp - SUB_BITS - 1) as usize * SUB + sub
}

/// The smallest value of a bucket.
fn bucket_floor(bucket: usize) -> u64 {
    if bucket < LINEAR as usize {
        return bucket as u64;
    }
    let k = bucket - LINEAR as usize;
    let exp = (k / SUB) as u32 + SUB_BITS + 1;
    let sub = (k % SUB) as u64;
    (SUB as u64 + sub) << (exp - SUB_BITS)
}

impl Histogram {
    /// Add one sample.
    pub fn record(&mut self, d: Duration) {
        let ns = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        if let Some(c) = self.counts.get_mut(bucket_of(ns)) {
            *c += 1;
        }
        self.samples += 1;
        self.sum_ns += u128::from(ns);
        self.max_ns = self.max_ns.max(ns);
    }

    /// The value at quantile `q` (0..=1), nanoseconds: the floor of the bucket that
    /// holds it (exact to within 3 %); 0 without samples.
    pub fn quantile_ns(&self, q: f64) -> u64 {
        if self.samples == 0 {
            return 0;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.samples as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (bucket, count) in self.counts.iter().enumerate() {
            seen += count;
            if seen >= rank {
                return bucket_floor(bucket).min(self.max_ns);
            }
        }
        self.max_ns
    }

    /// The summary that goes into the stats.
    pub fn summary(&self) -> LatencySummary {
        let us = |ns: u64| ns as f64 / 1e3;
        LatencySummary {
            samples: self.samples,
            p50_us: us(self.quantile_ns(0.50)),
            p90_us: us(self.quantile_ns(0.90)),
            p99_us: us(self.quantile_ns(0.99)),
            max_us: us(self.max_ns),
            mean_us: if self.samples == 0 {
                0.0
            } else {
                self.sum_ns as f64 / self.samples as f64 / 1e3
            },
        }
    }
}

/// Quantiles of a latency, microseconds.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct LatencySummary {
    /// Number of frames measured.
    pub samples: u64,
    pub p50_us: f64,
    pub p90_us: f64,
    pub p99_us: f64,
    pub max_us: f64,
    pub mean_us: f64,
}

/// Frames that stayed on the bus they were read from, by reason.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct LocalCounts {
    /// IDs the DBC does not define (29-bit IDs included).
    pub unknown_id: u64,
    /// Sender lives on the other side (an echo).
    pub sender_on_other_side: u64,
    /// No receiver on the other side.
    pub no_receiver_across: u64,
    /// Malformed: data length other than 8.
    pub wrong_dlc: u64,
    /// Malformed: remote frames.
    pub remote: u64,
    /// Malformed: error frames.
    pub error_frame: u64,
    /// Malformed: FAULT_REPORT whose Source names no node.
    pub unknown_source: u64,
}

impl LocalCounts {
    fn add(&mut self, reason: LocalReason) {
        let c = match reason {
            LocalReason::UnknownId => &mut self.unknown_id,
            LocalReason::SenderOnOtherSide => &mut self.sender_on_other_side,
            LocalReason::NoReceiverAcross => &mut self.no_receiver_across,
            LocalReason::WrongDlc => &mut self.wrong_dlc,
            LocalReason::Remote => &mut self.remote,
            LocalReason::ErrorFrame => &mut self.error_frame,
            LocalReason::UnknownSource => &mut self.unknown_source,
        };
        *c += 1;
    }

    /// All frames kept local.
    pub fn total(&self) -> u64 {
        self.unknown_id
            + self.sender_on_other_side
            + self.no_receiver_across
            + self.wrong_dlc
            + self.remote
            + self.error_frame
            + self.unknown_source
    }

    /// The malformed ones (wrong DLC, remote, error frames, unknown source).
    pub fn malformed(&self) -> u64 {
        self.wrong_dlc + self.remote + self.error_frame + self.unknown_source
    }
}

/// Counts of one DBC message in one direction.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct MessageCounts {
    /// Sent on the other side.
    pub forwarded: u64,
    /// Kept on the side it was read from (any reason).
    pub local: u64,
}

/// One direction of the gateway: frames read on `from`, forwarded to `to`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DirectionStats {
    /// The interface frames are read from.
    pub from: String,
    /// The interface they are forwarded to.
    pub to: String,
    /// The side frames are read from.
    pub from_side: Side,
    /// Frames read on `from`.
    pub received: u64,
    /// Frames sent on `to`.
    pub forwarded: u64,
    /// Frames kept on `from`, by reason.
    pub local: LocalCounts,
    /// Per DBC message name (messages never seen are listed with zeros).
    pub messages: BTreeMap<String, MessageCounts>,
    /// Transmit attempts that found the queue full (ENOBUFS/EAGAIN) and were retried.
    pub tx_retries: u64,
    /// Frames given up after the transmit queue stayed full (or the interface down)
    /// for `tx_give_up_ms`: counted, logged, never silent.
    pub tx_dropped: u64,
    /// Frames the kernel dropped because the gateway's receive queue was full (from
    /// SO_RXQ_OVFL with each frame, and SO_MEMINFO when the bus is idle and at stop).
    pub rx_overflow: u64,
    /// Receive errors other than timeouts (each logged).
    pub rx_errors: u64,
    /// Frames that came with the kernel's receive timestamp (SO_TIMESTAMPNS).
    pub kernel_timestamps: u64,
    /// Latency from the kernel's receive timestamp (wall clock, SO_TIMESTAMPNS; the
    /// monotonic read time when the kernel gave none) to the end of the transmit call:
    /// time queued in the gateway's socket plus its handling. The transmit call
    /// includes the kernel's delivery to local sockets, so a receiver on the same host
    /// may already hold the frame when it returns.
    pub latency: LatencySummary,
    /// Latency from the gateway's read returning to the end of the transmit call
    /// (monotonic clock): the gateway's own handling, retries included.
    pub handling: LatencySummary,
}

/// A snapshot of the gateway (what [`super::GatewayHandle::stats`] returns and the
/// binary prints as JSON).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GatewayStats {
    /// The simulator's interface.
    pub sim_iface: String,
    /// The physical interface.
    pub physical_iface: String,
    /// Nodes on the physical side.
    pub physical_nodes: Vec<String>,
    /// Nodes on the simulated side.
    pub sim_nodes: Vec<String>,
    /// Seconds since the gateway started.
    pub uptime_s: f64,
    /// Whether both forwarding threads are still running.
    pub running: bool,
    /// The error that stopped a forwarding thread, if one did.
    pub error: Option<String>,
    /// How each forwarding thread is scheduled (one line each, as it started).
    pub scheduling: Vec<String>,
    /// Frames read on the simulator's side, forwarded to the physical one.
    pub to_physical: DirectionStats,
    /// Frames read on the physical side, forwarded to the simulator's.
    pub to_sim: DirectionStats,
}

/// The live counters of one direction (behind the direction's mutex).
#[derive(Debug, Clone)]
pub(crate) struct DirectionCounters {
    from: String,
    to: String,
    from_side: Side,
    received: u64,
    forwarded: u64,
    local: LocalCounts,
    /// Per message of the routing table (same order).
    messages: Vec<MessageCounts>,
    pub(crate) tx_retries: u64,
    pub(crate) tx_dropped: u64,
    pub(crate) rx_overflow: u64,
    pub(crate) rx_errors: u64,
    kernel_timestamps: u64,
    latency: Histogram,
    handling: Histogram,
}

impl DirectionCounters {
    pub(crate) fn new(from: &str, to: &str, from_side: Side, table: &RoutingTable) -> Self {
        DirectionCounters {
            from: from.to_owned(),
            to: to.to_owned(),
            from_side,
            received: 0,
            forwarded: 0,
            local: LocalCounts::default(),
            messages: vec![MessageCounts::default(); table.messages().len()],
            tx_retries: 0,
            tx_dropped: 0,
            rx_overflow: 0,
            rx_errors: 0,
            kernel_timestamps: 0,
            latency: Histogram::default(),
            handling: Histogram::default(),
        }
    }

    pub(crate) fn received(&mut self) {
        self.received += 1;
    }

    pub(crate) fn local(&mut self, reason: LocalReason, message: Option<usize>) {
        self.local.add(reason);
        if let Some(m) = message.and_then(|m| self.messages.get_mut(m)) {
            m.local += 1;
        }
    }

    pub(crate) fn forwarded(
        &mut self,
        message: usize,
        latency: Duration,
        kernel_stamp: bool,
        handling: Duration,
    ) {
        self.forwarded += 1;
        if let Some(m) = self.messages.get_mut(message) {
            m.forwarded += 1;
        }
        if kernel_stamp {
            self.kernel_timestamps += 1;
        }
        self.latency.record(latency);
        self.handling.record(handling);
    }

    /// The kernel's cumulative drop count of the receive queue.
    pub(crate) fn overflow_total(&mut self, total: u32) {
        self.rx_overflow = self.rx_overflow.max(u64::from(total));
    }

    pub(crate) fn snapshot(&self, table: &RoutingTable) -> DirectionStats {
        DirectionStats {
            from: self.from.clone(),
            to: self.to.clone(),
            from_side: self.from_side,
            received: self.received,
            forwarded: self.forwarded,
            local: self.local.clone(),
            messages: table
                .messages()
                .iter()
                .zip(&self.messages)
                .map(|(m, c)| (m.name.clone(), c.clone()))
                .collect(),
            tx_retries: self.tx_retries,
            tx_dropped: self.tx_dropped,
            rx_overflow: self.rx_overflow,
            rx_errors: self.rx_errors,
            kernel_timestamps: self.kernel_timestamps,
            latency: self.latency.summary(),
            handling: self.handling.summary(),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn buckets_are_monotonic_and_tight() {
        let mut last = 0;
        for b in 0..BUCKETS {
            let floor = bucket_floor(b);
            assert!(b == 0 || floor > last, "bucket {b}");
            assert_eq!(bucket_of(floor), b, "bucket {b} floor {floor}");
            last = floor;
        }
        for ns in [
            0u64,
            1,
            63,
            64,
            65,
            1000,
            12_345,
            999_999,
            1 << 40,
            u64::MAX,
        ] {
            let floor = bucket_floor(bucket_of(ns));
            assert!(
                floor <= ns && (ns - floor) as f64 <= ns as f64 / 32.0,
                "{ns} -> {floor}"
            );
        }
    }

    #[test]
    fn quantiles_of_a_known_set() {
        let mut h = Histogram::default();
        assert_eq!(h.summary(), LatencySummary::default());
        for us in 1..=1000u64 {
            h.record(Duration::from_micros(us));
        }
        let s = h.summary();
        assert_eq!(s.samples, 1000);
        assert!((s.p50_us - 500.0).abs() <= 500.0 / 32.0, "{s:?}");
        assert!((s.p99_us - 990.0).abs() <= 990.0 / 32.0, "{s:?}");
        assert_eq!(s.max_us, 1000.0);
        assert!((s.mean_us - 500.5).abs() < 1e-6, "{s:?}");
    }
}
