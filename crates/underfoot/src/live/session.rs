//! The session: its settings, opening and starting it, the poll loop that runs it, and
//! the summary it ends with (see the [module docs](super)).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread;
use std::time::{Duration, Instant};

use crate::atomic_file::OutputFile;
use crate::compensation::equalizer::SpectralWeights;
use crate::engine::{
    self, ChannelLevels, Controller, EngineConfig, Event, MaterialBank, TelemetrySnapshot,
    TimedEvent,
};
use crate::interface::config::InterfaceConfig;
use crate::io::prosthetic::{ProstheticHost, ProstheticStats};
use crate::io::spec::{InputSpec, OutputSpec};
use crate::io::{EventSource, LinkEvent, SourceState, SourceStats};
use crate::sim::{SimulatedReport, SimulatorHandle};
use crate::units::Seconds;

use super::LiveError;
use super::adapt::{AdaptLoop, AdaptSettings, AdaptStatus, DriveTap};
use super::input::{self, Input};
use super::output::{Output, OutputInfo, OutputReport, Start};
use super::record::{EndReason, RecordCounts, RecordSettings, RecordStart, Recorder};
use super::remote::{self, Remote, Request};

/// How long a poll of the input waits for readings, and the loop's period when it has
/// nothing to wait for.
const POLL: Duration = Duration::from_millis(20);

/// How long the output rings out after an input that ends (a replay, a walk) has ended.
const RING_OUT: Duration = Duration::from_secs(1);

/// How long the shut-down fade is waited for before the output is closed anyway.
const FADE_WAIT: Duration = Duration::from_millis(500);

/// Where force comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum SessionInput {
    /// A replay, a walk, a serial port or OSC ([`InputSpec`]).
    Spec(InputSpec),
    /// A prosthetic-skin interface, from its configuration file (`prosthetic.toml`).
    Interface(PathBuf),
}

/// How a serial port's frames are read ([`crate::io::serial`]).
#[derive(Debug, Clone, PartialEq)]
pub struct SerialSettings {
    /// Line speed.
    pub baud: u32,
    /// Sensors per channel in a frame, e.g. `[2, 2]` (heel and toe of two feet).
    pub layout: Vec<usize>,
    /// Newtons per ADC count of every sensor, when there is no calibration.
    pub newtons_per_count: f32,
    /// A per-sensor calibration file (`underfoot calibrate sensors`), one curve per
    /// sensor of the frame in frame order; replaces `newtons_per_count`.
    pub sensors: Option<PathBuf>,
}

impl Default for SerialSettings {
    /// 115200 baud, one channel of two sensors, 0.5 N per count.
    fn default() -> Self {
        Self {
            baud: 115_200,
            layout: vec![2],
            newtons_per_count: 0.5,
            sensors: None,
        }
    }
}

/// What a session plays from and to.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionConfig {
    /// Where force comes from.
    pub input: SessionInput,
    /// Where vibration goes.
    pub output: OutputSpec,
    /// The audio host (`default`, `alsa` or `jack`), for an audio output.
    pub host: String,
    /// Frames per buffer: requested of an audio device; the pacing period of a paced
    /// output (16 to 8192, 256 when `None`).
    pub buffer: Option<u32>,
    /// A serial input's settings.
    pub serial: SerialSettings,
    /// Stop after this long; `None` runs until the input ends or the caller stops it.
    pub duration: Option<Seconds>,
    /// End the session when the input's device is lost ([`Summary::lost`]) instead of
    /// reopening it until it comes back.
    pub exit_on_disconnect: bool,
    /// The files the session reads that it does not open itself (the library its
    /// materials came from, an equalizer), and other names its input may be taken for
    /// (a `replay:a@2` written for a track named `a@2`): a `wav:` output may be none of
    /// them.
    pub reads: Vec<PathBuf>,
    /// Adapt the equalizer while the user walks, from an accelerometer on an audio input
    /// ([`super::adapt`]); needs an audio output and an equalizer.
    pub adapt: Option<AdaptSettings>,
    /// Record the session into a folder ([`super::record`]).
    pub record: Option<RecordSettings>,
}

