//! Long recordings, read as excerpts around their strikes.
//!
//! A fit needs the heel strikes of a recording, not the minutes of walking between them,
//! and its analysis holds several copies of what it is given at the recording's own rate.
//! A 30-minute walk at 44.1 kHz is 79 million samples, 635 MB as one `f64` copy and 7.7 GB
//! through the whole fit; so [`read_for_analysis`] reads a recording longer than
//! [`LONG_FRAMES`] in two streaming passes and keeps only excerpts around its strikes:
//!
//! 1. **Find the strikes.** The file is decoded packet by packet (never held whole, in
//!    bytes or in samples) into the energy of 5 ms blocks, and checked on the way as any
//!    recording is ([the checks](super#checks)). On the blocks' RMS `e_k`, strikes are
//!    found by [`find_onsets`](super::strikes::find_onsets)' detection rule with its
//!    default settings: the threshold `max(P - 20 dB, sigma + 12 dB)` (`P` the loudest
//!    block, `sigma` the 10th percentile), a 6 dB hysteresis and 0.3 s between strikes.
//!    The rule is the file's, not an excerpt's: a strike more than 20 dB under the
//!    file's loudest is not one, as in a short recording.
//! 2. **Cut.** Strikes detected within [`JOIN_WITHIN`] of the one before share an
//!    excerpt, up to [`LONGEST_EXCERPT`] (a granular step can burst twice; the whole
//!    file's analysis takes the second burst for the first strike's, an excerpt of its
//!    own would make it a strike). An excerpt runs from [`EXCERPT_BEFORE`] before its
//!    first detection to [`EXCERPT_AFTER`] after its last, but starts no earlier than the
//!    quiet between it and the strike before (the latest 5 ms block within 3 dB of the
//!    quietest, at least 20 ms before the strike: no excerpt begins in the last one's
//!    ring, which its own analysis would take for a strike) and ends where the next
//!    excerpt starts. That holds
//!    everything the analysis looks at around a strike: the quiet before it for the noise
//!    floor and the onset search (at most 0.1 s back), the 0.5 s spectrum window, and the
//!    600 ms the step descriptors measure.
//! 3. **Keep at most [`MAX_EXCERPTS`]**, and at most [`MAX_EXCERPT_SAMPLES`] samples
//!    in all, spread evenly over the file (excerpt `floor(j n / k)` for `j < k` of `n`), so a
//!    session's drift is sampled from its start to its end. Past a hundred strikes the
//!    averaged spectrum and the step statistics no longer change in any way a fit can
//!    use; the memory would.
//! 4. **Read them.** A second decoding pass copies the excerpts out, and checks that the
//!    file is the one the first pass read (its length, modification time and frame
//!    count); a file changed between the passes is refused rather than mixed.
//!
//! Each excerpt is then a [`Recording`] of its own with [`Recording::excerpt`] saying
//! where it came from; the quality checks, the leave-one-out check and the model's
//! sources take a file's excerpts together ([`by_file`]). A recording of at most
//! [`LONG_FRAMES`] frames is read whole, exactly as [`read`](super::read) reads it.
//! So is a CSV file (a logger's rate keeps it small) and anything that is not a regular
//! file (a pipe cannot be read twice; its size is capped as any recording's).

use super::decode::{Sink, decode_source, riff_fault_at, riff_starts};
use super::{
    MAX_SAMPLE, Recording, RecordingError, SILENCE_TOLERANCE, check, file_name, hex, is_csv,
};
use crate::document::FileError;
use crate::limits::{MAX_RECORDING_BYTES, reads};
use crate::recording::strikes::{OnsetConfig, crossings};
use crate::units::{SampleRate, Seconds};
use sha2::{Digest, Sha256};
use std::cell::RefCell;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::ops::Range;
use std::path::Path;

/// Recordings longer than this many frames are read as excerpts: 2^21, 44 s at 48 kHz
/// (a fit of that many samples peaks at about 200 MB).
pub const LONG_FRAMES: usize = 1 << 21;

