//! Vibration to a WAV file.
//!
//! [`WavSink`] takes interleaved `f32` blocks as the engine renders them and writes 32-bit
//! float, 16-bit or 24-bit integer PCM. Integer samples are `x * 2^(bits-1)` truncated
//! towards zero ([`crate::safety::quantize`]: never rounded past the limiter's ceiling),
//! clamped to the format's range: +1.0 lands one step below full scale and anything
//! beyond +-1 is clipped and counted in [`WavSummary::clipped_samples`].
//!
//! Every file goes through the output policy ([`crate::atomic_file`]): a device, FIFO,
//! read-only file or an input of the command is refused, a symlink is written through.
//! The file is written beside the (resolved) target under a temporary name and renamed
//! over it only by [`WavSink::finish`], so a render that fails or is abandoned never
//! destroys an existing file. Dropping an unfinished sink removes the temporary file.
//!
//! # Live recordings
//!
//! A session recorded by `run --output wav:` may last hours and end with a crash, a
//! full disk or a `SIGKILL`, so [`WavSink::live`] keeps the file valid on disk at every
//! moment and at most [`LIVE_FLUSH_MAX`] behind, and never lets a session that fails
//! replace the file that was there. It records into a *partial* file beside the target,
//! `STEM.partial-PID.EXT` (`walk.partial-4242.wav` for `walk.wav`:
//! [`OutputFile::create_partial`]), which replaces the target only when the session
//! [finishes](WavSink::finish). What is left otherwise:
//! - a write that fails (a full disk): the target as it was, and the partial file, valid
//!   up to the last update, named in the error;
//! - a crash or a kill: the same, without the message. The partial file is visible,
//!   not hidden, because it is the user's data; no later run removes it.
//!
//! At least once a second, from the
//! thread that writes the samples (never the audio thread), the buffered samples are
//! written, *then* the RIFF and data sizes in the header are updated to count them, then
//! the file is flushed ([`WavSink::sync`]). So between two updates the file holds more
//! sample bytes than its header counts, and a reader sees the audio up to the last
//! update: valid, just shorter. (The bytes past the counted data are at the end of the
//! file, where readers stop.) The data reach the kernel, which keeps them through a
//! killed process; [`WavSink::finish`] also flushes them to the disk itself, against a
//! power cut.
//!
//! ```
//! use underfoot::io::wav::{WavFormat, WavSink};
//! use underfoot::units::SampleRate;
//!
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("steps.wav");
//! let mut sink = WavSink::create(&path, SampleRate(48_000), 2, WavFormat::Int16)?;
//! sink.write_interleaved(&[0.5, -0.5, 1.5, 0.0])?;
//! let summary = sink.finish()?;
//! assert_eq!(summary.frames, 2);
//! assert_eq!(summary.clipped_samples, 1);
//! assert!(path.exists());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::fs::{self, File};
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::IoError;
use crate::atomic_file::{AtomicWriteError, OutputFile};
use crate::units::SampleRate;

/// The sample encoding of the file.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub enum WavFormat {
    /// 32-bit IEEE float: exact for the engine's `f32` output, values beyond +-1 kept.
    #[default]
    Float32,
    /// 16-bit signed integer PCM.
    Int16,
    /// 24-bit signed integer PCM.
    Int24,
}

impl WavFormat {
    fn bits(self) -> u16 {
        match self {
            Self::Float32 => 32,
            Self::Int16 => 16,
            Self::Int24 => 24,
        }
    }

    fn bytes(self) -> u64 {
        u64::from(self.bits() / 8)
    }
}

/// What a finished file holds.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct WavSummary {
    /// Frames written (samples per channel).
    pub frames: u64,
    /// Largest absolute sample value among the finite ones, before any clipping.
    pub peak: f32,
    /// Integer formats only: samples beyond +-1 that were clipped to full scale.
    pub clipped_samples: u64,
    /// NaN or infinite samples, written as silence.
    pub non_finite_samples: u64,
}

/// hound keeps the data size in the RIFF header's 32-bit fields; the margin leaves room
/// for the header itself so that its size arithmetic cannot overflow.
const MAX_DATA_BYTES: u64 = u32::MAX as u64 - 4096;

