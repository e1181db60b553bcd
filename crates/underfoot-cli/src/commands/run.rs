//! `underfoot run`: the live engine. Force from a replayed track, a generated walk, a
//! serial port or OSC; vibration to an audio device, a WAV file or nowhere (`null`).
//!
//! `--interface prosthetic.toml` replaces `--input` with a prosthetic-skin interface
//! (`underfoot::io::prosthetic`): its insole frames become force events, one vibration
//! channel per `[[channel]]`, and its servo frames are written by the same poll below,
//! never by the audio thread. A simulated interface ends, like a walk, when its walk is
//! over.
//!
//! The input is polled on this thread and crosses to the audio thread over the engine's
//! lock-free queue. `wav:` and `null` outputs are paced by a thread that renders one
//! buffer per buffer period, like a device would, so a session can run without one. Like
//! a device's, its frame clock keeps time with the wall clock: a wake-up that comes late
//! renders the buffers it missed at once instead of dropping them from the timeline.
//!
//! A replay or a walk stamps each reading with its sensor time, and the engine plays it at
//! the frame its sensor clock gives it, one buffer plus `--sensor-latency` after that
//! time (`underfoot::engine`, *Timing*): the steps come out as loud and as far apart as in
//! `underfoot render`, whatever `--buffer`. The report gives the clock's anchor, so the
//! frame of every reading can be checked; late readings and re-anchorings are counted.
//! A session ends when a replay or walk has played out (plus one second to ring out),
//! after `--duration`, on Ctrl-C or SIGTERM, or on Enter when stdin is a terminal; the
//! output then fades out before the device is closed.
//!
//! A serial port that hangs up (or an interface board's) is reported on stderr and
//! reopened with a backoff (100 ms doubling to 2 s) until it comes back, which is reported
//! too; the engine's watchdog fades the output meanwhile. `--exit-on-disconnect` ends the
//! session with an error instead. However a source behaves, the poll loop below never
//! spins: a poll that reports anything but an open source is followed by a sleep for
//! the rest of the poll period.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Args;
use underfoot::atomic_file::OutputFile;
use underfoot::engine::{self, Engine, TimedEvent};
use underfoot::force::calibration::SensorCalibration;
use underfoot::force::gait::{self, GaitConfig};
use underfoot::force::scale::CountScale;
use underfoot::force::track::ForceTrack;
use underfoot::interface::config::InterfaceConfig;
use underfoot::io::osc::OscSource;
use underfoot::io::prosthetic::ProstheticHost;
use underfoot::io::replay::ReplaySource;
use underfoot::io::serial::{SerialConfig, SerialSource};
use underfoot::io::spec::{self, InputSpec, OutputSpec, SpecError};
use underfoot::io::wav::{WavFormat, WavSink};
use underfoot::io::{Backoff, EventSource, LinkEvent, SourceState};
use underfoot::sim::{SimulatorHandle, open_interface};
use underfoot::units::{Decibels, SampleRate, Seconds};

use crate::commands::synth::SynthArgs;
use crate::output::emit;