impl SessionConfig {
    /// A session from `input` to `output` with the default settings: the default audio
    /// host and buffer, [`SerialSettings::default`], no time limit, and reconnection.
    #[must_use]
    pub fn new(input: SessionInput, output: OutputSpec) -> Self {
        Self {
            input,
            output,
            host: "default".to_owned(),
            buffer: None,
            serial: SerialSettings::default(),
            duration: None,
            exit_on_disconnect: false,
            reads: Vec::new(),
            adapt: None,
            record: None,
        }
    }

    /// The file of a `wav:` output, checked against the output policy
    /// ([`crate::atomic_file`]) with every file the session reads, before anything is
    /// opened: it is replaced (and only then) when the session has started and written
    /// its first buffer, and from then on it is a valid WAV file on disk at any moment.
    fn check_wav_output(&self) -> Result<Option<OutputFile>, LiveError> {
        let OutputSpec::Wav { path } = &self.output else {
            return Ok(None);
        };
        Ok(Some(OutputFile::check(path, &self.inputs())?))
    }

    /// Every file the session reads: what no file it writes may be.
    #[must_use]
    pub fn inputs(&self) -> Vec<&Path> {
        let mut inputs: Vec<&Path> = self.reads.iter().map(PathBuf::as_path).collect();
        if let SessionInput::Interface(config) = &self.input {
            inputs.push(config);
        }
        inputs.extend(self.serial.sensors.as_deref());
        if let SessionInput::Spec(InputSpec::Replay { file, .. }) = &self.input {
            inputs.push(file);
        }
        inputs
    }
}

/// A session whose input is open, ready to start.
pub struct Session {
    config: SessionConfig,
    wav: Option<OutputFile>,
    input: Input,
    channels: Option<usize>,
    ends: bool,
    interface: Option<InterfaceConfig>,
}

impl std::fmt::Debug for Session {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Session")
            .field("config", &self.config)
            .field("channels", &self.channels)
            .field("ends", &self.ends)
            .finish_non_exhaustive()
    }
}

impl Session {
    /// Checks a `wav:` output's file, then opens the input (an OSC input is bound by
    /// [`start`](Self::start), when the materials are known).
    ///
    /// # Errors
    /// The output file is refused, or the input cannot be opened: a track or
    /// configuration that does not load, a walk that cannot be generated, a port that
    /// cannot be opened.
    pub fn open(config: &SessionConfig) -> Result<Self, LiveError> {
        // The output file is checked before any input is opened.
        let wav = config.check_wav_output()?;
        if let Some(record) = &config.record {
            let mut inputs = config.inputs();
            if let OutputSpec::Wav { path } = &config.output {
                inputs.push(path);
            }
            record.check(&inputs)?;
        }
        let opened = input::open(&config.input, &config.serial)?;
        Ok(Self {
            config: config.clone(),
            wav,
            input: opened.input,
            channels: opened.channels,
            ends: opened.ends,
            interface: opened.interface,
        })
    }

    /// The number of channels the input carries, if it says: a track's or a walk's
    /// channels, a serial frame's, an interface's vibration channels.
    #[must_use]
    pub fn channels(&self) -> Option<usize> {
        self.channels
    }

    /// Whether the input ends by itself (a replay, a walk, a simulated interface board).
    #[must_use]
    pub fn ends(&self) -> bool {
        self.ends
    }

    /// The prosthetic interface's configuration, if the input is one.
    #[must_use]
    pub fn interface(&self) -> Option<&InterfaceConfig> {
        self.interface.as_ref()
    }

