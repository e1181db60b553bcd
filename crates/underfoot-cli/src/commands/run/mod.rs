//! `underfoot run`: the live engine. Force from a replayed track, a generated walk, a
//! serial port, OSC or a prosthetic-skin interface (`--interface prosthetic.toml`);
//! vibration to an audio device, a WAV file or nowhere (`null`).
//!
//! The session itself (opening the input, the engine, the output, the poll loop, the
//! watchdog, the summary) is the library's `underfoot::live`; this command maps its
//! arguments to a `live::SessionConfig`, prepares the materials, says on stderr what was
//! opened and what happens to the input's device, stops the session on Ctrl-C, SIGTERM or
//! Enter (when stdin is a terminal), and prints the summary.
//!
//! A serial port that hangs up (or an interface board's) is reported on stderr and
//! reopened until it comes back, which is reported too; `--exit-on-disconnect` ends the
//! session with an error instead, after its summary.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;

use anyhow::{Context, bail};
use clap::Args;
use underfoot::atomic_file::OutputFile;
use underfoot::compensation::equalizer::Realisation;
use underfoot::compensation::files::EqualizerFile;
use underfoot::document;
use underfoot::io::spec::{self, InputSpec, OutputSpec, SpecError};
use underfoot::io::{Backoff, LinkEvent};
use underfoot::live::adapt::AdaptSettings;
use underfoot::live::record::{self, Marker};
use underfoot::live::{
    InterfaceSummary, LiveError, OutputInfo, OutputReport, RecordSettings, RemoteCommand,
    RunningSession, SerialSettings, Session, SessionConfig, SessionInput, Status, Summary,
};
use underfoot::units::Seconds;

use crate::commands::synth::{Setup, SynthArgs};
use crate::output::emit;

pub mod status;

/// Arguments of `underfoot run`.
#[derive(Debug, Clone, Args)]
pub struct RunArgs {
    /// Where force comes from: replay:FILE.csv[@SPEED], gait:SPEC, serial:PORT, osc:HOST:PORT.
    /// Default (no --input, no --interface): a generated walk, `gait:steps=4`, said so on
    /// stderr.
    #[arg(long, value_name = "SOURCE", conflicts_with = "interface", long_help = input_help())]
    input: Option<InputArg>,
    /// A prosthetic-skin interface (prosthetic.toml): insole force in, servo targets out,
    /// one vibration channel per [[channel]]. Replaces --input.
    /// Default: none.
    #[arg(long, value_name = "FILE.toml")]
    interface: Option<PathBuf>,
    /// Where vibration goes: audio[:DEVICE], wav:FILE.wav, or null (paced in real time,
    /// counted, not heard). Default: audio when this build has it (`--features audio`),
    /// else null, said so on stderr.
    #[arg(long, value_name = "SINK")]
    output: Option<OutputSpec>,
    /// Material of each channel, comma-separated (default: the library's first).
    #[arg(long, value_name = "NAME[,NAME...]", value_delimiter = ',')]
    material: Vec<String>,
    /// Output channels (actuators); default: the track's channels, else 1.
    #[arg(long, value_name = "N", value_parser = parse_channels)]
    channels: Option<usize>,
    /// Frames per device buffer, 16 to 8192 (audio: requested, default the device's own
    /// choice; wav/null: the pacing period, default 256).
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
    /// Default: run until stopped.
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
    /// Default: none (--newtons-per-count for every sensor).
    #[arg(long, value_name = "FILE.json")]
    sensors: Option<PathBuf>,
    /// When the serial port (or the interface's) is lost, exit with an error instead of
    /// reopening it until it comes back.
    #[arg(long = "exit-on-disconnect")]
    exit_on_disconnect: bool,
    /// List the audio devices and exit.
    #[arg(long = "list-devices")]
    list_devices: bool,
    /// No live status block (it is shown on stderr when stderr is a terminal).
    #[arg(long, short = 'q')]
    quiet: bool,
    /// Say on stderr, as they happen (at most once a second), the input's rejected
    /// messages: how many, for which reasons, and what the last one did wrong.
    #[arg(long, short = 'v')]
    verbose: bool,
    /// A line of JSON a second to FILE (or `-`, standard output, before the summary):
    /// elapsed time, per channel force (N), strikes, peak (dBFS, null for silence) and
    /// limited samples; input events, rejects, losses; late events, non-finite samples,
    /// watchdog fades.
    /// Default: none.
    #[arg(long = "status-json", value_name = "FILE|-")]
    status_json: Option<PathBuf>,
    /// Adapt the equalizer (--eq) while the user walks: an accelerometer on an audio input
    /// of the same host (--adapt-input) is compared with the drive, the delay between
    /// them removed, and the weights moved towards flat (at most 0.5 dB per update, within
    /// the sweeps' bounds). Needs --output audio.
    #[arg(long, requires = "eq")]
    adapt: bool,
    /// The input channel the accelerometer is on, from 1 [default: 1].
    #[arg(long = "adapt-input", value_name = "N", requires = "adapt", value_parser = parse_adapt_input)]
    adapt_input: Option<u16>,
    /// The input device the accelerometer is on [default: the output's device].
    #[arg(long = "adapt-device", value_name = "NAME", requires = "adapt")]
    adapt_device: Option<String>,
    /// The output channel whose equalizer adapts, from 1 [default: 1].
    #[arg(long = "adapt-channel", value_name = "N", requires = "adapt", value_parser = parse_adapt_channel)]
    adapt_channel: Option<u16>,
    /// Save the adapted equalizer when the session ends (the format of --eq, to start
    /// from next time).
    /// Default: not saved.
    #[arg(long = "adapt-out", value_name = "FILE.json", requires = "adapt")]
    adapt_out: Option<PathBuf>,
    /// Record the session into the folder DIR (new, or empty): manifest.json, every force
    /// reading (force.csv), every strike (strikes.csv), every change and marker
    /// (events.jsonl), the status a second (status.jsonl) and the output (output.wav),
    /// written as it goes. With it, each line typed on standard input is a marker (plain
    /// text, or a JSON object {"text", "trial", "participant", "condition"}); on a
    /// terminal an empty line stops. `underfoot session show DIR` reads it.
    /// Default: not recorded.
    #[arg(long, value_name = "DIR")]
    record: Option<PathBuf>,
    /// The most the record may hold, in MiB; at the bound the force, status and output
    /// stop and an event says so (strikes, markers and changes go on).
    #[arg(long = "record-max-mb", value_name = "MIB", default_value_t = 4096, requires = "record", value_parser = clap::value_parser!(u64).range(1..=1_048_576))]
    record_max_mb: u64,
    /// Publish the record's force, strikes and markers as Lab Streaming Layer streams too
    /// ("underfoot force", "underfoot strikes", "underfoot markers", on LSL's clock), for a
    /// lab's LabRecorder. Needs a build with `--features lsl` and liblsl (set
    /// UNDERFOOT_LIBLSL to its path, e.g. the one `pip install pylsl` carries).
    #[arg(long, requires = "record")]
    lsl: bool,
    #[command(flatten)]
    synth: SynthArgs,
}