/// Arguments of `underfoot run`.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Where force comes from: replay:FILE.csv[@SPEED], gait:SPEC, serial:PORT, osc:HOST:PORT.
    #[arg(
        long,
        value_name = "SOURCE",
        required_unless_present_any = ["interface", "list_devices"],
        conflicts_with = "interface",
        value_parser = validated_input
    )]
    input: Option<String>,
    /// A prosthetic-skin interface (prosthetic.toml): insole force in, servo targets out,
    /// one vibration channel per [[channel]]. Replaces --input.
    #[arg(long, value_name = "FILE.toml")]
    interface: Option<PathBuf>,
    /// Where vibration goes: audio[:DEVICE], wav:FILE.wav, or null.
    #[arg(long, default_value = "audio", value_name = "SINK", value_parser = validated_output)]
    output: String,
    /// Material of each channel, comma-separated (default: the library's first).
    #[arg(long, value_name = "NAME[,NAME...]", value_delimiter = ',')]
    material: Vec<String>,
    /// Output channels (actuators); default: the track's channels, else 1.
    #[arg(long, value_name = "N", value_parser = parse_channels)]
    channels: Option<usize>,
    /// Frames per device buffer, 16 to 8192 (audio: requested; wav/null: the pacing
    /// period).
    #[arg(long, value_name = "N", value_parser = parse_buffer)]
    buffer: Option<u32>,
    /// Audio host: default, alsa or jack.
    #[arg(long, default_value = "default", value_name = "HOST")]
    host: String,
    /// Jitter margin of the sensor clock, in milliseconds: a timed reading (replay, gait)
    /// plays one buffer plus this after its sensor time.
    #[arg(
        long = "sensor-latency",
        default_value_t = 10.0,
        value_name = "MS",
        value_parser = parse_sensor_latency
    )]
    sensor_latency: f64,
    /// Stop after this many seconds (at most 30 days).
    #[arg(long, visible_alias = "seconds", value_name = "SECONDS", value_parser = parse_duration)]
    duration: Option<f64>,
    /// Serial line speed.
    #[arg(long, default_value_t = 115_200, value_name = "BAUD")]
    baud: u32,
    /// Serial frame layout: sensors per channel, e.g. 2,2 (heel and toe of two feet).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "2",
        value_name = "N[,N...]"
    )]
    layout: Vec<usize>,
    /// Newtons per ADC count of the serial sensors (when no --sensors calibration).
    #[arg(long = "newtons-per-count", default_value_t = 0.5, value_name = "N")]
    newtons_per_count: f32,
    /// Per-sensor calibration of the serial sensors, from `underfoot calibrate sensors`
    /// (one curve per sensor of the frame, in frame order); replaces --newtons-per-count.
    #[arg(long, value_name = "FILE.json")]
    sensors: Option<PathBuf>,
    /// When the serial port (or the interface's) is lost, exit with an error instead of
    /// reopening it until it comes back.
    #[arg(long = "exit-on-disconnect")]
    exit_on_disconnect: bool,
    /// List the audio devices and exit.
    #[arg(long = "list-devices")]
    list_devices: bool,
    #[command(flatten)]
    synth: SynthArgs,
}

/// An input spec checked by [`InputSpec::parse`] (kept as text: [`open_input`] opens it).
fn validated_input(s: &str) -> Result<String, SpecError> {
    InputSpec::parse(s).map(|_| s.to_owned())
}

/// An output spec checked by [`OutputSpec::parse`] (kept as text: [`Output::start`] opens it).
fn validated_output(s: &str) -> Result<String, SpecError> {
    OutputSpec::parse(s).map(|_| s.to_owned())
}

fn parse_duration(s: &str) -> Result<f64, SpecError> {
    spec::parse_session_duration(s).map(|d| d.0)
}

fn parse_sensor_latency(s: &str) -> Result<f64, SpecError> {
    // In milliseconds, like the flag.
    spec::parse_seconds(s, "sensor latency (ms)", 0.0, 1000.0).map(|d| d.0)
}

fn parse_channels(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "channels", 1, 64)
}

fn parse_buffer(s: &str) -> Result<u32, SpecError> {
    // 8192 fits a u32.
    spec::parse_count(s, "buffer", 16, 8192).map(|n| n as u32)
}