/// The most excerpts kept of one recording.
pub const MAX_EXCERPTS: usize = 256;

/// The most samples kept of one recording in all its excerpts: 12 Mi, 96 MiB as `f64`
/// (208 excerpts of 1.2 s at 48 kHz, 104 at 96 kHz).
pub const MAX_EXCERPT_SAMPLES: usize = 12 << 20;

/// How far before a strike's detection its excerpt starts, at most.
pub const EXCERPT_BEFORE: Seconds = Seconds(0.3);

/// How far after a strike's detection its excerpt ends, at most.
pub const EXCERPT_AFTER: Seconds = Seconds(0.9);

/// Strikes detected this close after the one before share its excerpt: a granular
/// ground's step can burst twice, and the analysis of the whole file would take the
/// second burst as part of the first strike; cut apart, it would be a strike of its own.
pub const JOIN_WITHIN: Seconds = Seconds(1.0);

/// The longest excerpt that strikes are joined into (a walk does not become one).
pub const LONGEST_EXCERPT: Seconds = Seconds(4.0);

/// The energy blocks of the first pass.
const BLOCK: Seconds = Seconds(0.005);

/// Where an excerpt of a long recording came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Excerpt {
    /// Its first frame's index in the file.
    pub start: usize,
    /// The file's length in frames.
    pub file_frames: usize,
    /// Which of the file's kept excerpts it is (from 0).
    pub index: usize,
    /// How many excerpts of the file were kept.
    pub kept: usize,
    /// How many excerpts the file was cut into, before keeping (strikes close together
    /// share one).
    pub cut: usize,
    /// How many strikes the first pass found in the whole file (0: none stands above
    /// the noise, and the one excerpt is around the loudest moment).
    pub strikes: usize,
}

