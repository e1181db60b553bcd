//! Steps in time: a material's recorded steps against rendered ones, one panel per
//! material on a grid. Each panel's upper part is the decay envelope (energy per bin from
//! the step's onset, dB re the loudest bin), its lower strip the micro-events' rate in
//! each bin; both are the step summaries' (`underfoot::analysis::steps`), drawn as they
//! are, except that an envelope stops where the steps had no signal left (see
//! [`SILENT_DB`]). Every panel has the same axes, so that materials can be compared at a
//! glance.

use std::path::Path;

use anyhow::bail;
use plotters::coord::Shift;
use plotters::prelude::*;
use underfoot::analysis::steps::{StepConfig, StepSummary};

use super::axes::{
    LegendEntry, LegendPlacement, draw_title_and_legend, panel_title_end, place_legend,
};
use super::font::FAMILY;
use super::layout::AxisSpan;
use super::{Canvas, Drawn, Figure, Scale, TITLE_HEIGHT, draw, ink, write_figure};

/// One panel: a title and the two summaries to draw (either may be absent: a library
/// without recorded steps, a render with none found).
pub struct StepPanel<'a> {
    pub title: String,
    pub recorded: Option<&'a StepSummary>,
    pub rendered: Option<&'a StepSummary>,
}

/// Each panel, pixels: narrower than a spectrum's, so that four fit in a row.
const STEP_PANEL_SIZE: (u32, u32) = (480, 400);
/// The envelope's floor, dB re the loudest bin; a bin below it is drawn on it. A render
/// decays with no noise under it, and its tail would otherwise stretch the shared axis
/// far below anything a recording shows.
const FLOOR_DB: f64 = -50.0;
/// A summary's envelope is at -150 dB where at least half its steps had no signal at all:
/// a step is cut where the recording ends or the next step begins, and zero-padded. The
/// line stops there rather than plunge to the floor, which would read as a step that
/// ended abruptly.
const SILENT_DB: f64 = -140.0;
/// Above 0 dB (the loudest bin), so that the recorded line at 0 is not cut by the frame.
const TOP_DB: f64 = 3.0;
/// The share of a panel's plotting height the envelope gets; the events' strip has the
/// rest.
const ENVELOPE_SHARE: f64 = 0.56;
/// Between the envelope and the events' strip, pixels.
const STRIP_GAP: u32 = 20;
/// The event strip's lowest top, events per second: a material with one micro-event a
/// step would otherwise fill the strip with a bar that is one event.
const MIN_EVENTS_TOP: f64 = 100.0;

fn recorded_line() -> ShapeStyle {
    BLACK.stroke_width(3)
}

fn rendered_line() -> ShapeStyle {
    RED.stroke_width(1)
}

fn recorded_bars() -> ShapeStyle {
    BLACK.mix(0.3).filled()
}

fn rendered_bars() -> ShapeStyle {
    RED.stroke_width(1)
}

fn legend() -> [LegendEntry<'static>; 2] {
    [
        LegendEntry {
            label: "recorded",
            line: recorded_line(),
            patch: Some(recorded_bars()),
        },
        LegendEntry {
            label: "rendered",
            line: rendered_line(),
            patch: Some(rendered_bars()),
        },
    ]
}