/// A WAV file being written; see the [module docs](self).
pub struct WavSink {
    path: PathBuf,
    out: OutputFile,
    temp: PathBuf,
    /// `None` once finished.
    writer: Option<hound::WavWriter<BufWriter<File>>>,
    format: WavFormat,
    channels: u16,
    samples: u64,
    peak: f32,
    clipped: u64,
    non_finite: u64,
    /// A write failed, so the temporary file must not replace `path`.
    failed: bool,
    /// The temporary file has become `path` and must not be removed.
    persisted: bool,
    /// A live recording: periodic updates on disk, into a partial file worth keeping.
    live: Option<Live>,
}

/// When a live recording was last brought up to date on disk.
#[derive(Debug, Clone, Copy)]
struct Live {
    every: Duration,
    last: Instant,
}

/// The longest interval between two updates of a [live](WavSink::live) recording on disk.
pub const LIVE_FLUSH_MAX: Duration = Duration::from_secs(1);

impl std::fmt::Debug for WavSink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WavSink")
            .field("path", &self.path)
            .field("format", &self.format)
            .field("channels", &self.channels)
            .field("samples", &self.samples)
            .finish_non_exhaustive()
    }
}

impl WavSink {
    /// Starts a file that will become `path` when [finished](Self::finish), under the
    /// output policy of a command that reads nothing
    /// ([`OutputFile::check`](crate::atomic_file::OutputFile::check)).
    ///
    /// # Errors
    /// - [`IoError::Unsupported`] for zero channels or a zero rate.
    /// - [`IoError::Open`] naming `path` if the policy refuses it (a device, a read-only
    ///   file, ...) or the temporary file cannot be created beside it (missing directory,
    ///   no permission).
    pub fn create(
        path: impl AsRef<Path>,
        rate: SampleRate,
        channels: u16,
        format: WavFormat,
    ) -> Result<Self, IoError> {
        let path = path.as_ref();
        let out = OutputFile::check(path, &[]).map_err(|e| open_error(path, &e))?;
        Self::to_output(out, rate, channels, format)
    }

    /// Starts a file for an output already checked by the caller (with its inputs); it
    /// replaces the target when [finished](Self::finish).
    ///
    /// # Errors
    /// As [`create`](Self::create).
    pub fn to_output(
        out: OutputFile,
        rate: SampleRate,
        channels: u16,
        format: WavFormat,
    ) -> Result<Self, IoError> {
        Self::start(out, rate, channels, format, None)
    }

    /// Starts a live recording (see the module docs, *Live recordings*): a partial file
    /// beside the target, brought up to date on disk at least every `every` (at most
    /// [`LIVE_FLUSH_MAX`]), so a killed process leaves a valid WAV file that lacks at
    /// most that much audio; it replaces the target when [finished](Self::finish).
    ///
    /// # Errors
    /// As [`create`](Self::create).
    pub fn live(
        out: OutputFile,
        rate: SampleRate,
        channels: u16,
        format: WavFormat,
        every: Duration,
    ) -> Result<Self, IoError> {
        Self::start(out, rate, channels, format, Some(every.min(LIVE_FLUSH_MAX)))
    }

    fn start(
        out: OutputFile,
        rate: SampleRate,
        channels: u16,
        format: WavFormat,
        live: Option<Duration>,
    ) -> Result<Self, IoError> {
        let path = out.path().to_path_buf();
        let unsupported = |reason: &str| IoError::Unsupported {
            device: path.display().to_string(),
            reason: reason.to_string(),
        };
        if channels == 0 {
            return Err(unsupported("a WAV file needs at least one channel"));
        }
        if rate.0 == 0 {
            return Err(unsupported("a sample rate of 0 Hz"));
        }
        let created = if live.is_some() {
            out.create_partial()
        } else {
            out.create_temporary()
        };
        let (temp, file) = created.map_err(|e| open_error(&path, &e))?;

        let spec = hound::WavSpec {
            channels,
            sample_rate: rate.0,
            bits_per_sample: format.bits(),
            sample_format: match format {
                WavFormat::Float32 => hound::SampleFormat::Float,
                WavFormat::Int16 | WavFormat::Int24 => hound::SampleFormat::Int,
            },
        };
        let writer = match hound::WavWriter::new(BufWriter::new(file), spec) {
            Ok(w) => w,
            Err(e) => {
                let _ = fs::remove_file(&temp);
                return Err(io_error(&path, e));
            }
        };
        Ok(Self {
            path,
            out,
            temp,
            writer: Some(writer),
            format,
            channels,
            samples: 0,
            peak: 0.0,
            clipped: 0,
            non_finite: 0,
            failed: false,
            persisted: false,
            live: live.map(|every| Live {
                every,
                last: Instant::now(),
            }),
        })
    }

