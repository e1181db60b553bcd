//! Magnitude responses in one panel, dB on a log-frequency axis: a device's response,
//! an equalizer's passes against flat, a limb model against its measurement.

use std::path::Path;

use anyhow::bail;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::axes::{
    LegendEntry, draw_title_and_legend, magnitude_chart, panel_title_end, place_legend,
};
use super::layout::AxisSpan;
use super::{Drawn, FLOOR_DB, Figure, PANEL_SIZE, Scale, draw, ink, write_figure};

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
pub fn draw_responses(
    path: &Path,
    scale: Scale,
    title: &str,
    y_desc: &str,
    curves: &[Curve<'_>],
) -> anyhow::Result<Drawn> {
    draw(path, scale, |canvas| {
        if curves.is_empty() || curves.iter().any(|c| c.freqs_hz.len() < 2) {
            bail!("nothing to plot in {}", path.display());
        }
        let figure = Responses {
            title,
            y_desc,
            curves,
            show_text: canvas.show_text,
        };
        write_figure(path, canvas, PANEL_SIZE, &figure)
    })
}

/// Curves in one panel, with a title and a legend.
struct Responses<'a> {
    title: &'a str,
    y_desc: &'a str,
    curves: &'a [Curve<'a>],
    show_text: bool,
}

impl Responses<'_> {
    /// The frequency axis: from the lowest curve's first point to the highest's last.
    fn freq_range(&self) -> (f64, f64) {
        let lo = self
            .curves
            .iter()
            .map(|c| c.freqs_hz[0])
            .fold(f64::INFINITY, f64::min);
        let hi = self
            .curves
            .iter()
            .map(|c| c.freqs_hz[c.freqs_hz.len() - 1])
            .fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    }

    /// The dB axis: the curves, at most [`FLOOR_DB`] deep, with at least ±3 dB around
    /// them so that a flat response looks flat, not magnified.
    fn db_range(&self) -> (f64, f64) {
        let values = self
            .curves
            .iter()
            .flat_map(|c| c.db.iter().copied())
            .filter(|v| v.is_finite());
        let top = values.clone().fold(f64::NEG_INFINITY, f64::max);
        let low = values.fold(f64::INFINITY, f64::min).max(top - FLOOR_DB);
        let mid = 0.5 * (top + low);
        let half = (0.5 * (top - low) + 1.0).max(3.0);
        (mid - half, mid + half)
    }

    fn legend(&self) -> Vec<LegendEntry<'_>> {
        self.curves
            .iter()
            .enumerate()
            .map(|(i, c)| LegendEntry {
                label: &c.label,
                line: curve_style(i),
                patch: None,
            })
            .collect()
    }
}

fn curve_style(i: usize) -> ShapeStyle {
    CURVE_COLOURS[i % CURVE_COLOURS.len()].stroke_width(2)
}

impl Figure for Responses<'_> {
    fn draw_on<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        area.fill(&WHITE)?;
        let ink = ink(self.show_text);
        let (floor, top) = self.db_range();
        let (w, _) = area.dim_in_pixel();
        let legend = self.legend();
        let placement = place_legend(w, panel_title_end(self.title, w), &legend);
        if self.show_text {
            draw_title_and_legend(area, self.title, &legend, &placement, ink)?;
        }
        let area = &area.margin(placement.drop, 0, 0, 0);
        let mut chart = magnitude_chart(area, self.freq_range(), (floor, top), ink, self.y_desc)?;
        for (i, c) in self.curves.iter().enumerate() {
            let points: Vec<(f64, f64)> = c
                .freqs_hz
                .iter()
                .zip(c.db)
                .filter(|(_, v)| v.is_finite())
                .map(|(&f, &v)| (f, v.clamp(floor, top)))
                .collect();
            chart.draw_series(LineSeries::new(points, curve_style(i)))?;
        }
        Ok(())
    }

    fn axes(&self) -> Vec<AxisSpan> {
        vec![
            AxisSpan::log("frequency", self.freq_range()),
            AxisSpan::linear("magnitude", self.db_range()),
        ]
    }
}
