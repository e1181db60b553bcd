//! `underfoot calibrate`: measure the device, equalize it, fit a user's limb model, and
//! calibrate the force sensors.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::{Args, Subcommand};
use underfoot::atomic_file::OutputFile;
use underfoot::compensation::equalizer::{
    Equalized, EqualizerConfig, EqualizerFilter, PassReport, Realisation, equalize,
};
use underfoot::compensation::files::{EqualizerFile, LimbFile, PassFigures, ResponseFile};
use underfoot::compensation::limb::{DEFAULT_G2, LimbFitConfig, LimbModel, LimbParams, fit_limb};
use underfoot::compensation::sweep::{
    Device, FrequencyResponse, MAX_SWEEP_DURATION, MAX_SWEEP_REPEATS, MeasuredDevice, Sweep,
    SweepConfig, measure,
};
use underfoot::document;
use underfoot::force::calibration::{CurveKind, CurveModel, SensorCalibration, read_session};
use underfoot::io::spec::{self, SpecError};
use underfoot::sim::{SimulatedTile, SimulatedUser, TileConfig};
use underfoot::units::{Band, Decibels, Hz, SampleRate, Seconds};

use crate::output::emit;
use crate::plot::{Curve, Omitted, draw_responses};
use crate::report::{Align, table};

/// The calibration steps, in the order a session runs them.
#[derive(Debug, Subcommand)]
pub enum CalibrateCommand {
    /// Measure a device's frequency response with exponential sine sweeps.
    Sweep(SweepArgs),
    /// Tune the device equalizer by successive sweeps (the paper's equations 4-5).
    Equalize(EqualizeArgs),
    /// Fit a user's rheological limb model (equations 1-3) to loaded sweeps.
    Limb(LimbArgs),
    /// Fit each force sensor's curve from readings under known loads (a lab scale).
    Sensors(SensorsArgs),
}

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

fn parse_device(s: &str) -> Result<DeviceArg, String> {
    match s {
        "simulated" => Ok(DeviceArg::Simulated),
        "audio" => Ok(DeviceArg::Audio {
            output: None,
            input: None,
        }),
        "" => Err("expected `simulated`, `audio[:DEVICE]` or a measured-response file".into()),
        _ => match s.strip_prefix("audio:") {
            Some(device) if !device.is_empty() => Ok(DeviceArg::Audio {
                output: Some(device.to_string()),
                input: Some(device.to_string()),
            }),
            _ => Ok(DeviceArg::Measured(PathBuf::from(s))),
        },
    }
}

/// The sound card's settings for `--device audio`.
#[derive(Debug, Clone, Args)]
pub struct AudioDeviceArgs {
    /// `--device audio`: the output that drives the actuator (an id such as `hw:1`, a
    /// description or part of either; `run --list-devices` lists them); the host's
    /// default without it.
    #[arg(long = "output-device", value_name = "DEVICE")]
    pub output_device: Option<String>,
    /// `--device audio`: the input the accelerometer is on; the host's default without it.
    #[arg(long = "input-device", value_name = "DEVICE")]
    pub input_device: Option<String>,
    /// `--device audio`: audio host: default, alsa or jack.
    #[arg(long, default_value = "default", value_name = "HOST")]
    pub host: String,
    /// `--device audio`: the output channel that drives the actuator, from 0.
    #[arg(long = "out-channel", default_value_t = 0, value_name = "N")]
    pub out_channel: u16,
    /// `--device audio`: the input channel the accelerometer is on, from 0.
    #[arg(long = "in-channel", default_value_t = 0, value_name = "N")]
    pub in_channel: u16,
    /// `--device audio`: channels of the output stream (the others play silence).
    #[arg(long = "output-channels", default_value_t = 2, value_name = "N")]
    pub output_channels: u16,
    /// `--device audio`: channels of the input stream (only `--in-channel` is recorded).
    #[arg(long = "input-channels", default_value_t = 2, value_name = "N")]
    pub input_channels: u16,
    /// `--device audio`: frames per device buffer; the host's default without it. A
    /// measurement needs no low latency: large buffers (1024) keep it clear of xruns.
    #[arg(long, value_name = "FRAMES")]
    pub buffer: Option<u32>,
}

fn parse_band(s: &str) -> Result<Band, SpecError> {
    spec::parse_band(s)
}

