//! Opening each kind of input: a replayed track, a generated walk, a serial port, OSC, or
//! a prosthetic interface.
//!
//! OSC names materials, so it is bound only when the bank exists
//! ([`Input::bind_osc`]); every other input opens with the session.

use crate::force::calibration::SensorCalibration;
use crate::force::gait;
use crate::force::scale::CountScale;
use crate::force::track::ForceTrack;
use crate::interface::config::InterfaceConfig;
use crate::io::EventSource;
use crate::io::osc::OscSource;
use crate::io::prosthetic::ProstheticHost;
use crate::io::replay::ReplaySource;
use crate::io::serial::{SerialConfig, SerialSource};
use crate::io::spec::InputSpec;
use crate::sim::{SimulatorHandle, open_interface};

use super::LiveError;
use super::session::{SerialSettings, SessionInput};

/// An opened input.
pub(super) enum Input {
    Source(Box<dyn EventSource>),
    /// `osc:HOST:PORT`, bound by [`Input::bind_osc`].
    OscPending(String),
    Interface(Box<ProstheticHost>, Option<SimulatorHandle>),
}

/// An input, the number of channels it carries (if it says), whether it ends by itself,
/// and the interface's configuration if it is one.
pub(super) struct Opened {
    pub input: Input,
    pub channels: Option<usize>,
    pub ends: bool,
    pub interface: Option<InterfaceConfig>,
}

/// Opens `input`; a serial port with `serial`'s settings.
pub(super) fn open(input: &SessionInput, serial: &SerialSettings) -> Result<Opened, LiveError> {
    let spec = match input {
        SessionInput::Interface(path) => {
            let config = InterfaceConfig::load(path)?;
            let channels = config.channels.len();
            let (host, sim) = open_interface(&config)?;
            let ends = sim.is_some();
            return Ok(Opened {
                input: Input::Interface(Box::new(host), sim),
                channels: Some(channels),
                ends,
                interface: Some(config),
            });
        }
        SessionInput::Spec(spec) => spec,
    };
    let (input, channels, ends) = match spec {
        InputSpec::Replay { file, speed } => {
            let track = ForceTrack::read(file)?;
            let channels = track.channel_count();
            (
                Input::Source(Box::new(ReplaySource::new(track, *speed)?)),
                Some(channels),
                true,
            )
        }
        InputSpec::Gait(config) => {
            let g = gait::generate(config)?;
            let channels = g.track.channel_count();
            (
                Input::Source(Box::new(ReplaySource::new(g.track, 1.0)?)),
                Some(channels),
                true,
            )
        }
        InputSpec::Serial { port } => {
            let scale = match &serial.sensors {
                Some(path) => CountScale::calibrated(&SensorCalibration::load(path)?),
                None => CountScale::Uniform {
                    newtons_per_count: serial.newtons_per_count,
                },
            };
            let config = SerialConfig {
                port: port.clone(),
                baud: serial.baud,
                layout: serial.layout.clone(),
                scale,
            };
            (
                Input::Source(Box::new(SerialSource::open(&config)?)),
                Some(serial.layout.len()),
                false,
            )
        }
        InputSpec::Osc { addr } => (Input::OscPending(addr.clone()), None, false),
    };
    Ok(Opened {
        input,
        channels,
        ends,
        interface: None,
    })
}

impl Input {
    /// Binds a pending OSC input, which needs the bank's material names.
    pub(super) fn bind_osc(self, names: Vec<String>, channels: usize) -> Result<Self, LiveError> {
        Ok(match self {
            Input::OscPending(addr) => {
                Input::Source(Box::new(OscSource::bind(&addr, names, channels)?))
            }
            other => other,
        })
    }
}
