//! The laser driver of a run whose laser is a CoLa-A device (the simulator's own
//! CoLa-A server, or a physical SICK): on a thread, it reads the scanner's scans
//! with [`ColaClient`] and publishes them on the run's iceoryx2 service as
//! [`LaserFrame`]s, so the controller gets the same frames either way. A lost
//! connection is retried once a second.

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use firmware_bridge::cola::{ClientConfig, ColaClient, ColaError, DecodeOptions};
use firmware_bridge::laser::LaserPublisher;
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
    stop: Arc<AtomicBool>,
    stats: Arc<Mutex<ColaDriverStats>>,
    thread: Option<JoinHandle<()>>,
}

fn lock(m: &Mutex<ColaDriverStats>) -> std::sync::MutexGuard<'_, ColaDriverStats> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
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
        let stop = Arc::new(AtomicBool::new(false));
        let stats = Arc::new(Mutex::new(ColaDriverStats {
            device: client.device_ident().name.clone(),
            ..ColaDriverStats::default()
        }));
        let (flag, shared) = (Arc::clone(&stop), Arc::clone(&stats));
        let thread = std::thread::Builder::new()
            .name("cola-driver".to_owned())
            .spawn(move || {
                while !flag.load(Ordering::Relaxed) {
                    let result = match client.next_frame(Duration::from_millis(100)) {
                        Ok(Some(frame)) => publisher
                            .publish(&frame)
                            .map(|_| true)
                            .map_err(|e| e.to_string()),
                        Ok(None) => Ok(false),
                        Err(ColaError::ConnectionLost { .. } | ColaError::Io { .. }) => {
                            std::thread::sleep(Duration::from_secs(1));
                            client
                                .reconnect()
                                .map(|()| false)
                                .map_err(|e| e.to_string())
                        }
                        Err(e) => Err(e.to_string()),
                    };
                    let c = client.stats();
                    let mut s = lock(&shared);
                    s.frames += u64::from(result == Ok(true));
                    s.lost_scans = c.lost_scans;
                    s.bad_telegrams = c.bad_telegrams;
                    s.connects = c.connects;
                    if let Err(e) = result {
                        s.last_error = Some(e);
                    }
                }
            })
            .map_err(|source| ColaError::Io {
                action: "starting the laser driver thread",
                source,
            })?;
        Ok(ColaDriverThread {
            stop,
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
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
