//! `underfoot render`: force in, a WAV file of vibration out, offline.
//!
//! The force comes from a CSV track (`--force`) or from the gait generator (`--gait`).
//! The track's channel `k` drives output channel `k`. Times count from the track's first
//! reading (a logger's clock at 1700000000 s renders from frame 0), and a render is at
//! most an hour of one channel (half an hour of two, ...), since it is held in memory. The real-time engine does the
//! rendering, so a render is what a live session with the same input would play.
//!
//! # Outputs
//!
//! `--out` holds the drive and nothing else: every channel is what the actuator of that
//! channel would get. `--force-out` writes each channel's total force as the engine saw
//! it into a file of its own (32-bit float, kilonewtons, same rate and length), so force
//! that reaches thousands of kN (a logger's raw counts) never shares a file with
//! something that may be played. Every output (`--out`, `--force-out`, `--save-force`)
//! is checked against the output policy (`underfoot::atomic_file`) together with the
//! files the render reads, and the materials and library are checked too, before
//! anything is written: a render that fails leaves every file as it was.

use std::path::PathBuf;
use std::time::Instant;

use clap::{ArgGroup, Args};
use underfoot::atomic_file::OutputFile;
use underfoot::engine::offline::{render_track, track_events};
use underfoot::engine::{EngineError, Event, TimedEvent};
use underfoot::force::condition::ForceConditioner;
use underfoot::force::gait::{self, GaitConfig};
use underfoot::force::track::ForceTrack;
use underfoot::io::spec::{self, SpecError};
use underfoot::io::wav::{WavFormat, WavSink};
use underfoot::units::{Hz, Seconds};

use crate::commands::synth::SynthArgs;
use crate::output::emit;

/// Arguments of `underfoot render`.
#[derive(Debug, Args)]
#[command(group(ArgGroup::new("input").required(true).args(["force", "gait"])))]
pub struct RenderArgs {
    /// Material of each channel, comma-separated (the last one serves the rest).
    #[arg(
        long,
        value_name = "NAME[,NAME...]",
        value_delimiter = ',',
        required = true
    )]
    material: Vec<String>,
    /// Force track (CSV: `time_s,<channel>.<sensor>,...`, newtons).
    /// Default: none; give this or --gait.
    #[arg(long, value_name = "FILE.csv")]
    force: Option<PathBuf>,
    /// Generate the force of a walk instead, e.g. "steps=12,cadence=1.8,weight=70"
    /// (steps per foot; `--help` lists every key with its unit and range).
    #[arg(long, value_name = "SPEC", long_help = gait_help())]
    gait: Option<String>,
    /// Save the generated force track too.
    /// Default: not saved.
    #[arg(long = "save-force", value_name = "FILE.csv", requires = "gait")]
    save_force: Option<PathBuf>,
    /// Output WAV file: the drive of each channel, nothing else.
    #[arg(long, value_name = "FILE.wav")]
    out: PathBuf,
    /// Also write each channel's total force as the engine saw it to this WAV file of its
    /// own (32-bit float, in kilonewtons, one channel per output channel).
    /// Default: not written.
    #[arg(long = "force-out", value_name = "FILE.wav")]
    force_out: Option<PathBuf>,
    /// Replaced by --force-out: force no longer shares a file with the drive.
    #[arg(long = "with-force", hide = true)]
    with_force: bool,
    /// Sample format: f32, i16 or i24.
    #[arg(long = "sample-format", default_value = "f32", value_parser = parse_format)]
    format: WavFormat,
    /// Silence rendered after the last force reading (lets the last step ring out).
    #[arg(long, default_value_t = 1.0, value_name = "SECONDS", value_parser = parse_tail)]
    tail: f64,
    /// Frames per engine call, 1 to 65536 (the output does not depend on it).
    #[arg(long, default_value_t = 256, value_name = "N", value_parser = parse_block)]
    block: usize,
    #[command(flatten)]
    synth: SynthArgs,
}

fn parse_format(s: &str) -> Result<WavFormat, String> {
    match s {
        "f32" | "float" => Ok(WavFormat::Float32),
        "i16" => Ok(WavFormat::Int16),
        "i24" => Ok(WavFormat::Int24),
        _ => Err(format!("unknown format {s:?}: expected f32, i16 or i24")),
    }
}

fn parse_tail(s: &str) -> Result<f64, SpecError> {
    spec::parse_seconds(s, "tail", 0.0, 60.0).map(|t| t.0)
}

fn parse_block(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "block", 1, 65_536)
}

