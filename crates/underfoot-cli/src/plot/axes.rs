//! Axes: the frame of a magnitude plot (dB against log-frequency) that spectra and
//! responses share, the labels of log-frequency and time axes, and a panel's title row
//! with its legend.

use plotters::coord::Shift;
use plotters::coord::combinators::WithKeyPoints;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::TITLE_HEIGHT;
use super::font::FAMILY;

/// Decimals enough to tell apart the labels of a time axis `span_s` long.
pub(super) fn time_decimals(span_s: f64) -> usize {
    (1.0 - span_s.log10().floor()).clamp(0.0, 4.0) as usize
}

/// A generous width for `text` at `size` pixels: 0.6 em a character. Text is not
/// measured, so that an SVG (which needs no font) and a PNG of the same figure are laid
/// out alike.
pub(super) fn text_width(text: &str, size: f64) -> i32 {
    (0.6 * size * text.chars().count() as f64).ceil() as i32
}

/// The size of a panel title's text, pixels.
pub(super) const TITLE_FONT_PX: f64 = 17.0;
/// The smallest a title is shrunk to before it is cut short, pixels.
const MIN_TITLE_FONT_PX: f64 = 11.0;

/// A title made to fit its room: at [`TITLE_FONT_PX`] when it fits, else smaller (down
/// to [`MIN_TITLE_FONT_PX`]), else cut short with an ellipsis. A 64-character material
/// name in `compare`'s title would otherwise run off a 720-pixel panel.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct FittedTitle {
    pub text: String,
    pub size: f64,
}

impl FittedTitle {
    pub fn new(title: &str, room_px: i32) -> Self {
        let chars = title.chars().count().max(1) as f64;
        let room = f64::from(room_px.max(0));
        let size = (room / (0.6 * chars)).floor().min(TITLE_FONT_PX);
        if size >= MIN_TITLE_FONT_PX {
            return Self {
                text: title.to_owned(),
                size,
            };
        }
        let keep = ((room / (0.6 * MIN_TITLE_FONT_PX)) as usize).saturating_sub(1);
        let text = title.chars().take(keep).chain(['…']).collect();
        Self {
            text,
            size: MIN_TITLE_FONT_PX,
        }
    }

    /// Where the title ends when drawn from x = 12.
    pub fn end(&self) -> i32 {
        12 + text_width(&self.text, self.size)
    }
}

/// The room a panel `width` pixels wide gives its title.
pub(super) fn title_room(width: u32) -> i32 {
    width as i32 - 24
}

/// Where `title` ends in a panel `width` pixels wide, made to fit as
/// [`draw_title_and_legend`] draws it: what a legend beside it must clear.
pub(super) fn panel_title_end(title: &str, width: u32) -> i32 {
    FittedTitle::new(title, title_room(width)).end()
}

/// Labels along a time axis, in a few rows: each takes the first row where it clears
/// the label before it, moved left to end before `right`; one that finds no row is left
/// out (its mark still shows) rather than drawn over another. A spectrogram's segments
/// and a timeline's markers are labelled this way.
pub(super) struct LabelRows<const ROWS: usize> {
    /// Where each row is free from, pixels.
    free: [i32; ROWS],
    /// Space kept after each label, pixels.
    gap: i32,
}

impl<const ROWS: usize> LabelRows<ROWS> {
    pub fn new(gap: i32) -> Self {
        Self {
            free: [i32::MIN; ROWS],
            gap,
        }
    }

    /// The row and left end of a label `width` pixels wide meant to start at `x`, or
    /// `None` when no row has room for it.
    pub fn place(&mut self, x: i32, width: i32, right: i32) -> Option<(usize, i32)> {
        let x = x.min(right - width);
        let row = self.free.iter().position(|&free| free <= x)?;
        self.free[row] = x + width + self.gap;
        Some((row, x))
    }
}
/// The size of a legend's labels, pixels.
const LEGEND_FONT_PX: f64 = 13.0;
/// The height of each legend row below the title row, pixels.
const LEGEND_ROW: u32 = 18;
/// A legend entry's sample line.
const SAMPLE_LINE: i32 = 22;
/// A legend entry's sample patch (a bar), beside its line.
const SAMPLE_PATCH: i32 = 10;

