//! `underfoot session show DIR`: what a recorded session holds (`run --record DIR`), as
//! text and, with `--plot`, as a timeline: force, strikes, the output's envelope and the
//! markers on one time axis.
//!
//! The folder is read by the library (`underfoot::live::record::SessionRecord`), a
//! finished record or one whose process was killed; this command summarises and draws.
//! Steps per trial: a marker with a `trial` opens that trial, and the strikes until the
//! next marker with another trial (or the end) are its steps.

use std::collections::BTreeMap;
use std::path::PathBuf;

use clap::{Args, Subcommand};
use serde_json::Value;
use underfoot::live::record::{RecordedOutput, SessionRecord};

use crate::output::emit;
use crate::plot::{self, Timeline, TimelineMarker};

/// `underfoot session`: recorded sessions.
#[derive(Debug, Subcommand)]
pub enum SessionCommand {
    /// Summarise a recorded session (run --record DIR): its materials, steps per trial,
    /// levels, markers, dropped or late buffers; --plot draws its timeline.
    Show(ShowArgs),
}

/// Arguments of `underfoot session show`.
#[derive(Debug, Args)]
pub struct ShowArgs {
    /// The record's folder.
    #[arg(value_name = "DIR")]
    dir: PathBuf,
    /// Draw the timeline (force, strikes, output envelope, markers) into FILE (.png or
    /// .svg).
    /// Default: no figure.
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    #[command(flatten)]
    plot_scale: crate::plot::PlotScale,
}

/// Runs `underfoot session`.
pub fn run(command: &SessionCommand) -> anyhow::Result<()> {
    match command {
        SessionCommand::Show(args) => show(args),
    }
}

fn show(args: &ShowArgs) -> anyhow::Result<()> {
    // Checked before anything is read: the plot never replaces a file of the record.
    let plot_out = match &args.plot {
        Some(p) => {
            plot::Format::of(p)?;
            let inputs: Vec<PathBuf> = [
                "manifest.json",
                "force.csv",
                "strikes.csv",
                "events.jsonl",
                "status.jsonl",
                "output.wav",
            ]
            .iter()
            .map(|f| args.dir.join(f))
            .collect();
            let inputs: Vec<&std::path::Path> = inputs.iter().map(PathBuf::as_path).collect();
            Some(underfoot::atomic_file::OutputFile::check(p, &inputs)?)
        }
        None => None,
    };
    let record = SessionRecord::read(&args.dir)?;
    let output = record.read_output()?;
    emit(&summary(&record, output.as_ref()))?;
    if let Some(out) = plot_out {
        let timeline = timeline(&record, output.as_ref());
        plot::draw_timeline(out.path(), args.plot_scale.get(), &timeline)?.report(out.path());
        eprintln!("underfoot: wrote {}", out.path().display());
    }
    Ok(())
}

/// A level for a person: dBFS, or "silent" by the library's one rule for silence.
fn dbfs(amplitude: f32) -> String {
    underfoot::safety::level_dbfs(amplitude)
        .map_or_else(|| "silent".to_owned(), |db| format!("{db:.1} dBFS"))
}