/// Runs `underfoot run`.
pub fn run(args: &RunArgs) -> anyhow::Result<()> {
    if args.list_devices {
        return list_devices(&args.host);
    }
    // The output file is checked before any input is opened (see `check_wav_output`).
    let wav_out = check_wav_output(args)?;
    let (mut source, track_channels, ends) = open_input(args)?;
    let channels = args.channels.or(track_channels).unwrap_or(1);
    anyhow::ensure!(
        (1..=64).contains(&channels),
        "--channels {channels}: need 1 to 64"
    );
    let mut setup = args.synth.setup(channels)?;
    anyhow::ensure!(
        args.sensor_latency.is_finite() && (0.0..=1000.0).contains(&args.sensor_latency),
        "--sensor-latency {} ms: need 0 to 1000",
        args.sensor_latency
    );
    setup.config.sensor_latency = Seconds(args.sensor_latency * 1e-3);
    let names = if args.material.is_empty() {
        vec![setup.library.materials[0].name.clone()]
    } else {
        args.material.clone()
    };
    let slots = setup.slots(&names, channels)?;
    // OSC names materials: give it the bank's names now that the bank exists.
    if let Input::OscPending(addr) = &source {
        source = Input::Source(Box::new(OscSource::bind(
            addr,
            setup.bank.names(),
            channels,
        )?));
    }
    let mut boxed: Option<Box<dyn EventSource>> = None;
    let mut interface: Option<(ProstheticHost, Option<SimulatorHandle>)> = None;
    match source {
        Input::Source(s) => boxed = Some(s),
        Input::Interface(host, sim) => interface = Some((*host, sim)),
        Input::OscPending(_) => unreachable!("OSC is bound above"),
    }
    let rate = setup.config.rate;
    let (mut controller, engine) = engine::build(&setup.config, setup.bank, &slots)?;
    let output = Output::start(
        &args.output,
        wav_out,
        &args.host,
        args.buffer,
        channels,
        rate,
        engine,
    )?;
    eprintln!("underfoot: {}", output.describe());

    let stop = Arc::new(AtomicBool::new(false));
    {
        // Ctrl-C (and SIGTERM) end the session through the fade-out like any other stop:
        // killing the stream mid-vibration would put a step on the actuator.
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }
    if std::io::stdin().is_terminal() {
        let stop = Arc::clone(&stop);
        eprintln!("underfoot: running; press Enter or Ctrl-C to stop");
        thread::spawn(move || {
            let mut line = String::new();
            let _ = std::io::stdin().read_line(&mut line);
            stop.store(true, Ordering::SeqCst);
        });
    }
    let source: &mut dyn EventSource = match (&mut boxed, &mut interface) {
        (Some(b), _) => b.as_mut(),
        (None, Some((host, _))) => host,
        (None, None) => unreachable!("every input is opened above"),
    };
    let started = Instant::now();
    let deadline = args
        .duration
        .map(|d| started + Duration::from_secs_f64(d.max(0.0)));
    let mut queue_full = 0u64;
    let mut ended_at = None;
    // Set when the input was lost and --exit-on-disconnect asks to stop: the session
    // still fades out and reports before the error.
    let mut lost: Option<String> = None;
    const POLL: Duration = Duration::from_millis(20);
    loop {
        if stop.load(Ordering::SeqCst) || deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
        if let Some(t) = ended_at {
            if Instant::now().duration_since(t) >= Duration::from_secs(1) {
                break;
            }
            thread::sleep(Duration::from_millis(20));
            continue;
        }
        let polled = Instant::now();
        let state = source.poll(POLL, &mut |event| {
            if controller.send(TimedEvent::now(event)).is_err() {
                queue_full += 1;
            }
        })?;
        while let Some(event) = source.link_event() {
            if let Some(message) = report_link(&event, args.exit_on_disconnect) {
                lost = Some(message);
            }
        }
        if lost.is_some() {
            break;
        }
        if state == SourceState::Ended && ends {
            ended_at = Some(Instant::now());
        } else if state != SourceState::Open {
            // A source that is lost or ended has nothing to wait for and may return at
            // once: pace the loop so that it cannot spin.
            thread::sleep(POLL.saturating_sub(polled.elapsed()));
        }
        controller.collect();
        if let Some(problem) = output.problem() {
            bail!("{problem}");
        }
    }
    controller.stop()?;
    let fade_deadline = Instant::now() + Duration::from_millis(500);
    while !controller.telemetry().stopped && Instant::now() < fade_deadline {
        thread::sleep(Duration::from_millis(5));
    }
    let device_report = output.finish()?;
    let t = controller.telemetry();
    let s = source.stats();
    let interface_report = match interface {
        Some((host, sim)) => interface_report(&host, sim)?,
        None => String::new(),
    };
    let clock = match t.sensor_clock {
        Some(a) => format!(
            "sensor clock: t = {:.6} s at frame {}; late readings {}, resyncs {}\n",
            a.time.0, a.frame, t.late, t.resyncs
        ),
        None => String::new(),
    };
    let link = if s.disconnects > 0 {
        format!(
            "link: lost {} time(s), reconnected {} time(s)\n",
            s.disconnects, s.reconnects
        )
    } else {
        String::new()
    };
    emit(&format!(
        "ran {:.1} s: {} strike(s), peak {:.1} dBFS, {} sample(s) limited, {} non-finite \
         silenced, {} watchdog fade(s)\ninput: {} event(s), {} rejected, {} byte(s) skipped, \
         {} dropped (queue full)\n{link}{clock}{interface_report}{device_report}\n",
        started.elapsed().as_secs_f64(),
        t.strikes,
        Decibels::from_amplitude(f64::from(t.peak).max(1e-12)).0,
        t.limited,
        t.non_finite,
        t.watchdog_trips,
        s.events,
        s.rejected,
        s.skipped_bytes,
        queue_full,
    ))?;
    match lost {
        Some(message) => bail!("{message}"),
        None => Ok(()),
    }
}

