//! Text tables and JSON summaries of material models.
//!
//! # `--report` file format
//!
//! ```json
//! { "materials": [ { "name": "gravel", "order": 8, "nrmse": 0.05, "lsd_db": 0.41,
//!                    "fit_seconds": 3.2, "strikes": 12, "method": "...",
//!                    "physical": { "kind": "aggregate", "modes": 32,
//!                                  "nrmse": 0.6, "lsd_db": 1.3 },
//!                    "sources": [ { "file": "gravel-01.wav", "sha256": "..." } ] } ] }
//! ```
//!
//! One entry per material fitted by the run that wrote it. Every figure is the model's
//! record, computed by `underfoot::fit::metrics` on the fit's 96-point grid: `nrmse` and
//! `lsd_db` of the filter; `physical` (absent when the calibration failed) those of the
//! physical model's calibration render, the same figures `compare` prints in its
//! `phys NRMSE` and `LSD dB` columns.
//! `poor_fit` is true when the fit
//! was above the quality bound and kept with `--accept-poor-fit`. `strike_to_noise_db` gives
//! each recording's strike-to-noise ratio, and `leave_one_out` the generalisation check
//! (see `underfoot::material::quality`): per recording left out, the gain-aligned LSD of
//! the model fitted on the others against it (`lsd_db`) and of the model fitted on all
//! (`in_sample_lsd_db`), and their means; `null` with a single recording.

use serde::Serialize;
use underfoot::analysis::steps::StepSummary;
use underfoot::material::evaluate::StepComparison;
use underfoot::material::quality::LeaveOneOut;
use underfoot::material::{MaterialModel, SourceFile};
use underfoot::units::{Band, SampleRate};

/// The `--report` file of a `fit` run.
#[derive(Debug, Serialize)]
pub struct FitReport<'a> {
    /// The materials fitted.
    pub materials: Vec<FitReportEntry<'a>>,
}

/// One fitted material in a [`FitReport`].
#[derive(Debug, Serialize)]
pub struct FitReportEntry<'a> {
    pub name: &'a str,
    pub order: usize,
    pub nrmse: f64,
    pub lsd_db: f64,
    pub fit_seconds: f64,
    pub strikes: usize,
    pub method: &'a str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub physical: Option<PhysicalReportEntry>,
    pub sources: &'a [SourceFile],
    pub poor_fit: bool,
    pub strike_to_noise_db: Vec<RecordingFigure>,
    pub leave_one_out: Option<LeaveOneOutReport>,
    /// The recordings' steps in time and renders beside them (`--report` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time: Option<TimeScore>,
    /// The playback level re the recordings, dB.
    pub level_db: f64,
}

/// The steps in time: the recordings', and renders of each model beside them.
#[derive(Debug, Serialize)]
pub struct TimeScore {
    pub recorded: Option<StepSummary>,
    pub iir: Option<RenderedSteps>,
    pub physical: Option<RenderedSteps>,
}

impl TimeScore {
    pub fn of(
        model: &MaterialModel,
        iir: Option<&StepComparison>,
        physical: Option<&StepComparison>,
    ) -> Self {
        Self {
            recorded: model.time.clone(),
            iir: iir.map(RenderedSteps::of),
            physical: physical.map(RenderedSteps::of),
        }
    }
}

/// Rendered steps, measured as recorded ones are, and how far from them.
#[derive(Debug, Clone, Serialize)]
pub struct RenderedSteps {
    pub steps: StepSummary,
    /// Gain-aligned LSD between the rendered and the recorded average step spectra, dB.
    pub spectrum_db: f64,
    /// The rendered steps' level over the recorded ones' (playback level taken out), dB.
    pub level_db: f64,
}

impl RenderedSteps {
    pub fn of(c: &StepComparison) -> Self {
        Self {
            steps: c.rendered.clone(),
            spectrum_db: c.spectrum_db,
            level_db: c.level_db,
        }
    }
}

/// One recording's figure in a [`FitReportEntry`].
#[derive(Debug, Serialize)]
pub struct RecordingFigure {
    pub file: String,
    pub db: f64,
}

/// The leave-one-recording-out figures of a [`FitReportEntry`].
#[derive(Debug, Clone, Serialize)]
pub struct LeaveOneOutReport {
    pub held_out: Vec<HeldOutReport>,
    pub mean_lsd_db: f64,
    pub mean_in_sample_lsd_db: f64,
}

/// One recording left out.
#[derive(Debug, Clone, Serialize)]
pub struct HeldOutReport {
    pub file: String,
    pub strikes: usize,
    pub order: usize,
    pub lsd_db: f64,
    pub in_sample_lsd_db: f64,
    pub gain_db: f64,
    /// In time: the left-out recording's steps, and steps of the model fitted on the others
    /// rendered and compared with them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recorded: Option<StepSummary>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rendered: Option<RenderedSteps>,
}

