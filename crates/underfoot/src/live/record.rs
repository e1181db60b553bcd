//! Recording a session: one self-describing folder that an analysis reads afterwards
//! beside a lab's other recordings (EEG, EMG, motion capture).
//!
//! A session given [`SessionConfig::record`](super::SessionConfig::record) writes, into a
//! folder of its own (new, or empty):
//!
//! | file | what it holds |
//! |---|---|
//! | `manifest.json` | what ran: [`RECORD_VERSION`], the command line, the library and its SHA-256, the material of each channel, the output and sensor rates, the start in UTC, in Unix time and on the monotonic clock; rewritten at the end with how the session ended and its counts |
//! | `force.csv` | every force reading, at the sensor rate, as a force track ([`crate::force::track`]): `time_s`, then one column per sensor, `ch1.s1`, `ch1.s2`, `ch2.s1`... |
//! | `strikes.csv` | every strike the engine played: `time_s` (on the output, `frame / rate`), `frame`, `channel` (from 1), `intensity`, `material`, `sensor_time_s` |
//! | `events.jsonl` | one JSON object a line: the start, every marker, material and gain change, link loss and return, the record filling up, the stop |
//! | `status.jsonl` | the session's status, one JSON object a second |
//! | `output.wav` | the drive of every channel as the device was given it (32-bit float, the engine's channels) |
//!
//! # Times
//! Every line carries `t`, seconds since the session started on the monotonic clock
//! (the manifest gives the start on that clock, `CLOCK_MONOTONIC` on Linux, which is the
//! clock of Lab Streaming Layer's timestamps, and in UTC). Events and markers carry the
//! engine's `frame` too: the output sample they happened at, to the block (so
//! `frame / rate` is their time in `output.wav`). A strike's `frame` is exact: the
//! sample its impulse starts on in `output.wav`.
//!
//! The force log's `time_s` is each reading's own sensor time, the one the engine places
//! it by ([`crate::engine`], *Timing*), or for a sensor that stamps none, its arrival
//! since the start. So `underfoot render --force DIR/force.csv` renders offline what the
//! session played, shifted by the sensor clock's anchor (in the manifest's end section).
//! The readings of one instant (every channel's) make one row; a channel missing from an
//! instant holds its last reading; a row whose time does not come after the previous
//! one is counted (`force_out_of_order` in the manifest's end), not written, because a
//! track's times only increase.
//!
//! # Written as it goes, bounded
//! The text files are appended line by line and flushed to the system every second,
//! the WAV file's header brought up to date every half second
//! ([`WavSink::live`](crate::io::wav::WavSink::live)): a killed process leaves a folder
//! that reads, missing at most the last second (a WAV file that was never finished is
//! `output.partial-PID.wav`). The folder is bounded ([`RecordSettings::max_bytes`]):
//! when it reaches the bound, the force log, the status log and the output stop, an
//! event says so, and the strikes, markers and changes (a few bytes each) go on.
//!
//! # Markers and LSL
//! Markers ([`Marker`]) come from a [`Remote`](super::Remote) (a panel's page or HTTP
//! call, a terminal's lines) or from the input (OSC's `/underfoot/v2/marker`). With
//! [`RecordSettings::lsl`], the force (a sample per instant, the sum of each channel's
//! sensors), the strikes and the markers also go out as Lab Streaming Layer streams
//! (`underfoot::io::lsl`), stamped on the same monotonic clock: a marker at
//! `started.monotonic_s + t`, a strike at `output_started_monotonic_s + time_s`.
//!
//! The output reaches the record through a lock-free ring ([`OutputTap`]) that the
//! audio callback writes (never allocating, locking or waiting) and the session's thread
//! drains; a ring the session did not drain in time drops whole buffers and counts them
//! (`output_frames_dropped`), so a record that says zero has every frame.

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant, SystemTime};

use serde::Serialize;
use serde_json::{Value, json};

use crate::atomic_file::OutputFile;
use crate::engine::{StrikeRecord, TelemetrySnapshot};
use crate::force::SensorReading;
use crate::io::IoError;
use crate::io::wav::{WavFormat, WavSink};
use crate::units::SampleRate;

use super::Status;

/// The version of the folder's layout, in its manifest: a reader refuses a version it
/// does not know.
pub const RECORD_VERSION: u32 = 1;

/// The default bound of a record folder: 4 GiB.
pub const DEFAULT_MAX_BYTES: u64 = 4 << 30;

/// How often the text files are flushed to the system: a killed process loses at most
/// this much of them.
const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// How often the output WAV's header is brought up to date.
const WAV_SYNC: Duration = Duration::from_millis(500);

/// How long the output ring holds: what the session's thread may fall behind by.
const TAP_SECONDS: f64 = 2.0;

pub use crate::io::marker::{MAX_MARKER_TEXT, Marker, MarkerError};

/// Why a record could not be made, or a marker not taken.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordError {
    /// The folder is not one a record can go into.
    #[error("--record {}: {reason}", path.display())]
    Folder {
        /// The folder.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// Writing a file of the record failed.
    #[error("writing the session record {}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The failure.
        #[source]
        source: std::io::Error,
    },
    /// The output WAV of the record failed, or the LSL streams could not open.
    #[error(transparent)]
    Wav(#[from] IoError),
    /// LSL was asked of a build without it.
    #[error(
        "this build has no Lab Streaming Layer: rebuild with `--features lsl` (liblsl is \
         loaded when a session starts)"
    )]
    NoLsl,
    /// A marker that cannot be recorded.
    #[error(transparent)]
    Marker(#[from] MarkerError),
}