/// Runs `underfoot render`.
pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        !args.with_force,
        "--with-force is gone: force goes to a file of its own, --force-out FILE.wav \
         (--out holds the drive only)"
    );
    // Every output is checked before anything is read or written (see the module docs).
    let inputs = args.synth.input_files();
    let inputs: Vec<&std::path::Path> = inputs
        .iter()
        .map(PathBuf::as_path)
        .chain(args.force.as_deref())
        .collect();
    let wav_out = OutputFile::check(&args.out, &inputs)?;
    let force_out = match &args.force_out {
        Some(p) => {
            let o = OutputFile::check(p, &inputs)?;
            o.distinct_from(&wav_out)?;
            Some(o)
        }
        None => None,
    };
    let save_force = match &args.save_force {
        Some(p) => {
            let o = OutputFile::check(p, &inputs)?;
            o.distinct_from(&wav_out)?;
            if let Some(f) = &force_out {
                o.distinct_from(f)?;
            }
            Some(o)
        }
        None => None,
    };
    let track = match (&args.force, &args.gait) {
        (Some(path), _) => ForceTrack::read(path)?,
        (None, Some(spec)) => {
            let config = GaitConfig::from_spec(spec)?;
            gait::generate(&config)?.track
        }
        (None, None) => unreachable!("clap requires one input"),
    };
    let channels = track.channel_count();
    // The speed printed is of the whole render from force to samples: the materials'
    // preparation (some 30 ms each) as well as the engine's run.
    let started = Instant::now();
    let setup = args.synth.setup_playing(channels, Some(&args.material))?;
    let slots = setup.slots(&args.material, channels)?;
    let rate = setup.config.rate;
    let out = render_track(
        &setup.config,
        setup.bank,
        &slots,
        &track,
        Seconds(args.tail),
        args.block,
    )
    .map_err(|e| match e {
        e @ EngineError::TooLong { .. } => anyhow::anyhow!(
            "{e} (use `underfoot run --input replay:FILE --output wav:OUT` for longer sessions)"
        ),
        e => e.into(),
    })?;
    let elapsed = started.elapsed().as_secs_f64();
    let frames = out.samples.len() / channels.max(1);

    // Everything is computed and checked: the writes come last.
    if let Some(o) = &save_force {
        track.save_to(o)?;
    }
    let mut sink = WavSink::to_output(wav_out, rate, channels as u16, args.format)?;
    for chunk in out.samples.chunks(channels * 4096) {
        sink.write_interleaved(chunk)?;
    }
    let summary = sink.finish()?;
    if let Some(o) = force_out {
        let events = track_events(&track, rate);
        let force =
            force_at_audio_rate(&events, channels, frames, rate, Hz(args.synth.sensor_rate));
        let mut sink = WavSink::to_output(o, rate, channels as u16, WavFormat::Float32)?;
        let kilonewtons: Vec<f32> = force.iter().map(|f| f / 1000.0).collect();
        for chunk in kilonewtons.chunks(channels * 4096) {
            sink.write_interleaved(chunk)?;
        }
        sink.finish()?;
    }

    let t = out.telemetry;
    let seconds = frames as f64 / rate.hz();
    emit(&format!(
        "{}: {channels} channel(s), {seconds:.2} s at {rate}, {} strike(s), peak {} dBFS \
         (ceiling {:.1} dB), rendered {:.1}x faster than real time\n",
        args.out.display(),
        t.strikes,
        crate::commands::run::status::peak_text(t.peak),
        args.synth.ceiling_db,
        seconds / elapsed.max(1e-9),
    ))?;
    if let Some(warning) =
        crate::commands::run::status::limiter_warning(&t, args.synth.gain_db, args.synth.ceiling_db)
    {
        eprintln!("underfoot: warning: {warning}");
    }
    if t.non_finite > 0 || summary.clipped_samples > 0 {
        eprintln!(
            "underfoot: warning: {} non-finite sample(s) silenced, {} clipped by the format",
            t.non_finite, summary.clipped_samples
        );
    }
    if t.strikes == 0 {
        eprintln!(
            "underfoot: warning: no heel strike found: the force never rose through {} \
             (is the track in newtons? --step-threshold sets the force a strike rises \
             through)",
            setup.config.detector.on
        );
    }
    Ok(())
}

/// Each channel's total force as the engine saw it (the same interpolation), interleaved.
fn force_at_audio_rate(
    events: &[TimedEvent],
    channels: usize,
    frames: usize,
    rate: underfoot::units::SampleRate,
    sensor_rate: Hz,
) -> Vec<f32> {
    let mut conditioners = vec![ForceConditioner::new(rate, sensor_rate); channels];
    let mut force = Vec::with_capacity(frames * channels);
    let mut next = 0;
    for i in 0..frames {
        while next < events.len() && events[next].at.unwrap_or(0) <= i as u64 {
            if let Event::Force { channel, reading } = events[next].event
                && let Some(c) = conditioners.get_mut(usize::from(channel))
            {
                c.push(&reading);
            }
            next += 1;
        }
        force.extend(conditioners.iter_mut().map(ForceConditioner::next_total));
    }
    force
}

/// `--gait`'s long help: the one-line summary, then every key.
fn gait_help() -> String {
    format!(
        "Generate the force of a walk instead, e.g. \"steps=12,cadence=1.8,weight=70\".\n\n{}",
        underfoot::force::gait::SPEC_HELP
    )
}
