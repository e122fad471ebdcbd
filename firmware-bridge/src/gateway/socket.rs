//! The gateway's socket on one interface, and the interface checks.
//!
//! One raw CAN socket per interface, used for both directions: the thread that
//! forwards *from* the interface reads it, the other thread writes it. Socket options:
//!
//! - `CAN_RAW_RECV_OWN_MSGS` off (the kernel's default, set explicitly and read back):
//!   a socket never receives the frames it sent itself, so a frame the gateway puts on
//!   a bus is never read back by the gateway. This is why there is exactly one socket
//!   per interface: a second socket on the same interface *would* receive the first
//!   one's transmissions (through the local loopback), and the gateway would see its
//!   own frames as if a node had sent them.
//! - `CAN_RAW_LOOPBACK` on (the default, set explicitly): other sockets on the same
//!   host and interface see what the gateway sends. On vcan this loopback is the only
//!   way frames reach the simulator; on can0 local tools (candump) see them too.
//! - error frames: all classes are received, to be counted (never forwarded).
//! - `SO_TIMESTAMPNS`: the kernel's receive time arrives with each frame.
//! - `SO_RXQ_OVFL`: the kernel's count of frames it dropped because the receive queue
//!   was full arrives with each frame, and `SO_MEMINFO` reads it when the bus is idle,
//!   so such a loss is counted, never silent.
//! - `SO_RCVBUFFORCE` (with CAP_NET_ADMIN, else `SO_RCVBUF` up to rmem_max): a deep
//!   receive queue rides out a burst while the other side's transmit queue is full.
//! - a receive timeout, so a reader notices a stop request.
//!
//! Frames are read with `recvmsg` and written as the kernel's 16-byte `can_frame`,
//! untouched: the bytes that cross are the bytes that arrived.

use std::io::{self, IoSliceMut};
use std::os::fd::AsRawFd;
use std::path::Path;
use std::time::{Duration, SystemTime};

use nix::errno::Errno;
use nix::sys::socket::{self, ControlMessageOwned, MsgFlags, sockopt};
use nix::sys::time::TimeSpec;
use socketcan::{CanSocket, Socket, SocketOptions};

use super::GatewayError;
use crate::can::QueueDrops;

/// Size of the kernel's classic `struct can_frame`.
pub const CAN_MTU: usize = 16;
/// ARPHRD_CAN: the link type of CAN interfaces in /sys/class/net/*/type.
const ARPHRD_CAN: u32 = 280;
/// IFF_UP in /sys/class/net/*/flags.
const IFF_UP: u32 = 0x1;

/// A frame as read from the kernel.
#[derive(Debug, Clone, Copy)]
pub struct RawFrame {
    /// The kernel's `struct can_frame`, verbatim.
    pub bytes: [u8; CAN_MTU],
    /// The kernel's receive time (SO_TIMESTAMPNS), when it came.
    pub stamp: Option<SystemTime>,
}

impl RawFrame {
    /// The raw `can_id` with its EFF/RTR/ERR flags.
    pub fn can_id(&self) -> u32 {
        u32::from_ne_bytes([self.bytes[0], self.bytes[1], self.bytes[2], self.bytes[3]])
    }

    /// The data bytes (as many as the length field says, at most 8).
    pub fn data(&self) -> &[u8] {
        let len = usize::from(self.bytes[4]).min(8);
        &self.bytes[8..8 + len]
    }
}

/// What a read returned.
#[derive(Debug)]
pub enum ReadOutcome {
    /// A frame, and the kernel's cumulative receive-queue drop count if it said.
    Frame(RawFrame, Option<u32>),
    /// The receive timeout passed without a frame.
    Timeout,
}

/// The gateway's socket on one interface.
#[derive(Debug)]
pub struct GatewaySocket {
    iface: String,
    socket: CanSocket,
    cmsg_len: usize,
}