/// What a session records, and where.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordSettings {
    /// The folder: created, or empty.
    pub dir: PathBuf,
    /// The bound on everything written ([`DEFAULT_MAX_BYTES`]).
    pub max_bytes: u64,
    /// The command line, for the manifest.
    pub command_line: Vec<String>,
    /// Where the materials came from (a path, or `built-in`), and the SHA-256 of its
    /// bytes, for the manifest.
    pub library: (String, String),
    /// The caller's settings worth keeping (model, step threshold...), as JSON.
    pub settings: Value,
    /// The input as the caller wrote it (`gait:steps=6`), for the manifest; else the
    /// session describes it.
    pub input: Option<String>,
    /// Publish the force, the strikes and the markers as Lab Streaming Layer streams
    /// too (`underfoot::io::lsl`; needs the `lsl` feature and liblsl).
    pub lsl: bool,
}

impl RecordSettings {
    /// A record into `dir`, bounded at [`DEFAULT_MAX_BYTES`], with no command line and
    /// an unnamed library.
    #[must_use]
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            max_bytes: DEFAULT_MAX_BYTES,
            command_line: Vec::new(),
            library: (String::new(), String::new()),
            settings: Value::Null,
            input: None,
            lsl: false,
        }
    }

    /// Checks that the folder can take a record without damaging anything: it does not
    /// exist yet (its parent does), or it is an empty folder; and it is none of
    /// `inputs`.
    ///
    /// # Errors
    /// [`RecordError::Folder`] saying why not.
    pub fn check(&self, inputs: &[&Path]) -> Result<(), RecordError> {
        let refuse = |reason: String| {
            Err(RecordError::Folder {
                path: self.dir.clone(),
                reason,
            })
        };
        if self.max_bytes < 1 << 20 {
            return refuse(format!(
                "a bound of {} bytes leaves no room: at least 1 MiB",
                self.max_bytes
            ));
        }
        if inputs.iter().any(|i| same_path(i, &self.dir)) {
            return refuse("it is one of the session's inputs".into());
        }
        match fs::symlink_metadata(&self.dir) {
            Ok(m) if m.is_dir() => match fs::read_dir(&self.dir) {
                Ok(mut entries) => {
                    if entries.next().is_some() {
                        refuse(
                            "the folder is not empty: a record goes into a new or empty \
                             folder, so that it never mixes with (or replaces) another"
                                .into(),
                        )
                    } else {
                        Ok(())
                    }
                }
                Err(e) => refuse(format!("cannot read the folder: {e}")),
            },
            Ok(_) => refuse("it exists and is not a folder".into()),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                let parent = match self.dir.parent() {
                    Some(p) if !p.as_os_str().is_empty() => p,
                    _ => Path::new("."),
                };
                if parent.is_dir() {
                    Ok(())
                } else {
                    refuse(format!("its parent {} is not a folder", parent.display()))
                }
            }
            Err(e) => refuse(format!("cannot read it: {e}")),
        }
    }
}

fn same_path(a: &Path, b: &Path) -> bool {
    match (fs::canonicalize(a), fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

/// What the session tells the record at its start.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordStart<'a> {
    /// The engine's output rate.
    pub rate: SampleRate,
    /// The engine's channels.
    pub channels: usize,
    /// The material each channel starts on.
    pub materials: Vec<String>,
    /// The input, as given (`gait:...`, `replay:...`, `serial:...`).
    pub input: String,
    /// The output, as given.
    pub output: String,
    /// The force sensors' rate the engine assumes.
    pub sensor_rate: f64,
    /// The engine's settings worth keeping (gain, ceiling, latency), as JSON.
    pub engine: &'a Value,
}

/// The audio thread's half of the output's way into the record: copies each buffer
/// into a lock-free ring. Never allocates, locks or waits.
pub struct OutputTap {
    ring: rtrb::Producer<f32>,
    channels: usize,
    dropped: Arc<AtomicU64>,
}

impl std::fmt::Debug for OutputTap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OutputTap")
            .field("channels", &self.channels)
            .finish_non_exhaustive()
    }
}

impl OutputTap {
    /// Copies the engine's channels of the interleaved `out` (`device_channels` wide;
    /// a channel the device lacks is recorded as zero). A buffer the ring has no room
    /// for is dropped whole and counted.
    pub fn push(&mut self, out: &[f32], device_channels: usize) {
        if device_channels == 0 {
            return;
        }
        let frames = out.len() / device_channels;
        let n = frames * self.channels;
        let Ok(mut chunk) = self.ring.write_chunk(n) else {
            self.dropped.fetch_add(frames as u64, Ordering::Relaxed);
            return;
        };
        let (a, b) = chunk.as_mut_slices();
        for (i, slot) in a.iter_mut().chain(b.iter_mut()).enumerate() {
            let (frame, c) = (i / self.channels, i % self.channels);
            *slot = if c < device_channels {
                out[frame * device_channels + c]
            } else {
                0.0
            };
        }
        chunk.commit_all();
    }
}

impl OutputTap {
    /// The two halves of an output's way into a record of `channels` channels at
    /// `rate`: the tap for the audio callback, and the reader for the session's thread
    /// (a ring of two seconds).
    #[must_use]
    pub fn pair(channels: usize, rate: SampleRate) -> (OutputTap, OutputReader) {
        let (tap, drain) = output_ring(channels, rate);
        (tap, OutputReader(drain))
    }
}

/// The session's half of an [`OutputTap`].
pub struct OutputReader(OutputDrain);

impl std::fmt::Debug for OutputReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OutputReader").finish_non_exhaustive()
    }
}