/// The text of `session show`.
fn summary(record: &SessionRecord, output: Option<&RecordedOutput>) -> String {
    let m = &record.manifest;
    let mut text = format!(
        "session {}: started {}\n",
        record.dir.display(),
        m["started"]["utc"].as_str().unwrap_or("at an unknown time")
    );
    let last_t = record
        .events
        .iter()
        .chain(&record.status)
        .filter_map(|e| e["t"].as_f64())
        .fold(0.0, f64::max);
    if record.finished() {
        let e = &m["ended"];
        text.push_str(&format!(
            "ended after {:.1} s: {}\n",
            e["elapsed_s"].as_f64().unwrap_or(last_t),
            e["reason"].as_str().unwrap_or("unknown")
        ));
    } else {
        text.push_str(&format!(
            "did NOT finish (the process was stopped without ending it): the record holds \
             {last_t:.1} s{}\n",
            if record.cut_lines > 0 {
                format!(
                    "; {} line(s) cut short at the end were skipped",
                    record.cut_lines
                )
            } else {
                String::new()
            }
        ));
    }
    let materials: Vec<String> = m["channels"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|c| {
            format!(
                "{}: {}",
                c["channel"],
                c["material"].as_str().unwrap_or("none")
            )
        })
        .collect();
    text.push_str(&format!(
        "channels: {}; input {}; output {} at {} Hz; library {}\n",
        materials.join(", "),
        m["input"].as_str().unwrap_or("?"),
        m["output"].as_str().unwrap_or("?"),
        m["rate_hz"],
        m["library"]["source"].as_str().unwrap_or("?")
    ));
    match &record.force {
        Some(track) => text.push_str(&format!(
            "force: {} reading instant(s) over {:.2} s{}\n",
            track.rows.len(),
            track.duration().0,
            track
                .sensor_rate()
                .map_or_else(String::new, |r| format!(", {r:.0} Hz"))
        )),
        None => text.push_str("force: none recorded\n"),
    }
    let mut per_channel: BTreeMap<u32, usize> = BTreeMap::new();
    for s in &record.strikes {
        *per_channel.entry(s.channel).or_default() += 1;
    }
    text.push_str(&format!(
        "strikes: {}{}\n",
        record.strikes.len(),
        if per_channel.len() > 1 {
            format!(
                " ({})",
                per_channel
                    .iter()
                    .map(|(c, n)| format!("channel {c}: {n}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        } else {
            String::new()
        }
    ));
    let markers: Vec<&Value> = record.markers().collect();
    text.push_str(&format!("markers: {}\n", markers.len()));
    for marker in &markers {
        let mut fields = Vec::new();
        for key in ["trial", "participant", "condition"] {
            if !marker[key].is_null() {
                fields.push(format!(
                    "{key} {}",
                    marker[key].to_string().trim_matches('"')
                ));
            }
        }
        text.push_str(&format!(
            "  {:>8.3} s  {}{}\n",
            marker["frame"].as_f64().unwrap_or(0.0) / record.rate(),
            marker["text"].as_str().unwrap_or(""),
            if fields.is_empty() {
                String::new()
            } else {
                format!(" ({})", fields.join(", "))
            }
        ));
    }
    let trials = steps_per_trial(record);
    if !trials.is_empty() {
        text.push_str("steps per trial:");
        for (trial, steps) in &trials {
            text.push_str(&format!(" trial {trial}: {steps};"));
        }
        text.pop();
        text.push('\n');
    }
    if let Some(out) = output {
        let peaks: Vec<String> = out
            .channels
            .iter()
            .enumerate()
            .map(|(c, x)| {
                let peak = x.iter().fold(0.0f32, |p, v| p.max(v.abs()));
                format!("channel {}: {}", c + 1, dbfs(peak))
            })
            .collect();
        text.push_str(&format!(
            "output: {:.2} s, peak {}\n",
            out.channels.first().map_or(0, Vec::len) as f64 / out.rate,
            peaks.join(", ")
        ));
    } else {
        text.push_str("output: no WAV file in the record\n");
    }
    let last = record.status.last();
    let end = &m["ended"];
    let count = |key: &str| {
        end[key]
            .as_u64()
            .or_else(|| last.and_then(|s| s[key].as_u64()))
            .unwrap_or(0)
    };
    let dropped = end["record"]["output_frames_dropped"]
        .as_u64()
        .or_else(|| last.and_then(|s| s["output_frames_dropped"].as_u64()))
        .unwrap_or(0);
    text.push_str(&format!(
        "limited samples {}, late buffers {}, events dropped (queue full) {}, output \
         frames dropped from the record {dropped}, strikes missing from the record {}\n",
        count("limited"),
        last.and_then(|s| s["late_buffers"].as_u64()).unwrap_or(0),
        last.and_then(|s| s["queue_full"].as_u64()).unwrap_or(0),
        end["unlogged_strikes"].as_u64().unwrap_or(0),
    ));
    if end["record"]["full"].as_bool() == Some(true)
        || record.events.iter().any(|e| e["kind"] == "record_full")
    {
        text.push_str(
            "the record reached its bound (--record-max-mb): force, status and output stop there\n",
        );
    }
    text
}

/// Each trial's steps: the strikes from a marker with that trial to the next marker
/// with another trial.
fn steps_per_trial(record: &SessionRecord) -> Vec<(u64, usize)> {
    let opens: Vec<(u64, u64)> = record
        .markers()
        .filter_map(|m| Some((m["frame"].as_u64()?, m["trial"].as_u64()?)))
        .collect();
    let mut trials: Vec<(u64, usize)> = Vec::new();
    for (i, (frame, trial)) in opens.iter().enumerate() {
        if trials.last().is_some_and(|(t, _)| t == trial) {
            continue;
        }
        let until = opens[i + 1..]
            .iter()
            .find(|(_, t)| t != trial)
            .map_or(u64::MAX, |(f, _)| *f);
        let steps = record
            .strikes
            .iter()
            .filter(|s| s.frame >= *frame && s.frame < until)
            .count();
        trials.push((*trial, steps));
    }
    trials
}

/// The timeline's series: force per channel and strikes on the output's time axis, the
/// output's RMS envelope in 20 ms windows, the markers.
fn timeline(record: &SessionRecord, output: Option<&RecordedOutput>) -> Timeline {
    let mut force: Vec<Vec<(f64, f64)>> = Vec::new();
    if let Some(track) = &record.force {
        force = vec![Vec::new(); track.channels.len()];
        for row in &track.rows {
            let t = record.output_time_of_sensor(row.time.0);
            for (c, r) in row.readings.iter().enumerate() {
                force[c].push((t, f64::from(r.total())));
            }
        }
    }
    let strikes = record
        .strikes
        .iter()
        .map(|s| (s.time, s.channel as usize))
        .collect();
    let envelope = output
        .map(|out| {
            let window = (0.02 * out.rate).max(1.0) as usize;
            out.channels
                .iter()
                .map(|x| {
                    x.chunks(window)
                        .enumerate()
                        .map(|(i, w)| {
                            let ms = w.iter().map(|v| f64::from(*v).powi(2)).sum::<f64>()
                                / w.len() as f64;
                            let db = if ms > 0.0 { 10.0 * ms.log10() } else { -120.0 };
                            ((i * window) as f64 / out.rate, db)
                        })
                        .collect()
                })
                .collect()
        })
        .unwrap_or_default();
    let markers = record
        .markers()
        .map(|m| TimelineMarker {
            time: m["frame"].as_f64().unwrap_or(0.0) / record.rate(),
            label: match m["trial"].as_u64() {
                Some(t) => format!("{} (trial {t})", m["text"].as_str().unwrap_or("")),
                None => m["text"].as_str().unwrap_or("").to_owned(),
            },
        })
        .collect();
    Timeline {
        title: format!("session {}", record.dir.display()),
        force,
        strikes,
        envelope,
        markers,
    }
}