    /// Appends interleaved samples: a whole number of frames.
    ///
    /// # Errors
    /// - [`IoError::Unsupported`] if `samples` is not a whole number of frames, or the file
    ///   would exceed the 4 GiB a WAV file can hold; nothing is written.
    /// - [`IoError::Io`] if writing fails; the sink is then spoiled and
    ///   [`finish`](Self::finish) will refuse to replace `path`.
    pub fn write_interleaved(&mut self, samples: &[f32]) -> Result<(), IoError> {
        let unsupported = |reason: String| IoError::Unsupported {
            device: self.path.display().to_string(),
            reason,
        };
        if !samples.len().is_multiple_of(usize::from(self.channels)) {
            return Err(unsupported(format!(
                "{} samples are not a whole number of {}-channel frames",
                samples.len(),
                self.channels
            )));
        }
        let total = self.samples + samples.len() as u64;
        if total.saturating_mul(self.format.bytes()) > MAX_DATA_BYTES {
            return Err(unsupported(format!(
                "a WAV file holds at most 4 GiB of samples ({} frames here)",
                MAX_DATA_BYTES / self.format.bytes() / u64::from(self.channels)
            )));
        }
        let Some(writer) = self.writer.as_mut() else {
            return Err(unsupported("the file is already finished".into()));
        };
        if self.failed {
            return Err(unsupported("an earlier write failed".into()));
        }

        for &x in samples {
            let x = if x.is_finite() {
                self.peak = self.peak.max(x.abs());
                x
            } else {
                self.non_finite += 1;
                0.0
            };
            let written = match self.format {
                WavFormat::Float32 => writer.write_sample(x),
                WavFormat::Int16 | WavFormat::Int24 => {
                    if x.abs() > 1.0 {
                        self.clipped += 1;
                    }
                    // Truncated, never rounded up: never past the ceiling (`safety`).
                    writer.write_sample(crate::safety::quantize(x, self.format.bits().into()))
                }
            };
            if let Err(e) = written {
                self.failed = true;
                return Err(self.kept(io_error(&self.path, e)));
            }
        }
        self.samples = total;
        // The first block at once, so that the partial file is a valid WAV from the
        // start; then at the recording's interval.
        if let Some(live) = self.live
            && (total == samples.len() as u64 || live.last.elapsed() >= live.every)
        {
            self.sync()?;
        }
        Ok(())
    }

    /// Brings the file on disk up to date with everything written so far: a live
    /// recording does this by itself, at least every [`LIVE_FLUSH_MAX`].
    ///
    /// # Errors
    /// [`IoError::Io`] naming the file; the sink is spoiled.
    pub fn sync(&mut self) -> Result<(), IoError> {
        let Some(writer) = self.writer.as_mut() else {
            return Err(io_error(&self.path, "the file is already finished"));
        };
        // hound writes the buffered samples, then the RIFF and data sizes, then flushes:
        // the header never counts a byte that is not in the file yet.
        if let Err(e) = writer.flush() {
            self.failed = true;
            return Err(self.kept(io_error(&self.path, e)));
        }
        if let Some(live) = self.live.as_mut() {
            live.last = Instant::now();
        }
        Ok(())
    }

    /// The partial file a live recording leaves when it fails.
    #[must_use]
    pub fn partial_path(&self) -> Option<&Path> {
        self.live.is_some().then_some(self.temp.as_path())
    }

    /// A live recording's failure, saying what is left: the old target, and the partial
    /// file with the samples up to the last update.
    fn kept(&self, e: IoError) -> IoError {
        match (self.partial_path(), e) {
            (Some(partial), IoError::Io { device, source }) => IoError::Io {
                device,
                source: std::io::Error::new(
                    source.kind(),
                    format!(
                        "{source}; the file that was there is kept, and the recording up to \
                         the last update is in {}",
                        partial.display()
                    ),
                ),
            },
            (_, e) => e,
        }
    }