impl OutputReader {
    /// Appends every sample the ring holds to `into`; the number appended.
    pub fn take(&mut self, into: &mut Vec<f32>) -> usize {
        let n = self.0.ring.slots();
        let Ok(chunk) = self.0.ring.read_chunk(n) else {
            return 0;
        };
        let (a, b) = chunk.as_slices();
        into.extend_from_slice(a);
        into.extend_from_slice(b);
        chunk.commit_all();
        n
    }

    /// Frames dropped because the ring was full.
    #[must_use]
    pub fn dropped(&self) -> u64 {
        self.0.dropped.load(Ordering::Relaxed)
    }
}

fn output_ring(channels: usize, rate: SampleRate) -> (OutputTap, OutputDrain) {
    let capacity = (TAP_SECONDS * rate.hz()) as usize * channels.max(1);
    let (producer, consumer) = rtrb::RingBuffer::new(capacity.max(8192));
    let dropped = Arc::new(AtomicU64::new(0));
    (
        OutputTap {
            ring: producer,
            channels: channels.max(1),
            dropped: Arc::clone(&dropped),
        },
        OutputDrain {
            ring: consumer,
            dropped,
            scratch: Vec::new(),
        },
    )
}

struct OutputDrain {
    ring: rtrb::Consumer<f32>,
    dropped: Arc<AtomicU64>,
    scratch: Vec<f32>,
}

/// Why a session ended, as the record and the summary say it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[non_exhaustive]
pub enum EndReason {
    /// The input played out (a replay, a walk, a simulated board) and the output rang out.
    InputEnded,
    /// The session's duration was over.
    Duration,
    /// The caller stopped it (Ctrl-C, SIGTERM, Enter, a closing panel).
    Stopped,
    /// A [`Remote`](super::Remote) asked it to stop (a panel's STOP).
    RemoteStop,
    /// The input's device was lost (with `exit_on_disconnect`).
    InputLost,
    /// It failed; the error says how.
    Failed,
}

impl EndReason {
    /// The word the record and the status use.
    #[must_use]
    pub fn as_str(self) -> &'static str {
        match self {
            EndReason::InputEnded => "input_ended",
            EndReason::Duration => "duration",
            EndReason::Stopped => "stopped",
            EndReason::RemoteStop => "remote_stop",
            EndReason::InputLost => "input_lost",
            EndReason::Failed => "failed",
        }
    }
}

impl std::fmt::Display for EndReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            EndReason::InputEnded => "the input played out",
            EndReason::Duration => "its duration was over",
            EndReason::Stopped => "it was stopped (Ctrl-C, Enter or the caller)",
            EndReason::RemoteStop => "STOP was pressed (a remote stop)",
            EndReason::InputLost => "the input's device was lost",
            EndReason::Failed => "it failed",
        })
    }
}

/// A text file of the record, appended to and counted.
struct LineFile {
    path: PathBuf,
    out: BufWriter<File>,
}

impl LineFile {
    fn create(dir: &Path, name: &str) -> Result<Self, RecordError> {
        let path = dir.join(name);
        let file = File::options()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|source| RecordError::Write {
                path: path.clone(),
                source,
            })?;
        Ok(Self {
            path,
            out: BufWriter::new(file),
        })
    }

    /// Appends `line` and a line break; the bytes written.
    fn line(&mut self, line: &str) -> Result<u64, RecordError> {
        self.out
            .write_all(line.as_bytes())
            .and_then(|()| self.out.write_all(b"\n"))
            .map_err(|source| RecordError::Write {
                path: self.path.clone(),
                source,
            })?;
        Ok(line.len() as u64 + 1)
    }

    fn flush(&mut self) -> Result<(), RecordError> {
        self.out.flush().map_err(|source| RecordError::Write {
            path: self.path.clone(),
            source,
        })
    }
}

/// What a record holds, counted as it is written; the manifest's end section.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct RecordCounts {
    /// Force readings taken.
    pub force_readings: u64,
    /// Rows of `force.csv` (instants).
    pub force_rows: u64,
    /// Rows not written because their time did not come after the previous row's.
    pub force_out_of_order: u64,
    /// Readings whose sensor count differed from their channel's columns (padded with
    /// zeros or cut).
    pub force_mismatched: u64,
    /// Strikes in `strikes.csv`.
    pub strikes: u64,
    /// Markers in `events.jsonl`.
    pub markers: u64,
    /// Frames of `output.wav`.
    pub output_frames: u64,
    /// Output frames lost because the session's thread fell behind the ring.
    pub output_frames_dropped: u64,
    /// Bytes written in all.
    pub bytes: u64,
    /// Whether the record reached its bound (the force, status and output stopped).
    pub full: bool,
}

/// A session's record being written; see the [module docs](self).
pub(super) struct Recorder {
    dir: PathBuf,
    max_bytes: u64,
    started: Instant,
    rate: SampleRate,
    manifest: Value,
    force: LineFile,
    strikes: LineFile,
    events: LineFile,
    status: LineFile,
    wav: Option<WavSink>,
    drain: OutputDrain,
    /// Sensors per channel of `force.csv`'s columns, fixed by its header.
    columns: Option<Vec<usize>>,
    /// The instant being assembled: its time and each channel's reading.
    row_time: Option<f64>,
    row: Vec<Option<SensorReading>>,
    /// Each channel's last reading, held for an instant it is missing from.
    held: Vec<Option<SensorReading>>,
    last_row_time: Option<f64>,
    counts: RecordCounts,
    /// Whether the event saying the record is full has been written.
    full_noted: bool,
    last_flush: Instant,
    line: String,
    /// The Lab Streaming Layer streams, when asked for.
    #[cfg_attr(
        not(feature = "lsl"),
        expect(dead_code, reason = "pushed to with `lsl`")
    )]
    lsl: Option<Lsl>,
    /// The session's start and the output's first sample on the monotonic clock
    /// (seconds), where it can be read.
    #[cfg_attr(not(feature = "lsl"), expect(dead_code, reason = "markers' LSL time"))]
    started_monotonic: Option<f64>,
    output_monotonic: Option<f64>,
}

