//! `underfoot calibrate sweep`: a device's frequency response from exponential sine
//! sweeps, optionally through an equalizer; and the sweep settings that `sweep` and
//! `equalize` share.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use underfoot::compensation::equalizer::{Equalized, EqualizerFilter};
use underfoot::compensation::files::{EqualizerFile, ResponseFile};
use underfoot::compensation::sweep::{
    FrequencyResponse, MAX_SWEEP_DURATION, MAX_SWEEP_REPEATS, Sweep, SweepConfig, measure,
};
use underfoot::document;
use underfoot::io::spec::{self, SpecError};
use underfoot::units::{Band, SampleRate, Seconds};

use super::device::{AudioDeviceArgs, DeviceArg, parse_device};
use super::user::{UserArg, parse_user};
use super::{check_outputs, plotted};
use crate::output::emit;
use crate::plot::{Curve, draw_responses};

fn parse_sweep_rate(s: &str) -> Result<u32, SpecError> {
    spec::parse_rate(s, "rate", 8_000, 384_000).map(|r| r.0)
}

fn parse_repeats(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "repeats", 1, MAX_SWEEP_REPEATS)
}

fn parse_sweep_duration(s: &str) -> Result<f64, SpecError> {
    spec::parse_seconds(s, "sweep duration", 0.01, MAX_SWEEP_DURATION.0).map(|t| t.0)
}

/// The sweep settings shared by `sweep` and `equalize`.
#[derive(Debug, Clone, Args)]
pub struct SweepSettings {
    /// The band measured, in Hz (the skin's vibrotactile range by default).
    #[arg(long, default_value = "40:1024", value_name = "LO:HI")]
    pub band: Band,
    /// Audio sample rate, in Hz.
    #[arg(long = "audio-rate", default_value_t = 48_000, value_name = "HZ", value_parser = parse_sweep_rate)]
    pub rate: u32,
    /// Sweeps averaged per measurement (1 to 100).
    #[arg(long, default_value_t = 3, value_name = "N", value_parser = parse_repeats)]
    pub repeats: usize,
    /// Duration of one sweep, in seconds (at most 60).
    #[arg(long = "sweep-duration", default_value_t = 2.0, value_name = "S", value_parser = parse_sweep_duration)]
    pub duration: f64,
    /// Simulated device only: accelerometer noise relative to the signal, in dB.
    #[arg(long = "noise-db", default_value_t = -40.0, value_name = "DB", allow_hyphen_values = true)]
    pub noise_db: f64,
    /// Simulated device only: seed of the noise.
    #[arg(long = "noise-seed", default_value_t = 0x5EED, value_name = "N")]
    pub seed: u64,
    /// Simulated device only: a user standing on it, `table1` (Table 1's mean user),
    /// `B3K3,K2M2,B2M2`, or a limb file.
    /// Default: nobody on it.
    #[arg(long, value_name = "USER", value_parser = parse_user)]
    pub load: Option<UserArg>,
    #[command(flatten)]
    pub audio: AudioDeviceArgs,
}

impl SweepSettings {
    pub(super) fn sweep(&self) -> anyhow::Result<Sweep> {
        anyhow::ensure!(
            (8_000..=384_000).contains(&self.rate),
            "--audio-rate {} Hz: need 8000 to 384000",
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
}

impl SweepSettings {
    /// Every file a sweep command reads with these settings and `device`: the limb file of
    /// `--load` and a replayed measurement. One list for every command, so that none can
    /// name one of them as its output (`--device-under-test x.json --out x.json` replaced the
    /// measurement it was replaying).
    pub(super) fn input_files<'a>(&'a self, device: &'a DeviceArg) -> Vec<&'a Path> {
        let load = match &self.load {
            Some(UserArg::File(p)) => Some(p.as_path()),
            _ => None,
        };
        load.into_iter().chain(device.input_file()).collect()
    }
}

/// `underfoot calibrate sweep`.
#[derive(Debug, Clone, Args)]
pub struct SweepArgs {
    /// The device: `simulated`, a measured-response file to replay, or `audio[:DEVICE]`
    /// (a sound card; see `--output-device`, `--input-device`, `--host`).
    #[arg(long = "device-under-test", visible_alias = "dut", default_value = "simulated", value_name = "DEVICE", value_parser = parse_device)]
    pub device: DeviceArg,
    /// Measure through this equalizer (a `calibrate equalize` file).
    /// Default: the device alone.
    #[arg(long, value_name = "FILE")]
    pub eq: Option<PathBuf>,
    /// Where to write the measured response (JSON).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also draw the response (.svg or .png).
    /// Default: no figure.
    #[arg(long, value_name = "FILE")]
    pub plot: Option<PathBuf>,
    #[command(flatten)]
    pub plot_scale: crate::plot::PlotScale,
    #[command(flatten)]
    pub settings: SweepSettings,
}

/// Runs `underfoot calibrate sweep`.
pub(super) fn run(args: &SweepArgs) -> anyhow::Result<()> {
    let s = &args.settings;
    let mut inputs = s.input_files(&args.device);
    inputs.extend(args.eq.as_deref());
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
                "{} is for {} Hz; use --audio-rate {}",
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
                draw_responses(
                    p,
                    args.plot_scale.get(),
                    "Frequency response (relative to its mean)",
                    "magnitude (dB re its mean in the band)",
                    &curves,
                )
            })?,
        )?;
    }
    Ok(())
}

/// Magnitude in dB minus its mean.
pub(super) fn centred(response: &FrequencyResponse) -> Vec<f64> {
    let db: Vec<f64> = response.magnitude_db().iter().map(|d| d.0).collect();
    let mean = db.iter().sum::<f64>() / db.len().max(1) as f64;
    db.iter().map(|d| d - mean).collect()
}
