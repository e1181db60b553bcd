//! `run`'s live status: a block of lines redrawn in place on a terminal (about 4 times a
//! second), and a line of JSON a second for scripts (`--status-json FILE|-`).
//!
//! Both read the session's [`Status`], which the session fills from the engine's atomics:
//! watching never makes the audio thread wait.

use std::io::Write;
use std::time::Duration;

use serde_json::json;
use underfoot::live::Status;
use underfoot::live::adapt::AdaptStatus;

/// How often the session reports: the terminal's refresh.
pub const EVERY: Duration = Duration::from_millis(250);

/// Terminal reports per JSON line: one line a second.
const JSON_EVERY: u32 = 4;

/// Statuses taken more often than the terminal's refresh, passed on at its pace: the
/// peaks in between are held (each status's peak is only since the one before it).
pub struct Paced {
    every: Duration,
    last: Option<std::time::Instant>,
    held: Vec<f32>,
    merged: Status,
}

impl Paced {
    /// Passes on one status per `every`.
    #[must_use]
    pub fn new(every: Duration) -> Self {
        Self {
            every,
            last: None,
            held: Vec::new(),
            merged: Status::default(),
        }
    }

    /// `s`, with the peaks held since the last one passed on, when `every` has passed.
    pub fn take(&mut self, s: &Status) -> Option<&Status> {
        self.held.resize(s.channels.len(), 0.0);
        for (h, ch) in self.held.iter_mut().zip(&s.channels) {
            *h = h.max(ch.peak);
        }
        let now = std::time::Instant::now();
        if self
            .last
            .is_some_and(|t| now.duration_since(t) < self.every)
        {
            return None;
        }
        self.last = Some(now);
        self.merged.clone_from(s);
        for (ch, h) in self.merged.channels.iter_mut().zip(&mut self.held) {
            ch.peak = std::mem::take(h);
        }
        Some(&self.merged)
    }
}

/// A level in dBFS for display, `None` (`null` in JSON, `-inf` for a person) for silence
/// (the library's rule, [`underfoot::safety::SILENT_LEVEL`]).
fn dbfs(peak: f32) -> Option<f64> {
    underfoot::safety::level_dbfs(peak)
}

/// A peak for a person, in dBFS to one decimal, `-inf` for silence: the one way the status
/// block and the `run` and `render` summaries show a level.
#[must_use]
pub fn peak_text(peak: f32) -> String {
    dbfs(peak).map_or_else(|| "-inf".to_owned(), |d| format!("{d:.1}"))
}

/// The status block's lines.
#[must_use]
pub fn block(s: &Status) -> Vec<String> {
    let t = &s.telemetry;
    // Every line under 80 columns: a wrapped line would throw the redraw off.
    let mut lines = vec![
        format!(
            "running {:.1} s | input: {} event(s), {} rejected, {} lost",
            s.elapsed.as_secs_f64(),
            s.input.events,
            s.input.rejected,
            s.queue_full,
        ),
        format!(
            "late events {} | non-finite {} | watchdog fades {} | reconnects {}",
            t.late, t.non_finite, t.watchdog_trips, s.input.reconnects
        ),
        "channel   force (N)   strikes   peak (dBFS)   limited samples".to_owned(),
    ];
    for (c, ch) in s.channels.iter().enumerate() {
        lines.push(format!(
            "{:>7}   {:>9.1}   {:>7}   {:>11}   {:>15}",
            c + 1,
            ch.force,
            ch.strikes,
            peak_text(ch.peak),
            ch.limited
        ));
    }
    lines.extend(s.adapt.as_ref().map(adapt_line));
    if let Some(why) = &s.last_reject {
        // Cut to the block's width: a wrapped line would throw the redraw off.
        let line = format!("last rejected: {why}");
        lines.push(line.chars().take(79).collect());
    }
    lines
}

