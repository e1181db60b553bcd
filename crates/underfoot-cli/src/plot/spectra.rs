//! Spectra: a material's measured response against its model's, in dB on a
//! log-frequency axis, one panel per material (two columns when there is more than one),
//! drawn from each model's fit record; `fit` and `compare` add each recording's own
//! spectrum (thin, grey, behind the mean that was fitted) and the physical model's.

use std::path::Path;

use anyhow::bail;
use plotters::coord::Shift;
use plotters::prelude::*;
use underfoot::material::FitRecord;

use super::axes::{
    LegendEntry, draw_title_and_legend, magnitude_chart, panel_title_end, place_legend,
};
use super::layout::AxisSpan;
use super::{Canvas, Drawn, FLOOR_DB, Figure, PANEL_SIZE, Scale, draw, ink, write_figure};

/// One panel: a title and the fit record to draw.
pub struct Panel<'a> {
    pub title: String,
    pub fit: &'a FitRecord,
    /// A second model on the same grid (the physical model), drawn in blue.
    pub physical: Option<&'a [f64]>,
    /// Each recording's own spectrum on the same grid, drawn thin and grey behind the
    /// mean (`fit.measured`) that was fitted; empty when there are none to show.
    pub recordings: &'a [Vec<f64>],
}

/// The dB axis of a figure of several panels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum YRange {
    /// One range for every panel, so that materials compare at a glance.
    #[default]
    Shared,
    /// Each panel its own range, the most detail for each.
    Own,
}

/// Draws `panels` into `path` (two columns when there is more than one panel).
pub fn draw_spectra(
    path: &Path,
    scale: Scale,
    panels: &[Panel<'_>],
    y: YRange,
) -> anyhow::Result<Drawn> {
    draw(path, scale, |canvas| render(path, canvas, panels, y))
}

/// Draws without looking for a font: with `show_text` false, every text is transparent,
/// which the bitmap backend skips before it would need a font.
fn render(
    path: &Path,
    canvas: Canvas,
    panels: &[Panel<'_>],
    y: YRange,
) -> anyhow::Result<Vec<String>> {
    if panels.is_empty() {
        bail!("nothing to plot in {}", path.display());
    }
    for p in panels {
        if p.fit.grid_hz.len() < 2 {
            bail!(
                "{}: the fit record has fewer than 2 points; nothing to plot",
                p.title
            );
        }
    }
    let cols = if panels.len() == 1 { 1 } else { 2 };
    let rows = panels.len().div_ceil(cols);
    let size = (PANEL_SIZE.0 * cols as u32, PANEL_SIZE.1 * rows as u32);
    let figure = Spectra {
        panels,
        grid: (rows, cols),
        ranges: ranges(panels, y),
        title_end: panels
            .iter()
            .map(|p| panel_title_end(&p.title, PANEL_SIZE.0))
            .max()
            .unwrap_or(0),
        show_text: canvas.show_text,
    };
    write_figure(path, canvas, size, &figure)
}

/// The panels on a grid of `(rows, columns)`.
struct Spectra<'a> {
    panels: &'a [Panel<'a>],
    grid: (usize, usize),
    /// `(floor, top)` of each panel.
    ranges: Vec<(f64, f64)>,
    /// Where the widest title ends: every panel places its legend by it, so that the
    /// plots of a row start at one height.
    title_end: i32,
    show_text: bool,
}

impl Figure for Spectra<'_> {
    fn axes(&self) -> Vec<AxisSpan> {
        self.panels
            .iter()
            .zip(&self.ranges)
            .flat_map(|(p, &range)| {
                let grid = &p.fit.grid_hz;
                [
                    AxisSpan::log(
                        format!("{}: frequency", p.title),
                        (grid[0], grid[grid.len() - 1]),
                    ),
                    AxisSpan::linear(format!("{}: magnitude", p.title), range),
                ]
            })
            .collect()
    }

    fn draw_on<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        root.fill(&WHITE)?;
        let areas = root.split_evenly(self.grid);
        for ((area, panel), &range) in areas.iter().zip(self.panels).zip(&self.ranges) {
            draw_panel(area, panel, range, self.title_end, self.show_text)?;
        }
        Ok(())
    }
}

