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

/// The height of each further legend row, in pixels.
const LEGEND_ROW: u32 = 18;

/// Draws magnitude responses (dB on a log-frequency axis) in one panel: an equalizer's
/// passes against flat, or a limb model against its measurement.
pub fn draw_responses(
    path: &Path,
    title: &str,
    y_desc: &str,
    curves: &[Curve<'_>],
) -> anyhow::Result<Omitted> {
    draw(path, |format, show_text| {
        if curves.is_empty() || curves.iter().any(|c| c.freqs_hz.len() < 2) {
            bail!("nothing to plot in {}", path.display());
        }
        let figure = Responses {
            title,
            y_desc,
            curves,
            show_text,
        };
        write_figure(path, format, PANEL_SIZE, &figure)
    })
}

/// Curves in one panel, with a title and a legend.
struct Responses<'a> {
    title: &'a str,
    y_desc: &'a str,
    curves: &'a [Curve<'a>],
    show_text: bool,
}

impl Figure for Responses<'_> {
    fn draw_on<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        draw_response_panel(root, self)
    }
}

fn draw_response_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    figure: &Responses<'_>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let Responses {
        title,
        y_desc,
        curves,
        show_text,
    } = *figure;
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
    // The legend goes right of the title when it fits (measured with the font), else on
    // a row of its own below it: never over the title.
    let mut legend_drop = 0u32;
    if show_text {
        let title_style = text(17.0).pos(Pos::new(HPos::Left, VPos::Center));
        let label_style = text(13.0).pos(Pos::new(HPos::Left, VPos::Center));
        area.draw(&Text::new(
            title.to_string(),
            (12, row_y),
            title_style.clone(),
        ))?;
        // Measured with the font when one is loaded (an SVG needs none to be written),
        // else at a generous 0.6 em a character.
        let width = |t: &str, style: &TextStyle<'_>, size: f64| {
            area.estimate_text_size(t, style).map_or_else(
                |_| (0.6 * size * t.chars().count() as f64) as i32,
                |(w, _)| w as i32,
            )
        };
        let title_end = 12 + width(title, &title_style, 17.0);
        let widths: Vec<i32> = curves
            .iter()
            .map(|c| 25 + width(&c.label, &label_style, 13.0) + 20)
            .collect();
        let right = w as i32 - 8;
        let mut x = right - widths.iter().sum::<i32>();
        let mut y = row_y;
        // Below the title, in as many rows as it takes: never past the right edge.
        let below = x < title_end + 24;
        if below {
            legend_drop = 20;
            y = row_y + legend_drop as i32;
            x = 12;
        }
        for (i, (c, width)) in curves.iter().zip(&widths).enumerate() {
            if below && x > 12 && x + width > right {
                legend_drop += LEGEND_ROW;
                y += LEGEND_ROW as i32;
                x = 12;
            }
            area.draw(&PathElement::new(vec![(x, y), (x + 20, y)], style(i)))?;
            area.draw(&Text::new(
                c.label.clone(),
                (x + 25, y),
                label_style.clone(),
            ))?;
            x += width;
        }
    }
    let area = &area.margin(legend_drop, 0, 0, 0);
    let mut chart = magnitude_chart(area, (lo, hi), (floor, top), ink, y_desc)?;
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