#[cfg(feature = "lsl")]
type Lsl = crate::io::lsl::LslOutlets;
/// Never made without the feature: [`RecordError::NoLsl`] is said instead.
#[cfg(not(feature = "lsl"))]
enum Lsl {}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("dir", &self.dir)
            .field("counts", &self.counts)
            .finish_non_exhaustive()
    }
}

impl Recorder {
    /// Creates the folder and its files (checked by [`RecordSettings::check`] when the
    /// session opened), writes the manifest, and returns the recorder with the tap the
    /// output's callback feeds.
    pub(super) fn create(
        settings: &RecordSettings,
        start: &RecordStart<'_>,
    ) -> Result<(Self, OutputTap), RecordError> {
        let dir = settings.dir.clone();
        let folder = |e: std::io::Error| RecordError::Folder {
            path: dir.clone(),
            reason: format!("cannot create it: {e}"),
        };
        match fs::create_dir(&dir) {
            Ok(()) => {}
            // Checked empty at open.
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && dir.is_dir() => {}
            Err(e) => return Err(folder(e)),
        }
        let lsl = open_lsl(settings.lsl, start.channels, start.sensor_rate)?;
        let started = Instant::now();
        let started_monotonic = monotonic_now();
        let wall = SystemTime::now();
        let unix = wall
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        let channels = start.channels;
        let manifest = json!({
            "format": "underfoot session record",
            "version": RECORD_VERSION,
            "underfoot": env!("CARGO_PKG_VERSION"),
            "command_line": settings.command_line,
            "library": { "source": settings.library.0, "sha256": settings.library.1 },
            "channels": (0..channels).map(|c| json!({
                "channel": c + 1,
                "material": start.materials.get(c),
            })).collect::<Vec<_>>(),
            "rate_hz": start.rate.0,
            "sensor_rate_hz": start.sensor_rate,
            "input": settings.input.as_deref().unwrap_or(&start.input),
            "output": start.output,
            "engine": start.engine,
            "settings": settings.settings,
            "started": {
                "utc": utc_text(wall),
                "unix_s": unix,
                "monotonic_s": started_monotonic,
            },
            "output_started_monotonic_s": Value::Null,
            "lsl": settings.lsl.then(|| json!({
                "streams": ["underfoot force", "underfoot strikes", "underfoot markers"],
                "clock": "lsl_local_clock, the monotonic clock: a marker at started.monotonic_s + t, \
                          a strike at output_started_monotonic_s + time_s",
            })),
            "max_bytes": settings.max_bytes,
            "files": {
                "force": "force.csv",
                "strikes": "strikes.csv",
                "events": "events.jsonl",
                "status": "status.jsonl",
                "output": "output.wav",
            },
            "ended": Value::Null,
        });
        let (tap, drain) = output_ring(channels, start.rate);
        let wav_out =
            OutputFile::check(&dir.join("output.wav"), &[]).map_err(|e| RecordError::Folder {
                path: dir.clone(),
                reason: format!("output.wav: {e}"),
            })?;
        let wav = WavSink::live(
            wav_out,
            start.rate,
            channels.clamp(1, usize::from(u16::MAX)) as u16,
            WavFormat::Float32,
            WAV_SYNC,
        )?;
        let mut recorder = Self {
            max_bytes: settings.max_bytes,
            started,
            rate: start.rate,
            manifest,
            force: LineFile::create(&dir, "force.csv")?,
            strikes: LineFile::create(&dir, "strikes.csv")?,
            events: LineFile::create(&dir, "events.jsonl")?,
            status: LineFile::create(&dir, "status.jsonl")?,
            wav: Some(wav),
            drain,
            columns: None,
            row_time: None,
            row: vec![None; channels],
            held: vec![None; channels],
            last_row_time: None,
            counts: RecordCounts::default(),
            full_noted: false,
            last_flush: started,
            line: String::new(),
            lsl,
            started_monotonic,
            output_monotonic: None,
            dir,
        };
        recorder.write_manifest()?;
        let header = "time_s,frame,channel,intensity,material,sensor_time_s";
        let n = recorder.strikes.line(header)?;
        recorder.counts.bytes += n;
        let materials = start.materials.clone();
        recorder.event(0, "start", json!({ "materials": materials }))?;
        recorder.flush()?;
        Ok((recorder, tap))
    }

    /// The output's first sample is now: strikes are placed from it on LSL's clock.
    pub(super) fn output_starts(&mut self) -> Result<(), RecordError> {
        self.output_monotonic = monotonic_now();
        self.manifest["output_started_monotonic_s"] = json!(self.output_monotonic);
        self.write_manifest()
    }

