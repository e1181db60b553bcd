//! The prosthetic-skin interface over a serial link: insole force in, servo targets out.
//!
//! The interface's board sends force frames (type `0x01`, raw counts of the insole's
//! sensors) and receives servo-target frames (type `0x02`); both use the framing, CRC and
//! timing rules documented in [`super::serial`]. This module is the host's end:
//!
//! - [`ProstheticHost`], the host: an [`EventSource`](crate::io::EventSource) that
//!   decodes insole frames, scales them to newtons (per-sensor calibration or a factor,
//!   [`CountScale`](crate::force::scale::CountScale)), hands one
//!   [`Event::Force`](crate::engine::Event::Force) per vibration channel to the engine,
//!   feeds the [`ServoBank`](crate::interface::servo::ServoBank), and writes a servo frame
//!   every `1 / servo_rate_hz` seconds from its own heartbeat thread (*Heartbeat* below).
//!   Decoding runs in [`EventSource::poll`](crate::io::EventSource::poll), on the input
//!   poll thread; neither runs on the audio thread. When a real board's port hangs up the
//!   host reopens it with a backoff (see [`super`], *A lost device*).
//! - [`open`]: the host on the serial port a configuration names.
//!
//! The board's end, simulated, is among the simulators:
//! [`SimulatedFoot`](crate::sim::SimulatedFoot) walks one foot and moves its servos as
//! the frames say, and [`open_interface`](crate::sim::open_interface) starts it on a
//! pseudo-terminal when the configuration says `port = "simulated"`.
//!
//! | file | what it does |
//! |---|---|
//! | `host.rs` | [`ProstheticHost`] and its counts ([`ProstheticStats`]): decoding, scaling, force events, a lost port |
//! | `heartbeat.rs` | the thread that writes servo frames on a deadline |
//!
//! # Heartbeat
//!
//! The firmware takes the servo frames as a heartbeat: with none for a few periods
//! (about 200 ms) it returns the servos to rest. So the frames must not wait for the
//! poll loop, which a loaded machine, a slow consumer or a long read can hold up (sent
//! from the poll loop, they were seen to stop for 1.04 s under CPU load). A dedicated thread sends them on a
//! deadline: frame `k` is due at `t₀ + k·T`, so a late wake-up delays one frame without
//! shifting the ones after it, and a stall of more than a period resumes the cadence
//! from now instead of sending a burst. Each tick advances the [`ServoBank`](crate::interface::servo::ServoBank) by the real
//! time since the last one (the rate limit and the insole timeout run on this clock, so
//! the servos return to rest even if the poll thread stops) and writes its targets; the
//! poll thread only hands in readings. The two share the bank under a mutex held for
//! microseconds and never across a write; the heartbeat writes through its own handle
//! on the port (a duplicate descriptor), whose timeout is one period, so a line that
//! does not drain drops a frame rather than holding up the next.
//! [`ProstheticStats::max_servo_gap`] reports the worst gap.
//!
//! # Timing and latency
//!
//! The host timestamps each insole frame as it is decoded and reports the delay from
//! the oldest frame not yet reflected in a servo frame to the servo frame that reflects
//! it ([`ProstheticStats::max_servo_delay`]): at most one servo period plus the
//! heartbeat's scheduling slack. The serial line adds `bytes × 10 / baud` each way (about 1.3 ms for a
//! 15-byte frame at 115200 baud), and the servo's own mechanics dominate everything.

use std::time::Duration;

use crate::interface::config::{InterfaceConfig, Link};
use crate::io::IoError;
use crate::io::serial::open_port;

mod heartbeat;
mod host;

pub use host::{ProstheticHost, ProstheticStats};

/// Opens the interface on the serial port its configuration names; the port is reopened
/// when it hangs up. A simulated link is started by
/// [`crate::sim::open_interface`], which opens either.
///
/// # Errors
/// [`IoError::Open`] if the port cannot be opened; [`IoError::Unsupported`] for a
/// configuration the host cannot run, or a simulated link.
pub fn open(config: &InterfaceConfig) -> Result<ProstheticHost, IoError> {
    match &config.link {
        Link::Serial { port, baud } => {
            let p = open_port(port, *baud, Duration::from_millis(10))?;
            let mut host = ProstheticHost::with_port(p, port, config)?;
            // A real board's port is reopened when it hangs up.
            host.reopen_at(*baud);
            Ok(host)
        }
        Link::Simulated(_) => Err(IoError::Unsupported {
            device: "simulated".into(),
            reason: "a simulated board is started by underfoot::sim::open_interface".into(),
        }),
    }
}