fn parse_sweep_rate(s: &str) -> Result<u32, SpecError> {
    spec::parse_rate(s, "rate", 8_000, 384_000).map(|r| r.0)
}

fn parse_repeats(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "repeats", 1, MAX_SWEEP_REPEATS)
}

fn parse_sweep_duration(s: &str) -> Result<f64, SpecError> {
    spec::parse_seconds(s, "sweep duration", 0.01, MAX_SWEEP_DURATION.0).map(|t| t.0)
}

fn parse_passes(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "passes", 1, 50)
}

fn parse_taps(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "taps", 1, 1 << 16)
}

/// The sweep settings shared by `sweep` and `equalize`.
#[derive(Debug, Clone, Args)]
pub struct SweepSettings {
    /// The band measured, in Hz (the skin's vibrotactile range by default).
    #[arg(long, default_value = "40,1024", value_name = "LO,HI", value_parser = parse_band)]
    pub band: Band,
    /// Sample rate.
    #[arg(long, default_value_t = 48_000, value_name = "HZ", value_parser = parse_sweep_rate)]
    pub rate: u32,
    /// Sweeps averaged per measurement (1 to 100).
    #[arg(long, default_value_t = 3, value_name = "N", value_parser = parse_repeats)]
    pub repeats: usize,
    /// Duration of one sweep, in seconds (at most 60).
    #[arg(long, default_value_t = 2.0, value_name = "S", value_parser = parse_sweep_duration)]
    pub duration: f64,
    /// Simulated device only: accelerometer noise relative to the signal, in dB.
    #[arg(long = "noise-db", default_value_t = -40.0, value_name = "DB", allow_hyphen_values = true)]
    pub noise_db: f64,
    /// Simulated device only: seed of the noise.
    #[arg(long, default_value_t = 0x5EED, value_name = "N")]
    pub seed: u64,
    /// Simulated device only: a user standing on it, `table1` (Table 1's mean user),
    /// `B3K3,K2M2,B2M2`, or a limb file.
    #[arg(long, value_name = "USER", value_parser = parse_user)]
    pub load: Option<UserArg>,
    #[command(flatten)]
    pub audio: AudioDeviceArgs,
}

impl SweepSettings {
    fn sweep(&self) -> anyhow::Result<Sweep> {
        anyhow::ensure!(
            (8_000..=384_000).contains(&self.rate),
            "--rate {} Hz: need 8000 to 384000",
            self.rate
        );
        let cfg = SweepConfig {
            band: self.band,
            repeats: self.repeats,
            duration: Seconds(self.duration),
            ..SweepConfig::new(SampleRate(self.rate))
        };
        Sweep::new(cfg).context("setting up the sweep")
    }

    fn device(&self, device: &DeviceArg) -> anyhow::Result<(Box<dyn Device>, String)> {
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
                    "{} was measured at {} Hz; use --rate {}",
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
        args.out_channel,
        name(&input),
        args.in_channel
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
        "--device audio (output {:?}, input {:?}, host {}): this build has no audio support; \
         rebuild with `--features audio` (needs the libasound2-dev package) or `--features jack`",
        output.as_deref().unwrap_or("default"),
        input.as_deref().unwrap_or("default"),
        args.host
    )
}

/// `underfoot calibrate sweep`.
#[derive(Debug, Clone, Args)]
pub struct SweepArgs {
    /// The device: `simulated`, a measured-response file to replay, or `audio[:DEVICE]`
    /// (a sound card; see `--output-device`, `--input-device`, `--host`).
    #[arg(long, default_value = "simulated", value_name = "DEVICE", value_parser = parse_device)]
    pub device: DeviceArg,
    /// Measure through this equalizer (a `calibrate equalize` file).
    #[arg(long, value_name = "FILE")]
    pub eq: Option<PathBuf>,
    /// Where to write the measured response (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also draw the response (.svg or .png).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub settings: SweepSettings,
}