    /// Seconds since the session started, on the monotonic clock.
    fn now(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    fn write_manifest(&self) -> Result<(), RecordError> {
        let path = self.dir.join("manifest.json");
        let text = serde_json::to_string_pretty(&self.manifest).unwrap_or_default();
        // Written beside and renamed over: a reader never sees half a manifest.
        let temp = self.dir.join(".manifest.json.tmp");
        let write = || -> std::io::Result<()> {
            let mut f = File::create(&temp)?;
            f.write_all(text.as_bytes())?;
            f.write_all(b"\n")?;
            f.sync_all()?;
            fs::rename(&temp, &path)
        };
        write().map_err(|source| RecordError::Write { path, source })
    }

    fn room(&mut self, bytes: u64) -> bool {
        if self.counts.full {
            return false;
        }
        if self.counts.bytes + bytes > self.max_bytes {
            self.counts.full = true;
            return false;
        }
        true
    }

    /// One force reading of `channel` (from 0), arrived now.
    pub(super) fn force(
        &mut self,
        channel: u16,
        reading: &SensorReading,
    ) -> Result<(), RecordError> {
        let c = usize::from(channel);
        if c >= self.row.len() {
            return Ok(());
        }
        self.counts.force_readings += 1;
        let time = reading.time().map_or_else(|| self.now(), |t| t.0);
        if let Some(t) = self.row_time
            && (t != time || self.row[c].is_some())
        {
            self.write_row()?;
        }
        self.row_time = Some(time);
        self.row[c] = Some(*reading);
        Ok(())
    }

    fn write_row(&mut self) -> Result<(), RecordError> {
        let Some(time) = self.row_time.take() else {
            return Ok(());
        };
        for (held, reading) in self.held.iter_mut().zip(self.row.iter_mut()) {
            if let Some(r) = reading.take() {
                *held = Some(r);
            }
        }
        if self.last_row_time.is_some_and(|last| time <= last) {
            self.counts.force_out_of_order += 1;
            return Ok(());
        }
        if self.counts.full {
            return Ok(());
        }
        if self.columns.is_none() {
            let columns: Vec<usize> = self.held.iter().map(|r| r.map_or(1, |r| r.len())).collect();
            let mut header = String::from(
                "# underfoot session record: every force reading in newtons; time_s is the \
                 sensor's time (or the arrival since the start)\ntime_s",
            );
            for (c, n) in columns.iter().enumerate() {
                for s in 0..*n {
                    header.push_str(&format!(",ch{}.s{}", c + 1, s + 1));
                }
            }
            self.counts.bytes += self.force.line(&header)?;
            self.columns = Some(columns);
        }
        let mut line = std::mem::take(&mut self.line);
        line.clear();
        line.push_str(&format!("{time}"));
        let mut mismatched = 0;
        for (reading, n) in self.held.iter().zip(self.columns.iter().flatten()) {
            let values = reading.as_ref().map_or(&[][..], SensorReading::as_slice);
            if reading.is_some() && values.len() != *n {
                mismatched += 1;
            }
            for s in 0..*n {
                line.push(',');
                line.push_str(&format!("{}", values.get(s).copied().unwrap_or(0.0)));
            }
        }
        self.counts.force_mismatched += mismatched;
        #[cfg(feature = "lsl")]
        if let Some(lsl) = &mut self.lsl {
            let totals: Vec<f64> = self
                .held
                .iter()
                .map(|r| r.map_or(0.0, |r| f64::from(r.total())))
                .collect();
            let at = lsl.clock();
            lsl.push_force(&totals, at);
        }
        let written = if self.room(line.len() as u64 + 1) {
            let n = self.force.line(&line)?;
            self.counts.force_rows += 1;
            self.last_row_time = Some(time);
            n
        } else {
            0
        };
        self.line = line;
        self.counts.bytes += written;
        if self.counts.full && written == 0 {
            self.note_full()?;
        }
        Ok(())
    }

    fn note_full(&mut self) -> Result<(), RecordError> {
        if self.full_noted {
            return Ok(());
        }
        self.full_noted = true;
        let max = self.max_bytes;
        self.event(
            0,
            "record_full",
            json!({ "max_bytes": max, "note": "force, status and output stop here" }),
        )
    }

    /// A strike the engine played; `names` are the bank's materials by slot.
    pub(super) fn strike(&mut self, s: &StrikeRecord, names: &[String]) -> Result<(), RecordError> {
        let material = s
            .slot
            .and_then(|slot| names.get(usize::from(slot)))
            .map_or("", String::as_str);
        let line = format!(
            "{},{},{},{},{},{}",
            s.frame as f64 / self.rate.hz(),
            s.frame,
            u32::from(s.channel) + 1,
            s.intensity,
            material,
            s.sensor_time.map_or_else(String::new, |t| t.0.to_string()),
        );
        self.counts.bytes += self.strikes.line(&line)?;
        self.counts.strikes += 1;
        #[cfg(feature = "lsl")]
        if let (Some(lsl), Some(t0)) = (&mut self.lsl, self.output_monotonic) {
            let sample = json!({
                "channel": u32::from(s.channel) + 1,
                "intensity": s.intensity,
                "material": material,
                "frame": s.frame,
            });
            lsl.push_strike(&sample.to_string(), t0 + s.frame as f64 / self.rate.hz());
        }
        Ok(())
    }

    /// An event of `kind` at engine frame `frame`, with its `fields` (an object).
    pub(super) fn event(
        &mut self,
        frame: u64,
        kind: &str,
        fields: Value,
    ) -> Result<(), RecordError> {
        self.event_at(self.now(), frame, kind, fields)
    }

    fn event_at(
        &mut self,
        t: f64,
        frame: u64,
        kind: &str,
        fields: Value,
    ) -> Result<(), RecordError> {
        let mut object = json!({ "t": t, "frame": frame, "kind": kind });
        if let (Some(o), Value::Object(fields)) = (object.as_object_mut(), fields) {
            o.extend(fields);
        }
        let line = object.to_string();
        self.counts.bytes += self.events.line(&line)?;
        Ok(())
    }

    /// A marker, at engine frame `frame`.
    pub(super) fn marker(&mut self, frame: u64, marker: &Marker) -> Result<(), RecordError> {
        let fields = serde_json::to_value(marker).unwrap_or(Value::Null);
        let t = self.now();
        self.event_at(t, frame, "marker", fields.clone())?;
        self.counts.markers += 1;
        #[cfg(feature = "lsl")]
        if let (Some(lsl), Some(t0)) = (&mut self.lsl, self.started_monotonic) {
            lsl.push_marker(&fields.to_string(), t0 + t);
        }
        Ok(())
    }

    /// The session's status: a line of `status.jsonl`.
    pub(super) fn status(&mut self, status: &Status) -> Result<(), RecordError> {
        let channels: Vec<Value> = status
            .channels
            .iter()
            .enumerate()
            .map(|(c, l)| {
                json!({
                    "channel": c + 1,
                    "force_n": l.force,
                    "strikes": l.strikes,
                    "peak_dbfs": dbfs(l.peak),
                    "rms_dbfs": dbfs(l.rms),
                    "limited": l.limited,
                    "live": l.live,
                    "material": l.slot.and_then(|s| status.materials.get(usize::from(s))),
                })
            })
            .collect();
        let t = &status.telemetry;
        let line = json!({
            "t": self.now(),
            "frame": t.frames,
            "strikes": t.strikes,
            "channels": channels,
            "limited": t.limited,
            "non_finite": t.non_finite,
            "watchdog_fades": t.watchdog_trips,
            "late_readings": t.late,
            "late_buffers": status.late_buffers,
            "queue_full": status.queue_full,
            "input_events": status.input.events,
            "input_rejected": status.input.rejected,
            "output_frames_dropped": self.drain.dropped.load(Ordering::Relaxed),
            "record_full": self.counts.full,
            "sensor_clock": t.sensor_clock.map(|a| json!({ "time_s": a.time.0, "frame": a.frame })),
        })
        .to_string();
        if self.room(line.len() as u64 + 1) {
            self.counts.bytes += self.status.line(&line)?;
        } else {
            self.note_full()?;
        }
        Ok(())
    }

    /// Moves what the output's ring holds into `output.wav`, and flushes the text
    /// files when a second has passed since the last flush.
    pub(super) fn poll(&mut self) -> Result<(), RecordError> {
        self.drain_output()?;
        if self.last_flush.elapsed() >= FLUSH_EVERY {
            self.flush()?;
        }
        Ok(())
    }

    fn drain_output(&mut self) -> Result<(), RecordError> {
        let channels = self.row.len().max(1);
        let available = self.drain.ring.slots();
        let n = available - available % channels;
        if n == 0 {
            return Ok(());
        }
        let Ok(chunk) = self.drain.ring.read_chunk(n) else {
            return Ok(());
        };
        let (a, b) = chunk.as_slices();
        self.drain.scratch.clear();
        self.drain.scratch.extend_from_slice(a);
        self.drain.scratch.extend_from_slice(b);
        chunk.commit_all();
        let bytes = 4 * n as u64;
        if !self.room(bytes) {
            return self.note_full();
        }
        if let Some(wav) = &mut self.wav {
            wav.write_interleaved(&self.drain.scratch)?;
            self.counts.output_frames += (n / channels) as u64;
            self.counts.bytes += bytes;
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), RecordError> {
        self.last_flush = Instant::now();
        self.force.flush()?;
        self.strikes.flush()?;
        self.events.flush()?;
        self.status.flush()
    }

    /// Ends the record: the last instant of force, the rest of the output, the end
    /// event and the manifest's end section. Returns what the record holds.
    pub(super) fn finish(
        mut self,
        frame: u64,
        reason: EndReason,
        telemetry: &TelemetrySnapshot,
    ) -> Result<RecordCounts, RecordError> {
        self.write_row()?;
        self.drain_output()?;
        self.counts.output_frames_dropped = self.drain.dropped.load(Ordering::Relaxed);
        self.event(frame, "end", json!({ "reason": reason.as_str() }))?;
        self.flush()?;
        if let Some(wav) = self.wav.take() {
            wav.finish()?;
        }
        let ended = json!({
            "reason": reason.as_str(),
            "elapsed_s": self.now(),
            "frames": telemetry.frames,
            "strikes": telemetry.strikes,
            "unlogged_strikes": telemetry.unlogged_strikes,
            "limited": telemetry.limited,
            "non_finite": telemetry.non_finite,
            "watchdog_fades": telemetry.watchdog_trips,
            "sensor_clock": telemetry.sensor_clock.map(|a| json!({
                "time_s": a.time.0,
                "frame": a.frame,
            })),
            "record": self.counts,
        });
        self.manifest["ended"] = ended;
        self.write_manifest()?;
        Ok(self.counts)
    }
}

/// The LSL streams, when asked for and built with them.
fn open_lsl(wanted: bool, channels: usize, sensor_rate: f64) -> Result<Option<Lsl>, RecordError> {
    if !wanted {
        return Ok(None);
    }
    #[cfg(feature = "lsl")]
    {
        Ok(Some(crate::io::lsl::LslOutlets::open(
            channels,
            sensor_rate,
        )?))
    }
    #[cfg(not(feature = "lsl"))]
    {
        let _ = (channels, sensor_rate);
        Err(RecordError::NoLsl)
    }
}

/// The SHA-256 of `bytes`, as 64 lower-case hex digits (a manifest's library hash).
#[must_use]
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// A level in dBFS, `null` for silence (as the status JSON says it).
fn dbfs(amplitude: f32) -> Value {
    crate::safety::level_dbfs(amplitude).map_or(Value::Null, |db| json!(db))
}

/// `2026-11-28T18:30:05.123Z`.
fn utc_text(t: SystemTime) -> String {
    let d = t
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap_or(Duration::ZERO);
    let secs = d.as_secs();
    let (days, rest) = (secs / 86_400, secs % 86_400);
    // Days to a civil date (proleptic Gregorian), after Howard Hinnant's algorithm.
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}.{:03}Z",
        rest / 3600,
        rest / 60 % 60,
        rest % 60,
        d.subsec_millis()
    )
}

