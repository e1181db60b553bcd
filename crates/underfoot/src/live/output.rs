//! Starting the output: an audio device (with the `audio` feature), or the
//! [paced](super::paced) pseudo-device into a WAV file or nowhere.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use crate::atomic_file::OutputFile;
use crate::engine::Engine;
use crate::io::IoError;
use crate::io::spec::OutputSpec;
use crate::io::wav::{WavFormat, WavSink};
use crate::units::{SampleRate, Seconds};

use super::LiveError;
use super::adapt::DriveTap;
use super::paced::{PacedDevice, PacedReport};
use super::record::OutputTap;

/// How often a `wav:` recording is brought up to date on disk: a killed session loses at
/// most this much (see [`crate::io::wav`], *Live recordings*).
const LIVE_WAV_SYNC: Duration = Duration::from_millis(500);

/// The paced pseudo-device's buffer, in frames, when none is asked for.
const DEFAULT_BLOCK: u32 = 256;

/// What was started, for the caller to describe.
#[derive(Debug, Clone, PartialEq)]
pub enum OutputInfo {
    /// An audio device, as opened.
    #[cfg(feature = "audio")]
    Audio(crate::io::audio::StreamInfo),
    /// The paced pseudo-device.
    Paced {
        /// The output asked for (`wav:FILE` or `null`).
        spec: OutputSpec,
        /// Interleaved channels.
        channels: usize,
        /// The engine's rate.
        rate: SampleRate,
        /// Frames per buffer: the pacing period.
        block: usize,
    },
}

/// What an output did, when it is finished.
#[derive(Debug, Clone, PartialEq)]
pub enum OutputReport {
    /// An audio device's counts.
    #[cfg(feature = "audio")]
    Audio(crate::io::audio::StreamStats),
    /// The paced pseudo-device's.
    Paced(PacedReport),
}

/// A running output.
pub(super) enum Output {
    #[cfg(feature = "audio")]
    Audio(crate::io::audio::AudioOutput),
    Paced(PacedThread),
}

/// The paced pseudo-device's thread. Dropped (a session that ends on an error), it is
/// told to stop, so that it does not render for ever.
pub(super) struct PacedThread {
    /// `None` once joined.
    thread: Option<JoinHandle<Result<PacedReport, IoError>>>,
    stop: Arc<AtomicBool>,
    /// The device's late wake-ups so far.
    late: Arc<AtomicU64>,
    /// One buffer's duration.
    period: Seconds,
}

impl PacedThread {
    /// Whether the thread has ended before it was told to: the error that ended it, if any.
    fn ended(&mut self) -> Option<Option<IoError>> {
        if !self.thread.as_ref().is_some_and(JoinHandle::is_finished) {
            return None;
        }
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(Err(e))) => Some(Some(e)),
            _ => Some(None),
        }
    }

    /// Stops the thread and waits for its report.
    fn finish(&mut self) -> Result<PacedReport, LiveError> {
        self.stop.store(true, Ordering::SeqCst);
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => Ok(result?),
            _ => Err(LiveError::OutputPanicked),
        }
    }
}

impl Drop for PacedThread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

/// The settings an output starts with.
pub(super) struct Start<'a> {
    pub spec: &'a OutputSpec,
    /// The `wav:` output's file, checked when the session opened.
    pub wav: Option<OutputFile>,
    pub host: &'a str,
    pub buffer: Option<u32>,
    pub channels: usize,
    pub rate: SampleRate,
    /// The adaptation's tap on the drive (an audio output only).
    pub tap: Option<DriveTap>,
    /// The session record's copy of the output.
    pub record: Option<OutputTap>,
}