/// What a session plays with, as a person reads it: the texts `--input` and `--output`
/// take, the library file (none: the built-in one) and the prosthetic interface, if any
/// (its file sets the input and the servo output).
#[cfg(feature = "panel")]
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SessionSettings {
    pub input: String,
    pub output: String,
    pub library: Option<PathBuf>,
    pub interface: Option<PathBuf>,
}

/// A choice of input, output or library for the next session, parsed as the flags
/// parse them; `None` keeps the current one.
#[cfg(feature = "panel")]
#[derive(Debug, Clone, Default)]
pub struct SessionChoice {
    input: Option<InputArg>,
    output: Option<OutputSpec>,
    /// `Some(None)`: the built-in library.
    library: Option<Option<PathBuf>>,
}

#[cfg(feature = "panel")]
impl SessionChoice {
    /// Parses the texts as `--input`, `--output` and `--library` would (an empty library
    /// is the built-in one), and checks them against the session they change.
    ///
    /// # Errors
    /// What is wrong, naming the field: a spec that does not parse, an input for a panel
    /// that drives a prosthetic interface, or (with `paths_allowed` false, a panel that
    /// serves other machines) a file the command line did not name.
    pub fn parse(
        input: Option<&str>,
        output: Option<&str>,
        library: Option<&str>,
        current: &SessionSettings,
        paths_allowed: bool,
    ) -> Result<Self, String> {
        let input = input
            .map(str::trim)
            .filter(|t| *t != current.input)
            .map(|t| {
                if let Some(file) = &current.interface {
                    return Err(format!(
                        "input {t:?}: this panel drives the prosthetic interface {}, whose \
                         file sets the input; start the panel with --input instead of \
                         --interface to choose it here",
                        file.display()
                    ));
                }
                t.parse::<InputArg>().map_err(|e| format!("input: {e}"))
            })
            .transpose()?;
        let output = output
            .map(str::trim)
            .filter(|t| *t != current.output)
            .map(|t| t.parse::<OutputSpec>().map_err(|e| format!("output: {e}")))
            .transpose()?;
        let library = library
            .map(str::trim)
            .map(|t| (!t.is_empty()).then(|| PathBuf::from(t)))
            .filter(|l| *l != current.library);
        if !paths_allowed {
            let named = [
                input.as_ref().and_then(|i| match &i.spec {
                    InputSpec::Replay { .. } => Some("input"),
                    _ => None,
                }),
                output.as_ref().and_then(|o| match o {
                    OutputSpec::Wav { .. } => Some("output"),
                    _ => None,
                }),
                library.as_ref().and_then(|l| l.as_ref().map(|_| "library")),
            ];
            if let Some(what) = named.into_iter().flatten().next() {
                return Err(format!(
                    "{what}: a file chosen from the page is taken only by a panel on a \
                     loopback address (this one serves other machines); name it on the \
                     command line instead"
                ));
            }
        }
        Ok(Self {
            input,
            output,
            library,
        })
    }
}