/// The limiter's warning, the same for `render`, `run` and `panel`: how many samples it
/// reduced, how far over the ceiling the loudest moment went, and the `--gain-db` that
/// would have fitted it (the limiter's smallest gain taken off the gain used). `None`
/// when it never acted.
#[must_use]
pub fn limiter_warning(
    t: &underfoot::engine::TelemetrySnapshot,
    gain_db: f64,
    ceiling_db: f64,
) -> Option<String> {
    if t.limited == 0 {
        return None;
    }
    let over_db = -20.0 * f64::from(t.limiter_min_gain.clamp(1e-6, 1.0)).log10();
    // Rounded down to a tenth of a dB: the gain said must fit, not nearly fit.
    let fits = ((gain_db - over_db) * 10.0).floor() / 10.0;
    Some(format!(
        "the limiter reduced {} sample(s): the loudest moment went {over_db:.1} dB over the \
         ceiling ({ceiling_db:.1} dBFS), and was flattened there; --gain-db {fits:.1} (or \
         lower) keeps every step under it, with its recorded shape",
        t.limited
    ))
}

/// The adaptation's progress in one line (under 80 columns).
#[must_use]
pub fn adapt_line(a: &AdaptStatus) -> String {
    let delay = a
        .delay
        .map_or_else(|| "searching".to_owned(), |d| format!("{d} samples"));
    let deviation = a
        .estimated_deviation
        .map_or_else(|| "-".to_owned(), |d| format!("{:.2} dB", d.0));
    format!(
        "adapt: delay {delay}, {} update(s), est. deviation {deviation}, {} bins",
        a.updates, a.trusted_bins
    )
}

/// One JSON status line (no newline): channel peaks are the largest since the previous
/// line, given in `peaks`.
#[must_use]
pub fn json_line(s: &Status, peaks: &[f32]) -> String {
    let t = &s.telemetry;
    let channels: Vec<_> = s
        .channels
        .iter()
        .zip(peaks)
        .enumerate()
        .map(|(c, (ch, &peak))| {
            json!({
                "channel": c + 1,
                "force_n": ch.force,
                "strikes": ch.strikes,
                "peak_dbfs": dbfs(peak),
                "limited": ch.limited,
            })
        })
        .collect();
    json!({
        "elapsed_s": s.elapsed.as_secs_f64(),
        "frames": t.frames,
        "strikes": t.strikes,
        "channels": channels,
        "input": {
            "events": s.input.events,
            "rejected": s.input.rejected,
            "skipped_bytes": s.input.skipped_bytes,
            "disconnects": s.input.disconnects,
            "reconnects": s.input.reconnects,
            "lost_queue_full": s.queue_full,
            "rejected_by_reason": s.rejections.iter().map(|(why, n)| (why.to_string(), json!(n))).collect::<serde_json::Map<_, _>>(),
            "last_reject": s.last_reject,
            "markers_unrecorded": s.markers_unrecorded,
        },
        "late_events": t.late,
        "non_finite": t.non_finite,
        "limited": t.limited,
        "watchdog_fades": t.watchdog_trips,
        "adapt": s.adapt.as_ref().map(|a| json!({
            "delay_samples": a.delay,
            "realignments": a.realignments,
            "frames": a.frames,
            "updates": a.updates,
            "trusted_bins": a.trusted_bins,
            "last_change_db": a.last_change.0,
            "estimated_deviation_db": a.estimated_deviation.map(|d| d.0),
            "dropped": a.dropped,
        })),
    })
    .to_string()
}

/// Where the status goes, and what has been drawn.
pub struct Display {
    /// Redraw the block on stderr (a terminal).
    pub block: bool,
    /// The JSON lines' destination.
    pub json: Option<Box<dyn Write>>,
    /// Lines of the block now on the terminal (to move back over).
    drawn: usize,
    reports: u32,
    peaks: Vec<f32>,
}

impl Display {
    /// A display; `block` only makes sense when stderr is a terminal.
    #[must_use]
    pub fn new(block: bool, json: Option<Box<dyn Write>>) -> Self {
        Self {
            block,
            json,
            drawn: 0,
            reports: 0,
            peaks: Vec::new(),
        }
    }