    /// Builds the engine of `config` over `bank`, each channel starting on its material
    /// of `slots`, and starts the output playing it.
    ///
    /// # Errors
    /// An OSC address that cannot be bound, an engine that cannot be built, an output
    /// that cannot start (no such audio device or host, an audio output in a build
    /// without one, a WAV file that cannot be created).
    pub fn start(
        self,
        config: &EngineConfig,
        bank: MaterialBank,
        slots: &[u16],
    ) -> Result<RunningSession, LiveError> {
        let adapt = match &self.config.adapt {
            Some(settings) => Some(self.check_adapt(settings, config)?),
            None => None,
        };
        let input = self.input.bind_osc(bank.names(), config.channels)?;
        let names = bank.names();
        let (mut controller, engine) = engine::build(config, bank, slots)?;
        let (recorder, record_tap) = match &self.config.record {
            Some(settings) => {
                let engine_settings = serde_json::json!({
                    "gain_db": config.gain.0,
                    "ceiling_db": config.ceiling.0,
                    "sensor_latency_s": config.sensor_latency.0,
                    "seed": config.seed,
                });
                let (recorder, tap) = Recorder::create(
                    settings,
                    &RecordStart {
                        rate: config.rate,
                        channels: config.channels,
                        materials: (0..config.channels)
                            .map(|c| {
                                slots
                                    .get(c)
                                    .and_then(|s| names.get(usize::from(*s)))
                                    .cloned()
                                    .unwrap_or_default()
                            })
                            .collect(),
                        input: input_text(&self.config.input),
                        output: self.config.output.to_string(),
                        sensor_rate: config.sensor_rate.0,
                        engine: &engine_settings,
                    },
                )?;
                (Some(recorder), Some(tap))
            }
            None => (None, None),
        };
        let (adapt, tap) = match adapt {
            Some((settings, weights)) => {
                let (running, tap) =
                    Self::start_adapt(&self.config, settings, weights, config, &mut controller)?;
                (Some(running), Some(tap))
            }
            None => (None, None),
        };
        let mut recorder = recorder;
        if let Some(r) = &mut recorder {
            r.output_starts()?;
        }
        let (output, info) = Output::start(
            Start {
                spec: &self.config.output,
                wav: self.wav,
                host: &self.config.host,
                buffer: self.config.buffer,
                channels: config.channels,
                rate: config.rate,
                tap,
                record: record_tap,
            },
            engine,
        )?;
        let source = match input {
            Input::Source(s) => Source::Events(s),
            Input::Interface(host, sim) => Source::Interface(host, sim),
            Input::OscPending(_) => unreachable!("OSC is bound above"),
        };
        let (remote, requests) = Remote::new();
        Ok(RunningSession {
            controller,
            remote,
            requests,
            output,
            info,
            adapt,
            source,
            ends: self.ends,
            duration: self.config.duration,
            exit_on_disconnect: self.config.exit_on_disconnect,
            recorder,
        })
    }
}

/// The input as the command line gives it, for a record's manifest.
fn input_text(input: &SessionInput) -> String {
    match input {
        SessionInput::Spec(InputSpec::Replay { file, speed }) => {
            format!("replay:{}@{speed}", file.display())
        }
        // The walk's settings in full: the spec's text is the caller's.
        SessionInput::Spec(InputSpec::Gait(gait)) => format!("gait: {gait:?}"),
        SessionInput::Spec(InputSpec::Serial { port }) => format!("serial:{port}"),
        SessionInput::Spec(InputSpec::Osc { addr }) => format!("osc:{addr}"),
        SessionInput::Interface(path) => format!("interface:{}", path.display()),
    }
}

