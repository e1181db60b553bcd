//! Where sweeps are played and recorded: the simulated tile (with a simulated user on it,
//! `--load`), a replayed measurement, or a sound card (`--device-under-test audio`, with the
//! `audio` feature).

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use underfoot::compensation::files::ResponseFile;
use underfoot::compensation::sweep::{Device, MeasuredDevice};
use underfoot::document;
use underfoot::io::spec::SpecError;
use underfoot::sim::{SimulatedTile, SimulatedUser, TileConfig};
use underfoot::units::{Decibels, SampleRate};

use super::sweep::SweepSettings;

/// Where sweeps are played and recorded.
#[derive(Debug, Clone)]
pub enum DeviceArg {
    /// The simulated tile (resonances at 180, 420 and 760 Hz, a 20 Hz suspension notch,
    /// a 50-900 Hz actuator, accelerometer noise).
    Simulated,
    /// A replay of a measured response (a `calibrate sweep` file).
    Measured(PathBuf),
    /// A sound card: the actuator on an output, the accelerometer on an input (`audio`,
    /// or `audio:DEVICE` for both); `--output-device` and `--input-device` override.
    Audio {
        output: Option<String>,
        input: Option<String>,
    },
}

impl DeviceArg {
    /// The file this device reads, if it is a replayed measurement.
    pub(super) fn input_file(&self) -> Option<&Path> {
        match self {
            Self::Measured(p) => Some(p),
            Self::Simulated | Self::Audio { .. } => None,
        }
    }
}

pub(super) fn parse_device(s: &str) -> Result<DeviceArg, SpecError> {
    match s {
        "simulated" => Ok(DeviceArg::Simulated),
        "audio" => Ok(DeviceArg::Audio {
            output: None,
            input: None,
        }),
        "" => Err(SpecError::Invalid {
            what: "--device-under-test",
            input: String::new(),
            reason: "expected `simulated`, `audio[:DEVICE]` or a measured-response file".into(),
        }),
        _ => match s.strip_prefix("audio:") {
            Some(device) if !device.is_empty() => Ok(DeviceArg::Audio {
                output: Some(device.to_string()),
                input: Some(device.to_string()),
            }),
            _ => Ok(DeviceArg::Measured(PathBuf::from(s))),
        },
    }
}

/// The sound card's settings for `--device-under-test audio`.
#[derive(Debug, Clone, Args)]
pub struct AudioDeviceArgs {
    /// `--device-under-test audio`: the output that drives the actuator (an id such as `hw:1`, a
    /// description or part of either; `run --list-devices` lists them); the host's
    /// default without it.
    #[arg(long = "output-device", value_name = "DEVICE")]
    pub output_device: Option<String>,
    /// `--device-under-test audio`: the input the accelerometer is on; the host's default without it.
    #[arg(long = "input-device", value_name = "DEVICE")]
    pub input_device: Option<String>,
    /// `--device-under-test audio`: audio host: default, alsa or jack.
    #[arg(long, default_value = "default", value_name = "HOST")]
    pub host: String,
    /// `--device-under-test audio`: the output channel that drives the actuator, from 1.
    #[arg(long = "out-channel", default_value = "1", value_name = "N", value_parser = parse_out_channel)]
    pub out_channel: u16,
    /// `--device-under-test audio`: the input channel the accelerometer is on, from 1.
    #[arg(long = "in-channel", default_value = "1", value_name = "N", value_parser = parse_in_channel)]
    pub in_channel: u16,
    /// `--device-under-test audio`: channels of the output stream (the others play silence).
    #[arg(long = "output-channels", default_value_t = 2, value_name = "N")]
    pub output_channels: u16,
    /// `--device-under-test audio`: channels of the input stream (only `--in-channel` is recorded).
    #[arg(long = "input-channels", default_value_t = 2, value_name = "N")]
    pub input_channels: u16,
    /// `--device-under-test audio`: frames per device buffer; the host's default without it. A
    /// measurement needs no low latency: large buffers (1024) keep it clear of xruns.
    #[arg(long, value_name = "FRAMES")]
    pub buffer: Option<u32>,
}