/// The monotonic clock now, in seconds (`CLOCK_MONOTONIC`: the clock `Instant` reads on
/// Linux, and liblsl's `local_clock`), where it can be read.
fn monotonic_now() -> Option<f64> {
    #[cfg(target_os = "linux")]
    {
        // /proc/uptime is CLOCK_BOOTTIME to 10 ms; the exact reading needs the clock
        // itself, which std does not expose: read it from the vDSO through libc.
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on
        // Linux, and the call writes nothing else.
        let r = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &raw mut ts) };
        (r == 0).then_some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
    }
    #[cfg(not(target_os = "linux"))]
    {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_text_matches_known_dates() {
        let at = |s: u64, ms: u64| {
            utc_text(SystemTime::UNIX_EPOCH + Duration::from_millis(s * 1000 + ms))
        };
        assert_eq!(at(0, 0), "1970-01-01T00:00:00.000Z");
        // `date -u -d @951782400` (a leap day).
        assert_eq!(at(951_782_400, 5), "2000-02-29T00:00:00.005Z");
        assert_eq!(at(1_796_000_000, 0), "2026-11-30T00:53:20.000Z");
    }

    #[test]
    fn a_marker_with_a_line_break_or_nothing_is_refused() {
        assert!(Marker::new("trial 1 starts").check().is_ok());
        assert!(Marker::new("  ").check().is_err());
        assert!(Marker::new("a\nb").check().is_err());
        let long = Marker {
            participant: Some("p".repeat(300)),
            ..Marker::new("x")
        };
        assert!(
            long.check()
                .unwrap_err()
                .to_string()
                .contains("participant")
        );
    }

    #[test]
    fn the_tap_keeps_the_engine_channels_and_drops_whole_buffers() {
        let (mut tap, mut drain) = output_ring(2, SampleRate(4000));
        // A 3-channel device buffer of 2 frames: the third channel is not recorded.
        tap.push(&[1.0, 2.0, 9.0, 3.0, 4.0, 9.0], 3);
        let n = drain.ring.slots();
        let chunk = drain.ring.read_chunk(n).unwrap();
        let (a, b) = chunk.as_slices();
        assert_eq!([a, b].concat(), [1.0, 2.0, 3.0, 4.0]);
        chunk.commit_all();
        // More than the ring holds: dropped whole, counted in frames.
        let big = vec![0.5; 2 * 20_000];
        tap.push(&big, 2);
        assert_eq!(drain.dropped.load(Ordering::Relaxed), 20_000);
        assert_eq!(drain.ring.slots(), 0);
    }
}