impl LeaveOneOutReport {
    pub fn of(loo: &LeaveOneOut) -> Self {
        Self {
            held_out: loo
                .held_out
                .iter()
                .map(|h| HeldOutReport {
                    file: h.file.clone(),
                    strikes: h.strikes,
                    order: h.order,
                    lsd_db: h.lsd.0,
                    in_sample_lsd_db: h.in_sample_lsd.0,
                    gain_db: h.gain.0,
                    recorded: h.recorded.clone(),
                    rendered: None,
                })
                .collect(),
            mean_lsd_db: loo.mean_lsd().0,
            mean_in_sample_lsd_db: loo.mean_in_sample_lsd().0,
        }
    }
}

/// The leave-one-out table printed by `fit --report`.
pub fn leave_one_out_table(loo: &LeaveOneOut) -> String {
    use Align::{Left, Right};
    let mut rows: Vec<Vec<String>> = loo
        .held_out
        .iter()
        .map(|h| {
            vec![
                h.file.clone(),
                h.strikes.to_string(),
                h.order.to_string(),
                format!("{:.2}", h.lsd.0),
                format!("{:.2}", h.in_sample_lsd.0),
                format!("{:+.1}", h.gain.0),
            ]
        })
        .collect();
    rows.push(vec![
        "mean".to_string(),
        String::new(),
        String::new(),
        format!("{:.2}", loo.mean_lsd().0),
        format!("{:.2}", loo.mean_in_sample_lsd().0),
        String::new(),
    ]);
    table(
        &[
            ("left out", Left),
            ("strikes", Right),
            ("order", Right),
            ("LSD dB", Right),
            ("in-sample dB", Right),
            ("gain dB", Right),
        ],
        &rows,
    )
}

/// The physical model of a [`FitReportEntry`].
#[derive(Debug, Serialize)]
pub struct PhysicalReportEntry {
    pub kind: &'static str,
    pub modes: usize,
    pub nrmse: f64,
    pub lsd_db: f64,
}

impl<'a> FitReportEntry<'a> {
    pub fn of(m: &'a MaterialModel) -> Self {
        Self {
            name: &m.name,
            order: m.order,
            nrmse: m.fit.nrmse,
            lsd_db: m.fit.lsd_db,
            fit_seconds: m.fit.fit_seconds,
            strikes: m.fit.strikes,
            method: &m.fit.method,
            physical: m.physical.as_ref().map(|p| PhysicalReportEntry {
                kind: p.kind.name(),
                modes: p.modes.len(),
                nrmse: p.record.nrmse,
                lsd_db: p.record.lsd_db,
            }),
            sources: &m.sources,
            poor_fit: m.fit.poor_fit,
            strike_to_noise_db: Vec::new(),
            time: None,
            level_db: m.level_db,
            leave_one_out: None,
        }
    }
}

/// One row of `library list --json`.
#[derive(Debug, Serialize)]
pub struct ListEntry<'a> {
    pub name: &'a str,
    pub sample_rate: SampleRate,
    pub band_hz: Band,
    pub order: usize,
    pub nrmse: f64,
    pub lsd_db: f64,
    pub strikes: usize,
    pub poor_fit: bool,
}

impl<'a> ListEntry<'a> {
    pub fn of(m: &'a MaterialModel) -> Self {
        Self {
            name: &m.name,
            sample_rate: m.sample_rate,
            band_hz: m.band_hz,
            order: m.order,
            nrmse: m.fit.nrmse,
            lsd_db: m.fit.lsd_db,
            strikes: m.fit.strikes,
            poor_fit: m.fit.poor_fit,
        }
    }
}

/// How a column is aligned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Align {
    Left,
    Right,
}