    /// Completes the header, flushes the file to disk and renames it over `path`.
    ///
    /// # Errors
    /// [`IoError::Io`] naming `path` if finishing or renaming fails, or if an earlier
    /// write failed; the temporary file is removed and any old file at `path` is left as
    /// it was.
    pub fn finish(mut self) -> Result<WavSummary, IoError> {
        let Some(writer) = self.writer.take() else {
            return Err(io_error(&self.path, "the file is already finished"));
        };
        if self.failed {
            drop(writer);
            return Err(self.kept(io_error(
                &self.path,
                "an earlier write failed; the old file is kept",
            )));
        }
        if let Err(e) = writer.finalize() {
            return Err(self.kept(io_error(&self.path, e)));
        }
        // hound has flushed its buffer and closed the file; fsync through a new handle.
        let file = File::options()
            .write(true)
            .open(&self.temp)
            .map_err(|e| io_error(&self.path, e))?;
        self.out
            .persist(&self.temp, &file)
            .map_err(|e| open_error(&self.path, &e))?;
        self.persisted = true;
        Ok(WavSummary {
            frames: self.samples / u64::from(self.channels),
            peak: self.peak,
            clipped_samples: self.clipped,
            non_finite_samples: self.non_finite,
        })
    }

    /// The file this sink will become.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for WavSink {
    fn drop(&mut self) {
        // hound rewrites the header when its writer drops; that must happen before the
        // file is removed, or the removal would race the last write on some systems.
        drop(self.writer.take());
        // A live recording that holds samples keeps them in its partial file (hound's
        // drop has just written the final sizes): it is the user's data.
        let keep = self.live.is_some() && self.samples > 0;
        if !self.persisted && !keep {
            let _ = fs::remove_file(&self.temp);
        }
    }
}

fn open_error(path: &Path, e: &AtomicWriteError) -> IoError {
    IoError::Open {
        device: path.display().to_string(),
        reason: format!("{e}: {}", e.source),
    }
}

fn io_error(path: &Path, e: impl Into<HoundOrIo>) -> IoError {
    let source = match e.into() {
        HoundOrIo::Io(e) => e,
        HoundOrIo::Hound(hound::Error::IoError(e)) => e,
        HoundOrIo::Hound(e) => std::io::Error::other(e.to_string()),
        HoundOrIo::Message(m) => std::io::Error::other(m),
    };
    IoError::Io {
        device: path.display().to_string(),
        source,
    }
}

enum HoundOrIo {
    Io(std::io::Error),
    Hound(hound::Error),
    Message(&'static str),
}

impl From<std::io::Error> for HoundOrIo {
    fn from(e: std::io::Error) -> Self {
        Self::Io(e)
    }
}

impl From<hound::Error> for HoundOrIo {
    fn from(e: hound::Error) -> Self {
        Self::Hound(e)
    }
}

impl From<&'static str> for HoundOrIo {
    fn from(m: &'static str) -> Self {
        Self::Message(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_back(path: &Path) -> (hound::WavSpec, Vec<f32>) {
        let mut reader = hound::WavReader::open(path).expect("readable WAV");
        let spec = reader.spec();
        let samples = match spec.sample_format {
            hound::SampleFormat::Float => reader
                .samples::<f32>()
                .map(|s| s.expect("sample"))
                .collect(),
            hound::SampleFormat::Int => {
                let scale = f32::powi(2.0, i32::from(spec.bits_per_sample) - 1);
                reader
                    .samples::<i32>()
                    .map(|s| s.expect("sample") as f32 / scale)
                    .collect()
            }
        };
        (spec, samples)
    }

    /// A deterministic test signal in [-1, 1] with a few values at and beyond full scale.
    fn signal(n: usize) -> Vec<f32> {
        let mut x: Vec<f32> = (0..n)
            .map(|i| (i as f32 * 0.37).sin() * 0.9 + (i as f32 * 0.011).cos() * 0.05)
            .collect();
        x[3] = 1.0;
        x[4] = -1.0;
        x
    }

    #[test]
    fn round_trip_through_hound_in_every_format() {
        let dir = tempfile::tempdir().expect("tempdir");
        for (format, bits, tolerance) in [
            (WavFormat::Float32, 32, 0.0),
            // Truncation is under a step; +1.0 lands one step below full scale.
            (WavFormat::Int16, 16, 1.0 / 32_768.0),
            (WavFormat::Int24, 24, 1.0 / 8_388_608.0),
        ] {
            let path = dir.path().join(format!("{format:?}.wav"));
            let x = signal(2 * 1000);
            let mut sink = WavSink::create(&path, SampleRate(8000), 2, format).expect("create");
            // Blocks of uneven size, as a render would hand them over.
            for block in x.chunks(2 * 37) {
                sink.write_interleaved(block).expect("write");
            }
            let summary = sink.finish().expect("finish");
            assert_eq!(summary.frames, 1000);
            assert_eq!(summary.clipped_samples, 0);
            assert_eq!(summary.peak, 1.0);

            let (spec, y) = read_back(&path);
            assert_eq!(spec.channels, 2);
            assert_eq!(spec.sample_rate, 8000);
            assert_eq!(spec.bits_per_sample, bits);
            assert_eq!(y.len(), x.len());
            let worst = x
                .iter()
                .zip(&y)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0_f32, f32::max);
            assert!(
                worst <= tolerance,
                "{format:?}: error {worst} > {tolerance}"
            );
        }
    }

    #[test]
    fn integer_formats_clip_and_count_beyond_full_scale() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("clip.wav");
        let mut sink =
            WavSink::create(&path, SampleRate(8000), 1, WavFormat::Int16).expect("create");
        sink.write_interleaved(&[1.5, -2.0, 0.25, f32::NAN, 1.0])
            .expect("write");
        let summary = sink.finish().expect("finish");
        assert_eq!(summary.clipped_samples, 2);
        assert_eq!(summary.non_finite_samples, 1);
        assert_eq!(summary.peak, 2.0);
        let (_, y) = read_back(&path);
        assert_eq!(
            y,
            vec![32_767.0 / 32_768.0, -1.0, 0.25, 0.0, 32_767.0 / 32_768.0]
        );

        // Float keeps values beyond full scale and does not call them clipped.
        let path = dir.path().join("float.wav");
        let mut sink =
            WavSink::create(&path, SampleRate(8000), 1, WavFormat::Float32).expect("create");
        sink.write_interleaved(&[1.5, -2.0]).expect("write");
        assert_eq!(sink.finish().expect("finish").clipped_samples, 0);
        assert_eq!(read_back(&path).1, vec![1.5, -2.0]);
    }