/// Reads a recording for analysis: whole when it is short, as excerpts around its strikes
/// when it is longer than [`LONG_FRAMES`]; see the [module docs](self).
///
/// # Errors
/// Any [`RecordingError`] [`read`](super::read) gives, and
/// [`RecordingError::Corrupt`] when the file changes between the two passes.
pub fn read_for_analysis(
    path: &Path,
    csv: Option<&super::CsvSpec>,
) -> Result<Vec<Recording>, RecordingError> {
    let file_error = |action: &'static str, source: std::io::Error| {
        RecordingError::File(FileError {
            path: path.to_path_buf(),
            action,
            source,
        })
    };
    let meta = std::fs::metadata(path).map_err(|e| file_error("reading", e))?;
    if is_csv(path) || !meta.is_file() {
        return super::read(path, csv).map(|r| vec![r]);
    }
    let mut file = File::open(path).map_err(|e| file_error("reading", e))?;
    let meta = file.metadata().map_err(|e| file_error("reading", e))?;
    reads::note_read(&meta);
    let too_long = || RecordingError::TooLong {
        file: path.to_path_buf(),
        limit: format!("{} MiB", MAX_RECORDING_BYTES >> 20),
    };
    if meta.len() > MAX_RECORDING_BYTES {
        return Err(too_long());
    }
    let (sha256, starts, len) = scan(&mut file).map_err(|e| file_error("reading", e))?;
    if len > MAX_RECORDING_BYTES {
        return Err(too_long());
    }
    {
        let reader = RefCell::new(&mut file);
        let read_at = |at: usize, n: usize| {
            let mut f = reader.borrow_mut();
            let end = at.checked_add(n)?;
            if end as u64 > len {
                return None;
            }
            f.seek(SeekFrom::Start(at as u64)).ok()?;
            let mut buf = vec![0; n];
            f.read_exact(&mut buf).ok()?;
            Some(buf)
        };
        if let Some(fault) = starts.iter().find_map(|&s| riff_fault_at(&read_at, s)) {
            return Err(RecordingError::Corrupt {
                file: path.to_path_buf(),
                reason: fault,
            });
        }
    }
    let name = file_name(path);

    let mut probe = Probe::default();
    file.seek(SeekFrom::Start(0))
        .map_err(|e| file_error("reading", e))?;
    let source = file.try_clone().map_err(|e| file_error("reading", e))?;
    let rate = decode_source(path, Box::new(source), &mut probe)?;
    if let Some(samples) = probe.whole.take() {
        check(path, rate, &samples)?;
        return Ok(vec![Recording {
            name,
            rate,
            samples,
            sha256,
            excerpt: None,
        }]);
    }
    probe.check(path)?;

    let block = block_len(rate);
    let strikes = strike_blocks(&probe.energy, rate, block);
    // With no strike, the loudest moment: the quality check then has something to
    // measure, and says how far it is from a strike.
    let around = if strikes.is_empty() {
        let loudest = probe
            .energy
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or(0, |(i, _)| i);
        vec![loudest]
    } else {
        strikes.clone()
    };
    let spans = excerpt_spans(&around, &probe.energy, rate, block, probe.frames);
    let kept = keep_evenly(&spans);

    let changed = || RecordingError::Corrupt {
        file: path.to_path_buf(),
        reason: "the file changed while it was read".into(),
    };
    let now = std::fs::metadata(path).map_err(|e| file_error("reading", e))?;
    if now.len() != meta.len() || now.modified().ok() != meta.modified().ok() {
        return Err(changed());
    }
    let mut cut = Cut::new(kept.iter().map(|&i| spans[i].clone()).collect());
    file.seek(SeekFrom::Start(0))
        .map_err(|e| file_error("reading", e))?;
    decode_source(path, Box::new(file), &mut cut)?;
    if cut.frames != probe.frames {
        return Err(changed());
    }
    let count = cut.excerpts.len();
    Ok(cut
        .excerpts
        .into_iter()
        .zip(&kept)
        .enumerate()
        .map(|(index, (samples, &i))| Recording {
            name: name.clone(),
            rate,
            samples,
            sha256: sha256.clone(),
            excerpt: Some(Excerpt {
                start: spans[i].start,
                file_frames: probe.frames,
                index,
                kept: count,
                cut: spans.len(),
                strikes: strikes.len(),
            }),
        })
        .collect())
}

/// The recordings of each file, as index ranges: consecutive excerpts of one file
/// together, every other recording alone.
#[must_use]
pub fn by_file(recordings: &[Recording]) -> Vec<Range<usize>> {
    let mut files: Vec<Range<usize>> = Vec::new();
    for (i, r) in recordings.iter().enumerate() {
        let same = |last: &Range<usize>| {
            let first = &recordings[last.start];
            r.excerpt.is_some_and(|e| e.index > 0)
                && first.excerpt.is_some()
                && first.sha256 == r.sha256
                && first.name == r.name
        };
        match files.last_mut() {
            Some(last) if same(last) => last.end = i + 1,
            _ => files.push(i..i + 1),
        }
    }
    files
}

/// One pass over the file's bytes, capped at one past [`MAX_RECORDING_BYTES`]: its
/// SHA-256, where a RIFF/WAVE header starts, and its length.
fn scan(file: &mut File) -> std::io::Result<(String, Vec<usize>, u64)> {
    let mut hash = Sha256::new();
    let mut starts = Vec::new();
    // The last 11 bytes of the chunk before, so a marker across two chunks is seen.
    let mut carry: Vec<u8> = Vec::with_capacity(11);
    let mut buf = vec![0u8; 1 << 20];
    let mut len = 0u64;
    let mut limited = file.take(MAX_RECORDING_BYTES + 1);
    loop {
        let n = limited.read(&mut buf)?;
        if n == 0 {
            break;
        }
        hash.update(&buf[..n]);
        let base = len as usize - carry.len();
        carry.extend_from_slice(&buf[..n]);
        starts.extend(riff_starts(&carry, base));
        len += n as u64;
        let keep = carry.len().min(11);
        carry.drain(..carry.len() - keep);
    }
    Ok((hex(&hash.finalize()), starts, len))
}