impl Session {
    /// Whether adaptation can run on this session and engine: the settings and the
    /// equalizer's weights it starts from.
    fn check_adapt<'a>(
        &self,
        settings: &'a AdaptSettings,
        config: &'a EngineConfig,
    ) -> Result<(&'a AdaptSettings, &'a SpectralWeights), LiveError> {
        if !matches!(self.config.output, OutputSpec::Audio { .. }) {
            return Err(LiveError::AdaptNeedsAudio);
        }
        let Some((weights, _)) = &config.compensation.equalizer else {
            return Err(LiveError::AdaptNeedsEqualizer);
        };
        if usize::from(settings.channel) >= config.channels {
            return Err(LiveError::AdaptChannel {
                channel: settings.channel,
                channels: config.channels,
            });
        }
        Ok((settings, weights))
    }

    /// Starts the accelerometer's input stream and the loop that reads it; returns them
    /// with the tap the output's callback feeds. The engine is sent the adapter's
    /// starting weights first.
    #[cfg(feature = "audio")]
    fn start_adapt(
        session: &SessionConfig,
        settings: &AdaptSettings,
        weights: &SpectralWeights,
        config: &EngineConfig,
        controller: &mut crate::engine::Controller,
    ) -> Result<(RunningAdapt, DriveTap), LiveError> {
        use crate::io::audio::{AudioConfig, AudioInput};
        let parts = super::adapt::AdaptParts::new(
            settings,
            weights,
            config.rate,
            controller.telemetry_handle(),
        )?;
        controller.set_equalizer_weights(settings.channel, &parts.adapt.weights().gains_db)?;
        let output_device = match &session.output {
            OutputSpec::Audio { device } => device.clone(),
            _ => None,
        };
        let input_config = AudioConfig {
            host: super::output::audio_host(&session.host)?,
            device: settings.device.clone().or(output_device),
            channels: settings.input_channel.saturating_add(1),
            rate: config.rate,
            buffer_frames: session.buffer,
        };
        let mut sensor = parts.sensor;
        let input = AudioInput::start(&input_config, move |samples: &[f32], channels| {
            sensor.push(samples, channels);
        })?;
        Ok((
            RunningAdapt {
                adapt: parts.adapt,
                input,
            },
            parts.drive,
        ))
    }

    #[cfg(not(feature = "audio"))]
    fn start_adapt(
        _session: &SessionConfig,
        _settings: &AdaptSettings,
        _weights: &SpectralWeights,
        _config: &EngineConfig,
        _controller: &mut crate::engine::Controller,
    ) -> Result<(RunningAdapt, DriveTap), LiveError> {
        Err(LiveError::NoAudio)
    }
}

/// The adaptation of a started session: its loop and the accelerometer's stream.
struct RunningAdapt {
    adapt: AdaptLoop,
    #[cfg(feature = "audio")]
    input: crate::io::audio::AudioInput,
}

impl RunningAdapt {
    /// Stops the input stream; the final status and weights.
    fn finish(self) -> (AdaptStatus, SpectralWeights) {
        #[cfg(feature = "audio")]
        self.input.stop();
        (self.adapt.status(), self.adapt.weights().clone())
    }
}

/// The input of a started session.
enum Source {
    Events(Box<dyn EventSource>),
    Interface(Box<ProstheticHost>, Option<SimulatorHandle>),
}

impl Source {
    fn events(&mut self) -> &mut dyn EventSource {
        match self {
            Source::Events(s) => s.as_mut(),
            Source::Interface(host, _) => host.as_mut(),
        }
    }
}

/// A session whose output is playing: [`run`](Self::run) it.
pub struct RunningSession {
    controller: Controller,
    remote: Remote,
    requests: std::sync::mpsc::Receiver<Request>,
    output: Output,
    info: OutputInfo,
    adapt: Option<RunningAdapt>,
    source: Source,
    ends: bool,
    duration: Option<Seconds>,
    exit_on_disconnect: bool,
    recorder: Option<Recorder>,
}

impl std::fmt::Debug for RunningSession {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunningSession")
            .field("output", &self.info)
            .field("ends", &self.ends)
            .field("duration", &self.duration)
            .finish_non_exhaustive()
    }
}