/// Check that `iface` is a CAN interface that exists and is up (from sysfs, which
/// needs no privileges), with an error that says what to do.
pub fn check_interface(iface: &str) -> Result<(), GatewayError> {
    if iface.is_empty()
        || iface.len() > 15
        || iface
            .chars()
            .any(|c| c == '/' || c.is_whitespace() || c.is_control())
        || iface == "."
        || iface == ".."
    {
        return Err(GatewayError::BadInterfaceName {
            iface: iface.to_owned(),
        });
    }
    let dir = Path::new("/sys/class/net").join(iface);
    if !dir.exists() {
        return Err(GatewayError::NoInterface {
            iface: iface.to_owned(),
        });
    }
    let read_number = |file: &str| -> Option<u32> {
        let text = std::fs::read_to_string(dir.join(file)).ok()?;
        let text = text.trim();
        match text.strip_prefix("0x") {
            Some(hex) => u32::from_str_radix(hex, 16).ok(),
            None => text.parse().ok(),
        }
    };
    if let Some(kind) = read_number("type")
        && kind != ARPHRD_CAN
    {
        return Err(GatewayError::NotCan {
            iface: iface.to_owned(),
            link_type: kind,
        });
    }
    if let Some(flags) = read_number("flags")
        && flags & IFF_UP == 0
    {
        return Err(GatewayError::InterfaceDown {
            iface: iface.to_owned(),
        });
    }
    Ok(())
}

impl GatewaySocket {
    /// Open and configure the socket on `iface` (see the module documentation);
    /// `rcvbuf` is the receive buffer asked for, bytes.
    pub fn open(iface: &str, rcvbuf: usize, read_timeout: Duration) -> Result<Self, GatewayError> {
        let err = |what: &'static str| {
            let iface = iface.to_owned();
            move |source: io::Error| match source.raw_os_error() {
                Some(libc::ENODEV) => GatewayError::NoInterface {
                    iface: iface.clone(),
                },
                Some(libc::ENETDOWN) => GatewayError::InterfaceDown {
                    iface: iface.clone(),
                },
                _ => GatewayError::Socket {
                    iface: iface.clone(),
                    what,
                    source,
                },
            }
        };
        let errno = |what: &'static str| {
            let f = err(what);
            move |e: Errno| f(io::Error::from(e))
        };
        let socket = CanSocket::open(iface).map_err(err("opening a raw CAN socket"))?;
        socket
            .set_recv_own_msgs(false)
            .map_err(err("turning CAN_RAW_RECV_OWN_MSGS off"))?;
        socket
            .set_loopback(true)
            .map_err(err("turning CAN_RAW_LOOPBACK on"))?;
        let own = socket
            .recv_own_msgs()
            .map_err(err("reading CAN_RAW_RECV_OWN_MSGS back"))?;
        let loopback = socket
            .loopback()
            .map_err(err("reading CAN_RAW_LOOPBACK back"))?;
        if own || !loopback {
            return Err(GatewayError::Socket {
                iface: iface.to_owned(),
                what: "checking the socket options",
                source: io::Error::other(format!(
                    "the kernel kept CAN_RAW_RECV_OWN_MSGS={own} CAN_RAW_LOOPBACK={loopback}"
                )),
            });
        }
        socket
            .set_error_filter_accept_all()
            .map_err(err("receiving error frames"))?;
        socket::setsockopt(&socket, sockopt::ReceiveTimestampns, &true)
            .map_err(errno("turning SO_TIMESTAMPNS on"))?;
        socket::setsockopt(&socket, sockopt::RxqOvfl, &1)
            .map_err(errno("turning SO_RXQ_OVFL on"))?;
        crate::can::set_receive_queue(&socket, rcvbuf).map_err(errno("setting SO_RCVBUF"))?;
        socket
            .set_read_timeout(read_timeout)
            .map_err(err("setting the receive timeout"))?;
        let cmsg_len = nix::cmsg_space!(TimeSpec, u32).len();
        Ok(GatewaySocket {
            iface: iface.to_owned(),
            socket,
            cmsg_len,
        })
    }

    /// The interface name.
    pub fn iface(&self) -> &str {
        &self.iface
    }

    /// The receive buffer the kernel granted, bytes.
    pub fn rcvbuf(&self) -> Option<usize> {
        socket::getsockopt(&self.socket, sockopt::RcvBuf).ok()
    }

    /// A buffer for [`GatewaySocket::read`]'s control messages.
    pub fn cmsg_buffer(&self) -> Vec<u8> {
        vec![0; self.cmsg_len]
    }

    /// Read one frame (waits up to the read timeout).
    pub fn read(&self, cmsg: &mut [u8]) -> io::Result<ReadOutcome> {
        let mut bytes = [0u8; CAN_MTU];
        let (n, stamp, drops) = {
            let mut iov = [IoSliceMut::new(&mut bytes)];
            let msg = match socket::recvmsg::<()>(
                self.socket.as_raw_fd(),
                &mut iov,
                Some(cmsg),
                MsgFlags::empty(),
            ) {
                Ok(msg) => msg,
                Err(Errno::EAGAIN | Errno::EINTR) => return Ok(ReadOutcome::Timeout),
                Err(e) => return Err(io::Error::from(e)),
            };
            let mut stamp = None;
            let mut drops = None;
            if let Ok(cmsgs) = msg.cmsgs() {
                for c in cmsgs {
                    match c {
                        ControlMessageOwned::ScmTimestampns(ts) => {
                            stamp = u64::try_from(ts.tv_sec())
                                .ok()
                                .zip(u32::try_from(ts.tv_nsec()).ok())
                                .map(|(s, ns)| SystemTime::UNIX_EPOCH + Duration::new(s, ns));
                        }
                        ControlMessageOwned::RxqOvfl(n) => drops = Some(n),
                        _ => {}
                    }
                }
            }
            (msg.bytes, stamp, drops)
        };
        if n != CAN_MTU {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("read {n} bytes, a classic CAN frame has {CAN_MTU}"),
            ));
        }
        Ok(ReadOutcome::Frame(RawFrame { bytes, stamp }, drops))
    }

    /// Try once to send a frame, verbatim, without waiting.
    pub fn try_send(&self, frame: &[u8; CAN_MTU]) -> Result<(), Errno> {
        match socket::send(self.socket.as_raw_fd(), frame, MsgFlags::MSG_DONTWAIT) {
            Ok(n) if n == CAN_MTU => Ok(()),
            Ok(_) => Err(Errno::EMSGSIZE),
            Err(e) => Err(e),
        }
    }
}