/// A strike as a record's `strikes.csv` holds it.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedStrike {
    /// Seconds on the output (`frame / rate`).
    pub time: f64,
    /// The output frame its impulse starts on.
    pub frame: u64,
    /// The channel, from 1.
    pub channel: u32,
    /// Strength relative to a nominal step.
    pub intensity: f64,
    /// The material the channel played.
    pub material: String,
}

/// A record's output, read back: one vector of samples per channel.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedOutput {
    /// The sample rate, in hertz.
    pub rate: f64,
    /// Each channel's samples.
    pub channels: Vec<Vec<f32>>,
}

/// A recorded session, read back ([`SessionRecord::read`]).
#[derive(Debug, Clone)]
pub struct SessionRecord {
    /// The folder.
    pub dir: PathBuf,
    /// `manifest.json`.
    pub manifest: Value,
    /// `force.csv`, if it holds a row.
    pub force: Option<crate::force::track::ForceTrack>,
    /// `strikes.csv`.
    pub strikes: Vec<RecordedStrike>,
    /// `events.jsonl`, in order.
    pub events: Vec<Value>,
    /// `status.jsonl`, in order.
    pub status: Vec<Value>,
    /// The output's WAV file: `output.wav`, or the partial file of a session that never
    /// finished.
    pub output: Option<PathBuf>,
    /// Lines cut short at the end of a file (a process killed mid-write), skipped.
    pub cut_lines: usize,
}