/// `--input`: the spec, and the text it was given as.
#[derive(Debug, Clone)]
struct InputArg {
    spec: InputSpec,
    text: String,
}

impl FromStr for InputArg {
    type Err = SpecError;

    fn from_str(s: &str) -> Result<Self, SpecError> {
        Ok(Self {
            spec: s.parse()?,
            text: s.to_owned(),
        })
    }
}

impl InputArg {
    /// The name of a `replay:` track as written, when it has an `@`: `replay:a@2` plays
    /// `a` at twice real time, but may have been meant for a track named `a@2`, which an
    /// output must not overwrite either.
    fn other_reading(&self) -> Option<PathBuf> {
        match &self.spec {
            InputSpec::Replay { .. } => self
                .text
                .strip_prefix("replay:")
                .filter(|name| name.contains('@'))
                .map(PathBuf::from),
            _ => None,
        }
    }
}

fn parse_duration(s: &str) -> Result<f64, SpecError> {
    spec::parse_session_duration(s).map(|d| d.0)
}

fn parse_sensor_latency(s: &str) -> Result<f64, SpecError> {
    // In milliseconds, like the flag.
    spec::parse_seconds(s, "sensor latency (ms)", 0.0, 1000.0).map(|d| d.0)
}

/// `--adapt-input`: from 1, held as the stream's index from 0.
fn parse_adapt_input(s: &str) -> Result<u16, SpecError> {
    spec::parse_channel_number(s, "--adapt-input")
}

/// `--adapt-channel`: from 1, held as the engine's index from 0.
fn parse_adapt_channel(s: &str) -> Result<u16, SpecError> {
    spec::parse_channel_number(s, "--adapt-channel")
}

fn parse_channels(s: &str) -> Result<usize, SpecError> {
    spec::parse_count(s, "channels", 1, 64)
}

fn parse_buffer(s: &str) -> Result<u32, SpecError> {
    // 8192 fits a u32.
    spec::parse_count(s, "buffer", 16, 8192).map(|n| n as u32)
}

/// `--input`'s long help: each kind of source, then the gait spec's keys.
fn input_help() -> String {
    format!(
        "Where force comes from (default, with no --input and no --interface: \
         {DEFAULT_INPUT}, said so on stderr):\n\
         \x20 replay:FILE.csv[@SPEED]  a force track (time_s, then newtons per sensor), at\n\
         \x20                          SPEED times real time (default 1)\n\
         \x20 gait:SPEC                a generated walk, as below\n\
         \x20 serial:PORT              sensor frames from a microcontroller (--baud, --layout)\n\
         \x20 osc:HOST:PORT            OSC messages over UDP (a VR engine, a patch)\n\n{}",
        underfoot::force::gait::SPEC_HELP
    )
}

/// The input of a bare `underfoot run`: a short generated walk, so that the command does
/// something a newcomer can see (and hear, with audio) without hardware.
const DEFAULT_INPUT: &str = "gait:steps=4";