fn db(m: f64) -> f64 {
    20.0 * m.log10()
}

/// `(floor, top)` of each panel: its own, or one range holding them all (never deeper
/// than [`FLOOR_DB`] under the loudest).
fn ranges(panels: &[Panel<'_>], y: YRange) -> Vec<(f64, f64)> {
    let own: Vec<(f64, f64)> = panels.iter().map(db_range).collect();
    match y {
        YRange::Own => own,
        YRange::Shared => {
            let top = own.iter().map(|r| r.1).fold(f64::NEG_INFINITY, f64::max);
            let floor = own.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
            vec![(floor.max(top - FLOOR_DB - 6.0), top); panels.len()]
        }
    }
}

/// `(floor, top)` of a panel drawn on its own: 3 dB around its curves, at most
/// [`FLOOR_DB`] deep.
fn db_range(panel: &Panel<'_>) -> (f64, f64) {
    let fit = panel.fit;
    let all_db = fit
        .measured
        .iter()
        .chain(&fit.model)
        .chain(panel.physical.unwrap_or_default())
        .chain(panel.recordings.iter().flatten())
        .map(|&m| db(m))
        .filter(|v| v.is_finite());
    let top = all_db.clone().fold(f64::NEG_INFINITY, f64::max);
    if top.is_finite() {
        let low = all_db.fold(f64::INFINITY, f64::min).max(top - FLOOR_DB);
        (low - 3.0, top + 3.0)
    } else {
        // All magnitudes are zero: an empty frame is the honest picture.
        (-FLOOR_DB, 0.0)
    }
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel<'_>,
    (floor, top): (f64, f64),
    title_end: i32,
    show_text: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let fit = panel.fit;
    let ink = ink(show_text);
    let series = |values: &[f64]| -> Vec<(f64, f64)> {
        fit.grid_hz
            .iter()
            .zip(values)
            .map(|(&f, &m)| (f, db(m).max(floor)))
            .collect()
    };
    let (lo, hi) = (fit.grid_hz[0], fit.grid_hz[fit.grid_hz.len() - 1]);
    let recording_style = BLACK.mix(0.3).stroke_width(1);
    let measured_style = BLACK.stroke_width(2);
    let model_style = RED.stroke_width(2);
    let physical_style = BLUE.stroke_width(2);
    let entry = |label, line| LegendEntry {
        label,
        line,
        patch: None,
    };
    let mut legend = Vec::with_capacity(4);
    if panel.recordings.is_empty() {
        legend.push(entry("measured", measured_style));
    } else {
        legend.push(entry("each recording", recording_style));
        legend.push(entry("mean (fitted)", measured_style));
    }
    if panel.physical.is_some() {
        legend.push(entry("IIR", model_style));
        legend.push(entry("physical", physical_style));
    } else {
        legend.push(entry("model", model_style));
    }
    let (w, _) = area.dim_in_pixel();
    let placement = place_legend(w, title_end, &legend);
    if show_text {
        draw_title_and_legend(area, &panel.title, &legend, &placement, ink)?;
    }
    let area = &area.margin(placement.drop, 0, 0, 0);
    let mut chart = magnitude_chart(
        area,
        (lo, hi),
        (floor, top),
        ink,
        "strike spectrum (dB re full scale)",
    )?;
    for recording in panel.recordings {
        chart.draw_series(LineSeries::new(series(recording), recording_style))?;
    }
    chart.draw_series(LineSeries::new(series(&fit.measured), measured_style))?;
    chart.draw_series(LineSeries::new(series(&fit.model), model_style))?;
    if let Some(physical) = panel.physical {
        chart.draw_series(LineSeries::new(series(physical), physical_style))?;
    }
    Ok(())
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::plot::Format;
    use crate::plot::font::font;

    pub(in crate::plot) fn record() -> FitRecord {
        let grid: Vec<f64> = (0..32)
            .map(|i| 20.0 * 45f64.powf(f64::from(i) / 31.0))
            .collect();
        let measured: Vec<f64> = grid
            .iter()
            .map(|f| 1.0 / (1.0 + (f / 200.0).powi(2)))
            .collect();
        let mut model = measured.clone();
        model[3] = 0.0; // a zero magnitude must not break the dB scale
        FitRecord {
            grid_hz: grid,
            measured,
            model,
            nrmse: 0.01,
            lsd_db: 0.2,
            method: "test".into(),
            poor_fit: false,
            strikes: 4,
            fit_seconds: 1.0,
            longest_decay: underfoot::units::Seconds(0.5),
            worst: None,
        }
    }

    #[test]
    fn a_shared_range_holds_every_panel_and_is_the_same_for_all() {
        let loud = record();
        let mut quiet = record();
        quiet.measured.iter_mut().for_each(|m| *m *= 0.01);
        quiet.model.iter_mut().for_each(|m| *m *= 0.01);
        let panels = [
            Panel {
                title: "loud".into(),
                fit: &loud,
                physical: None,
                recordings: &[],
            },
            Panel {
                title: "quiet".into(),
                fit: &quiet,
                physical: None,
                recordings: &[],
            },
        ];
        let own = ranges(&panels, YRange::Own);
        // 40 dB apart, each 3 dB around its own curves.
        assert!(((own[0].1 - own[1].1) - 40.0).abs() < 1e-9, "{own:?}");
        let shared = ranges(&panels, YRange::Shared);
        assert_eq!(shared[0], shared[1]);
        assert_eq!(shared[0], (own[1].0, own[0].1));
    }

    #[test]
    fn svg_has_text_without_a_font() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("s.svg");
        let fit = record();
        let panels = [
            Panel {
                title: "gravel".into(),
                fit: &fit,
                physical: None,
                recordings: &[],
            },
            Panel {
                title: "snow".into(),
                fit: &fit,
                physical: None,
                recordings: &[],
            },
        ];
        // No font was registered under this family by this path: SVG must not need one.
        render(&path, Canvas::new(Format::Svg, true), &panels, YRange::Own).expect("svg");
        let svg = std::fs::read_to_string(&path).expect("read");
        assert!(
            svg.contains(">\ngravel\n</text>") && svg.contains(">\nsnow\n</text>"),
            "titles"
        );
        assert!(
            svg.contains("frequency (Hz)") && svg.contains("<polyline"),
            "axes and curves"
        );
    }

    #[test]
    fn png_without_text_needs_no_font() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("s.png");
        let fit = record();
        render(
            &path,
            Canvas::new(Format::Png, false),
            &[Panel {
                title: "x".into(),
                fit: &fit,
                physical: None,
                recordings: &[],
            }],
            YRange::Own,
        )
        .expect("png");
        let bytes = std::fs::read(&path).expect("read");
        assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"));
    }

    #[test]
    fn png_with_text_when_a_font_is_found() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("t.png");
        let fit = record();
        let drawn = draw_spectra(
            &path,
            Scale::default(),
            &[Panel {
                title: "x".into(),
                fit: &fit,
                physical: None,
                recordings: &[],
            }],
            YRange::Own,
        )
        .expect("png");
        let expected = if font().expect("font lookup").is_some() {
            crate::plot::Omitted::Nothing
        } else {
            crate::plot::Omitted::Text
        };
        assert_eq!(drawn.omitted, expected);
        assert_eq!(drawn.problems, Vec::<String>::new());
        assert!(std::fs::read(&path).expect("read").starts_with(b"\x89PNG"));
    }

    #[test]
    fn short_fit_record_is_an_error() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut fit = record();
        fit.grid_hz.truncate(1);
        let e = render(
            &dir.path().join("x.svg"),
            Canvas::new(Format::Svg, true),
            &[Panel {
                title: "m".into(),
                fit: &fit,
                physical: None,
                recordings: &[],
            }],
            YRange::Own,
        )
        .expect_err("one point");
        assert!(e.to_string().contains("fewer than 2 points"));
    }
}