/// The kernel's count for its socket (SO_MEMINFO), at any time (SO_RXQ_OVFL only
/// tells with the next frame).
impl QueueDrops for GatewaySocket {
    fn queue_drops(&self) -> Option<u32> {
        self.socket.queue_drops()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn interface_names_are_checked_before_touching_sysfs() {
        for bad in ["", "../etc", "a/b", "sixteen_chars_xx", "can 0", "."] {
            assert!(
                matches!(
                    check_interface(bad),
                    Err(GatewayError::BadInterfaceName { .. })
                ),
                "{bad:?}"
            );
        }
        let err = check_interface("ugvnosuch0").unwrap_err();
        assert!(matches!(err, GatewayError::NoInterface { .. }), "{err}");
        assert!(err.to_string().contains("ugvnosuch0"), "{err}");
    }

    #[test]
    fn a_non_can_interface_is_refused() {
        // The loopback interface exists on every Linux host and is not CAN.
        let err = check_interface("lo").unwrap_err();
        assert!(
            matches!(err, GatewayError::NotCan { link_type: 772, .. }),
            "{err}"
        );
    }

    #[test]
    fn raw_frame_fields() {
        let mut bytes = [0u8; CAN_MTU];
        bytes[..4].copy_from_slice(&0x101u32.to_ne_bytes());
        bytes[4] = 8;
        bytes[8..].copy_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8]);
        let f = RawFrame { bytes, stamp: None };
        assert_eq!(f.can_id(), 0x101);
        assert_eq!(f.data(), [1, 2, 3, 4, 5, 6, 7, 8]);
        let mut short = f;
        short.bytes[4] = 3;
        assert_eq!(short.data(), [1, 2, 3]);
        short.bytes[4] = 200;
        assert_eq!(short.data().len(), 8);
    }
}