fn block_len(rate: SampleRate) -> usize {
    rate.samples_in(BLOCK).max(1)
}

/// The first pass: every frame while the recording is short, the blocks' energy, and
/// the checks every recording must pass.
#[derive(Default)]
struct Probe {
    /// Every frame, until there are more than [`LONG_FRAMES`].
    whole: Option<Vec<f64>>,
    frames: usize,
    block: usize,
    sum: f64,
    in_block: usize,
    /// Mean square of each block (the last one may be partial).
    energy: Vec<f64>,
    first: Option<f64>,
    varied: bool,
    non_finite: Option<(usize, f64)>,
    out_of_range: Option<(usize, f64)>,
}

impl Sink for Probe {
    fn begin(&mut self, promised_frames: Option<u64>) {
        let promised = promised_frames.map_or(0, |n| n as usize);
        self.whole = Some(Vec::with_capacity(promised.min(LONG_FRAMES + 1)));
    }

    fn push(&mut self, rate: SampleRate, mono: &[f64]) {
        if self.block == 0 {
            self.block = block_len(rate);
        }
        if let Some(w) = &mut self.whole {
            if w.len() + mono.len() > LONG_FRAMES {
                self.whole = None;
            } else {
                w.extend_from_slice(mono);
            }
        }
        for (k, &v) in mono.iter().enumerate() {
            let index = self.frames + k;
            let v = if v.is_finite() {
                if v.abs() > MAX_SAMPLE && self.out_of_range.is_none() {
                    self.out_of_range = Some((index, v));
                }
                v
            } else {
                if self.non_finite.is_none() {
                    self.non_finite = Some((index, v));
                }
                0.0
            };
            match self.first {
                None => self.first = Some(v),
                Some(f) => {
                    self.varied |= (v - f).abs() > SILENCE_TOLERANCE * f.abs().max(1.0);
                }
            }
            let v = v.clamp(-MAX_SAMPLE, MAX_SAMPLE);
            self.sum += v * v;
            self.in_block += 1;
            if self.in_block == self.block {
                self.energy.push(self.sum / self.block as f64);
                self.sum = 0.0;
                self.in_block = 0;
            }
        }
        self.frames += mono.len();
    }
}

impl Probe {
    /// The checks of [`check`] on what the pass saw (a long recording is never empty or
    /// too short).
    fn check(&mut self, file: &Path) -> Result<(), RecordingError> {
        if self.in_block > 0 {
            self.energy.push(self.sum / self.in_block as f64);
            self.in_block = 0;
        }
        let file = || file.to_path_buf();
        if let Some((index, value)) = self.non_finite {
            return Err(RecordingError::NonFinite {
                file: file(),
                index,
                value,
            });
        }
        if let Some((index, value)) = self.out_of_range {
            return Err(RecordingError::OutOfRange {
                file: file(),
                index,
                value,
            });
        }
        if !self.varied {
            return Err(RecordingError::Silent {
                file: file(),
                first: self.first.unwrap_or(0.0),
            });
        }
        Ok(())
    }
}

/// The blocks where strikes are detected: [`find_onsets`](super::strikes::find_onsets)'
/// detection ([`crossings`]) on the blocks' RMS, with its default settings.
fn strike_blocks(energy: &[f64], rate: SampleRate, block: usize) -> Vec<usize> {
    let cfg = OnsetConfig::default();
    let rms: Vec<f64> = energy.iter().map(|e| e.sqrt()).collect();
    let min_gap = rate.samples_in(cfg.min_interval).div_ceil(block);
    crossings(&rms, &cfg, min_gap).map_or_else(Vec::new, |(kept, _)| kept)
}

