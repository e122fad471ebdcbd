//! A SocketCAN socket that hands out only the frames that had arrived by a horizon:
//! each frame reaches the tick during which it arrived, even when the loop runs late.
//!
//! A fixed-step loop on the wall clock that falls behind (a stall of the machine) runs
//! its missed ticks back to back to catch up. Read from a plain socket, every frame
//! that arrived during the stall lands in the first of those ticks, and the ticks
//! after it see none while their time runs on: an ECU's 100 ms command watchdog then
//! trips on a controller that never stopped sending. With the kernel's receive time
//! of each frame (SO_TIMESTAMPNS) and the horizon set to each tick's own time, the
//! catch-up ticks get the frames that arrived in their own periods, as a device
//! sampling its bus at a fixed rate would have.

use std::io;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::SystemTime;

use socketcan::{CanFrame, CanSocket, Socket, SocketOptions};

use super::paced::Pacer;
use super::{Filtered, QueueDrops};
use crate::clock::unix_ns;

/// The time up to which the timed sockets sharing it hand out frames, set by the loop
/// at each tick. Until first set, there is no limit.
#[derive(Clone, Debug)]
pub struct Horizon(Arc<AtomicU64>);

impl Default for Horizon {
    fn default() -> Self {
        Horizon(Arc::new(AtomicU64::new(u64::MAX)))
    }
}

impl Horizon {
    pub fn new() -> Horizon {
        Horizon::default()
    }

    /// Frames that arrived at or before `t` (the kernel's receive time, on the real
    /// time clock) are handed out; later ones wait.
    pub fn set(&self, t: SystemTime) {
        self.0.store(unix_ns(t), Ordering::Relaxed);
    }

    /// The tick that is running now, `late` seconds after its deadline: the horizon
    /// is the deadline. Taken from the real time clock at the call, so a step of that
    /// clock (NTP) moves the horizon with the kernel's timestamps.
    pub fn set_for_tick(&self, late: f64) {
        let late = std::time::Duration::from_secs_f64(late.max(0.0));
        let now = SystemTime::now();
        self.set(now.checked_sub(late).unwrap_or(now));
    }

    fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

/// A raw CAN socket read through a [`Horizon`]; it sends like any socket, or paced at
/// the bus's bit rate ([`TimedSocket::paced`]).
#[derive(Debug)]
pub struct TimedSocket {
    socket: CanSocket,
    horizon: Horizon,
    /// The first frame that arrived after the horizon, with its receive time (ns).
    held: Option<(CanFrame, u64)>,
    /// The pacing this socket's frames go through, and its node number there.
    pacer: Option<(Pacer, usize)>,
}

impl TimedSocket {
    /// Open `iface` non-blocking with kernel receive timestamps and a receive queue
    /// of [`super::DEEP_QUEUE_BYTES`]: a stall of the loop that reads it then ends
    /// with the frames that came meanwhile waiting, for the catch-up ticks to take in
    /// their own periods, rather than dropped by the kernel once its default queue
    /// (a quarter of a second of a loaded bus) is full.
    pub fn open(iface: &str, horizon: Horizon) -> io::Result<TimedSocket> {
        let socket = CanSocket::open(iface)?;
        socket.set_nonblocking(true)?;
        socket.set_recv_timestamp(true)?;
        super::set_receive_queue(&socket, super::DEEP_QUEUE_BYTES)?;
        Ok(TimedSocket {
            socket,
            horizon,
            held: None,
            pacer: None,
        })
    }

    /// Send through `pacer` from now on (see [`super::paced`]): a frame goes onto
    /// the interface when it wins the bus. The first socket paced by a pacer also
    /// reports the other nodes' frames to it, so the bus time they take is counted
    /// once.
    pub fn paced(mut self, pacer: &Pacer) -> TimedSocket {
        self.pacer = Some((pacer.clone(), pacer.node()));
        self
    }

    /// Put the frames whose turn has come onto the interface; those the kernel cannot
    /// take now wait for the next call.
    fn flush(&mut self) -> nb::Result<(), socketcan::Error> {
        let Some((pacer, node)) = &self.pacer else {
            return Ok(());
        };
        let mut frames = pacer.take(*node).into_iter();
        while let Some(frame) = frames.next() {
            match embedded_can::nb::Can::transmit(&mut self.socket, &frame) {
                Ok(_) => {}
                Err(nb::Error::WouldBlock) => {
                    pacer.put_back(*node, std::iter::once(frame).chain(frames));
                    return Ok(());
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    fn hand_out(frame: CanFrame) -> nb::Result<CanFrame, socketcan::Error> {
        match frame {
            CanFrame::Error(e) => Err(nb::Error::Other(socketcan::Error::from(e.into_error()))),
            other => Ok(other),
        }
    }
}

/// The kernel's count for its socket.
impl QueueDrops for TimedSocket {
    fn queue_drops(&self) -> Option<u32> {
        self.socket.queue_drops()
    }
}

impl Filtered for TimedSocket {
    fn set_acceptance(&self, ids: &[u16]) -> io::Result<()> {
        self.socket.set_acceptance(ids)
    }
}

impl embedded_can::nb::Can for TimedSocket {
    type Frame = CanFrame;
    type Error = socketcan::Error;

    fn receive(&mut self) -> nb::Result<CanFrame, socketcan::Error> {
        self.flush()?;
        let (frame, at) = match self.held.take() {
            Some(held) => held,
            None => match self.socket.read_frame_with_timestamp() {
                Ok((frame, at)) => (frame, unix_ns(at)),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    return Err(nb::Error::WouldBlock);
                }
                Err(e) => return Err(nb::Error::Other(socketcan::Error::from(e))),
            },
        };
        if at > self.horizon.get() {
            // Frames arrive in order: this one and all after it wait.
            self.held = Some((frame, at));
            return Err(nb::Error::WouldBlock);
        }
        if let Some((pacer, 0)) = &self.pacer {
            pacer.seen(&frame, at);
        }
        TimedSocket::hand_out(frame)
    }

    fn transmit(&mut self, frame: &CanFrame) -> nb::Result<Option<CanFrame>, socketcan::Error> {
        match &self.pacer {
            Some((pacer, node)) => {
                pacer.submit(*node, *frame);
                self.flush()?;
                Ok(None)
            }
            None => embedded_can::nb::Can::transmit(&mut self.socket, frame),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_horizon_is_unlimited_until_set_and_then_the_tick_deadline() {
        let h = Horizon::new();
        assert_eq!(h.get(), u64::MAX);
        let before = unix_ns(SystemTime::now());
        h.set_for_tick(0.25);
        let after = unix_ns(SystemTime::now());
        let quarter = 250_000_000;
        assert!(h.get() + quarter >= before && h.get() + quarter <= after);
        // A clone is the same horizon.
        let c = h.clone();
        c.set(std::time::UNIX_EPOCH);
        assert_eq!(h.get(), 0);
    }
}