/// A plain-text table: a header row, a rule, then the rows, columns two spaces apart.
pub fn table(headers: &[(&str, Align)], rows: &[Vec<String>]) -> String {
    let mut widths: Vec<usize> = headers.iter().map(|(h, _)| h.chars().count()).collect();
    for row in rows {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |cells: &mut dyn Iterator<Item = &str>| {
        let mut s = cells
            .zip(headers.iter().zip(&widths))
            .map(|(c, ((_, align), &w))| match align {
                Align::Left => format!("{c:<w$}"),
                Align::Right => format!("{c:>w$}"),
            })
            .collect::<Vec<_>>()
            .join("  ");
        // Left-aligned last columns would otherwise leave trailing blanks.
        s.truncate(s.trim_end().len());
        s.push('\n');
        s
    };
    let mut out = line(&mut headers.iter().map(|(h, _)| *h));
    let rules: Vec<String> = widths.iter().map(|&w| "-".repeat(w)).collect();
    out.push_str(&line(&mut rules.iter().map(String::as_str)));
    for row in rows {
        out.push_str(&line(&mut row.iter().map(String::as_str)));
    }
    out
}

/// What marks a poor fit kept with `--accept-poor-fit` in the tables.
pub const POOR_MARK: &str = "POOR";

/// The `library list` table: name, rate, band, order, NRMSE, LSD dB, strikes; a poor fit
/// kept on request has its LSD marked, and a note under the table says what that means.
pub fn list_table(models: &[MaterialModel]) -> String {
    use Align::{Left, Right};
    let rows: Vec<Vec<String>> = models
        .iter()
        .map(|m| {
            vec![
                m.name.clone(),
                m.sample_rate.0.to_string(),
                format!("{}-{}", m.band_hz.lo.0, m.band_hz.hi.0),
                m.order.to_string(),
                format!("{:.4}", m.fit.nrmse),
                if m.fit.poor_fit {
                    format!("{:.2} {POOR_MARK}", m.fit.lsd_db)
                } else {
                    format!("{:.2}", m.fit.lsd_db)
                },
                m.fit.strikes.to_string(),
            ]
        })
        .collect();
    let mut out = table(
        &[
            ("name", Left),
            ("rate Hz", Right),
            ("band Hz", Right),
            ("order", Right),
            ("NRMSE", Right),
            ("LSD dB", Right),
            ("strikes", Right),
        ],
        &rows,
    );
    if models.iter().any(|m| m.fit.poor_fit) {
        out.push_str(&format!(
            "{POOR_MARK}: a poor fit, above the quality bound, kept with --accept-poor-fit\n"
        ));
    }
    out
}

/// The fit table of the IIR paper's Table I, one row per material.
pub fn fit_table(models: &[MaterialModel]) -> String {
    use Align::{Left, Right};
    let rows: Vec<Vec<String>> = models
        .iter()
        .map(|m| {
            vec![
                m.name.clone(),
                m.order.to_string(),
                format!("{:.4}", m.fit.nrmse),
                format!("{:.2}", m.fit.lsd_db),
            ]
        })
        .collect();
    table(
        &[
            ("material", Left),
            ("order", Right),
            ("NRMSE", Right),
            ("LSD dB", Right),
        ],
        &rows,
    )
}

/// The warning for a set of recordings one of which does not belong, naming it. Either
/// the model fitted on all fits it well (it pulled the fit its way) while the model fitted
/// on the others is far from it (its left-out distance more than twice its in-sample one,
/// and [`STANDS_OUT_DB`] more), or the model fitted on all is far from it alone (its
/// in-sample distance more than twice the recordings' median, and [`STANDS_OUT_DB`]
/// more). Needs three recordings: with two, each is the other's only evidence and neither
/// can be told to be the odd one.
pub fn generalisation_warning(model: &MaterialModel, loo: &LeaveOneOut) -> Option<String> {
    if loo.held_out.len() < 3 {
        return None;
    }
    let far = |a: f64, b: f64| a > 2.0 * b && a - b >= STANDS_OUT_DB;
    let pulled = loo
        .held_out
        .iter()
        .filter(|h| far(h.lsd.0, h.in_sample_lsd.0))
        .max_by(|a, b| (a.lsd.0 - a.in_sample_lsd.0).total_cmp(&(b.lsd.0 - b.in_sample_lsd.0)));
    if let Some(odd) = pulled {
        return Some(format!(
            "{} stands out from the other recordings of {:?}: the model fitted on all is \
             {:.2} dB from it, the model fitted on the others {:.2} dB (LSD; the fit's own \
             {:.2} dB looks good because the mean spectrum hides it). It may be another \
             material or a bad take: fit without it, or see --report's leave-one-out table",
            odd.file, model.name, odd.in_sample_lsd.0, odd.lsd.0, model.fit.lsd_db
        ));
    }
    let mut in_sample: Vec<f64> = loo.held_out.iter().map(|h| h.in_sample_lsd.0).collect();
    let median = underfoot::numeric::median(&mut in_sample);
    let odd = loo
        .held_out
        .iter()
        .filter(|h| far(h.in_sample_lsd.0, median))
        .max_by(|a, b| a.in_sample_lsd.0.total_cmp(&b.in_sample_lsd.0))?;
    Some(format!(
        "{} stands out from the other recordings of {:?}: the model fitted on all is {:.2} dB \
         from it, against {median:.2} dB for the recordings' median (LSD; the fit's own \
         {:.2} dB looks good because the mean spectrum hides it). It may be another material \
         or a bad take: fit without it, or see --report's leave-one-out table",
        odd.file, model.name, odd.in_sample_lsd.0, model.fit.lsd_db
    ))
}

/// How much further a left-out recording must be from the model fitted on the others
/// than from the model fitted on all (or than the median recording is), besides twice as
/// far, to be named: on the shared recordings a material's own takes differ by up to
/// 1.6 dB (0.5 dB from the median) this way; a glass step among gravel ones by 5.8 dB, a
/// metal step among snow ones by 4.1 dB from the median.
const STANDS_OUT_DB: f64 = 3.0;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_aligns_columns() {
        let t = table(
            &[("name", Align::Left), ("n", Align::Right)],
            &[
                vec!["gravel".into(), "8".into()],
                vec!["ice".into(), "12".into()],
            ],
        );
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(
            lines,
            ["name     n", "------  --", "gravel   8", "ice     12"]
        );
    }
}