/// `underfoot calibrate equalize`.
#[derive(Debug, Clone, Args)]
pub struct EqualizeArgs {
    /// The device: `simulated`, a measured-response file (from `calibrate sweep`), whose
    /// magnitude is replayed for the passes after the first, or `audio[:DEVICE]` (a sound
    /// card, measured at every pass; see `--output-device`, `--input-device`, `--host`).
    #[arg(long, value_name = "DEVICE", value_parser = parse_device)]
    pub device: DeviceArg,
    /// Sweeps (passes); the first is through flat weights.
    #[arg(long, default_value_t = 3, value_name = "N", value_parser = parse_passes)]
    pub passes: usize,
    /// How the weights are applied: low-delay (a minimum-phase filter, no bulk delay) or
    /// bank (the uniform filter bank, N - 1 samples of delay).
    #[arg(long, default_value = "low-delay", value_name = "KIND")]
    pub realisation: String,
    /// Low-delay only: filter length in taps.
    #[arg(long, default_value_t = 2048, value_name = "N", value_parser = parse_taps)]
    pub taps: usize,
    /// Size N of the uniform bank that carries the weights (bins fs/N apart).
    #[arg(long, default_value_t = 4096, value_name = "N", value_parser = parse_taps)]
    pub bins: usize,
    /// Largest boost of any frequency, in dB.
    #[arg(long = "max-boost-db", default_value_t = 12.0, value_name = "DB")]
    pub max_boost_db: f64,
    /// Where to write the equalizer (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also draw every pass against flat (.svg or .png).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub settings: SweepSettings,
}

/// `underfoot calibrate limb`.
#[derive(Debug, Clone, Args)]
pub struct LimbArgs {
    /// Responses measured with the user standing on the device (`calibrate sweep` files),
    /// averaged in dB. Measured through the equalizer, or divided by `--unloaded`.
    #[arg(long, value_name = "FILE", num_args = 1.., required = true)]
    pub sweeps: Vec<PathBuf>,
    /// The unloaded device's response, measured the same way, to divide by.
    #[arg(long, value_name = "FILE")]
    pub unloaded: Option<PathBuf>,
    /// Where to write the limb model (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also draw the model against the measurement (.svg or .png).
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
}

/// `underfoot calibrate sensors`.
#[derive(Debug, Clone, Args)]
pub struct SensorsArgs {
    /// The calibration session: CSV rows of `sensor,raw,load_n` (raw reading, known load
    /// in newtons).
    #[arg(long, value_name = "FILE.csv")]
    pub readings: PathBuf,
    /// Where to write the sensor calibration (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// The curve: `power` (F = a (r - r0)^b, the FSR conductance law) or `piecewise`
    /// (monotone, for dense data).
    #[arg(long, default_value = "power", value_parser = clap::value_parser!(CurveKind))]
    pub kind: CurveKind,
}

/// A user: a limb file, Table 1's mean (`table1`), or three parameters.
#[derive(Debug, Clone)]
pub enum UserArg {
    Params(LimbParams),
    File(PathBuf),
}

pub fn parse_user(s: &str) -> Result<UserArg, String> {
    if s == "table1" {
        return Ok(UserArg::Params(LimbParams::TABLE1_MEAN));
    }
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() == 3 {
        let values: Result<Vec<f64>, _> = parts.iter().map(|p| p.trim().parse::<f64>()).collect();
        if let Ok(v) = values {
            let params = LimbParams::from_array([v[0], v[1], v[2]]);
            params.validate().map_err(|e| format!("{s:?}: {e}"))?;
            return Ok(UserArg::Params(params));
        }
    }
    Ok(UserArg::File(PathBuf::from(s)))
}

impl UserArg {
    /// The limb model, and who it is for messages.
    pub fn model(&self) -> anyhow::Result<(LimbModel, String)> {
        match self {
            UserArg::Params(p) => Ok((
                LimbModel::new(*p, DEFAULT_G2, 1.0)?,
                format!(
                    "a user with b3/k3 = {}, k2/m2 = {}, b2/m2 = {}",
                    p.b3_k3, p.k2_m2, p.b2_m2
                ),
            )),
            UserArg::File(path) => {
                let file: LimbFile = document::load(path)?;
                Ok((file.model, path.display().to_string()))
            }
        }
    }

    /// The band its compensation covers: the file's, or the default sweep band.
    pub fn band(&self) -> anyhow::Result<Band> {
        match self {
            UserArg::Params(_) => Ok(Band::new(40.0, 1024.0)),
            UserArg::File(path) => Ok(document::load::<LimbFile>(path)?.band),
        }
    }
}

