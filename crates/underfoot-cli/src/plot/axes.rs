//! Axes: the frame of a magnitude plot (dB against log-frequency) that spectra and
//! responses share, and the labels of log-frequency and time axes.

use plotters::coord::Shift;
use plotters::coord::combinators::WithKeyPoints;
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

pub(super) type MagnitudeChart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<WithKeyPoints<LogCoord<f64>>, plotters::coord::types::RangedCoordf64>,
>;

/// The grid of a log-frequency axis from `lo` to `hi`: labelled lines at 1, 2 and 5 times
/// each power of ten, light lines at every other integer multiple (3, 4, 6...9). Given
/// to plotters explicitly: its own log-axis points repeat a decade's first point (the
/// "100" was drawn twice, on top of itself) and pack light lines into grey bands near
/// each decade's top.
pub(super) fn log_grid(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    let (mut bold, mut light) = (Vec::new(), Vec::new());
    let first = lo.log10().floor() as i32;
    let last = hi.log10().ceil() as i32;
    for decade in first..=last {
        let base = 10f64.powi(decade);
        for m in 1..=9 {
            let f = base * f64::from(m);
            if f < lo * (1.0 - 1e-9) || f > hi * (1.0 + 1e-9) {
                continue;
            }
            if matches!(m, 1 | 2 | 5) {
                bold.push(f);
            } else {
                light.push(f);
            }
        }
    }
    (bold, light)
}

/// The frame of a magnitude plot: dB against log-frequency from `lo` to `hi`, with its
/// mesh and labels drawn; `y_desc` names the dB axis and what it is relative to.
pub(super) fn magnitude_chart<'a, DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (lo, hi): (f64, f64),
    (floor, top): (f64, f64),
    ink: RGBAColor,
    y_desc: &str,
) -> Result<MagnitudeChart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let text = |size: f64| (FAMILY, size).into_font().color(&ink);
    // plotters puts log-axis key points at powers of ten and their multiples only from the
    // first power of ten inside the range; starting the axis at the decade below the band
    // keeps the band's lowest frequencies labelled (20 and 50 Hz for the default band).
    let axis_lo = 10f64.powf(lo.log10().floor());
    let mut chart = ChartBuilder::on(&area.margin(TITLE_HEIGHT, 8, 8, 18))
        .x_label_area_size(44)
        .y_label_area_size(58)
        .build_cartesian_2d(
            {
                let (bold, light) = log_grid(axis_lo, hi);
                (axis_lo..hi)
                    .log_scale()
                    .with_key_points(bold)
                    .with_light_points(light)
            },
            floor..top,
        )?;
    chart
        .configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc(y_desc)
        .label_style(text(13.0))
        .axis_desc_style(text(14.0))
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
    fn the_log_grid_has_each_line_once() {
        let (bold, light) = log_grid(10.0, 1000.0);
        assert_eq!(bold, [10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0]);
        assert_eq!(light.len(), 12);
        assert!(light.iter().all(|f| !bold.contains(f)));
        let mut all: Vec<f64> = bold.iter().chain(&light).copied().collect();
        all.sort_by(f64::total_cmp);
        all.dedup();
        assert_eq!(all.len(), 19);
    }

    #[test]
    fn log_axis_labels_only_one_two_five() {
        let labels: Vec<String> = [20.0, 30.0, 50.0, 100.0, 400.0, 500.0]
            .map(one_two_five)
            .to_vec();
        assert_eq!(labels, ["20", "", "50", "100", "", "500"]);
    }
}