impl RunArgs {
    /// These arguments as `panel` runs its `n`th session (from 1): a `--library` that
    /// does not exist yet plays the built-in materials until a fit creates it, and a
    /// restarted session records into `DIR-n`, beside the first's `DIR`.
    #[cfg_attr(
        not(feature = "panel"),
        expect(dead_code, reason = "the panel restarts sessions")
    )]
    pub fn for_panel_session(&self, n: u32) -> Self {
        let mut args = self.clone();
        args.synth.library_created_by_fits = true;
        if n > 1
            && let Some(dir) = &self.record
        {
            let mut name = dir.as_os_str().to_owned();
            name.push(format!("-{n}"));
            args.record = Some(PathBuf::from(name));
        }
        args
    }

    /// The input, output and library this session plays with, as the panel's page shows
    /// and offers to change them.
    #[cfg(feature = "panel")]
    pub fn settings(&self) -> SessionSettings {
        SessionSettings {
            input: match (&self.input, &self.interface) {
                (Some(input), _) => input.text.clone(),
                (None, Some(_)) => String::new(),
                (None, None) => DEFAULT_INPUT.to_owned(),
            },
            output: self.output().to_string(),
            library: self.synth.library.clone(),
            interface: self.interface.clone(),
        }
    }

    /// These arguments with the page's choice of input, output or library in place of
    /// the command line's (what the choice leaves out stays as it was).
    #[cfg(feature = "panel")]
    pub fn choose(&mut self, choice: &SessionChoice) {
        if let Some(input) = &choice.input {
            self.input = Some(input.clone());
        }
        if let Some(output) = &choice.output {
            self.output = Some(output.clone());
        }
        if let Some(library) = &choice.library {
            self.synth.library.clone_from(library);
        }
    }

    /// `--host`: the audio host.
    #[cfg(feature = "panel")]
    pub fn audio_host(&self) -> &str {
        &self.host
    }

    /// `--record`, if given.
    #[cfg_attr(
        not(feature = "panel"),
        expect(dead_code, reason = "the panel shows where it records")
    )]
    pub fn record_path(&self) -> Option<PathBuf> {
        self.record.clone()
    }

    /// `--output`, or the default: the sound card when this build can play to one, else
    /// `null`, the paced pseudo-device. Never an error: the default build has no audio
    /// (it needs the ALSA headers), and a bare `run` should still run.
    fn output(&self) -> OutputSpec {
        self.output.clone().unwrap_or(if cfg!(feature = "audio") {
            OutputSpec::Audio { device: None }
        } else {
            OutputSpec::Null
        })
    }

    /// What was chosen for the user, to say on stderr: the defaults of a bare `run`.
    fn defaults_taken(&self) -> Vec<String> {
        let mut said = Vec::new();
        if self.input.is_none() && self.interface.is_none() && !self.list_devices {
            said.push(format!(
                "no --input: a generated walk ({DEFAULT_INPUT}); give --input for real force \
                 (replay:FILE.csv, serial:PORT, osc:HOST:PORT)"
            ));
        }
        if self.output.is_none() {
            said.push(if cfg!(feature = "audio") {
                "no --output: the default audio device".to_owned()
            } else {
                "no --output, and this build has no audio (scripts/install-audio adds the ALSA \
                 headers and builds with it, or rebuild with `--features audio`): \
                 playing to null, paced in real time and counted but not heard; \
                 --output wav:FILE.wav to keep it"
                    .to_owned()
            });
        }
        said
    }

    /// The session these arguments ask for.
    fn session(&self) -> anyhow::Result<SessionConfig> {
        let input = match (&self.interface, &self.input) {
            (Some(path), _) => SessionInput::Interface(path.clone()),
            (None, Some(input)) => SessionInput::Spec(input.spec.clone()),
            (None, None) => SessionInput::Spec(DEFAULT_INPUT.parse()?),
        };
        let mut reads = self.synth.input_files();
        reads.extend(self.input.as_ref().and_then(InputArg::other_reading));
        Ok(SessionConfig {
            host: self.host.clone(),
            buffer: self.buffer,
            serial: SerialSettings {
                baud: self.baud,
                layout: self.layout.clone(),
                newtons_per_count: self.newtons_per_count,
                sensors: self.sensors.clone(),
            },
            duration: self.duration.map(Seconds),
            exit_on_disconnect: self.exit_on_disconnect,
            reads,
            adapt: self.adapt.then(|| AdaptSettings {
                channel: self.adapt_channel.unwrap_or(0),
                device: self.adapt_device.clone(),
                input_channel: self.adapt_input.unwrap_or(0),
                ..AdaptSettings::default()
            }),
            record: self.record_settings()?,
            ..SessionConfig::new(input, self.output())
        })
    }

    /// `--record`'s settings: the folder, its bound, and what the manifest says of the
    /// command (its line, the library's hash, the synthesis settings).
    fn record_settings(&self) -> anyhow::Result<Option<RecordSettings>> {
        let Some(dir) = &self.record else {
            return Ok(None);
        };
        let builtin = || -> anyhow::Result<String> {
            let text = serde_json::to_vec(&underfoot::material::builtin::builtin())?;
            Ok(record::sha256_hex(&text))
        };
        let library = match &self.synth.library {
            // The panel's library that a fit will create: the built-in one plays until then.
            Some(path) if self.synth.library_created_by_fits && !path.exists() => (
                format!("built-in ({} does not exist yet)", path.display()),
                builtin()?,
            ),
            Some(path) => {
                let bytes =
                    underfoot::limits::read_capped(path, underfoot::limits::MAX_LIBRARY_BYTES)
                        .with_context(|| format!("reading the library {}", path.display()))?;
                (path.display().to_string(), record::sha256_hex(&bytes))
            }
            None => ("built-in".to_owned(), builtin()?),
        };
        let s = &self.synth;
        Ok(Some(RecordSettings {
            max_bytes: self.record_max_mb << 20,
            command_line: std::env::args().collect(),
            library,
            input: Some(match (&self.interface, &self.input) {
                (Some(path), _) => format!("interface:{}", path.display()),
                (None, Some(input)) => input.text.clone(),
                (None, None) => DEFAULT_INPUT.to_owned(),
            }),
            settings: serde_json::json!({
                "materials": self.material,
                "model": format!("{:?}", s.model),
                "drive": format!("{:?}", s.drive),
                "excitation": format!("{:?}", s.excitation),
                "perturbation": s.perturbation,
                "weight_kg": s.weight_kg,
                "step_threshold_n": s.step_threshold_n,
                "sensor_rate_hz": s.sensor_rate,
                "eq": s.eq.as_ref().map(|p| p.display().to_string()),
                "gain_db": s.gain_db,
                "ceiling_db": s.ceiling_db,
            }),
            lsl: self.lsl,
            ..RecordSettings::new(dir)
        }))
    }
}

