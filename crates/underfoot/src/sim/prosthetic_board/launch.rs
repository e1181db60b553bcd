//! Starting the simulated board on a pseudo-terminal, on a thread of its own, with the
//! host on the other end.

use std::io;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::Duration;

#[cfg(unix)]
use serialport::SerialPort;

use super::{SimulatedFoot, SimulatedReport};
use crate::interface::config::{InterfaceConfig, Link, SimulatedConfig};
use crate::io::IoError;
use crate::io::prosthetic::{self, ProstheticHost};

/// A simulated board running on its own thread.
#[derive(Debug)]
pub struct SimulatorHandle {
    stop: Arc<AtomicBool>,
    thread: Option<thread::JoinHandle<io::Result<SimulatedReport>>>,
}

impl SimulatorHandle {
    /// Stops the board and returns what it recorded.
    ///
    /// # Errors
    /// [`IoError::Io`] if its port failed, or the thread panicked.
    pub fn finish(mut self) -> Result<SimulatedReport, IoError> {
        self.stop.store(true, Ordering::SeqCst);
        match self.thread.take().map(thread::JoinHandle::join) {
            Some(Ok(Ok(r))) => Ok(r),
            Some(Ok(Err(source))) => Err(IoError::Io {
                device: "simulated".into(),
                source,
            }),
            _ => Err(IoError::Unsupported {
                device: "simulated".into(),
                reason: "the simulated board's thread panicked".into(),
            }),
        }
    }
}

impl Drop for SimulatorHandle {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

/// Opens the interface a configuration names: its serial port
/// ([`prosthetic::open`]), or a [`SimulatedFoot`] on a pseudo-terminal (unix only) whose
/// walk ends the source when it is over, with the handle that stops the board and
/// returns what it recorded.
///
/// # Errors
/// [`IoError::Open`] if the port cannot be opened; [`IoError::Unsupported`] for a
/// configuration the host cannot run.
pub fn open_interface(
    config: &InterfaceConfig,
) -> Result<(ProstheticHost, Option<SimulatorHandle>), IoError> {
    match &config.link {
        Link::Serial { .. } => Ok((prosthetic::open(config)?, None)),
        Link::Simulated(sim) => open_simulated(config, sim),
    }
}

#[cfg(unix)]
fn open_simulated(
    config: &InterfaceConfig,
    sim: &SimulatedConfig,
) -> Result<(ProstheticHost, Option<SimulatorHandle>), IoError> {
    let open_err = |e: serialport::Error| IoError::Open {
        device: "simulated".into(),
        reason: format!("pseudo-terminal: {e}"),
    };
    let (mut master, slave) = serialport::TTYPort::pair().map_err(open_err)?;
    master
        .set_timeout(Duration::from_millis(2))
        .map_err(open_err)?;
    let servos = config
        .servos
        .iter()
        .map(|s| usize::from(s.id) + 1)
        .max()
        .unwrap_or(0);
    let mut rest = vec![0u16; servos];
    for s in &config.servos {
        rest[usize::from(s.id)] = s.calibration.rest.0;
    }
    let foot = SimulatedFoot::new(sim, config.frame_sensors, &rest)?;
    let mut host = ProstheticHost::with_port(Box::new(slave), "simulated", config)?;
    let stop = Arc::new(AtomicBool::new(false));
    let finished = Arc::new(AtomicBool::new(false));
    let polled = Arc::new(AtomicBool::new(false));
    host.follow_board(Arc::clone(&polled), Arc::clone(&finished));
    let thread = {
        let stop = Arc::clone(&stop);
        thread::spawn(move || {
            // Like a board that waits for its host: frames sent before anyone reads them
            // would reach the engine in one burst, a walk squeezed into an instant (whose
            // strikes the detector cannot tell apart) when the host is slow to start.
            while !polled.load(Ordering::SeqCst) && !stop.load(Ordering::SeqCst) {
                thread::sleep(Duration::from_millis(1));
            }
            // Linger so the host's last servo frames still arrive and are recorded.
            foot.serve(&mut master, &stop, &finished, Duration::from_millis(300))
        })
    };
    Ok((
        host,
        Some(SimulatorHandle {
            stop,
            thread: Some(thread),
        }),
    ))
}

#[cfg(not(unix))]
fn open_simulated(
    _config: &InterfaceConfig,
    _sim: &SimulatedConfig,
) -> Result<(ProstheticHost, Option<SimulatorHandle>), IoError> {
    Err(IoError::Unsupported {
        device: "simulated".into(),
        reason: "the simulated interface runs on a pseudo-terminal, which needs unix".into(),
    })
}