impl SessionRecord {
    /// Reads the record in `dir`: a finished one, or one whose process was killed (its
    /// files end wherever the last flush left them; a line cut short is skipped and
    /// counted).
    ///
    /// # Errors
    /// [`RecordError::Folder`] for a folder that is not a record, or a record of another
    /// version; [`RecordError::Write`] (naming the file) for one that cannot be read.
    pub fn read(dir: &Path) -> Result<Self, RecordError> {
        let refuse = |reason: String| RecordError::Folder {
            path: dir.to_path_buf(),
            reason,
        };
        let read = |name: &str| -> Result<Option<String>, RecordError> {
            let path = dir.join(name);
            match fs::read(&path) {
                Ok(bytes) => Ok(Some(String::from_utf8_lossy(&bytes).into_owned())),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
                Err(source) => Err(RecordError::Write { path, source }),
            }
        };
        let manifest = read("manifest.json")?.ok_or_else(|| {
            refuse("no manifest.json: not a session record (`run --record DIR` makes one)".into())
        })?;
        let manifest: Value = serde_json::from_str(&manifest)
            .map_err(|e| refuse(format!("manifest.json does not parse: {e}")))?;
        if manifest["format"] != "underfoot session record" {
            return Err(refuse(
                "manifest.json is not an underfoot session record's".into(),
            ));
        }
        match manifest["version"].as_u64() {
            Some(v) if v == u64::from(RECORD_VERSION) => {}
            v => {
                return Err(refuse(format!(
                    "a record of version {}; this build reads version {RECORD_VERSION}",
                    v.map_or_else(|| "unknown".to_owned(), |v| v.to_string())
                )));
            }
        }
        let mut cut_lines = 0;
        let mut whole = |text: Option<String>| -> String {
            let mut text = text.unwrap_or_default();
            if !text.is_empty() && !text.ends_with('\n') {
                // The last line was being written when the process stopped.
                let keep = text.rfind('\n').map_or(0, |i| i + 1);
                text.truncate(keep);
                cut_lines += 1;
            }
            text
        };
        let force_text = whole(read("force.csv")?);
        let strikes_text = whole(read("strikes.csv")?);
        let events_text = whole(read("events.jsonl")?);
        let status_text = whole(read("status.jsonl")?);
        let force = if force_text
            .lines()
            .any(|l| !l.starts_with('#') && !l.starts_with("time_s") && !l.trim().is_empty())
        {
            Some(
                crate::force::track::ForceTrack::from_csv_str(
                    &force_text,
                    &dir.join("force.csv").display().to_string(),
                )
                .map_err(|e| refuse(format!("force.csv: {e}")))?,
            )
        } else {
            None
        };
        let mut strikes = Vec::new();
        for (i, line) in strikes_text.lines().enumerate().skip(1) {
            let f: Vec<&str> = line.split(',').collect();
            let bad = || {
                refuse(format!(
                    "strikes.csv line {}: {line:?} does not parse",
                    i + 1
                ))
            };
            if f.len() < 5 {
                return Err(bad());
            }
            strikes.push(RecordedStrike {
                time: f[0].parse().map_err(|_| bad())?,
                frame: f[1].parse().map_err(|_| bad())?,
                channel: f[2].parse().map_err(|_| bad())?,
                intensity: f[3].parse().map_err(|_| bad())?,
                material: f[4].to_owned(),
            });
        }
        let lines = |text: &str, name: &str| -> Result<Vec<Value>, RecordError> {
            text.lines()
                .enumerate()
                .filter(|(_, l)| !l.trim().is_empty())
                .map(|(i, l)| {
                    serde_json::from_str(l)
                        .map_err(|e| refuse(format!("{name} line {}: {e}", i + 1)))
                })
                .collect()
        };
        let events = lines(&events_text, "events.jsonl")?;
        let status = lines(&status_text, "status.jsonl")?;
        let output = if dir.join("output.wav").is_file() {
            Some(dir.join("output.wav"))
        } else {
            fs::read_dir(dir)
                .ok()
                .into_iter()
                .flatten()
                .flatten()
                .map(|e| e.path())
                .find(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with("output.partial-") && n.ends_with(".wav"))
                })
        };
        Ok(Self {
            dir: dir.to_path_buf(),
            manifest,
            force,
            strikes,
            events,
            status,
            output,
            cut_lines,
        })
    }

    /// The output's samples, one vector per channel, and their rate; `None` when the
    /// record has no WAV file. A partial file (a killed session) reads up to its last
    /// update.
    ///
    /// # Errors
    /// [`RecordError::Wav`] naming the file when it does not read.
    pub fn read_output(&self) -> Result<Option<RecordedOutput>, RecordError> {
        let Some(path) = &self.output else {
            return Ok(None);
        };
        let bad = |e: hound::Error| {
            RecordError::Wav(IoError::Open {
                device: path.display().to_string(),
                reason: e.to_string(),
            })
        };
        let file = fs::File::open(path).map_err(|e| bad(hound::Error::IoError(e)))?;
        if let Ok(meta) = file.metadata() {
            crate::limits::reads::note_read(&meta);
        }
        let mut reader = hound::WavReader::new(std::io::BufReader::new(file)).map_err(bad)?;
        let spec = reader.spec();
        let n = usize::from(spec.channels.max(1));
        let mut channels = vec![Vec::with_capacity(reader.duration() as usize); n];
        for (i, s) in reader.samples::<f32>().enumerate() {
            channels[i % n].push(s.map_err(bad)?);
        }
        Ok(Some(RecordedOutput {
            rate: f64::from(spec.sample_rate),
            channels,
        }))
    }

    /// The output rate, in hertz.
    #[must_use]
    pub fn rate(&self) -> f64 {
        self.manifest["rate_hz"].as_f64().unwrap_or(48_000.0)
    }

    /// The markers, in order.
    pub fn markers(&self) -> impl Iterator<Item = &Value> {
        self.events.iter().filter(|e| e["kind"] == "marker")
    }

    /// Whether the session finished (its manifest has an end), rather than being killed.
    #[must_use]
    pub fn finished(&self) -> bool {
        !self.manifest["ended"].is_null()
    }

    /// Where a sensor time falls on the output's time axis: through the sensor clock's
    /// anchor when the session ended with one, else as it is.
    #[must_use]
    pub fn output_time_of_sensor(&self, t: f64) -> f64 {
        // A killed session has no end: its last status says the anchor.
        let anchor = [&self.manifest["ended"]["sensor_clock"]]
            .into_iter()
            .chain(self.status.iter().rev().map(|s| &s["sensor_clock"]))
            .find(|a| !a.is_null())
            .unwrap_or(&Value::Null);
        match (anchor["time_s"].as_f64(), anchor["frame"].as_f64()) {
            (Some(t0), Some(frame)) => frame / self.rate() + (t - t0),
            _ => t,
        }
    }
}