/// Something beside the terminal that watches and steers a session: `panel`'s web page.
/// Its calls come from the thread that runs the session, which never makes the audio
/// thread wait.
pub trait Observer {
    /// The bank and the channels' first slots, instead of the setup's own: called after
    /// the setup, before the engine is built. `names` are the `--material` names, one per
    /// channel or one for all. `None` keeps the setup's.
    fn prepare(
        &mut self,
        setup: &mut Setup,
        names: &[String],
        channels: usize,
    ) -> anyhow::Result<Option<Vec<u16>>>;
    /// The session has started: what plays, and the handle that steers it.
    fn started(&mut self, session: &RunningSession, setup: &Setup);
    /// What the session is doing, about every 20 ms.
    fn status(&mut self, status: &Status);
    /// The session has ended, with its summary or the error it ended on.
    fn ended(&mut self, outcome: Result<&Summary, &anyhow::Error>);
}

/// How often the session reports to an observer: often enough for meters that move
/// smoothly (the loop then polls the input this often too).
const OBSERVER_EVERY: std::time::Duration = std::time::Duration::from_millis(20);

/// Runs `underfoot run`.
pub fn run(args: &RunArgs) -> anyhow::Result<()> {
    let stop = Arc::new(AtomicBool::new(false));
    {
        // Ctrl-C (and SIGTERM) end the session through the fade-out like any other stop:
        // killing the stream mid-vibration would put a step on the actuator.
        let stop = Arc::clone(&stop);
        ctrlc::set_handler(move || stop.store(true, Ordering::SeqCst))
            .context("installing the Ctrl-C handler")?;
    }
    run_session(args, &stop, None)
}

/// Checks `args` against everything that must hold before a session starts (the files
/// it writes, the devices list); `Some` when there is nothing to run (the list was
/// printed).
pub fn precheck(args: &RunArgs) -> anyhow::Result<Option<()>> {
    if args.list_devices {
        return list_devices(&args.host).map(Some);
    }
    Ok(None)
}

/// Runs the session `args` ask for until it ends or `stop` is set, with `observer`
/// told what happens.
pub fn run_session(
    args: &RunArgs,
    stop: &Arc<AtomicBool>,
    mut observer: Option<&mut dyn Observer>,
) -> anyhow::Result<()> {
    let mut told = false;
    let outcome = session_body(args, stop, &mut observer, &mut told);
    // A session that failed before it started (a library that does not load, a device
    // that does not open) is an end the observer must hear of too: a page would
    // otherwise say "starting" for good.
    if let (Err(e), Some(o), false) = (&outcome, &mut observer, told) {
        o.ended(Err(e));
    }
    outcome
}

