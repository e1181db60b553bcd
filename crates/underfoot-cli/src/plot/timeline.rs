//! A recorded session's timeline: the force of each channel with its strikes above it,
//! and the output's envelope below, on one time axis (the output's: seconds from its
//! first sample), the markers as dashed lines through both with their labels on top.

use std::path::Path;

use anyhow::bail;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::axes::{
    LabelRows, LegendEntry, draw_title_and_legend, panel_title_end, place_legend, text_width,
};
use super::font::FAMILY;
use super::layout::AxisSpan;
use super::{Drawn, Figure, Scale, TITLE_HEIGHT, draw, ink, write_figure};

/// A marker on the timeline.
pub struct TimelineMarker {
    pub time: f64,
    pub label: String,
}

/// What a timeline shows; every time in seconds on the output's axis.
pub struct Timeline {
    pub title: String,
    /// Each channel's total force, (time, N).
    pub force: Vec<Vec<(f64, f64)>>,
    /// Each strike: (time, channel from 1).
    pub strikes: Vec<(f64, usize)>,
    /// Each channel's output RMS, (time, dBFS).
    pub envelope: Vec<Vec<(f64, f64)>>,
    pub markers: Vec<TimelineMarker>,
}

/// Channels' colours (Okabe-Ito): channel 1 blue, 2 vermilion, then the rest.
const CHANNEL_COLOURS: [RGBColor; 5] = [
    RGBColor(0x00, 0x72, 0xB2),
    RGBColor(0xD5, 0x5E, 0x00),
    RGBColor(0x00, 0x9E, 0x73),
    RGBColor(0xCC, 0x79, 0xA7),
    RGBColor(0xE6, 0x9F, 0x00),
];

fn colour(channel_from_0: usize) -> RGBColor {
    CHANNEL_COLOURS[channel_from_0 % CHANNEL_COLOURS.len()]
}

/// The envelope's floor, dBFS: silence is drawn on it.
const FLOOR_DBFS: f64 = -80.0;
const SIZE: (u32, u32) = (1200, 640);
/// The rows marker labels are staggered over, so that close markers do not overlap.
const LABEL_ROWS: usize = 3;
const LABEL_ROW_PX: u32 = 16;

/// Draws `timeline` into `path` (.png or .svg).
pub fn draw_timeline(path: &Path, scale: Scale, timeline: &Timeline) -> anyhow::Result<Drawn> {
    draw(path, scale, |canvas| {
        if timeline.force.iter().all(Vec::is_empty) && timeline.envelope.iter().all(Vec::is_empty) {
            bail!(
                "nothing to plot in {}: the record holds no force and no output",
                path.display()
            );
        }
        let end = timeline
            .force
            .iter()
            .chain(&timeline.envelope)
            .flatten()
            .map(|(t, _)| *t)
            .chain(timeline.markers.iter().map(|m| m.time))
            .chain(timeline.strikes.iter().map(|s| s.0))
            .fold(0.0, f64::max);
        let start = timeline
            .force
            .iter()
            .chain(&timeline.envelope)
            .flatten()
            .map(|(t, _)| *t)
            .fold(end, f64::min)
            .min(0.0);
        let figure = Drawing {
            timeline,
            span: start..end.max(start + 1.0),
            show_text: canvas.show_text,
        };
        write_figure(path, canvas, SIZE, &figure)
    })
}

struct Drawing<'a> {
    timeline: &'a Timeline,
    span: std::ops::Range<f64>,
    show_text: bool,
}

impl Drawing<'_> {
    /// The force axis's top: 15% above the largest force, at least 1.15 N.
    fn force_top(&self) -> f64 {
        self.timeline
            .force
            .iter()
            .flatten()
            .map(|(_, f)| *f)
            .fold(1.0, f64::max)
            * 1.15
    }
}