    #[test]
    fn a_dropped_sink_leaves_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("old.wav");
        fs::write(&path, b"the previous render").expect("old file");
        {
            let mut sink =
                WavSink::create(&path, SampleRate(8000), 1, WavFormat::Float32).expect("create");
            sink.write_interleaved(&[0.1; 100]).expect("write");
            // Dropped without finish: a render that failed half way.
        }
        assert_eq!(fs::read(&path).expect("old file"), b"the previous render");
        let names: Vec<_> = fs::read_dir(dir.path())
            .expect("dir")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("old.wav")]);
    }

    #[test]
    fn finish_replaces_the_old_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("old.wav");
        fs::write(&path, b"the previous render").expect("old file");
        let mut sink =
            WavSink::create(&path, SampleRate(8000), 1, WavFormat::Int24).expect("create");
        sink.write_interleaved(&[0.5; 10]).expect("write");
        sink.finish().expect("finish");
        assert_eq!(read_back(&path).1, vec![0.5; 10]);
        assert_eq!(fs::read_dir(dir.path()).expect("dir").count(), 1);
    }

    #[test]
    fn a_live_recording_is_a_valid_file_at_every_sync_and_after_a_kill() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("live.wav");
        fs::write(&path, b"the previous session").expect("old file");
        let out = OutputFile::check(&path, &[]).expect("check");
        let mut sink = WavSink::live(
            out,
            SampleRate(8000),
            2,
            WavFormat::Float32,
            Duration::from_secs(3600),
        )
        .expect("live");
        let partial = sink
            .partial_path()
            .expect("a live sink's partial")
            .to_path_buf();
        assert_eq!(
            partial.file_name().unwrap().to_string_lossy(),
            format!("live.partial-{}.wav", std::process::id())
        );
        // The first block is on disk at once, as a valid file holding that block.
        sink.write_interleaved(&[0.25; 2 * 100]).expect("write");
        assert_eq!(read_back(&partial).1.len(), 200);
        // Later blocks are on disk only from the next sync on, but the file stays valid
        // in between: its header counts what was synced.
        sink.write_interleaved(&[0.5; 2 * 5000]).expect("write");
        assert_eq!(read_back(&partial).1.len(), 200);
        sink.sync().expect("sync");
        let (_, y) = read_back(&partial);
        assert_eq!(y.len(), 2 * 5100);
        assert_eq!(y[2 * 5100 - 1], 0.5);
        // A kill: no finish, no drop. The old file is as it was, the recording beside it.
        sink.write_interleaved(&[0.75; 2 * 10]).expect("write");
        std::mem::forget(sink);
        assert_eq!(read_back(&partial).1.len(), 2 * 5100);
        assert_eq!(fs::read(&path).expect("old"), b"the previous session");
        assert_eq!(fs::read_dir(dir.path()).expect("dir").count(), 2);
    }

    #[test]
    fn a_live_recording_syncs_by_itself_and_finishes_whole() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("live.wav");
        fs::write(&path, b"the previous session").expect("old file");
        let out = OutputFile::check(&path, &[]).expect("check");
        let mut sink = WavSink::live(
            out,
            SampleRate(8000),
            1,
            WavFormat::Int16,
            Duration::from_millis(10),
        )
        .expect("live");
        let partial = sink.partial_path().expect("partial").to_path_buf();
        sink.write_interleaved(&[0.5; 10]).expect("write");
        std::thread::sleep(Duration::from_millis(20));
        sink.write_interleaved(&[0.5; 30]).expect("write");
        assert_eq!(
            read_back(&partial).1.len(),
            40,
            "not synced after the interval"
        );
        assert_eq!(fs::read(&path).expect("old"), b"the previous session");
        sink.write_interleaved(&[0.5; 7]).expect("write");
        assert_eq!(sink.finish().expect("finish").frames, 47);
        assert_eq!(read_back(&path).1.len(), 47);
        assert_eq!(fs::read_dir(dir.path()).expect("dir").count(), 1);
    }

    #[test]
    fn a_live_recording_dropped_before_its_first_block_leaves_nothing() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("live.wav");
        let out = OutputFile::check(&path, &[]).expect("check");
        let sink = WavSink::live(out, SampleRate(8000), 1, WavFormat::Int16, LIVE_FLUSH_MAX)
            .expect("live");
        drop(sink);
        assert_eq!(fs::read_dir(dir.path()).expect("dir").count(), 0);
    }

    #[cfg(unix)]
    #[test]
    fn devices_and_read_only_files_are_refused_and_links_written_through() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().expect("tempdir");
        let link = dir.path().join("null.wav");
        std::os::unix::fs::symlink("/dev/null", &link).expect("link");
        let err =
            WavSink::create(&link, SampleRate(8000), 1, WavFormat::Float32).expect_err("a device");
        assert!(err.to_string().contains("character device"), "{err}");
        let ro = dir.path().join("ro.wav");
        fs::write(&ro, b"keep").expect("file");
        fs::set_permissions(&ro, fs::Permissions::from_mode(0o444)).expect("chmod");
        assert!(WavSink::create(&ro, SampleRate(8000), 1, WavFormat::Float32).is_err());
        assert_eq!(fs::read(&ro).expect("kept"), b"keep");
        let real = dir.path().join("real.wav");
        let to_real = dir.path().join("to-real.wav");
        std::os::unix::fs::symlink("real.wav", &to_real).expect("link");
        let mut sink =
            WavSink::create(&to_real, SampleRate(8000), 1, WavFormat::Float32).expect("create");
        sink.write_interleaved(&[0.5; 3]).expect("write");
        sink.finish().expect("finish");
        assert!(fs::symlink_metadata(&to_real).expect("link").is_symlink());
        assert_eq!(read_back(&real).1, vec![0.5; 3]);
    }

    #[test]
    fn a_missing_directory_is_an_error_naming_the_path() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("no-such-dir").join("out.wav");
        let err = WavSink::create(&path, SampleRate(8000), 1, WavFormat::Float32)
            .expect_err("missing directory");
        assert!(matches!(err, IoError::Open { .. }), "{err:?}");
        let message = err.to_string();
        assert!(message.contains(&path.display().to_string()), "{message}");
        assert!(message.contains("no-such-dir"), "{message}");
    }

    #[test]
    fn partial_frames_and_bad_settings_are_errors() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("x.wav");
        assert!(matches!(
            WavSink::create(&path, SampleRate(8000), 0, WavFormat::Float32),
            Err(IoError::Unsupported { .. })
        ));
        assert!(matches!(
            WavSink::create(&path, SampleRate(0), 1, WavFormat::Float32),
            Err(IoError::Unsupported { .. })
        ));
        let mut sink =
            WavSink::create(&path, SampleRate(8000), 2, WavFormat::Float32).expect("create");
        assert!(matches!(
            sink.write_interleaved(&[0.0; 3]),
            Err(IoError::Unsupported { .. })
        ));
        sink.write_interleaved(&[0.0; 4]).expect("whole frames");
        assert_eq!(sink.finish().expect("finish").frames, 2);
    }
}