pub fn run(cmd: &CalibrateCommand) -> anyhow::Result<()> {
    match cmd {
        CalibrateCommand::Sweep(args) => sweep(args),
        CalibrateCommand::Equalize(args) => equalize_cmd(args),
        CalibrateCommand::Limb(args) => limb(args),
        CalibrateCommand::Sensors(args) => sensors(args),
    }
}

/// `--out` and `--plot` of a calibrate command against the output policy
/// (`underfoot::atomic_file`) with the files the command reads, before anything is
/// measured or written.
fn check_outputs(
    out: &Path,
    plot: Option<&Path>,
    inputs: &[&Path],
) -> anyhow::Result<(OutputFile, Option<OutputFile>)> {
    let out = OutputFile::check(out, inputs)?;
    let plot = match plot {
        Some(p) => {
            let o = OutputFile::check(p, inputs)?;
            o.distinct_from(&out)?;
            Some(o)
        }
        None => None,
    };
    Ok((out, plot))
}

impl SweepSettings {
    /// The limb file of `--load`, if it is one.
    fn input_file(&self) -> Option<&Path> {
        match &self.load {
            Some(UserArg::File(p)) => Some(p),
            _ => None,
        }
    }
}

fn sensors(args: &SensorsArgs) -> anyhow::Result<()> {
    let (out, _) = check_outputs(&args.out, None, &[&args.readings])?;
    let session = read_session(&args.readings)?;
    let (calibration, reports) = SensorCalibration::fit(&session, args.kind)
        .with_context(|| format!("fitting the sensors of {}", args.readings.display()))?;
    calibration.save_to(&out)?;
    let rows: Vec<Vec<String>> = reports
        .iter()
        .zip(&calibration.sensors)
        .map(|(r, c)| {
            let model = match &c.model {
                CurveModel::Power { a, b, r0 } => format!("{a:.4e} (r - {r0:.1})^{b:.3}"),
                CurveModel::Piecewise { knots } => format!("{} knots", knots.len()),
            };
            vec![
                r.sensor.clone(),
                r.points.to_string(),
                format!("{:.0} to {:.0}", r.load_range.0.0, r.load_range.1.0),
                format!("{:.2}", r.rms_error.0),
                format!("{:.2}", r.max_error.0),
                r.downweighted.to_string(),
                model,
            ]
        })
        .collect();
    let text = table(
        &[
            ("sensor", Align::Left),
            ("points", Align::Right),
            ("load N", Align::Right),
            ("rms N", Align::Right),
            ("max N", Align::Right),
            ("outliers", Align::Right),
            ("curve", Align::Left),
        ],
        &rows,
    );
    emit(&format!(
        "{} curves of {} sensors from {}\n{text}wrote {}\n",
        args.kind,
        reports.len(),
        args.readings.display(),
        args.out.display()
    ))
}