/// What a prosthetic interface did in a session.
#[derive(Debug, Clone, PartialEq)]
pub struct InterfaceSummary {
    /// The host's counts: insole frames in, servo frames out, delays.
    pub host: ProstheticStats,
    /// The simulated board's report, if the board was simulated.
    pub board: Option<SimulatedReport>,
}

/// What a session did.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    /// From the start of [`RunningSession::run`] to the output's close.
    pub elapsed: Duration,
    /// The engine's counters: strikes, peak, limited and non-finite samples, watchdog
    /// fades, the sensor clock.
    pub telemetry: TelemetrySnapshot,
    /// The input's counts.
    pub input: SourceStats,
    /// Events dropped because the engine's queue was full.
    pub queue_full: u64,
    /// The prosthetic interface's report, if the input was one.
    pub interface: Option<InterfaceSummary>,
    /// The output's report.
    pub output: OutputReport,
    /// The loss of the input's device that ended the session, with
    /// [`SessionConfig::exit_on_disconnect`].
    pub lost: Option<LinkEvent>,
    /// What the adaptation did, and the weights it ended with, if it ran.
    pub adapt: Option<(AdaptStatus, SpectralWeights)>,
    /// Why it ended.
    pub ended: EndReason,
    /// What the session's record holds, if it was recorded.
    pub record: Option<RecordCounts>,
}

/// What a running session is doing now, given to
/// [`RunningSession::run_with_status`]'s callback.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Status {
    /// Since the start of the run.
    pub elapsed: Duration,
    /// The engine's counters so far.
    pub telemetry: TelemetrySnapshot,
    /// Each engine channel's levels: the last force, strikes, the peak since the
    /// previous status, limited samples.
    pub channels: Vec<ChannelLevels>,
    /// The input's counts so far.
    pub input: SourceStats,
    /// Events dropped so far because the engine's queue was full.
    pub queue_full: u64,
    /// The adaptation's progress, if it runs.
    pub adapt: Option<AdaptStatus>,
    /// The bank's material names, in slot order (materials added by a [`Remote`]
    /// included).
    pub materials: Vec<String>,
    /// Output buffers late so far: an audio device's late callbacks, the paced
    /// device's late wake-ups.
    pub late_buffers: u64,
    /// The output's latency: what the audio device measures (the time from a callback
    /// to its buffer being heard), or one buffer for the paced device; `None` until the
    /// device has said.
    pub output_latency: Option<Seconds>,
    /// The input's rejections by reason, for a source that tells them apart (OSC):
    /// only the reasons that occurred.
    pub rejections: Vec<(&'static str, u64)>,
    /// Why the input's last rejected message was refused, if it says.
    pub last_reject: Option<String>,
    /// Markers the input sent (OSC) to a session that is not recorded: nowhere to go.
    pub markers_unrecorded: u64,
}

impl RunningSession {
    /// What output was started.
    #[must_use]
    pub fn output(&self) -> &OutputInfo {
        &self.info
    }

    /// A handle to steer this session from another thread while it runs: switch
    /// materials, trim a channel, add a material, stop ([`Remote`]).
    #[must_use]
    pub fn remote(&self) -> Remote {
        self.remote.clone()
    }

    /// Polls the input and plays its events until the session ends: the input has ended
    /// (and the output rung out for a second), the duration is over, `stop` is set, or
    /// (with [`SessionConfig::exit_on_disconnect`]) the input's device is lost. Every
    /// other change of the input's link is given to `on_link` as it happens. The output
    /// then fades out and is closed.
    ///
    /// # Errors
    /// The input failed, the output stopped or failed, or the engine's stop command could
    /// not be sent.
    pub fn run(
        self,
        stop: &AtomicBool,
        on_link: impl FnMut(&LinkEvent),
    ) -> Result<Summary, LiveError> {
        self.run_with_status(stop, on_link, Duration::MAX, |_| {})
    }