/// [`run_session`]'s body; sets `told` once the observer has heard how it ended.
fn session_body(
    args: &RunArgs,
    stop: &Arc<AtomicBool>,
    observer: &mut Option<&mut dyn Observer>,
    told: &mut bool,
) -> anyhow::Result<()> {
    if precheck(args)?.is_some() {
        return Ok(());
    }
    for line in args.defaults_taken() {
        eprintln!("underfoot: {line}");
    }
    let config = args.session()?;
    // Said before anything is loaded or opened (the session would refuse it too, later).
    if config.adapt.is_some() && !matches!(config.output, OutputSpec::Audio { .. }) {
        return Err(LiveError::AdaptNeedsAudio.into());
    }
    // The status file is checked like every output, before anything starts: never one
    // of the session's inputs, nor its WAV output.
    let mut inputs = config.inputs();
    if let OutputSpec::Wav { path } = &config.output {
        inputs.push(path);
    }
    let status_file = match &args.status_json {
        Some(p) if p.as_os_str() != "-" => Some(OutputFile::check(p, &inputs)?),
        _ => None,
    };
    let adapt_out = match &args.adapt_out {
        Some(p) => {
            inputs.extend(status_file.as_ref().map(OutputFile::path));
            Some(OutputFile::check(p, &inputs)?)
        }
        None => None,
    };
    let session = Session::open(&config)?;
    if let (Some(path), Some(config)) = (&args.interface, session.interface()) {
        eprintln!(
            "underfoot: interface {}: {} insole sensor(s), {} servo(s) at {} Hz, {} vibration \
             channel(s){}",
            path.display(),
            config.sensors.len(),
            config.servos.len(),
            config.servo_rate.0,
            config.channels.len(),
            if session.ends() {
                ", simulated board"
            } else {
                ""
            }
        );
    }
    let channels = args.channels.or(session.channels()).unwrap_or(1);
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
    let slots = match observer {
        Some(o) => o.prepare(&mut setup, &names, channels)?,
        None => None,
    };
    let slots = match slots {
        Some(slots) => slots,
        None => setup.slots(&names, channels)?,
    };
    // The bank goes to the engine; the observer may want the setup's other parts.
    let bank = std::mem::take(&mut setup.bank);
    let running = session.start(&setup.config, bank, &slots)?;
    eprintln!("underfoot: {}", describe(running.output()));
    if let Some(o) = observer {
        o.started(&running, &setup);
    }

    if args.record.is_some() {
        read_markers(&running, stop);
    } else if std::io::stdin().is_terminal() {
        let stop = Arc::clone(stop);
        eprintln!("underfoot: running; press Enter or Ctrl-C to stop");
        thread::spawn(move || {
            let mut line = String::new();
            let _ = std::io::stdin().read_line(&mut line);
            stop.store(true, Ordering::SeqCst);
        });
    }
    let json: Option<Box<dyn std::io::Write>> = match (&args.status_json, &status_file) {
        (_, Some(file)) => Some(Box::new(std::io::LineWriter::new(
            // A log that grows while the session runs: written in place, not replaced
            // at the end like a document.
            std::fs::File::create(file.path())
                .with_context(|| format!("creating the status file {}", file.path().display()))?,
        ))),
        (Some(_), None) => Some(Box::new(std::io::stdout())),
        (None, None) => None,
    };
    let mut display = status::Display::new(!args.quiet && std::io::stderr().is_terminal(), json);
    let summary = if display.active() || observer.is_some() || args.verbose {
        let mut failed = None;
        let mut rejects = Rejects::default();
        let mut paced = status::Paced::new(status::EVERY);
        // Both callbacks draw on the terminal; the session calls them one at a time.
        let display = std::cell::RefCell::new(&mut display);
        let summary = running.run_with_status(
            stop,
            |event| {
                display.borrow_mut().clear();
                report_link(event);
            },
            if observer.is_some() {
                OBSERVER_EVERY
            } else {
                status::EVERY
            },
            |s| {
                if let Some(o) = observer.as_mut() {
                    o.status(s);
                }
                let mut display = display.borrow_mut();
                if args.verbose
                    && let Some(line) = rejects.news(s)
                {
                    display.clear();
                    eprintln!("underfoot: {line}");
                }
                if failed.is_none()
                    && display.active()
                    && let Some(s) = paced.take(s)
                    && let Err(e) = display.show(s)
                {
                    // A status reader that went away does not stop the session.
                    failed = Some(e);
                }
            },
        );
        if let Some(e) = failed {
            eprintln!("underfoot: the status stopped: {e}");
        }
        summary
    } else {
        running.run(stop, report_link)
    };
    let summary = summary.map_err(anyhow::Error::from);
    if let Some(o) = observer {
        o.ended(summary.as_ref());
        *told = true;
    }
    let summary = summary?;
    emit(&report(&summary))?;
    if let Some(warning) = status::limiter_warning(
        &summary.telemetry,
        args.synth.gain_db,
        args.synth.ceiling_db,
    ) {
        eprintln!("underfoot: warning: {warning}");
    }
    if let (Some(out), Some((status, weights))) = (&adapt_out, &summary.adapt) {
        let realisation = setup
            .config
            .compensation
            .equalizer
            .as_ref()
            .map_or(Realisation::Bank, |(_, r)| *r);
        let from = args
            .synth
            .eq
            .as_deref()
            .map_or_else(String::new, |p| format!(" from {}", p.display()));
        let file = EqualizerFile::new(
            weights.clone(),
            realisation,
            Vec::new(),
            format!(
                "adapted online{from} over {:.0} s of walking: {} update(s), estimated \
                 deviation {}",
                summary.elapsed.as_secs_f64(),
                status.updates,
                status
                    .estimated_deviation
                    .map_or_else(|| "unknown".to_owned(), |d| format!("{:.2} dB", d.0))
            ),
        );
        document::save_to(out, &file)?;
        eprintln!(
            "underfoot: wrote the adapted equalizer to {}",
            out.path().display()
        );
    }
    match &summary.lost {
        Some(event) => bail!("input {event}; exiting (--exit-on-disconnect)"),
        None => Ok(()),
    }
}

/// What `--verbose` has said of the input's rejections.
#[derive(Default)]
struct Rejects {
    said: u64,
    markers_said: u64,
    at: Option<std::time::Instant>,
}

impl Rejects {
    /// A line about rejections or markers that went nowhere since the last one, at most
    /// once a second.
    fn news(&mut self, s: &Status) -> Option<String> {
        let new = s.input.rejected > self.said || s.markers_unrecorded > self.markers_said;
        if !new
            || self
                .at
                .is_some_and(|t| t.elapsed() < std::time::Duration::from_secs(1))
        {
            return None;
        }
        self.at = Some(std::time::Instant::now());
        self.said = s.input.rejected;
        self.markers_said = s.markers_unrecorded;
        let mut parts = Vec::new();
        if s.input.rejected > 0 {
            let reasons: Vec<String> = s
                .rejections
                .iter()
                .map(|(why, n)| format!("{why}: {n}"))
                .collect();
            parts.push(format!(
                "{} input message(s) rejected so far{}{}",
                s.input.rejected,
                if reasons.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", reasons.join(", "))
                },
                s.last_reject
                    .as_ref()
                    .map_or_else(String::new, |w| format!("; the last: {w}"))
            ));
        }
        if s.markers_unrecorded > 0 {
            parts.push(format!(
                "{} marker(s) received with no record to keep them (--record DIR)",
                s.markers_unrecorded
            ));
        }
        Some(parts.join("; "))
    }
}