fn limb(args: &LimbArgs) -> anyhow::Result<()> {
    let mut inputs: Vec<&Path> = args.sweeps.iter().map(PathBuf::as_path).collect();
    inputs.extend(args.unloaded.as_deref());
    let (out, plot_out) = check_outputs(&args.out, args.plot.as_deref(), &inputs)?;
    let loaded: Vec<ResponseFile> = args
        .sweeps
        .iter()
        .map(|p| document::load(p))
        .collect::<Result<_, _>>()?;
    let first = &loaded[0];
    for (file, path) in loaded.iter().zip(&args.sweeps) {
        anyhow::ensure!(
            file.freqs_hz == first.freqs_hz,
            "{} is on another frequency grid than {}; measure with the same sweep settings",
            path.display(),
            args.sweeps[0].display()
        );
    }
    let mut db: Vec<f64> = (0..first.freqs_hz.len())
        .map(|i| loaded.iter().map(|f| f.magnitude_db[i]).sum::<f64>() / loaded.len() as f64)
        .collect();
    let mut description = format!(
        "{} loaded sweep(s): {}",
        loaded.len(),
        args.sweeps
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    if let Some(path) = &args.unloaded {
        let unloaded: ResponseFile = document::load(path)?;
        anyhow::ensure!(
            unloaded.freqs_hz == first.freqs_hz,
            "{} is on another frequency grid than the loaded sweeps",
            path.display()
        );
        for (d, u) in db.iter_mut().zip(&unloaded.magnitude_db) {
            *d -= u;
        }
        description.push_str(&format!(", over unloaded {}", path.display()));
    }
    let freqs: Vec<Hz> = first.freqs_hz.iter().map(|&f| Hz(f)).collect();
    let started = std::time::Instant::now();
    let fit = fit_limb(&freqs, &db, &LimbFitConfig::default()).context("fitting the limb model")?;
    let seconds = started.elapsed().as_secs_f64();
    let p = fit.model.params;
    let file = LimbFile::new(fit.model, first.band, fit.rms_error_db, description);
    document::save_to(&out, &file)?;
    let pct = |i: usize| {
        let s = fit.relative_std[i];
        if s.is_finite() {
            format!("±{:.1}%", 100.0 * s)
        } else {
            "-".to_string()
        }
    };
    emit(&format!(
        "limb model of {} ({:.2} s, {} starts)\n  b3/k3 = {:.5} s ({}; leg corner {:.1} Hz)\n  k2/m2 = {:.4e} s^-2 ({}; skin resonance {:.0} Hz)\n  b2/m2 = {:.1} s^-1 ({})\n  level {:.2} dB, residual {:.3} dB RMS\nwrote {}\n",
        file.description,
        seconds,
        fit.starts,
        p.b3_k3,
        pct(0),
        p.leg_corner().0,
        p.k2_m2,
        pct(1),
        p.skin_resonance().0,
        p.b2_m2,
        pct(2),
        20.0 * fit.model.level.log10(),
        fit.rms_error_db,
        args.out.display()
    ))?;
    if let Some(plot_out) = &plot_out {
        let plot = plot_out.path();
        let f: Vec<f64> = first.freqs_hz.clone();
        let model: Vec<f64> = freqs
            .iter()
            .map(|&x| 20.0 * fit.model.response(x).norm().log10())
            .collect();
        let curves = [
            Curve {
                label: "measured".into(),
                freqs_hz: &f,
                db: &db,
            },
            Curve {
                label: "limb model".into(),
                freqs_hz: &f,
                db: &model,
            },
        ];
        plotted(
            plot,
            plot_out.write_with(|p| {
                draw_responses(p, "Loaded response and the limb model H_u", &curves)
            })?,
        )?;
    }
    Ok(())
}

fn sweep(args: &SweepArgs) -> anyhow::Result<()> {
    let s = &args.settings;
    let inputs: Vec<&Path> = args
        .eq
        .as_deref()
        .into_iter()
        .chain(s.input_file())
        .collect();
    let (out, plot_out) = check_outputs(&args.out, args.plot.as_deref(), &inputs)?;
    let sweep = s.sweep()?;
    let (mut device, mut description) = s.device(&args.device)?;
    let response = match &args.eq {
        Some(path) => {
            let eq: EqualizerFile = document::load(path)?;
            let mut filter = EqualizerFilter::new(&eq.weights, eq.realisation)
                .with_context(|| format!("preparing the equalizer of {}", path.display()))?;
            anyhow::ensure!(
                filter.rate().0 == s.rate,
                "{} is for {} Hz; use --rate {}",
                path.display(),
                filter.rate().0,
                filter.rate().0
            );
            description.push_str(&format!(", through {}", path.display()));
            measure(
                &mut Equalized {
                    filter: &mut filter,
                    device: device.as_mut(),
                },
                &sweep,
            )
        }
        None => measure(device.as_mut(), &sweep),
    }
    .context("measuring the response")?;
    let file = ResponseFile::new(
        &response,
        SampleRate(s.rate),
        s.band,
        s.repeats,
        description,
    );
    document::save_to(&out, &file)?;
    emit(&format!(
        "measured {}: {} points over {}-{} Hz, {:.2} dB from flat (RMS); wrote {}\n",
        file.description,
        file.freqs_hz.len(),
        s.band.lo.0,
        s.band.hi.0,
        file.deviation_db,
        args.out.display()
    ))?;
    if let Some(plot_out) = &plot_out {
        let plot = plot_out.path();
        let db = centred(&response);
        let freqs: Vec<f64> = response.freqs.iter().map(|f| f.0).collect();
        let curves = [Curve {
            label: "measured".into(),
            freqs_hz: &freqs,
            db: &db,
        }];
        plotted(
            plot,
            plot_out.write_with(|p| {
                draw_responses(p, "Frequency response (relative to its mean)", &curves)
            })?,
        )?;
    }
    Ok(())
}

fn equalize_cmd(args: &EqualizeArgs) -> anyhow::Result<()> {
    let s = &args.settings;
    let inputs: Vec<&Path> = s.input_file().into_iter().collect();
    let (out, plot_out) = check_outputs(&args.out, args.plot.as_deref(), &inputs)?;
    let realisation = match args.realisation.as_str() {
        "low-delay" => Realisation::LowDelay { taps: args.taps },
        "bank" => Realisation::Bank,
        other => anyhow::bail!("--realisation {other:?}: expected low-delay or bank"),
    };
    anyhow::ensure!(
        (1..=10).contains(&args.passes),
        "--passes {}: need 1 to 10",
        args.passes
    );
    let sweep = s.sweep()?;
    let (mut device, description) = s.device(&args.device)?;
    let config = EqualizerConfig {
        band: s.band,
        bins: args.bins,
        max_boost: Decibels(args.max_boost_db),
        ..EqualizerConfig::default()
    };
    let eq = equalize(device.as_mut(), &sweep, config, realisation, args.passes)
        .context("equalizing")?;
    let passes: Vec<PassFigures> = eq.passes.iter().map(PassFigures::from).collect();
    let latency_ms = match realisation {
        Realisation::Bank => (args.bins - 1) as f64 / f64::from(s.rate) * 1e3,
        Realisation::LowDelay { .. } => 0.0,
    };
    let file = EqualizerFile::new(eq.weights, realisation, passes.clone(), description);
    document::save_to(&out, &file)?;
    let rows: Vec<Vec<String>> = passes
        .iter()
        .map(|p| {
            vec![
                p.pass.to_string(),
                format!("{:.2}", p.deviation_db),
                format!("{:.2}", p.peak_db),
            ]
        })
        .collect();
    emit(&format!(
        "equalizing {} over {}-{} Hz ({}, {:.1} ms bulk delay)\n{}wrote {}\n",
        file.description,
        s.band.lo.0,
        s.band.hi.0,
        match realisation {
            Realisation::Bank => format!("filter bank, N = {}", args.bins),
            Realisation::LowDelay { taps } =>
                format!("low-delay minimum-phase filter, {taps} taps"),
        },
        latency_ms,
        table(
            &[
                ("pass", Align::Right),
                ("deviation RMS (dB)", Align::Right),
                ("peak (dB)", Align::Right),
            ],
            &rows
        ),
        args.out.display()
    ))?;
    if let Some(plot_out) = &plot_out {
        let plot = plot_out.path();
        let _ = plot;
        draw_passes(plot_out, &eq.passes)?;
    }
    Ok(())
}

/// Magnitude in dB minus its mean.
fn centred(response: &FrequencyResponse) -> Vec<f64> {
    let db: Vec<f64> = response.magnitude_db().iter().map(|d| d.0).collect();
    let mean = db.iter().sum::<f64>() / db.len().max(1) as f64;
    db.iter().map(|d| d - mean).collect()
}

fn draw_passes(out: &OutputFile, passes: &[PassReport]) -> anyhow::Result<()> {
    let data: Vec<(Vec<f64>, Vec<f64>)> = passes
        .iter()
        .map(|p| {
            (
                p.response.freqs.iter().map(|f| f.0).collect(),
                centred(&p.response),
            )
        })
        .collect();
    let curves: Vec<Curve<'_>> = passes
        .iter()
        .zip(&data)
        .map(|(p, (f, db))| Curve {
            label: format!("pass {} ({:.2} dB)", p.pass, p.deviation.0),
            freqs_hz: f,
            db,
        })
        .collect();
    plotted(
        out.path(),
        out.write_with(|p| {
            draw_responses(p, "Equalized device against flat, pass by pass", &curves)
        })?,
    )
}

fn plotted(path: &Path, omitted: Omitted) -> anyhow::Result<()> {
    if omitted == Omitted::Text {
        eprintln!(
            "underfoot: warning: no font found, so {} has no text (set UNDERFOOT_FONT)",
            path.display()
        );
    }
    emit(&format!("drew {}\n", path.display()))
}
