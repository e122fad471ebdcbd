//! The laser driver of a run whose laser is a CoLa-A device (the simulator's own
//! CoLa-A server, or a physical SICK): on a thread, it reads the scanner's scans
//! with [`ColaClient`] and publishes them on the run's iceoryx2 service as
//! [`LaserFrame`]s, so the controller gets the same frames either way. A lost
//! connection is retried once a second. The loop is `ugv-sick`'s
//! ([`firmware_bridge::cola::driver`]); this module runs it on a thread and keeps its
//! counts for the verdict.
//!
//! [`LaserFrame`]: firmware_bridge::laser::LaserFrame

use std::net::SocketAddr;
use std::sync::mpsc::{Sender, channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

use firmware_bridge::cola::driver::{DriverConfig, DriverEvent, DriverStats, drive};
use firmware_bridge::cola::{ClientConfig, ColaClient, ColaError, DecodeOptions};
use firmware_bridge::laser::LaserPublisher;
use firmware_bridge::sync::lock;
use serde::Serialize;

/// What the driver did so far.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct ColaDriverStats {
    /// The scanner's `DeviceIdent`.
    pub device: String,
    /// Frames published.
    pub frames: u64,
    /// Scans missing between consecutive scan counters.
    pub lost_scans: u64,
    /// Telegrams that did not parse or convert.
    pub bad_telegrams: u64,
    /// Connections made (the first and every reconnect).
    pub connects: u64,
    /// The last error met, if any.
    pub last_error: Option<String>,
}

/// The driver's thread; stopped and joined on drop.
#[derive(Debug)]
pub struct ColaDriverThread {
    /// Dropped to stop the loop.
    stop: Option<Sender<()>>,
    stats: Arc<Mutex<ColaDriverStats>>,
    thread: Option<JoinHandle<()>>,
}

impl ColaDriverThread {
    /// Connect to the scanner at `address` (the handshake happens here, so a scanner
    /// that is not there is an error now) and publish its scans on `service`, with the
    /// frames' range limits from `decode`.
    pub fn spawn(
        address: SocketAddr,
        service: &str,
        decode: DecodeOptions,
    ) -> Result<ColaDriverThread, ColaError> {
        let publisher = LaserPublisher::new(service).map_err(ColaError::from)?;
        let mut client = ColaClient::connect(
            &address.to_string(),
            ClientConfig {
                decode,
                ..ClientConfig::default()
            },
        )?;
        let (stop, stopped) = channel();
        let stats = Arc::new(Mutex::new(ColaDriverStats {
            device: client.device_ident().name.clone(),
            ..ColaDriverStats::default()
        }));
        let shared = Arc::clone(&stats);
        let thread = std::thread::Builder::new()
            .name("cola-driver".to_owned())
            .spawn(move || {
                let watch = |event: &DriverEvent<'_>, counts: &DriverStats| {
                    let mut s = lock(&shared);
                    s.frames = counts.published;
                    s.lost_scans = counts.client.lost_scans;
                    s.bad_telegrams = counts.client.bad_telegrams;
                    s.connects = counts.client.connects;
                    if let Some(e) = event.error() {
                        s.last_error = Some(e.to_string());
                    }
                };
                let config = DriverConfig::default();
                // With reconnect on, only the stop ends the loop.
                if let Err(e) = drive(&mut client, &publisher, &config, &stopped, watch) {
                    lock(&shared).last_error = Some(e.to_string());
                }
            })
            .map_err(|source| ColaError::Io {
                action: "starting the laser driver thread",
                source,
            })?;
        Ok(ColaDriverThread {
            stop: Some(stop),
            stats,
            thread: Some(thread),
        })
    }

    pub fn stats(&self) -> ColaDriverStats {
        lock(&self.stats).clone()
    }
}

impl Drop for ColaDriverThread {
    fn drop(&mut self) {
        self.stop.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