/// The excerpts, in frames; see the [module docs](self) (step 2).
fn excerpt_spans(
    strikes: &[usize],
    energy: &[f64],
    rate: SampleRate,
    block: usize,
    frames: usize,
) -> Vec<Range<usize>> {
    let blocks = |t: Seconds| rate.samples_in(t).div_ceil(block);
    let (before, after) = (blocks(EXCERPT_BEFORE), blocks(EXCERPT_AFTER));
    let (join, longest) = (blocks(JOIN_WITHIN), blocks(LONGEST_EXCERPT));
    // The ring of the strike before is over this long after its detection, at the
    // earliest; the quiet before a strike starts at least this long before it.
    let (ring, lead) = (blocks(Seconds(0.05)), blocks(Seconds(0.02)));
    // Strikes close together share an excerpt (up to its longest).
    let mut groups: Vec<Range<usize>> = Vec::new();
    for (i, &s) in strikes.iter().enumerate() {
        match groups.last_mut() {
            Some(g) if s - strikes[i - 1] <= join && s + after - strikes[g.start] <= longest => {
                g.end = i + 1;
            }
            _ => groups.push(i..i + 1),
        }
    }
    let energy_at = |k: usize| energy.get(k).copied().unwrap_or(f64::INFINITY);
    let starts: Vec<usize> = groups
        .iter()
        .map(|g| {
            let s = strikes[g.start];
            let earliest = s.saturating_sub(before);
            let Some(prev) = g.start.checked_sub(1).map(|p| strikes[p]) else {
                return earliest;
            };
            // The latest block within 3 dB of the quietest between the strikes: the last
            // excerpt keeps as much of its ring as the quiet allows.
            let lo = earliest.max(prev + ring).min(s);
            let hi = s.saturating_sub(lead).max(lo);
            let quietest = (lo..=hi).map(energy_at).fold(f64::INFINITY, f64::min);
            (lo..=hi)
                .rev()
                .find(|&k| energy_at(k) <= 2.0 * quietest)
                .unwrap_or(lo)
        })
        .collect();
    groups
        .iter()
        .zip(&starts)
        .enumerate()
        .map(|(i, (g, &start))| {
            let mut end = strikes[g.end - 1] + after;
            if let Some(&next) = starts.get(i + 1) {
                end = end.min(next);
            }
            (start * block).min(frames)..(end * block).min(frames)
        })
        .collect()
}

/// Which spans to keep: at most [`MAX_EXCERPTS`] and [`MAX_EXCERPT_SAMPLES`] samples,
/// spread evenly.
fn keep_evenly(spans: &[Range<usize>]) -> Vec<usize> {
    let n = spans.len();
    let mut k = n.min(MAX_EXCERPTS);
    loop {
        let pick: Vec<usize> = (0..k).map(|j| j * n / k).collect();
        let total: usize = pick.iter().map(|&i| spans[i].len()).sum();
        if total <= MAX_EXCERPT_SAMPLES || k <= 1 {
            return pick;
        }
        k = (k * MAX_EXCERPT_SAMPLES / total).clamp(1, k - 1);
    }
}

/// The second pass: copies the frames of `spans` (sorted, disjoint) out.
struct Cut {
    spans: Vec<Range<usize>>,
    excerpts: Vec<Vec<f64>>,
    frames: usize,
}

impl Cut {
    fn new(spans: Vec<Range<usize>>) -> Self {
        let excerpts = spans.iter().map(|s| Vec::with_capacity(s.len())).collect();
        Self {
            spans,
            excerpts,
            frames: 0,
        }
    }
}

impl Sink for Cut {
    fn push(&mut self, _rate: SampleRate, mono: &[f64]) {
        let here = self.frames..self.frames + mono.len();
        for (span, out) in self.spans.iter().zip(&mut self.excerpts) {
            let lo = span.start.max(here.start);
            let hi = span.end.min(here.end);
            if lo < hi {
                out.extend_from_slice(&mono[lo - here.start..hi - here.start]);
            }
        }
        self.frames = here.end;
    }
}