    /// Whether it shows anything (else the session need not report).
    #[must_use]
    pub fn active(&self) -> bool {
        self.block || self.json.is_some()
    }

    /// Takes one status from the session.
    ///
    /// # Errors
    /// The JSON destination could not be written (a closed pipe, a full disk).
    pub fn show(&mut self, s: &Status) -> std::io::Result<()> {
        self.peaks.resize(s.channels.len(), 0.0);
        for (p, ch) in self.peaks.iter_mut().zip(&s.channels) {
            *p = p.max(ch.peak);
        }
        if self.block {
            let lines = block(s);
            let mut err = std::io::stderr().lock();
            // Back over the previous block, each line cleared: one block, redrawn.
            let up = self.drawn;
            if up > 0 {
                write!(err, "\x1b[{up}A")?;
            }
            for line in &lines {
                writeln!(err, "\x1b[2K{line}")?;
            }
            err.flush()?;
            self.drawn = lines.len();
        }
        self.reports += 1;
        if self.reports.is_multiple_of(JSON_EVERY)
            && let Some(out) = &mut self.json
        {
            writeln!(out, "{}", json_line(s, &self.peaks))?;
            out.flush()?;
            self.peaks.iter_mut().for_each(|p| *p = 0.0);
        }
        Ok(())
    }

    /// Clears the block from the terminal, so that a message printed next is not drawn
    /// over (the next status draws it again below the message).
    pub fn clear(&mut self) {
        let up = std::mem::take(&mut self.drawn);
        if self.block && up > 0 {
            let mut err = std::io::stderr().lock();
            let _ = write!(err, "\x1b[{up}A\x1b[J");
            let _ = err.flush();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use underfoot::engine::ChannelLevels;

    fn status() -> Status {
        Status {
            elapsed: Duration::from_millis(2500),
            channels: vec![
                ChannelLevels {
                    force: 612.5,
                    strikes: 3,
                    peak: 0.25,
                    limited: 0,
                    ..ChannelLevels::default()
                },
                ChannelLevels::default(),
            ],
            ..Status::default()
        }
    }

    #[test]
    fn the_block_has_a_line_per_channel_with_levels_in_dbfs() {
        let lines = block(&status());
        assert_eq!(lines.len(), 5);
        assert!(lines[0].starts_with("running 2.5 s"), "{}", lines[0]);
        assert!(
            lines[3].contains("612.5") && lines[3].contains("-12.0"),
            "{}",
            lines[3]
        );
        assert!(lines[4].contains("-inf"), "{}", lines[4]);
        assert!(lines.iter().all(|l| l.len() < 80), "{lines:#?}");
    }

    #[test]
    fn a_json_line_parses_and_silence_is_null() {
        let line = json_line(&status(), &[0.5, 0.0]);
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert_eq!(v["channels"][0]["strikes"], 3);
        assert!((v["channels"][0]["peak_dbfs"].as_f64().unwrap() + 6.02).abs() < 0.01);
        assert!(v["channels"][1]["peak_dbfs"].is_null());
        assert!((v["elapsed_s"].as_f64().unwrap() - 2.5).abs() < 1e-9);
    }

    #[test]
    fn a_decaying_tail_below_the_converter_step_is_silence() {
        // 3.9e-11 is the -208.1 dBFS a dying filter tail used to show as a level.
        let tail = 3.9e-11_f32;
        let quiet = 1.0 / (1u32 << 20) as f32;
        let line = json_line(&status(), &[tail, quiet]);
        let v: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert!(v["channels"][0]["peak_dbfs"].is_null(), "{line}");
        let quiet_db = v["channels"][1]["peak_dbfs"].as_f64().unwrap();
        assert!((quiet_db + 120.41).abs() < 0.01, "{quiet_db}");
        let mut s = status();
        s.channels[0].peak = tail;
        let lines = block(&s);
        assert!(
            lines[3].contains("-inf") && !lines[3].contains("-208"),
            "{}",
            lines[3]
        );
    }
}