/// Reads markers from standard input for a recorded session, on a thread of its own:
/// each line is one (plain text, or a JSON [`Marker`]); on a terminal, an empty line
/// stops the session, as Enter does without a record.
fn read_markers(running: &RunningSession, stop: &Arc<AtomicBool>) {
    let terminal = std::io::stdin().is_terminal();
    if terminal {
        eprintln!(
            "underfoot: recording; type a marker and Enter to mark the moment, an empty line \
             or Ctrl-C to stop"
        );
    }
    let remote = running.remote();
    let stop = Arc::clone(stop);
    thread::spawn(move || {
        for line in std::io::stdin().lines() {
            let Ok(line) = line else { break };
            let line = line.trim();
            if line.is_empty() {
                if terminal {
                    stop.store(true, Ordering::SeqCst);
                    break;
                }
                continue;
            }
            let marker = if line.starts_with('{') {
                match serde_json::from_str::<Marker>(line) {
                    Ok(m) => m,
                    Err(e) => {
                        eprintln!(
                            "underfoot: marker refused: {e} (a JSON marker has \
                                   \"text\" and optionally \"trial\", \"participant\", \
                                   \"condition\")"
                        );
                        continue;
                    }
                }
            } else {
                Marker::new(line)
            };
            match remote.send(RemoteCommand::Marker(marker)) {
                Ok(_) => {}
                Err(underfoot::live::RemoteError::Ended) => break,
                Err(e) => eprintln!("underfoot: {e}"),
            }
        }
    });
}

/// Says on stderr what happened to the input's device (a loss that ends the session is
/// the error it ends with instead).
fn report_link(event: &LinkEvent) {
    match event {
        LinkEvent::Lost { .. } => eprintln!(
            "underfoot: input {event}; reconnecting every {:.1} s, backing off to {:.0} s \
             (--exit-on-disconnect to stop instead); the output fades to silence meanwhile",
            Backoff::default().next_delay().as_secs_f64(),
            Backoff::default().max().as_secs_f64()
        ),
        _ => eprintln!("underfoot: input {event}"),
    }
}

/// The output, as it was started.
pub fn describe(output: &OutputInfo) -> String {
    match output {
        #[cfg(feature = "audio")]
        OutputInfo::Audio(i) => format!(
            "audio output {} on {}: {} channel(s) at {}, buffer {}, {:?}",
            i.device,
            i.host,
            i.channels,
            i.rate,
            i.buffer_frames
                .map_or("default".to_string(), |b| format!("{b} frames")),
            i.sample_format
        ),
        OutputInfo::Paced {
            spec,
            channels,
            rate,
            block,
        } => format!("paced output {spec}: {channels} channel(s) at {rate}, {block}-frame buffers"),
    }
}

/// The summary of a session: the engine, the input, the sensor clock, the interface, the
/// output.
fn report(summary: &Summary) -> String {
    let t = &summary.telemetry;
    let s = &summary.input;
    let clock = match t.sensor_clock {
        Some(a) => format!(
            "sensor clock: t = {:.6} s at frame {}; late readings {}, resyncs {}\n",
            a.time.0, a.frame, t.late, t.resyncs
        ),
        None => String::new(),
    };
    let record = summary
        .record
        .as_ref()
        .map(|r| {
            format!(
                "record: {} force row(s), {} strike(s), {} marker(s), {} output frame(s){}{}\n",
                r.force_rows,
                r.strikes,
                r.markers,
                r.output_frames,
                if r.output_frames_dropped > 0 {
                    format!(", {} output frame(s) DROPPED", r.output_frames_dropped)
                } else {
                    String::new()
                },
                if r.full {
                    "; it reached --record-max-mb"
                } else {
                    ""
                }
            )
        })
        .unwrap_or_default();
    let link = if s.disconnects > 0 {
        format!(
            "link: lost {} time(s), reconnected {} time(s)\n",
            s.disconnects, s.reconnects
        )
    } else {
        String::new()
    };
    let interface = summary
        .interface
        .as_ref()
        .map(interface_report)
        .unwrap_or_default();
    let adapt = summary
        .adapt
        .as_ref()
        .map(|(a, _)| format!("{}\n", status::adapt_line(a)))
        .unwrap_or_default();
    format!(
        "ran {:.1} s: {} strike(s), peak {} dBFS, {} sample(s) limited, {} non-finite \
         silenced, {} watchdog fade(s)\ninput: {} event(s), {} rejected, {} byte(s) skipped, \
         {} dropped (queue full)\n{link}{clock}{interface}{adapt}{record}{}\n",
        summary.elapsed.as_secs_f64(),
        t.strikes,
        status::peak_text(t.peak),
        t.limited,
        t.non_finite,
        t.watchdog_trips,
        s.events,
        s.rejected,
        s.skipped_bytes,
        summary.queue_full,
        output_report(&summary.output),
    )
}