/// Draws `panels` into `path` on a grid of up to four columns.
pub fn draw_steps(path: &Path, scale: Scale, panels: &[StepPanel<'_>]) -> anyhow::Result<Drawn> {
    draw(path, scale, |canvas| render(path, canvas, panels))
}

/// Draws without looking for a font: with `show_text` false, every text is transparent,
/// which the bitmap backend skips before it would need a font.
fn render(path: &Path, canvas: Canvas, panels: &[StepPanel<'_>]) -> anyhow::Result<Vec<String>> {
    if panels.is_empty() {
        bail!("nothing to plot in {}", path.display());
    }
    let cols = match panels.len() {
        1 => 1,
        2..=4 => 2,
        5..=9 => 3,
        _ => 4,
    };
    let rows = panels.len().div_ceil(cols);
    let size = (
        STEP_PANEL_SIZE.0 * cols as u32,
        STEP_PANEL_SIZE.1 * rows as u32,
    );
    let cfg = StepConfig::default();
    let widest = panels
        .iter()
        .map(|p| panel_title_end(&p.title, STEP_PANEL_SIZE.0))
        .max()
        .unwrap_or(0);
    let figure = Steps {
        panels,
        grid: (rows, cols),
        show_text: canvas.show_text,
        bin_ms: cfg.decay_bin.0 * 1e3,
        span_ms: cfg.after.0 * 1e3,
        events_top: events_top(panels),
        legend: place_legend(STEP_PANEL_SIZE.0, widest, &legend()),
    };
    write_figure(path, canvas, size, &figure)
}

/// The events strips' shared top: the highest rate of any panel, rounded up to one
/// significant digit.
fn events_top(panels: &[StepPanel<'_>]) -> f64 {
    let highest = panels
        .iter()
        .flat_map(|p| [p.recorded, p.rendered])
        .flatten()
        .flat_map(|s| s.event_rate_hz_by_bin.iter().copied())
        .filter(|v| v.is_finite())
        .fold(MIN_EVENTS_TOP, f64::max);
    let unit = 10f64.powf(highest.log10().floor());
    (highest / unit - 1e-9).ceil() * unit
}

/// The panels on a grid of `(rows, columns)`, with what they share: the bins, the time
/// span, the events' scale and where the legend goes.
struct Steps<'a> {
    panels: &'a [StepPanel<'a>],
    grid: (usize, usize),
    show_text: bool,
    bin_ms: f64,
    span_ms: f64,
    events_top: f64,
    legend: LegendPlacement,
}

impl Figure for Steps<'_> {
    fn axes(&self) -> Vec<AxisSpan> {
        vec![
            AxisSpan::linear("time", (0.0, self.span_ms)),
            AxisSpan::linear("envelope", (FLOOR_DB, TOP_DB)),
            AxisSpan::linear("events", (0.0, self.events_top)),
        ]
    }

    fn draw_on<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        for (area, panel) in root.split_evenly(self.grid).iter().zip(self.panels) {
            self.draw_panel(area, panel)?;
        }
        Ok(())
    }
}