/// One entry of a legend: a sample line, optionally a patch beside it (what the bars of
/// the same series look like), and a label.
pub(super) struct LegendEntry<'a> {
    pub label: &'a str,
    pub line: ShapeStyle,
    pub patch: Option<ShapeStyle>,
}

impl LegendEntry<'_> {
    fn width(&self) -> i32 {
        let patch = if self.patch.is_some() {
            SAMPLE_PATCH + 6
        } else {
            0
        };
        SAMPLE_LINE + patch + 5 + text_width(self.label, LEGEND_FONT_PX) + 18
    }
}

/// Where a legend goes in a panel `width` pixels wide: right of the title, which ends
/// at `title_end`, when it fits; else on rows of its own below the title row, never past
/// the right edge. Never over the title either way.
pub(super) struct LegendPlacement {
    /// Each entry's left end and vertical centre.
    origins: Vec<(i32, i32)>,
    /// How far the legend pushes the plot down below the title row, pixels.
    pub drop: u32,
}

/// Places `entries` in a panel `width` pixels wide whose title ends at `title_end` (see
/// [`LegendPlacement`]). A figure of several panels places its legends with its widest
/// title, so that every panel's plot starts at the same height.
pub(super) fn place_legend(
    width: u32,
    title_end: i32,
    entries: &[LegendEntry<'_>],
) -> LegendPlacement {
    let row_y = (super::TITLE_HEIGHT / 2) as i32;
    let widths: Vec<i32> = entries.iter().map(LegendEntry::width).collect();
    let right = width as i32 - 8;
    let beside = right - widths.iter().sum::<i32>();
    if beside >= title_end + 24 {
        let origins = widths
            .iter()
            .scan(beside, |x, w| {
                let at = *x;
                *x += w;
                Some((at, row_y))
            })
            .collect();
        return LegendPlacement { origins, drop: 0 };
    }
    let mut drop = 20;
    let (mut x, mut y) = (12, row_y + drop as i32);
    let mut origins = Vec::with_capacity(entries.len());
    for w in &widths {
        if x > 12 && x + w > right {
            drop += LEGEND_ROW;
            y += LEGEND_ROW as i32;
            x = 12;
        }
        origins.push((x, y));
        x += w;
    }
    LegendPlacement { origins, drop }
}

/// Draws a panel's title at the left of its top row (made to fit, see [`FittedTitle`])
/// and its legend where `placement` put it.
pub(super) fn draw_title_and_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    entries: &[LegendEntry<'_>],
    placement: &LegendPlacement,
    ink: RGBAColor,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let text = |size: f64| {
        (FAMILY, size)
            .into_font()
            .color(&ink)
            .pos(Pos::new(HPos::Left, VPos::Center))
    };
    let (w, _) = area.dim_in_pixel();
    let title = FittedTitle::new(title, title_room(w));
    area.draw(&Text::new(
        title.text,
        (12, (super::TITLE_HEIGHT / 2) as i32),
        text(title.size),
    ))?;
    for (entry, &(x, y)) in entries.iter().zip(&placement.origins) {
        area.draw(&PathElement::new(
            vec![(x, y), (x + SAMPLE_LINE, y)],
            entry.line,
        ))?;
        let mut label_x = x + SAMPLE_LINE + 5;
        if let Some(patch) = entry.patch {
            let px = x + SAMPLE_LINE + 6;
            let half = SAMPLE_PATCH / 2;
            area.draw(&Rectangle::new(
                [(px, y - half), (px + SAMPLE_PATCH, y + half)],
                patch,
            ))?;
            label_x = px + SAMPLE_PATCH + 5;
        }
        area.draw(&Text::new(
            entry.label.to_string(),
            (label_x, y),
            text(LEGEND_FONT_PX),
        ))?;
    }
    Ok(())
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

/// The labelled frequencies of a band's axis: the 1-2-5 ones inside it, and each edge
/// unless a 1-2-5 label is within a factor of 1.2 of it (the labels would collide).
pub(super) fn band_ticks(lo: f64, hi: f64, bold: &[f64]) -> Vec<f64> {
    let clear = |edge: f64| bold.iter().all(|&b| (b / edge).max(edge / b) >= 1.2);
    let mut ticks = bold.to_vec();
    for edge in [lo, hi] {
        if clear(edge) {
            ticks.push(edge);
        }
    }
    ticks.sort_by(f64::total_cmp);
    ticks
}

/// A frequency label: whole hertz, or one decimal below 10 Hz.
fn band_label(f: f64) -> String {
    if f < 10.0 && (f - f.round()).abs() > 1e-9 {
        format!("{f:.1}")
    } else {
        format!("{f:.0}")
    }
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
    // The axis is the data's band, not the decade around it (from 10 Hz, a band from
    // 40 Hz left 30% of the plot empty); its ends are labelled too (900 Hz had no tick),
    // unless a 1-2-5 label sits that close (1024 next to 1000).
    let (bold, light) = log_grid(lo, hi);
    let ticks = band_ticks(lo, hi, &bold);
    let labelled = ticks.clone();
    let mut chart = ChartBuilder::on(&area.margin(TITLE_HEIGHT, 8, 8, 18))
        .x_label_area_size(44)
        .y_label_area_size(58)
        .build_cartesian_2d(
            (lo..hi)
                .log_scale()
                .with_key_points(ticks)
                .with_light_points(light),
            floor..top,
        )?;
    chart
        .configure_mesh()
        .x_desc("frequency (Hz)")
        .y_desc(y_desc)
        .label_style(text(13.0))
        .axis_desc_style(text(14.0))
        .x_label_formatter(&|f| {
            if labelled.iter().any(|t| (t - f).abs() <= 1e-9 * t) {
                band_label(*f)
            } else {
                String::new()
            }
        })
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
    fn labels_take_the_first_free_row_stay_left_of_the_edge_or_are_left_out() {
        let mut rows = LabelRows::<2>::new(10);
        assert_eq!(rows.place(0, 50, 500), Some((0, 0)));
        assert_eq!(rows.place(30, 50, 500), Some((1, 30)));
        // Row 0 is free from 60: a label at 60 takes it again.
        assert_eq!(rows.place(60, 50, 500), Some((0, 60)));
        // Both rows busy: left out, and nothing changes.
        assert_eq!(rows.place(80, 50, 500), None);
        assert_eq!(rows.place(90, 50, 500), Some((1, 90)));
        // Past the edge: moved left to end at it.
        assert_eq!(rows.place(480, 50, 500), Some((0, 450)));
    }

    #[test]
    fn a_title_shrinks_to_fit_then_is_cut_short() {
        let short = FittedTitle::new("gravel", 696);
        assert_eq!((short.text.as_str(), short.size), ("gravel", TITLE_FONT_PX));
        let long = "x".repeat(80);
        let shrunk = FittedTitle::new(&long, 696);
        assert!(shrunk.size < TITLE_FONT_PX && shrunk.size >= MIN_TITLE_FONT_PX);
        assert!(shrunk.end() <= 12 + 696, "{shrunk:?}");
        let longer = "y".repeat(200);
        let cut = FittedTitle::new(&longer, 696);
        assert_eq!(cut.size, MIN_TITLE_FONT_PX);
        assert!(cut.text.ends_with('…') && cut.end() <= 12 + 696, "{cut:?}");
    }

    #[test]
    fn a_bands_axis_is_labelled_at_its_edges_unless_a_label_is_close() {
        let (bold, _) = log_grid(20.0, 900.0);
        assert_eq!(
            band_ticks(20.0, 900.0, &bold),
            [20.0, 50.0, 100.0, 200.0, 500.0, 900.0]
        );
        let (bold, _) = log_grid(40.0, 1024.0);
        // 40 is 1.25 times from 50; 1024 is next to 1000.
        assert_eq!(
            band_ticks(40.0, 1024.0, &bold),
            [40.0, 50.0, 100.0, 200.0, 500.0, 1000.0]
        );
    }

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
}
