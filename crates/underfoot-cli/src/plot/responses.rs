//! Magnitude responses in one panel, dB on a log-frequency axis: a device's response,
//! an equalizer's passes against flat, a limb model against its measurement.

use std::path::Path;

use anyhow::bail;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::axes::magnitude_chart;
use super::font::FAMILY;
use super::{FLOOR_DB, Figure, Omitted, PANEL_SIZE, TITLE_HEIGHT, draw, ink, write_figure};

/// One curve of a response plot: a label, frequencies, dB values, and a colour index.
pub struct Curve<'a> {
    pub label: String,
    pub freqs_hz: &'a [f64],
    pub db: &'a [f64],
}

/// Colours of successive curves: black first (the measurement or the first pass), then a
/// qualitative palette (Okabe-Ito, readable by colour-blind eyes).
const CURVE_COLOURS: [RGBColor; 6] = [
    RGBColor(0, 0, 0),
    RGBColor(0xD5, 0x5E, 0x00),
    RGBColor(0x00, 0x72, 0xB2),
    RGBColor(0x00, 0x9E, 0x73),
    RGBColor(0xCC, 0x79, 0xA7),
    RGBColor(0xE6, 0x9F, 0x00),
];

/// Draws magnitude responses (dB on a log-frequency axis) in one panel: an equalizer's
/// passes against flat, or a limb model against its measurement.
pub fn draw_responses(path: &Path, title: &str, curves: &[Curve<'_>]) -> anyhow::Result<Omitted> {
    draw(path, |format, show_text| {
        if curves.is_empty() || curves.iter().any(|c| c.freqs_hz.len() < 2) {
            bail!("nothing to plot in {}", path.display());
        }
        let figure = Responses {
            title,
            curves,
            show_text,
        };
        write_figure(path, format, PANEL_SIZE, &figure)
    })
}

/// Curves in one panel, with a title and a legend.
struct Responses<'a> {
    title: &'a str,
    curves: &'a [Curve<'a>],
    show_text: bool,
}

impl Figure for Responses<'_> {
    fn draw_on<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        draw_response_panel(root, self.title, self.curves, self.show_text)
    }
}

fn draw_response_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    curves: &[Curve<'_>],
    show_text: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    area.fill(&WHITE)?;
    let ink = ink(show_text);
    let text = |size: f64| (FAMILY, size).into_font().color(&ink);
    let values = curves
        .iter()
        .flat_map(|c| c.db.iter().copied())
        .filter(|v| v.is_finite());
    let top = values.clone().fold(f64::NEG_INFINITY, f64::max);
    let low = values.fold(f64::INFINITY, f64::min).max(top - FLOOR_DB);
    // At least ±3 dB around the curves, so a flat response looks flat, not magnified.
    let mid = 0.5 * (top + low);
    let half = (0.5 * (top - low) + 1.0).max(3.0);
    let (floor, top) = (mid - half, mid + half);
    let lo = curves
        .iter()
        .map(|c| c.freqs_hz[0])
        .fold(f64::INFINITY, f64::min);
    let hi = curves
        .iter()
        .map(|c| c.freqs_hz[c.freqs_hz.len() - 1])
        .fold(f64::NEG_INFINITY, f64::max);
    let (w, _) = area.dim_in_pixel();
    let row_y = (TITLE_HEIGHT / 2) as i32;
    let style = |i: usize| CURVE_COLOURS[i % CURVE_COLOURS.len()].stroke_width(2);
    if show_text {
        area.draw(&Text::new(
            title.to_string(),
            (12, row_y),
            text(17.0).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
        let first = w as i32 - 150 * curves.len() as i32;
        for (i, c) in curves.iter().enumerate() {
            let x = first + 150 * i as i32;
            area.draw(&PathElement::new(
                vec![(x, row_y), (x + 20, row_y)],
                style(i),
            ))?;
            area.draw(&Text::new(
                c.label.clone(),
                (x + 25, row_y),
                text(13.0).pos(Pos::new(HPos::Left, VPos::Center)),
            ))?;
        }
    }
    let mut chart = magnitude_chart(area, (lo, hi), (floor, top), ink)?;
    for (i, c) in curves.iter().enumerate() {
        let points: Vec<(f64, f64)> = c
            .freqs_hz
            .iter()
            .zip(c.db)
            .filter(|(_, v)| v.is_finite())
            .map(|(&f, &v)| (f, v.clamp(floor, top)))
            .collect();
        chart.draw_series(LineSeries::new(points, style(i)))?;
    }
    Ok(())
}