    /// [`run`](Self::run), giving `on_status` what the session is doing about every
    /// `every`, from the thread that runs it: the engine's levels are read from its
    /// atomics, so a status never makes the audio thread wait. The loop polls the input
    /// at least every 20 ms, and every `every` when that is shorter (down to 5 ms).
    ///
    /// # Errors
    /// As [`run`](Self::run).
    pub fn run_with_status(
        mut self,
        stop: &AtomicBool,
        mut on_link: impl FnMut(&LinkEvent),
        every: Duration,
        mut on_status: impl FnMut(&Status),
    ) -> Result<Summary, LiveError> {
        let started = Instant::now();
        let meters = self.controller.telemetry_handle();
        let mut status = Status {
            channels: vec![ChannelLevels::default(); meters.channels()],
            ..Status::default()
        };
        let mut last_status = started;
        let mut last_recorded = started;
        let deadline = self
            .duration
            .map(|d| started + Duration::from_secs_f64(d.0.max(0.0)));
        let mut queue_full = 0u64;
        let mut markers_unrecorded = 0u64;
        let mut ended_at = None;
        let mut reason = EndReason::Stopped;
        // Set when the input was lost and the session is to end on it: it still fades
        // out and reports.
        let mut lost: Option<LinkEvent> = None;
        let controller = &mut self.controller;
        let source = self.source.events();
        let mut recorder = self.recorder.take();
        // A caller that wants statuses more often than the input's poll period (a
        // panel's meters) gets the loop at its pace: shorter waits on the input, never
        // below 5 ms.
        let poll = POLL.min(every.max(Duration::from_millis(5)));
        let outcome = loop {
            if stop.load(Ordering::SeqCst) {
                break Ok(());
            }
            if deadline.is_some_and(|d| Instant::now() >= d) {
                reason = EndReason::Duration;
                break Ok(());
            }
            let status_due = last_status.elapsed() >= every;
            let record_due = recorder.is_some() && last_recorded.elapsed() >= RECORD_STATUS;
            if status_due || record_due {
                status.elapsed = started.elapsed();
                status.telemetry = controller.telemetry();
                for (c, levels) in status.channels.iter_mut().enumerate() {
                    *levels = meters.take_channel(c).unwrap_or_default();
                }
                status.input = source.stats();
                if status.input.rejected > 0 {
                    status.rejections = source.rejections();
                    status.last_reject = source.last_reject();
                }
                status.markers_unrecorded = markers_unrecorded;
                status.queue_full = queue_full;
                status.adapt = self.adapt.as_ref().map(|a| a.adapt.status());
                (status.late_buffers, status.output_latency) = self.output.live();
                if status.materials.len() != controller.material_names().len() {
                    status.materials = controller.material_names().to_vec();
                }
                // One status serves both, so that neither takes the other's meter
                // interval (peaks and RMS are taken, not read).
                last_status = Instant::now();
                on_status(&status);
                if let Some(r) = &mut recorder {
                    last_recorded = last_status;
                    if let Err(e) = r.status(&status) {
                        break Err(e.into());
                    }
                }
            }
            if remote::serve(&self.requests, controller, recorder.as_mut()) {
                reason = EndReason::RemoteStop;
                break Ok(());
            }
            if let Some(r) = &mut recorder
                && let Err(e) = record_strikes(r, controller)
            {
                break Err(e);
            }
            if let Some(t) = ended_at {
                if Instant::now().duration_since(t) >= RING_OUT {
                    reason = EndReason::InputEnded;
                    break Ok(());
                }
                thread::sleep(poll);
                continue;
            }
            let polled = Instant::now();
            let mut record_failed = None;
            let mut break_err = None;
            let state = source.poll(poll, &mut |event| {
                if let Some(r) = &mut recorder
                    && record_failed.is_none()
                {
                    let recorded = match event {
                        Event::Force { channel, reading } => r.force(channel, &reading),
                        Event::Material { channel, slot } => r.event(
                            meters.frames(),
                            "material",
                            serde_json::json!({
                                "channel": u32::from(channel) + 1,
                                "slot": slot,
                                "material": controller.material_names().get(usize::from(slot)),
                                "from": "input",
                            }),
                        ),
                        Event::Step { .. } => Ok(()),
                    };
                    record_failed = recorded.err();
                }
                if controller.send(TimedEvent::now(event)).is_err() {
                    queue_full += 1;
                }
            });
            let state = match (state, record_failed) {
                (Err(e), _) => break Err(e.into()),
                (_, Some(e)) => break Err(e.into()),
                (Ok(state), None) => state,
            };
            while let Some(marker) = source.take_marker() {
                match &mut recorder {
                    Some(r) => {
                        if let Err(e) = r.marker(meters.frames(), &marker) {
                            break_err = Some(e);
                        }
                    }
                    None => markers_unrecorded += 1,
                }
            }
            if let Some(e) = break_err.take() {
                break Err(e.into());
            }
            while let Some(event) = source.link_event() {
                if let Some(r) = &mut recorder {
                    let _ = r.event(
                        meters.frames(),
                        "link",
                        serde_json::json!({ "what": event.to_string() }),
                    );
                }
                if self.exit_on_disconnect && matches!(event, LinkEvent::Lost { .. }) {
                    lost = Some(event);
                } else {
                    on_link(&event);
                }
            }
            if lost.is_some() {
                reason = EndReason::InputLost;
                break Ok(());
            }
            if state == SourceState::Ended && self.ends {
                ended_at = Some(Instant::now());
            } else if state != SourceState::Open {
                // A source that is lost or ended has nothing to wait for and may return at
                // once: pace the loop so that it cannot spin.
                thread::sleep(poll.saturating_sub(polled.elapsed()));
            }
            if let Some(running) = &mut self.adapt {
                running.adapt.poll(controller);
            }
            controller.collect();
            if let Err(e) = self.output.check() {
                break Err(e);
            }
            if let Some(r) = &mut recorder
                && let Err(e) = r.poll()
            {
                break Err(e.into());
            }
        };
        if let Err(e) = outcome {
            // The record keeps what it has, and says it ended on a failure.
            if let Some(r) = recorder {
                let _ = controller.stop();
                let telemetry = controller.telemetry();
                let _ = r.finish(telemetry.frames, EndReason::Failed, &telemetry);
            }
            return Err(e);
        }
        controller.stop()?;
        let fade_deadline = Instant::now() + FADE_WAIT;
        while !controller.telemetry().stopped && Instant::now() < fade_deadline {
            if let Some(r) = &mut recorder {
                r.poll()?;
            }
            thread::sleep(Duration::from_millis(5));
        }
        let output = self.output.finish()?;
        let adapt = self.adapt.map(RunningAdapt::finish);
        let telemetry = controller.telemetry();
        let record = match recorder {
            Some(mut r) => {
                record_strikes(&mut r, controller)?;
                Some(r.finish(telemetry.frames, reason, &telemetry)?)
            }
            None => None,
        };
        let input = source.stats();
        let interface = match self.source {
            Source::Interface(host, sim) => Some(InterfaceSummary {
                host: host.stats(),
                board: sim.map(SimulatorHandle::finish).transpose()?,
            }),
            Source::Events(_) => None,
        };
        Ok(Summary {
            elapsed: started.elapsed(),
            telemetry,
            input,
            queue_full,
            interface,
            output,
            lost,
            adapt,
            ended: reason,
            record,
        })
    }
}

/// How often a recorded session writes its status.
const RECORD_STATUS: Duration = Duration::from_secs(1);

/// Moves the strikes the engine has logged into the record.
fn record_strikes(recorder: &mut Recorder, controller: &mut Controller) -> Result<(), LiveError> {
    // Taken first: the names are the controller's too.
    let mut strikes = Vec::new();
    controller.take_strikes(|strike| strikes.push(*strike));
    for strike in &strikes {
        recorder.strike(strike, controller.material_names())?;
    }
    Ok(())
}
