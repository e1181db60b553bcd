//! Axes: the frame of a magnitude plot (dB against log-frequency) that spectra and
//! responses share, and the labels of log-frequency and time axes.

use plotters::coord::Shift;
use plotters::prelude::*;

use super::TITLE_HEIGHT;
use super::font::FAMILY;

/// Labels a log axis only at 1, 2 and 5 times a power of ten: a label at every grid line
/// runs the upper decade's labels into each other.
pub(super) fn one_two_five(f: f64) -> String {
    let mantissa = f / 10f64.powf(f.log10().floor());
    if [1.0, 2.0, 5.0].iter().any(|m| (mantissa - m).abs() < 1e-6) {
        format!("{f:.0}")
    } else {
        String::new()
    }
}

/// Decimals enough to tell apart the labels of a time axis `span_s` long.
pub(super) fn time_decimals(span_s: f64) -> usize {
    (1.0 - span_s.log10().floor()).clamp(0.0, 4.0) as usize
}

pub(super) type MagnitudeChart<'a, DB> =
    ChartContext<'a, DB, Cartesian2d<LogCoord<f64>, plotters::coord::types::RangedCoordf64>>;

/// The frame of a magnitude plot: dB against log-frequency from `lo` to `hi`, with its
/// mesh and labels drawn.
pub(super) fn magnitude_chart<'a, DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (lo, hi): (f64, f64),
    (floor, top): (f64, f64),
    ink: RGBAColor,
) -> Result<MagnitudeChart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let text = |size: f64| (FAMILY, size).into_font().color(&ink);
    // plotters puts log-axis key points at powers of ten and their multiples only from the
    // first power of ten inside the range; starting the axis at the decade below the band
    // keeps the band's lowest frequencies labelled (20 and 50 Hz for the default band).
    let axis_lo = 10f64.powf(lo.log10().floor());
    let mut chart = ChartBuilder::on(&area.margin(TITLE_HEIGHT, 8, 8, 18))
        .x_label_area_size(44)
        .y_label_area_size(58)
        .build_cartesian_2d((axis_lo..hi).log_scale(), floor..top)?;
    chart
        .configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc("magnitude (dB)")
        .label_style(text(13.0))
        .axis_desc_style(text(14.0))
        .x_labels(30)
        .x_label_formatter(&|f| one_two_five(*f))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .light_line_style(BLACK.mix(0.06))
        .bold_line_style(BLACK.mix(0.15))
        .draw()?;
    Ok(chart)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axis_labels_only_one_two_five() {
        let labels: Vec<String> = [20.0, 30.0, 50.0, 100.0, 400.0, 500.0]
            .map(one_two_five)
            .to_vec();
        assert_eq!(labels, ["20", "", "50", "100", "", "500"]);
    }
}