impl Steps<'_> {
    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        panel: &StepPanel<'_>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let ink = ink(self.show_text);
        let text = |size: f64| (FAMILY, size).into_font().color(&ink);
        if self.show_text {
            draw_title_and_legend(area, &panel.title, &legend(), &self.legend, ink)?;
        }
        let body = area.margin(TITLE_HEIGHT + self.legend.drop, 8, 8, 18);
        let (_, h) = body.dim_in_pixel();
        let (upper, lower) = body.split_vertically((f64::from(h) * ENVELOPE_SHARE) as u32);
        let span = 0.0..self.span_ms;
        // Same label areas above and below, so that the two share their time axis; the
        // envelope's time labels are the strip's, below it.
        let x_lines = (self.span_ms / 100.0).round() as usize + 1;

        let mut envelope = ChartBuilder::on(&upper)
            .x_label_area_size(0)
            .y_label_area_size(58)
            .build_cartesian_2d(span.clone(), FLOOR_DB..TOP_DB)?;
        envelope
            .configure_mesh()
            .y_desc("dB re loudest bin")
            .label_style(text(13.0))
            .axis_desc_style(text(14.0))
            .x_labels(x_lines)
            .y_labels(6)
            .y_label_formatter(&|v| format!("{v:.0}"))
            .light_line_style(TRANSPARENT)
            .bold_line_style(BLACK.mix(0.12))
            .draw()?;
        for (summary, style) in [
            (panel.recorded, recorded_line()),
            (panel.rendered, rendered_line()),
        ] {
            for run in summary.map_or_else(Vec::new, |s| self.envelope(&s.decay_db)) {
                envelope.draw_series(LineSeries::new(run, style))?;
            }
        }

        // Apart enough that the strip's top label and the envelope's floor label do not
        // touch.
        let mut events = ChartBuilder::on(&lower.margin(STRIP_GAP, 0, 0, 0))
            .x_label_area_size(40)
            .y_label_area_size(58)
            .build_cartesian_2d(span, 0.0..self.events_top)?;
        events
            .configure_mesh()
            .x_desc("time from the step's onset (ms)")
            .y_desc("events/s")
            .label_style(text(13.0))
            .axis_desc_style(text(14.0))
            .x_labels(x_lines)
            .y_labels(4)
            .x_label_formatter(&|t| format!("{t:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .light_line_style(TRANSPARENT)
            .bold_line_style(BLACK.mix(0.12))
            .draw()?;
        if let Some(s) = panel.recorded {
            events.draw_series(
                self.bins(&s.event_rate_hz_by_bin)
                    .map(|(t0, t1, r)| Rectangle::new([(t0, 0.0), (t1, r)], recorded_bars())),
            )?;
        }
        if let Some(s) = panel.rendered {
            events.draw_series(std::iter::once(PathElement::new(
                self.steps(&s.event_rate_hz_by_bin),
                rendered_bars(),
            )))?;
        }
        Ok(())
    }

    /// The envelope's points at its bins' centres, inside the time span, at the floor
    /// where they are below it, in runs between silent bins.
    fn envelope(&self, decay_db: &[f64]) -> Vec<Vec<(f64, f64)>> {
        let mut runs = vec![Vec::new()];
        for (k, &v) in decay_db.iter().enumerate() {
            let t = (k as f64 + 0.5) * self.bin_ms;
            if t > self.span_ms {
                break;
            }
            if v > SILENT_DB {
                runs.last_mut()
                    .into_iter()
                    .for_each(|r| r.push((t, v.clamp(FLOOR_DB, 0.0))));
            } else if runs.last().is_some_and(|r| !r.is_empty()) {
                runs.push(Vec::new());
            }
        }
        runs.retain(|r| !r.is_empty());
        runs
    }

    /// Each bin with events: its start, its end (inside the span) and its rate, at the
    /// strip's top where it is above it.
    fn bins<'b>(&self, rates: &'b [f64]) -> impl Iterator<Item = (f64, f64, f64)> + 'b {
        let (bin, span, top) = (self.bin_ms, self.span_ms, self.events_top);
        rates
            .iter()
            .enumerate()
            .map(move |(k, &r)| (k as f64 * bin, ((k + 1) as f64 * bin).min(span), r))
            .filter(move |&(t0, _, r)| t0 < span && r.is_finite() && r > 0.0)
            .map(move |(t0, t1, r)| (t0, t1, r.min(top)))
    }

    /// The rates as a step outline from the span's start to the end of the last bin:
    /// an outline, not bars, so that the recorded bars show through.
    fn steps(&self, rates: &[f64]) -> Vec<(f64, f64)> {
        let mut points = vec![(0.0, 0.0)];
        let mut end = 0.0;
        for (k, &r) in rates.iter().enumerate() {
            let (t0, t1) = (k as f64 * self.bin_ms, (k + 1) as f64 * self.bin_ms);
            if t0 >= self.span_ms {
                break;
            }
            let t1 = t1.min(self.span_ms);
            let r = if r.is_finite() {
                r.clamp(0.0, self.events_top)
            } else {
                0.0
            };
            points.extend([(t0, r), (t1, r)]);
            end = t1;
        }
        points.push((end, 0.0));
        points
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::plot::Format;
    use crate::plot::font::font;

    pub(in crate::plot) fn summary(decay_len: usize, rate: f64) -> StepSummary {
        StepSummary {
            steps: 4,
            duration_ms: 200.0,
            events: 20.0,
            event_rate_hz: 100.0,
            interval_ms: 10.0,
            event_level_db: [-12.0, -8.0, -4.0],
            crest_db: 20.0,
            spread_db: Some(2.0),
            // A deep value, which must land on the floor, not stretch the axis.
            decay_db: (0..decay_len)
                .map(|k| if k == 30 { -90.0 } else { -0.8 * k as f64 })
                .collect(),
            event_rate_hz_by_bin: (0..decay_len)
                .map(|k| if k < 25 { rate } else { 0.0 })
                .collect(),
            bands_hz: vec![100.0, 200.0],
            spectrum_db: vec![-60.0, -70.0],
        }
    }

    #[test]
    fn svg_has_a_panel_per_material_and_both_series() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("s.svg");
        let (recorded, rendered) = (summary(60, 200.0), summary(60, 150.0));
        let panels = [
            StepPanel {
                title: "gravel".into(),
                recorded: Some(&recorded),
                rendered: Some(&rendered),
            },
            StepPanel {
                title: "snow".into(),
                recorded: Some(&recorded),
                rendered: None,
            },
        ];
        render(&path, Canvas::new(Format::Svg, true), &panels).expect("svg");
        let svg = std::fs::read_to_string(&path).expect("read");
        assert!(
            svg.contains(">\ngravel\n</text>") && svg.contains(">\nsnow\n</text>"),
            "titles"
        );
        assert!(svg.contains("onset (ms)"), "time axis");
        // Envelopes (60 points) and the rendered events' outline (122 points).
        let curves = svg
            .lines()
            .filter(|l| l.starts_with("<polyline") && l.matches(',').count() >= 60)
            .count();
        assert_eq!(
            curves, 4,
            "two envelopes, one outline in gravel; one envelope in snow"
        );
    }

    #[test]
    fn envelopes_stop_where_the_steps_were_silent_and_sit_on_the_floor_below_it() {
        let steps = Steps {
            panels: &[],
            grid: (1, 1),
            show_text: true,
            bin_ms: 10.0,
            span_ms: 600.0,
            events_top: 100.0,
            legend: place_legend(480, 0, &[]),
        };
        let decay = [-150.0, 0.0, -70.0, -150.0, -150.0, -20.0, -150.0];
        assert_eq!(
            steps.envelope(&decay),
            [vec![(15.0, 0.0), (25.0, FLOOR_DB)], vec![(55.0, -20.0)]]
        );
        // Past the span: not drawn.
        assert_eq!(steps.envelope(&vec![-1.0; 100]).concat().len(), 60);
    }

    #[test]
    fn the_events_scale_rounds_the_highest_rate_up() {
        let (a, b) = (summary(60, 230.0), summary(60, 40.0));
        let panel = |s| StepPanel {
            title: String::new(),
            recorded: Some(s),
            rendered: None,
        };
        assert_eq!(events_top(&[panel(&a), panel(&b)]), 300.0);
        assert_eq!(events_top(&[panel(&b)]), MIN_EVENTS_TOP);
        let c = summary(60, 1000.0);
        assert_eq!(events_top(&[panel(&c)]), 1000.0);
    }

    #[test]
    fn png_without_text_needs_no_font_and_empty_panels_draw() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("s.png");
        render(
            &path,
            Canvas::new(Format::Png, false),
            &[StepPanel {
                title: "x".into(),
                recorded: None,
                rendered: None,
            }],
        )
        .expect("png");
        let bytes = std::fs::read(&path).expect("read");
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
    }

    #[test]
    fn png_with_text_when_a_font_is_found() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("t.png");
        let s = summary(60, 100.0);
        let drawn = draw_steps(
            &path,
            Scale::default(),
            &[StepPanel {
                title: "x".into(),
                recorded: Some(&s),
                rendered: Some(&s),
            }],
        )
        .expect("png");
        let expected = if font().expect("font lookup").is_some() {
            crate::plot::Omitted::Nothing
        } else {
            crate::plot::Omitted::Text
        };
        assert_eq!(drawn.omitted, expected);
        assert_eq!(drawn.problems, Vec::<String>::new());
    }

    #[test]
    fn no_panels_is_an_error() {
        let dir = tempfile::tempdir().expect("tempdir");
        let e = render(
            &dir.path().join("x.svg"),
            Canvas::new(Format::Svg, true),
            &[],
        )
        .expect_err("empty");
        assert!(e.to_string().contains("nothing to plot"));
    }
}