impl SweepSettings {
    pub(super) fn device(&self, device: &DeviceArg) -> anyhow::Result<(Box<dyn Device>, String)> {
        let rate = SampleRate(self.rate);
        match device {
            DeviceArg::Simulated => {
                anyhow::ensure!(
                    self.noise_db.is_finite() && self.noise_db <= 0.0,
                    "--noise-db {}: need a finite level at most 0 dB",
                    self.noise_db
                );
                let cfg = TileConfig {
                    noise: Some(Decibels(self.noise_db)),
                    seed: self.seed,
                    ..TileConfig::default()
                };
                let noise = format!("{} dB sensor noise", self.noise_db);
                match &self.load {
                    None => {
                        let tile = SimulatedTile::new(&cfg, rate).context("the simulated tile")?;
                        Ok((Box::new(tile), format!("simulated tile, {noise}")))
                    }
                    Some(user) => {
                        let (model, who) = user.model()?;
                        let device =
                            SimulatedUser::new(&cfg, model, rate).context("the simulated user")?;
                        Ok((
                            Box::new(device),
                            format!("simulated tile loaded by {who}, {noise}"),
                        ))
                    }
                }
            }
            DeviceArg::Measured(path) => {
                anyhow::ensure!(
                    self.load.is_none(),
                    "--load simulates a user on the simulated tile; a replayed measurement already holds its load"
                );
                let file: ResponseFile = document::load(path)?;
                anyhow::ensure!(
                    file.rate == rate,
                    "{} was measured at {} Hz; use --audio-rate {}",
                    path.display(),
                    file.rate.0,
                    file.rate.0
                );
                let replay = MeasuredDevice::new(&file.response(), rate)
                    .with_context(|| format!("replaying {}", path.display()))?;
                Ok((
                    Box::new(replay),
                    format!("replay of {} ({})", path.display(), file.description),
                ))
            }
            DeviceArg::Audio { output, input } => {
                anyhow::ensure!(
                    self.load.is_none(),
                    "--load simulates a user on the simulated tile; on a sound card, stand on it"
                );
                let output = self.audio.output_device.clone().or_else(|| output.clone());
                let input = self.audio.input_device.clone().or_else(|| input.clone());
                audio_loop(&self.audio, output, input, rate)
            }
        }
    }
}

/// The sound card as a sweep device.
#[cfg(feature = "audio")]
fn audio_loop(
    args: &AudioDeviceArgs,
    output: Option<String>,
    input: Option<String>,
    rate: SampleRate,
) -> anyhow::Result<(Box<dyn Device>, String)> {
    use underfoot::io::audio::{AudioConfig, AudioLoop, LoopConfig};
    let host = args
        .host
        .parse()
        .map_err(|e| anyhow::anyhow!("--host {:?}: {e}", args.host))?;
    let stream = |device: Option<String>, channels: u16| AudioConfig {
        host,
        device,
        channels,
        rate,
        buffer_frames: args.buffer,
    };
    let name = |d: &Option<String>| d.clone().unwrap_or_else(|| "default".into());
    let description = format!(
        "sound card ({host} host): output {} channel {}, input {} channel {}",
        name(&output),
        u32::from(args.out_channel) + 1,
        name(&input),
        u32::from(args.in_channel) + 1
    );
    let cfg = LoopConfig {
        out_channel: args.out_channel,
        in_channel: args.in_channel,
        ..LoopConfig::new(
            stream(output, args.output_channels),
            stream(input, args.input_channels),
        )
    };
    let device = AudioLoop::new(cfg).context("the sound card")?;
    Ok((Box::new(device), description))
}

#[cfg(not(feature = "audio"))]
fn audio_loop(
    args: &AudioDeviceArgs,
    output: Option<String>,
    input: Option<String>,
    _rate: SampleRate,
) -> anyhow::Result<(Box<dyn Device>, String)> {
    anyhow::bail!(
        "--device-under-test audio (output {:?}, input {:?}, host {}): this build has no audio support; \
         rebuild with `--features audio` (needs the libasound2-dev package) or `--features jack`",
        output.as_deref().unwrap_or("default"),
        input.as_deref().unwrap_or("default"),
        args.host
    )
}

/// `--out-channel`: from 1, held as the stream's index from 0.
fn parse_out_channel(s: &str) -> Result<u16, underfoot::io::spec::SpecError> {
    underfoot::io::spec::parse_channel_number(s, "--out-channel")
}

/// `--in-channel`: from 1, held as the stream's index from 0.
fn parse_in_channel(s: &str) -> Result<u16, underfoot::io::spec::SpecError> {
    underfoot::io::spec::parse_channel_number(s, "--in-channel")
}