impl Figure for Drawing<'_> {
    fn axes(&self) -> Vec<AxisSpan> {
        let span = (self.span.start, self.span.end);
        vec![
            AxisSpan::linear("time", span),
            AxisSpan::linear("force", (0.0, self.force_top())),
            AxisSpan::linear("output level", (FLOOR_DBFS, 0.0)),
        ]
    }

    fn draw_on<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let ink = ink(self.show_text);
        let text = |size: f64| (FAMILY, size).into_font().color(&ink);
        let t = self.timeline;
        // One entry per channel, then the symbols' key; right of the title when they fit,
        // else in rows below it (a 16-channel session).
        let channels = t.force.len().max(t.envelope.len());
        let labels: Vec<String> = (1..=channels).map(|c| format!("channel {c}")).collect();
        let mut legend: Vec<LegendEntry<'_>> = labels
            .iter()
            .enumerate()
            .map(|(c, label)| LegendEntry {
                label,
                line: colour(c).stroke_width(3),
                patch: None,
            })
            .collect();
        legend.push(LegendEntry {
            label: "▲ strike   ┆ marker",
            line: TRANSPARENT.into(),
            patch: None,
        });
        let (w, _) = root.dim_in_pixel();
        let placement = place_legend(w, panel_title_end(&t.title, w), &legend);
        if self.show_text {
            draw_title_and_legend(root, &t.title, &legend, &placement, ink)?;
        }
        let (_, body) = root.split_vertically(TITLE_HEIGHT + placement.drop);
        let label_band = LABEL_ROWS as u32 * LABEL_ROW_PX + 6;
        let (labels, charts) = body.split_vertically(label_band);
        let (_, h) = charts.dim_in_pixel();
        let (upper, lower) = charts.split_vertically(h * 55 / 100);
        // A gap between the two, so that their y labels do not meet.
        let lower = lower.margin(14, 0, 0, 0);

        let force_top = self.force_top();
        let mut force = ChartBuilder::on(&upper)
            .margin_right(16)
            .margin_left(10)
            .x_label_area_size(0)
            .y_label_area_size(84)
            .build_cartesian_2d(self.span.clone(), 0.0..force_top)?;
        force
            .configure_mesh()
            .y_desc("force (N)")
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style(text(13.0))
            .axis_desc_style(text(14.0))
            .light_line_style(TRANSPARENT)
            .draw()?;
        for (c, series) in t.force.iter().enumerate() {
            force.draw_series(LineSeries::new(
                series.iter().copied(),
                colour(c).stroke_width(1),
            ))?;
        }
        // Strikes: a triangle above the force, one row per channel.
        for (time, channel) in &t.strikes {
            let c = channel.saturating_sub(1);
            let y = force_top * (0.97 - 0.04 * c as f64);
            force.draw_series(std::iter::once(TriangleMarker::new(
                (*time, y),
                5,
                colour(c).filled(),
            )))?;
        }
        let mut envelope = ChartBuilder::on(&lower)
            .margin_right(16)
            .margin_left(10)
            .x_label_area_size(44)
            .y_label_area_size(84)
            .build_cartesian_2d(self.span.clone(), FLOOR_DBFS..0.0)?;
        envelope
            .configure_mesh()
            .x_desc("time on the output (s)")
            .y_desc("output RMS, 20 ms (dBFS)")
            .y_label_formatter(&|v| format!("{v:.0}"))
            .x_label_formatter(&|v| format!("{v:.1}"))
            .label_style(text(13.0))
            .axis_desc_style(text(14.0))
            .light_line_style(TRANSPARENT)
            .draw()?;
        for (c, series) in t.envelope.iter().enumerate() {
            envelope.draw_series(LineSeries::new(
                series.iter().map(|(t, db)| (*t, db.max(FLOOR_DBFS))),
                colour(c).stroke_width(1),
            ))?;
        }
        let dashed = BLACK.mix(0.55).stroke_width(1);
        for m in &t.markers {
            force.draw_series(DashedLineSeries::new(
                [(m.time, 0.0), (m.time, force_top)],
                4,
                3,
                dashed,
            ))?;
            envelope.draw_series(DashedLineSeries::new(
                [(m.time, FLOOR_DBFS), (m.time, 0.0)],
                4,
                3,
                dashed,
            ))?;
        }
        if self.show_text {
            // Labels above the force panel, over their line, staggered over a few rows.
            let (x0, _) = force.backend_coord(&(self.span.start, 0.0));
            let (x1, _) = force.backend_coord(&(self.span.end, 0.0));
            let (lx, _) = labels.get_base_pixel();
            // A label with no room is left out: its dashed line still shows, and the
            // record keeps every marker's label.
            let (label_w, _) = labels.dim_in_pixel();
            let mut rows = LabelRows::<LABEL_ROWS>::new(6);
            let mut order: Vec<&TimelineMarker> = t.markers.iter().collect();
            order.sort_by(|a, b| a.time.total_cmp(&b.time));
            for m in order {
                let frac = (m.time - self.span.start) / (self.span.end - self.span.start);
                let at = x0 + ((x1 - x0) as f64 * frac) as i32 - lx + 3;
                let width = text_width(&m.label, 12.0);
                let Some((row, x)) = rows.place(at, width, label_w as i32 - 4) else {
                    continue;
                };
                labels.draw(&Text::new(
                    m.label.clone(),
                    (x, 2 + row as i32 * LABEL_ROW_PX as i32),
                    text(12.0),
                ))?;
            }
        }
        Ok(())
    }
}