impl Output {
    /// Starts the output of `start`, which plays `engine` from now on.
    pub(super) fn start(start: Start<'_>, engine: Engine) -> Result<(Self, OutputInfo), LiveError> {
        let Start {
            spec,
            wav,
            host,
            buffer,
            channels,
            rate,
            tap,
            record,
        } = start;
        if let OutputSpec::Audio { device } = spec {
            return start_audio(
                device.as_deref(),
                host,
                buffer,
                channels,
                rate,
                engine,
                (tap, record),
            );
        }
        debug_assert!(
            tap.is_none(),
            "adaptation is refused without an audio output"
        );
        let sink = match wav {
            Some(out) => Some(WavSink::live(
                out,
                rate,
                // `engine::build` refused more than `u16::MAX` channels.
                channels as u16,
                WavFormat::Float32,
                LIVE_WAV_SYNC,
            )?),
            None => None,
        };
        let block = buffer.unwrap_or(DEFAULT_BLOCK).clamp(16, 8192) as usize;
        let stop = Arc::new(AtomicBool::new(false));
        let mut device = PacedDevice::new(engine, sink, channels, rate, block);
        if let Some(record) = record {
            device = device.with_record(record);
        }
        let late = device.late_counter();
        let thread = {
            let stop = Arc::clone(&stop);
            thread::spawn(move || device.run(&stop))
        };
        let info = OutputInfo::Paced {
            spec: spec.clone(),
            channels,
            rate,
            block,
        };
        Ok((
            Output::Paced(PacedThread {
                thread: Some(thread),
                stop,
                late,
                period: Seconds(block as f64 / rate.hz()),
            }),
            info,
        ))
    }

    /// Whether the output is still playing: an error if the device reported one, or the
    /// paced thread ended (with the error that ended it).
    pub(super) fn check(&mut self) -> Result<(), LiveError> {
        match self {
            #[cfg(feature = "audio")]
            Output::Audio(a) => {
                if a.stats().stream_errors > 0 {
                    return Err(LiveError::DeviceFailed);
                }
                Ok(())
            }
            Output::Paced(paced) => match paced.ended() {
                Some(cause) => Err(LiveError::OutputStopped(cause)),
                None => Ok(()),
            },
        }
    }

    /// Buffers late so far (an audio device's late callbacks, the paced device's late
    /// wake-ups), and the output's latency: the device's measured latency when it
    /// reports one, else one buffer.
    pub(super) fn live(&self) -> (u64, Option<Seconds>) {
        match self {
            #[cfg(feature = "audio")]
            Output::Audio(a) => {
                let s = a.stats();
                (s.late_callbacks, s.latency)
            }
            Output::Paced(p) => (p.late.load(Ordering::Relaxed), Some(p.period)),
        }
    }

    /// Stops the output and says what it did.
    pub(super) fn finish(self) -> Result<OutputReport, LiveError> {
        match self {
            #[cfg(feature = "audio")]
            Output::Audio(a) => Ok(OutputReport::Audio(a.stop())),
            Output::Paced(mut paced) => paced.finish().map(OutputReport::Paced),
        }
    }
}

#[cfg(feature = "audio")]
fn start_audio(
    device: Option<&str>,
    host: &str,
    buffer: Option<u32>,
    channels: usize,
    rate: SampleRate,
    mut engine: Engine,
    (mut tap, mut record): (Option<DriveTap>, Option<OutputTap>),
) -> Result<(Output, OutputInfo), LiveError> {
    use crate::io::audio::{AudioConfig, AudioOutput};
    let config = AudioConfig {
        host: audio_host(host)?,
        device: device.map(str::to_owned),
        // `engine::build` refused more than `u16::MAX` channels.
        channels: channels as u16,
        rate,
        buffer_frames: buffer,
    };
    let output = AudioOutput::start(&config, move |out: &mut [f32], device_channels| {
        engine.process(out, device_channels);
        if let Some(tap) = &mut tap {
            tap.push(out, device_channels);
        }
        if let Some(record) = &mut record {
            record.push(out, device_channels);
        }
    })?;
    let info = OutputInfo::Audio(output.info().clone());
    Ok((Output::Audio(output), info))
}

/// The audio host named `host` (`--host`), or the session's error naming it.
#[cfg(feature = "audio")]
pub(super) fn audio_host(host: &str) -> Result<crate::io::audio::AudioHost, LiveError> {
    host.parse().map_err(|error| LiveError::Host {
        host: host.to_owned(),
        error,
    })
}

#[cfg(not(feature = "audio"))]
fn start_audio(
    _device: Option<&str>,
    _host: &str,
    _buffer: Option<u32>,
    _channels: usize,
    _rate: SampleRate,
    _engine: Engine,
    _taps: (Option<DriveTap>, Option<OutputTap>),
) -> Result<(Output, OutputInfo), LiveError> {
    Err(LiveError::NoAudio)
}