/// The lines the report gets for a prosthetic interface.
fn interface_report(summary: &InterfaceSummary) -> String {
    let h = &summary.host;
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
    if let Some(r) = &summary.board {
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
    text
}

/// The output's line of the report.
fn output_report(output: &OutputReport) -> String {
    match output {
        #[cfg(feature = "audio")]
        OutputReport::Audio(s) => format!(
            "audio: {} callback(s), {} late, {} xrun(s), output latency {}",
            s.callbacks,
            s.late_callbacks,
            s.xruns,
            s.latency
                .map_or("unknown".to_string(), |l| format!("{:.2} ms", l.0 * 1e3))
        ),
        OutputReport::Paced(p) => {
            let written = match &p.wav {
                Some((path, wav)) => format!(", {} frame(s) to {}", wav.frames, path.display()),
                None => String::new(),
            };
            format!(
                "paced output: {} buffer(s), {} late{written}",
                p.blocks, p.late
            )
        }
    }
}

/// The outputs the panel's page offers: `null`, and with audio, the default device and
/// each one the host lists now (none when the host cannot be asked).
#[cfg(feature = "panel")]
pub fn output_offers(host: &str) -> Vec<String> {
    #[cfg(feature = "audio")]
    {
        let mut offers = vec!["null".to_owned()];
        if let Ok(host) = host.parse() {
            offers.push("audio".to_owned());
            if let Ok(devices) = underfoot::io::audio::list_devices(host) {
                offers.extend(devices.into_iter().map(|d| format!("audio:{}", d.name)));
            }
        }
        offers
    }
    #[cfg(not(feature = "audio"))]
    {
        let _ = host;
        vec!["null".to_owned()]
    }
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

#[cfg(all(test, feature = "panel"))]
mod tests {
    use super::*;

    fn current(interface: Option<&str>) -> SessionSettings {
        SessionSettings {
            input: "gait:steps=4".into(),
            output: "null".into(),
            library: Some(PathBuf::from("lab.json")),
            interface: interface.map(PathBuf::from),
        }
    }

    #[test]
    fn a_choice_parses_as_the_flags_do_and_keeps_what_it_leaves_out() {
        let c = SessionChoice::parse(
            Some("gait:steps=8"),
            Some(" null "),
            Some(""),
            &current(None),
            true,
        )
        .unwrap();
        assert_eq!(c.input.as_ref().unwrap().text, "gait:steps=8");
        assert!(c.output.is_none(), "the same output is no change");
        assert_eq!(c.library, Some(None), "empty: the built-in library");
        let same = SessionChoice::parse(
            Some("gait:steps=4"),
            Some("null"),
            Some("lab.json"),
            &current(None),
            true,
        )
        .unwrap();
        assert!(same.input.is_none() && same.output.is_none() && same.library.is_none());
        let e = SessionChoice::parse(Some("gait:stepz=1"), None, None, &current(None), true)
            .unwrap_err();
        assert!(e.starts_with("input: ") && e.contains("stepz"), "{e}");
        let e =
            SessionChoice::parse(None, Some("speaker"), None, &current(None), true).unwrap_err();
        assert!(e.starts_with("output: "), "{e}");
    }

    #[test]
    fn a_panel_for_other_machines_takes_no_file_and_an_interface_keeps_its_input() {
        for (input, output, library, what) in [
            (Some("replay:a.csv"), None, None, "input"),
            (None, Some("wav:/etc/x.wav"), None, "output"),
            (None, None, Some("other.json"), "library"),
        ] {
            let e =
                SessionChoice::parse(input, output, library, &current(None), false).unwrap_err();
            assert!(e.starts_with(what) && e.contains("loopback"), "{e}");
        }
        // No file named: taken; the command line's own library is no change.
        let c = SessionChoice::parse(
            Some("gait:steps=9"),
            Some("null"),
            Some("lab.json"),
            &current(None),
            false,
        )
        .unwrap();
        assert!(c.input.is_some() && c.library.is_none());
        let e = SessionChoice::parse(
            Some("gait:steps=9"),
            None,
            None,
            &current(Some("skin.toml")),
            true,
        )
        .unwrap_err();
        assert!(e.contains("skin.toml"), "{e}");
    }

    #[test]
    fn a_choice_replaces_only_what_it_names() {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            run: RunArgs,
        }
        let mut args = <Cli as clap::Parser>::parse_from([
            "x",
            "--input",
            "gait:steps=2",
            "--library",
            "a.json",
        ])
        .run;
        let choice =
            SessionChoice::parse(None, Some("wav:o.wav"), None, &args.settings(), true).unwrap();
        args.choose(&choice);
        let s = args.settings();
        assert_eq!(s.input, "gait:steps=2");
        assert_eq!(s.output, "wav:o.wav");
        assert_eq!(s.library, Some(PathBuf::from("a.json")));
    }
}
