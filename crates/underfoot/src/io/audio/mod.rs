//! Vibration to an audio device through cpal (ALSA; JACK with the `jack` feature).
//!
//! [`AudioOutput::start`] opens a device, picks a stream configuration and calls a render
//! callback from the device's audio thread until [`AudioOutput::stop`]. The callback has
//! the engine's signature, `FnMut(&mut [f32], usize)`: interleaved output (frames x
//! channels) and the channel count. It must fill the whole slice and never allocate,
//! lock or block; it may be called with fewer frames than the device buffer (see
//! [`stream`](mod@stream)).
//!
//! [`AudioInput::start`] is the same for capture: the device is matched among the host's
//! input devices and configured by the same rules, and `on_input(samples, channels)` gets
//! interleaved `f32` (converted from the device's format through a scratch buffer
//! allocated at start-up, like the output's).
//!
//! | file | what it does |
//! |---|---|
//! | [`discovery`] | the host, its devices, matching a device by name, [`list_devices`] |
//! | [`choose`] | the stream configuration from what a device offers and what was asked: pure, no device |
//! | [`stream`](mod@stream) | [`AudioOutput`] and [`AudioInput`]: building a stream for the device's sample format, conversion |
//! | [`meter`] | what the audio thread records: callbacks, late callbacks, latency, xruns ([`StreamStats`]) |
//! | [`measure`] | [`AudioLoop`], the sweep `Device` through a sound card's output and input |
//!
//! # JACK
//!
//! cpal's JACK host does not start a server: one must be running before [`list_devices`]
//! or [`AudioOutput::start`] (otherwise there is no output device). The rate and buffer
//! size are the server's; a request for anything else is refused with the server's
//! values. Without a sound card, the dummy back-end is paced like a device
//! (`.ci/audio-setup` starts it):
//!
//! ```text
//! jackd --realtime -d dummy -r 48000 -p 64 &       # where SCHED_FIFO is allowed
//! jackd --no-realtime -d dummy -r 48000 -p 64 &    # otherwise
//! ```
//!
//! Real-time scheduling decides whether the pace holds on a busy machine: on 2 cores with
//! four busy processes, a `--no-realtime` server delivered 0.85x real time with ~80 xruns
//! a second, a `--realtime` one 1.00x with one or two. Root in this project's container may use
//! it; `chrt -f 10 true` tells. The dummy back-end reserves no sound card, so `JACK_NO_AUDIO_RESERVATION` is not
//! needed. Xruns are counted in [`StreamStats::xruns`], apart from real errors.

use std::fmt;
use std::str::FromStr;

use super::IoError;
use crate::units::SampleRate;

pub mod choose;
pub mod discovery;
pub mod measure;
pub mod meter;
pub mod stream;

#[cfg(test)]
mod tests;

pub use choose::MAX_SCRATCH_FRAMES;
/// The device's sample format, as cpal names it.
pub use cpal::SampleFormat;
pub use discovery::{DeviceInfo, list_devices};
pub use measure::{AudioLoop, LOOP_TIMEOUT_MARGIN, LoopConfig, LoopReport};
pub use meter::{LATENCY_WINDOW, StreamStats};
pub use stream::{AudioInput, AudioOutput};

/// Which cpal host (audio system) to use.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum AudioHost {
    /// The platform's default host (ALSA on Linux).
    #[default]
    Default,
    /// ALSA, Linux's kernel audio interface.
    Alsa,
    /// A running JACK server.
    #[cfg(feature = "jack")]
    Jack,
}

impl fmt::Display for AudioHost {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Default => "default",
            Self::Alsa => "ALSA",
            #[cfg(feature = "jack")]
            Self::Jack => "JACK",
        })
    }
}

impl FromStr for AudioHost {
    type Err = IoError;

    /// Parses `default`, `alsa` or `jack` (any case), for a `--host` flag.
    fn from_str(s: &str) -> Result<Self, IoError> {
        match s.to_ascii_lowercase().as_str() {
            "default" => Ok(Self::Default),
            "alsa" => Ok(Self::Alsa),
            #[cfg(feature = "jack")]
            "jack" => Ok(Self::Jack),
            #[cfg(not(feature = "jack"))]
            "jack" => Err(IoError::Unsupported {
                device: s.to_string(),
                reason: "this build has no JACK support (cargo feature `jack`)".into(),
            }),
            _ => Err(IoError::Unsupported {
                device: s.to_string(),
                reason: "unknown audio host; expected default, alsa or jack".into(),
            }),
        }
    }
}

/// What to open: host, device and stream format.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AudioConfig {
    /// The audio system.
    pub host: AudioHost,
    /// The device: an id, a description or a part of either (`"hw:1"`, `"null"`,
    /// `"default"`); `None` for the host's default output.
    pub device: Option<String>,
    /// Interleaved output channels.
    pub channels: u16,
    /// Sample rate; the device must support it (nothing is resampled here).
    pub rate: SampleRate,
    /// Frames per callback; `None` for the host's default.
    pub buffer_frames: Option<u32>,
}

impl Default for AudioConfig {
    /// Stereo at 48 kHz on the default device, default buffer size.
    fn default() -> Self {
        Self {
            host: AudioHost::Default,
            device: None,
            channels: 2,
            rate: SampleRate(48_000),
            buffer_frames: None,
        }
    }
}

/// What a started stream got.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StreamInfo {
    /// The host that was used (never [`AudioHost::Default`]).
    pub host: AudioHost,
    /// The device id.
    pub device: String,
    /// Sample rate.
    pub rate: SampleRate,
    /// Interleaved channels, as passed to the render callback.
    pub channels: u16,
    /// Frames per callback as reported by the host, else as requested; `None` if neither.
    pub buffer_frames: Option<u32>,
    /// The device's sample format; anything but `F32` is converted from `f32`.
    pub sample_format: SampleFormat,
}

/// Which way a stream carries audio; device matching and configuration take it so that
/// inputs and outputs are chosen by the same rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// Playback: [`AudioOutput`].
    Output,
    /// Capture: [`AudioInput`].
    Input,
}

impl fmt::Display for Direction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Output => "output",
            Self::Input => "input",
        })
    }
}
