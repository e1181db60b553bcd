//! Opening a serial port, and telling a quiet line from a lost port: what the sources on
//! a serial link ([`SerialSource`](super::SerialSource) and the prosthetic interface's
//! host) share.

use std::io;
use std::time::Duration;

use serialport::SerialPort;

use crate::io::IoError;

/// Opens `path` at `baud`, 8N1, no flow control, with a read timeout.
///
/// # Errors
/// [`IoError::Open`] if it cannot be opened or configured.
pub(crate) fn open_port(
    path: &str,
    baud: u32,
    timeout: Duration,
) -> Result<Box<dyn SerialPort>, IoError> {
    serialport::new(path, baud)
        .data_bits(serialport::DataBits::Eight)
        .parity(serialport::Parity::None)
        .stop_bits(serialport::StopBits::One)
        .flow_control(serialport::FlowControl::None)
        .timeout(timeout)
        .open()
        .map_err(|e| IoError::Open {
            device: path.to_owned(),
            reason: e.to_string(),
        })
}

/// The serial ports this machine has now, by the names `serial:PORT` takes; empty where
/// they cannot be listed (a container without udev, a platform serialport does not
/// enumerate): a list to choose from, not a check.
pub fn list_ports() -> Vec<String> {
    let mut names: Vec<String> = serialport::available_ports()
        .map(|ports| ports.into_iter().map(|p| p.port_name).collect())
        .unwrap_or_default();
    names.sort();
    names
}

/// A read that found nothing (yet): not a failure of the port.
pub(crate) fn is_quiet(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    )
}

/// A lost port's error, for the message.
pub(crate) fn describe(e: &io::Error) -> String {
    if e.kind() == io::ErrorKind::BrokenPipe {
        format!("the port hung up ({e})")
    } else {
        e.to_string()
    }
}