/// Says on stderr what happened to the input's device. With `exit`, a loss is not
/// reported here but returned as the message the run ends with.
fn report_link(event: &LinkEvent, exit: bool) -> Option<String> {
    match event {
        LinkEvent::Lost { .. } if exit => {
            return Some(format!("input {event}; exiting (--exit-on-disconnect)"));
        }
        LinkEvent::Lost { .. } => eprintln!(
            "underfoot: input {event}; reconnecting every {:.1} s, backing off to {:.0} s \
             (--exit-on-disconnect to stop instead); the output fades to silence meanwhile",
            Backoff::default().next_delay().as_secs_f64(),
            Backoff::default().max().as_secs_f64()
        ),
        _ => eprintln!("underfoot: input {event}"),
    }
    None
}

enum Input {
    Source(Box<dyn EventSource>),
    OscPending(String),
    Interface(Box<ProstheticHost>, Option<SimulatorHandle>),
}

/// The lines the report gets for a prosthetic interface.
fn interface_report(host: &ProstheticHost, sim: Option<SimulatorHandle>) -> anyhow::Result<String> {
    let h = host.stats();
    let mut text = format!(
        "interface: {} insole frame(s), {} rejected ({} unknown type), {} lost, {} servo \
         frame(s) sent, {} input timeout(s), {} non-finite force(s) held; servo update delay \
         max {:.1} ms, mean {:.1} ms; heartbeat gap max {:.1} ms\n",
        h.insole_frames,
        h.rejected,
        h.unknown_type,
        h.lost,
        h.servo_frames_sent,
        h.input_timeouts,
        h.non_finite,
        h.max_servo_delay.0 * 1e3,
        h.mean_servo_delay.0 * 1e3,
        h.max_servo_gap.0 * 1e3,
    );
    if h.scaling.above_range + h.scaling.below_range + h.scaling.non_finite > 0 {
        text.push_str(&format!(
            "calibration: {} reading(s) above and {} below a curve's range, {} non-finite\n",
            h.scaling.above_range, h.scaling.below_range, h.scaling.non_finite
        ));
    }
    if let Some(sim) = sim {
        let r = sim.finish()?;
        let last = r
            .positions
            .last()
            .map(|(_, p)| {
                p.iter()
                    .map(|x| format!("{x:.0}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            })
            .unwrap_or_default();
        text.push_str(&format!(
            "simulated board: {} insole frame(s) sent, {} servo frame(s) received, {} \
             rejected; servos at [{last}] µs\n",
            r.insole_frames, r.servo_frames, r.rejected
        ));
    }
    Ok(text)
}

/// The input, the number of channels it carries (if it says), and whether it ends.
fn open_input(args: &RunArgs) -> anyhow::Result<(Input, Option<usize>, bool)> {
    if let Some(path) = &args.interface {
        let config = InterfaceConfig::load(path)?;
        let channels = config.channels.len();
        let (host, sim) = open_interface(&config)?;
        let ends = sim.is_some();
        eprintln!(
            "underfoot: interface {}: {} insole sensor(s), {} servo(s) at {} Hz, {} vibration \
             channel(s){}",
            path.display(),
            config.sensors.len(),
            config.servos.len(),
            config.servo_rate.0,
            channels,
            if ends { ", simulated board" } else { "" }
        );
        return Ok((Input::Interface(Box::new(host), sim), Some(channels), ends));
    }
    let input = args
        .input
        .as_deref()
        .context("--input or --interface is needed")?;
    let (kind, rest) = input
        .split_once(':')
        .with_context(|| format!("--input {input:?}: expected KIND:WHAT"))?;
    Ok(match kind {
        "replay" => {
            let (file, speed) = match rest.rsplit_once('@') {
                Some((f, s)) => (f, spec::parse_speed(s)?),
                None => (rest, 1.0),
            };
            let track = ForceTrack::read(&PathBuf::from(file))?;
            let channels = track.channel_count();
            (
                Input::Source(Box::new(ReplaySource::new(track, speed)?)),
                Some(channels),
                true,
            )
        }
        "gait" => {
            let g = gait::generate(&GaitConfig::from_spec(rest)?)?;
            let channels = g.track.channel_count();
            (
                Input::Source(Box::new(ReplaySource::new(g.track, 1.0)?)),
                Some(channels),
                true,
            )
        }
        "serial" => {
            let scale = match &args.sensors {
                Some(path) => CountScale::calibrated(&SensorCalibration::load(path)?),
                None => CountScale::Uniform {
                    newtons_per_count: args.newtons_per_count,
                },
            };
            let config = SerialConfig {
                port: rest.to_string(),
                baud: args.baud,
                layout: args.layout.clone(),
                scale,
            };
            let layout = args.layout.len();
            (
                Input::Source(Box::new(SerialSource::open(&config)?)),
                Some(layout),
                false,
            )
        }
        "osc" => (Input::OscPending(rest.to_string()), None, false),
        _ => bail!("--input {input:?}: unknown kind {kind:?} (replay, gait, serial, osc)"),
    })
}

/// How often a `wav:` recording is brought up to date on disk: a killed session loses at
/// most this much (see `underfoot::io::wav`, *Live recordings*).
const LIVE_WAV_SYNC: Duration = Duration::from_millis(500);

/// The file of `--output wav:FILE`, checked against the output policy
/// (`underfoot::atomic_file`) with every file the session reads, before anything is
/// opened: it is replaced (and only then) when the session has started and written its
/// first buffer, and from then on it is a valid WAV file on disk at any moment.
fn check_wav_output(args: &RunArgs) -> anyhow::Result<Option<OutputFile>> {
    let Some(file) = args.output.strip_prefix("wav:") else {
        return Ok(None);
    };
    if file.is_empty() {
        return Ok(None); // Output::start says what is missing.
    }
    let mut inputs = args.synth.input_files();
    inputs.extend(args.interface.clone());
    inputs.extend(args.sensors.clone());
    if let Some(replay) = args
        .input
        .as_deref()
        .and_then(|i| i.strip_prefix("replay:"))
    {
        // The speed suffix, if any, is not part of the name; both readings are inputs.
        inputs.push(PathBuf::from(replay));
        if let Some((f, _)) = replay.rsplit_once('@') {
            inputs.push(PathBuf::from(f));
        }
    }
    let inputs: Vec<&std::path::Path> = inputs.iter().map(PathBuf::as_path).collect();
    Ok(Some(OutputFile::check(
        std::path::Path::new(file),
        &inputs,
    )?))
}

/// A running output.
enum Output {
    #[cfg(feature = "audio")]
    Audio(underfoot::io::audio::AudioOutput),
    Paced {
        thread: Option<thread::JoinHandle<anyhow::Result<String>>>,
        stop: Arc<AtomicBool>,
        what: String,
    },
}

impl Output {
    fn start(
        spec: &str,
        wav_out: Option<OutputFile>,
        host: &str,
        buffer: Option<u32>,
        channels: usize,
        rate: SampleRate,
        engine: Engine,
    ) -> anyhow::Result<Self> {
        let (kind, rest) = spec.split_once(':').unwrap_or((spec, ""));
        match kind {
            "audio" => start_audio(rest, host, buffer, channels, rate, engine),
            "wav" | "null" => {
                anyhow::ensure!(
                    kind == "null" || !rest.is_empty(),
                    "--output wav:FILE needs a file"
                );
                let sink = match wav_out {
                    Some(out) => Some(WavSink::live(
                        out,
                        rate,
                        channels as u16,
                        WavFormat::Float32,
                        LIVE_WAV_SYNC,
                    )?),
                    None => None,
                };
                let block = buffer.unwrap_or(256).clamp(16, 8192) as usize;
                let stop = Arc::new(AtomicBool::new(false));
                let what = format!(
                    "paced output {spec}: {channels} channel(s) at {rate}, {block}-frame buffers"
                );
                let thread = {
                    let stop = Arc::clone(&stop);
                    thread::spawn(move || paced(engine, sink, channels, rate, block, &stop))
                };
                Ok(Output::Paced {
                    thread: Some(thread),
                    stop,
                    what,
                })
            }
            _ => bail!("--output {spec:?}: expected audio[:DEVICE], wav:FILE or null"),
        }
    }

    fn describe(&self) -> String {
        match self {
            #[cfg(feature = "audio")]
            Output::Audio(a) => {
                let i = a.info();
                format!(
                    "audio output {} on {}: {} channel(s) at {}, buffer {}, {:?}",
                    i.device,
                    i.host,
                    i.channels,
                    i.rate,
                    i.buffer_frames
                        .map_or("default".to_string(), |b| format!("{b} frames")),
                    i.sample_format
                )
            }
            Output::Paced { what, .. } => what.clone(),
        }
    }

    fn problem(&self) -> Option<String> {
        match self {
            #[cfg(feature = "audio")]
            Output::Audio(a) => {
                let s = a.stats();
                (s.stream_errors > 0).then(|| "the audio device reported an error".to_string())
            }
            Output::Paced { thread, .. } => thread
                .as_ref()
                .is_some_and(|t| t.is_finished())
                .then(|| "the output stopped".to_string()),
        }
    }

    fn finish(self) -> anyhow::Result<String> {
        match self {
            #[cfg(feature = "audio")]
            Output::Audio(a) => {
                let s = a.stop();
                Ok(format!(
                    "audio: {} callback(s), {} late, {} xrun(s), output latency {}",
                    s.callbacks,
                    s.late_callbacks,
                    s.xruns,
                    s.latency
                        .map_or("unknown".to_string(), |l| format!("{:.2} ms", l.0 * 1e3))
                ))
            }
            Output::Paced {
                mut thread, stop, ..
            } => {
                stop.store(true, Ordering::SeqCst);
                match thread.take().map(thread::JoinHandle::join) {
                    Some(Ok(result)) => result,
                    _ => bail!("the output thread panicked"),
                }
            }
        }
    }
}

#[cfg(feature = "audio")]
fn start_audio(
    device: &str,
    host: &str,
    buffer: Option<u32>,
    channels: usize,
    rate: SampleRate,
    mut engine: Engine,
) -> anyhow::Result<Output> {
    use underfoot::io::audio::{AudioConfig, AudioOutput};
    let config = AudioConfig {
        host: host
            .parse()
            .map_err(|e| anyhow::anyhow!("--host {host:?}: {e}"))?,
        device: (!device.is_empty()).then(|| device.to_string()),
        channels: channels as u16,
        rate,
        buffer_frames: buffer,
    };
    let output = AudioOutput::start(&config, move |out: &mut [f32], device_channels| {
        engine.process(out, device_channels);
    })?;
    Ok(Output::Audio(output))
}

#[cfg(not(feature = "audio"))]
fn start_audio(
    _device: &str,
    _host: &str,
    _buffer: Option<u32>,
    _channels: usize,
    _rate: SampleRate,
    _engine: Engine,
) -> anyhow::Result<Output> {
    bail!(
        "this build has no audio output: rebuild with `--features audio` (needs the \
         libasound2-dev package), or use --output wav:FILE or --output null"
    )
}

#[cfg(feature = "audio")]
fn list_devices(host: &str) -> anyhow::Result<()> {
    let host = host
        .parse()
        .map_err(|e| anyhow::anyhow!("--host {host:?}: {e}"))?;
    let mut text = String::new();
    for d in underfoot::io::audio::list_devices(host)? {
        text.push_str(&format!(
            "{}\t{}\tup to {} ch\t{}\n",
            d.name,
            d.description,
            d.max_channels,
            d.rates
                .iter()
                .map(|r| r.0.to_string())
                .collect::<Vec<_>>()
                .join(",")
        ));
    }
    emit(&text)
}

#[cfg(not(feature = "audio"))]
fn list_devices(_host: &str) -> anyhow::Result<()> {
    bail!("this build has no audio output: rebuild with `--features audio`")
}

/// Renders one buffer per buffer period, as a device would, into a WAV file or nowhere.
fn paced(
    mut engine: Engine,
    mut sink: Option<WavSink>,
    channels: usize,
    rate: SampleRate,
    block: usize,
    stop: &AtomicBool,
) -> anyhow::Result<String> {
    let period = Duration::from_secs_f64(block as f64 / rate.hz());
    let mut buf = vec![0.0f32; block * channels];
    let mut next = Instant::now();
    let mut late = 0u64;
    let mut blocks = 0u64;
    while !stop.load(Ordering::SeqCst) {
        engine.process(&mut buf, channels);
        if let Some(sink) = &mut sink {
            sink.write_interleaved(&buf)?;
        }
        blocks += 1;
        next += period;
        let now = Instant::now();
        if next > now {
            thread::sleep(next - now);
        } else if now - next > Duration::from_secs(1) {
            // Stalled for over a second (a suspended process): start the clock afresh
            // rather than render a burst of catch-up buffers.
            late += 1;
            next = now;
        } else if now - next > period {
            // Behind by more than a buffer: render the missed ones back to back, as a
            // device's clock would have played them, so frames keep wall-clock time.
            late += 1;
        }
    }
    let written = match sink {
        Some(sink) => {
            let path = sink.path().display().to_string();
            let s = sink.finish()?;
            format!(", {} frame(s) to {path}", s.frames)
        }
        None => String::new(),
    };
    Ok(format!(
        "paced output: {blocks} buffer(s), {late} late{written}"
    ))
}
