//! Spectrograms: a signal's levels over time and frequency (computed by
//! `underfoot::signal::spectrum::Spectrogram`), with labelled segments of its timeline
//! (the materials of a walk) and a colour bar.
//!
//! A PNG spectrogram is one bitmap of the plot's pixels; an SVG one is a `<rect>` per run
//! of equal cells in a column, with levels rounded to half a decibel so that runs merge.

use std::path::Path;

use anyhow::bail;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use underfoot::signal::spectrum::Spectrogram;
use underfoot::units::{Decibels, Hz, SampleRate};

use super::axes::{FittedTitle, LabelRows, log_grid, text_width, time_decimals, title_room};
use super::font::FAMILY;
use super::layout::AxisSpan;
use super::{Canvas, Drawn, Figure, Format, Scale, TITLE_HEIGHT, draw, ink, write_figure};

/// One labelled stretch of the timeline (e.g. a material of a walk).
pub struct Segment<'a> {
    pub label: &'a str,
    pub start_s: f64,
    pub end_s: f64,
}

const SPECTROGRAM_SIZE: (u32, u32) = (1200, 560);
/// Levels more than this far below the loudest cell are drawn in the floor colour.
const RANGE_DB: f64 = 60.0;
/// At most this many time columns and frequency rows in a PNG spectrogram. It is drawn as
/// one bitmap of the plot's pixels, so these bound the STFT's work, not the drawing's.
const PNG_CELLS: (usize, usize) = (1200, 300);
/// An SVG spectrogram is one `<rect>` of about 85 bytes per cell at worst (noise, where no
/// two neighbouring cells look alike): 600 × 200 cells stay near 10 MB.
const SVG_CELLS: (usize, usize) = (600, 200);
/// SVG levels are rounded to this step so that a run of equal cells in a column merges
/// into one `<rect>`; half a decibel is finer than the colour map lets the eye tell apart.
const SVG_STEP_DB: f64 = 0.5;
/// Each of the two rows of segment labels above the plot.
const LANE_HEIGHT: u32 = 18;
/// The colour bar with its labels, right of the plot.
const COLOUR_BAR_WIDTH: u32 = 90;
const LABEL_FONT_PX: f64 = 13.0;

/// Viridis (van der Walt and Smith, for matplotlib) at nine evenly spaced points. Its
/// lightness rises steadily from end to end, so a level reads as brightness, also in grey
/// scale and to colour-blind eyes, and no band of levels stands out that the data doesn't.
const COLOUR_MAP: [(u8, u8, u8); 9] = [
    (0x44, 0x01, 0x54),
    (0x47, 0x2d, 0x7b),
    (0x3b, 0x52, 0x8b),
    (0x2c, 0x72, 0x8e),
    (0x21, 0x90, 0x8c),
    (0x27, 0xad, 0x81),
    (0x5d, 0xc8, 0x63),
    (0xaa, 0xdc, 0x32),
    (0xfd, 0xe7, 0x25),
];

/// The colour of `t` in `[0, 1]` (clamped; NaN is 0), linear between the anchors.
fn colour_map(t: f64) -> RGBColor {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (COLOUR_MAP.len() - 1) as f64;
    let i = (x as usize).min(COLOUR_MAP.len() - 2);
    let f = x - i as f64;
    let (a, b) = (COLOUR_MAP[i], COLOUR_MAP[i + 1]);
    let mix = |p: u8, q: u8| (f64::from(p) + f * (f64::from(q) - f64::from(p))).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// The colour of a level in dB re the loudest cell; the floor is the darkest.
fn level_colour(db: f64) -> RGBColor {
    colour_map(1.0 + db / RANGE_DB)
}

/// The library's spectrogram of checked `samples`, over the levels the colour map shows.
fn stft(
    samples: &[f32],
    rate_hz: u32,
    top_hz: f64,
    max_cells: (usize, usize),
) -> anyhow::Result<Spectrogram> {
    Ok(Spectrogram::new(
        samples,
        SampleRate(rate_hz),
        Hz(top_hz),
        max_cells,
        Decibels(RANGE_DB),
    )?)
}

/// Draws the spectrogram of `samples` (mono, at `rate_hz`) up to `max_hz`, with the
/// segments marked (vertical lines at their starts, labels along the top), into `path`
/// (.svg or .png).
///
/// The frequency axis is logarithmic, from an octave below `band`'s lower edge: a walk's
/// vibration spans decades, and on a linear axis nearly all of it sat in the bottom 15%.
/// The band's edges are marked by lines across the plot and labelled on the axis.
///
/// Levels are in dB re the loudest time-frequency cell, over the 60 dB below it; a colour
/// bar gives the scale. `max_hz` above the Nyquist frequency is lowered to it. Segments
/// may reach past either end of the signal; the parts outside are not drawn.
///
/// # Errors
/// A wrong extension, no samples, a zero rate, a `max_hz` that is not positive, a sample
/// that is not finite, a segment whose ends are not finite or in order, or a failure to
/// draw or write the file.
#[expect(
    clippy::too_many_arguments,
    reason = "each is its own quantity, named at the one call site"
)]
pub fn draw_spectrogram(
    path: &Path,
    scale: Scale,
    title: &str,
    samples: &[f32],
    rate_hz: u32,
    max_hz: f64,
    band: (f64, f64),
    segments: &[Segment<'_>],
) -> anyhow::Result<Drawn> {
    let input = Timeline {
        title,
        samples,
        rate_hz,
        max_hz,
        band,
        segments,
    };
    draw(path, scale, |canvas| {
        render_spectrogram(path, canvas, &input)
    })
}

/// The arguments of [`draw_spectrogram`], as they came.
struct Timeline<'a> {
    title: &'a str,
    samples: &'a [f32],
    rate_hz: u32,
    max_hz: f64,
    band: (f64, f64),
    segments: &'a [Segment<'a>],
}

/// A spectrogram ready to draw.
struct SpectrogramPlot<'a> {
    title: &'a str,
    spec: Spectrogram,
    duration_s: f64,
    /// The frequency axis, `(bottom, top)`.
    bottom_hz: f64,
    top_hz: f64,
    band: (f64, f64),
    segments: &'a [Segment<'a>],
    show_text: bool,
    /// Cells as one bitmap (PNG) rather than rectangles (SVG).
    raster: bool,
}

impl Figure for SpectrogramPlot<'_> {
    fn axes(&self) -> Vec<AxisSpan> {
        vec![
            AxisSpan::linear("time", (0.0, self.duration_s)),
            AxisSpan::log("frequency", (self.bottom_hz, self.top_hz)),
        ]
    }

    fn draw_on<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        draw_spectrogram_on(root, self)
    }
}

/// Like the other plots' `render`, draws without looking for a font.
fn render_spectrogram(
    path: &Path,
    canvas: Canvas,
    input: &Timeline<'_>,
) -> anyhow::Result<Vec<String>> {
    let &Timeline {
        title,
        samples,
        rate_hz,
        max_hz,
        band,
        segments,
    } = input;
    if samples.is_empty() {
        bail!("nothing to plot in {}: no samples", path.display());
    }
    if rate_hz == 0 {
        bail!("{}: the sample rate is 0 Hz", path.display());
    }
    if !(max_hz.is_finite() && max_hz > 0.0) {
        bail!(
            "{}: the top frequency must be positive, not {max_hz} Hz",
            path.display()
        );
    }
    if let Some(i) = samples.iter().position(|x| !x.is_finite()) {
        bail!(
            "{}: sample {i} is {}; a spectrogram needs finite samples",
            path.display(),
            samples[i]
        );
    }
    for s in segments {
        if !(s.start_s.is_finite() && s.end_s.is_finite() && s.start_s <= s.end_s) {
            bail!(
                "{}: segment {:?} runs from {} s to {} s; it needs finite ends in order",
                path.display(),
                s.label,
                s.start_s,
                s.end_s
            );
        }
    }
    let top_hz = max_hz.min(f64::from(rate_hz) / 2.0);
    if !(band.0.is_finite() && band.0 > 0.0 && band.0 < band.1 && band.0 < top_hz) {
        bail!(
            "{}: the band {} to {} Hz must be positive, in order and below {top_hz} Hz",
            path.display(),
            band.0,
            band.1
        );
    }
    let cells = match canvas.format {
        Format::Svg => SVG_CELLS,
        Format::Png => PNG_CELLS,
    };
    let plot = SpectrogramPlot {
        title,
        spec: stft(samples, rate_hz, top_hz, cells)?,
        duration_s: samples.len() as f64 / f64::from(rate_hz),
        bottom_hz: band.0 / 2.0,
        top_hz,
        band,
        segments,
        show_text: canvas.show_text,
        raster: canvas.format == Format::Png,
    };
    write_figure(path, canvas, SPECTROGRAM_SIZE, &plot)
}

fn draw_spectrogram_on<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    plot: &SpectrogramPlot<'_>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let spec = &plot.spec;
    let (duration_s, bottom_hz, top_hz) = (plot.duration_s, plot.bottom_hz, plot.top_hz);
    let ink = ink(plot.show_text);
    let text = |size: f64| (FAMILY, size).into_font().color(&ink);
    root.fill(&WHITE)?;

    let (w, _) = root.dim_in_pixel();
    let row_y = (TITLE_HEIGHT / 2) as i32;
    if plot.show_text {
        let window = format!(
            "Hann window of {} samples ({:.1} Hz bins), {:.0} ms columns",
            spec.window,
            spec.bin_hz,
            spec.col_s * 1e3
        );
        // The title has the row up to the window's note, which keeps its size.
        let title = FittedTitle::new(plot.title, title_room(w) - text_width(&window, 13.0) - 24);
        root.draw(&Text::new(
            title.text,
            (12, row_y),
            text(title.size).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
        root.draw(&Text::new(
            window,
            (w as i32 - 12, row_y),
            text(13.0).pos(Pos::new(HPos::Right, VPos::Center)),
        ))?;
    }

    let top = TITLE_HEIGHT + 2 * LANE_HEIGHT + 10;
    let (main, bar_area) = root.split_horizontally(w - COLOUR_BAR_WIDTH);
    let mut chart = ChartBuilder::on(&main.margin(top, 16, 8, 18))
        .x_label_area_size(44)
        .y_label_area_size(58)
        .build_cartesian_2d(0.0..duration_s, {
            let (bold, light) = log_grid(bottom_hz, top_hz);
            let mut ticks = bold;
            for edge in [plot.band.0, plot.band.1] {
                if edge < top_hz && ticks.iter().all(|&t| (t / edge).max(edge / t) >= 1.2) {
                    ticks.push(edge);
                }
            }
            ticks.sort_by(f64::total_cmp);
            (bottom_hz..top_hz)
                .log_scale()
                .with_key_points(ticks)
                .with_light_points(light)
        })?;
    let ratio = top_hz / bottom_hz;

    let (cols, rows) = (spec.cols(), spec.rows());
    if plot.raster {
        // Each pixel shows the cell under its centre.
        let (pw, ph) = chart.plotting_area().dim_in_pixel();
        let col_of: Vec<usize> = (0..pw)
            .map(|i| {
                let t = (f64::from(i) + 0.5) / f64::from(pw) * duration_s;
                ((t / spec.col_s) as usize).min(cols - 1)
            })
            .collect();
        let mut image = Vec::with_capacity(pw as usize * ph as usize * 3);
        for j in 0..ph {
            let f = bottom_hz * ratio.powf(1.0 - (f64::from(j) + 0.5) / f64::from(ph));
            let r = spec.edges_hz.partition_point(|&e| e <= f).clamp(1, rows) - 1;
            for &c in &col_of {
                let RGBColor(red, green, blue) = level_colour(spec.column(c)[r]);
                image.extend([red, green, blue]);
            }
        }
        // The buffer holds exactly `pw × ph` pixels, so the element always exists.
        let image: Option<BitMapElement<(f64, f64)>> =
            BitMapElement::with_owned_buffer((0.0, top_hz), (pw, ph), image);
        chart.draw_series(image)?;
    } else {
        let step = |db: f64| (db / SVG_STEP_DB).round() as i32;
        let mut cells = Vec::new();
        for c in 0..cols {
            let t0 = c as f64 * spec.col_s;
            let t1 = ((c + 1) as f64 * spec.col_s).min(duration_s);
            let column = spec.column(c);
            let mut r = 0;
            while r < rows {
                let level = step(column[r]);
                let end = r + column[r..]
                    .iter()
                    .take_while(|&&v| step(v) == level)
                    .count();
                // Cells below the axis are not drawn; one across its bottom is cut there.
                if spec.edges_hz[end] > bottom_hz {
                    cells.push(Rectangle::new(
                        [
                            (t0, spec.edges_hz[r].max(bottom_hz)),
                            (t1, spec.edges_hz[end]),
                        ],
                        level_colour(f64::from(level) * SVG_STEP_DB).filled(),
                    ));
                }
                r = end;
            }
        }
        chart.draw_series(cells)?;
    }

    // A dark line under a light one shows over both ends of the colour map.
    let starts = || {
        plot.segments
            .iter()
            .filter(|s| s.start_s > 0.0 && s.start_s < duration_s)
    };
    for style in [BLACK.mix(0.8).stroke_width(3), WHITE.stroke_width(1)] {
        chart.draw_series(
            starts().map(|s| {
                PathElement::new(vec![(s.start_s, bottom_hz), (s.start_s, top_hz)], style)
            }),
        )?;
    }
    // The band's edges, across the plot: dark under light, as the segment starts.
    let edges = [plot.band.0, plot.band.1]
        .into_iter()
        .filter(|&f| f > bottom_hz && f < top_hz);
    for style in [
        BLACK.mix(0.5).stroke_width(2),
        WHITE.mix(0.8).stroke_width(1),
    ] {
        chart.draw_series(
            edges
                .clone()
                .map(|f| PathElement::new(vec![(0.0, f), (duration_s, f)], style)),
        )?;
    }

    let decimals = time_decimals(duration_s);
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("time (s)")
        .y_desc("frequency (Hz; lines: the band fitted)")
        .label_style(text(13.0))
        .axis_desc_style(text(14.0))
        .x_labels(12)
        .x_label_formatter(&|t| format!("{t:.decimals$}"))
        .y_label_formatter(&|f| format!("{f:.0}"))
        .draw()?;

    // Each segment's extent is a bar along the top of the plot, shaded alternately so
    // that neighbours part; its label sits above, in the first of two lanes it fits in.
    let plot_top = chart.backend_coord(&(0.0, top_hz)).1;
    let x_of = |t: f64| chart.backend_coord(&(t, top_hz)).0;
    let mut lanes = LabelRows::<2>::new(10);
    let shown = plot
        .segments
        .iter()
        .filter(|s| s.end_s >= 0.0 && s.start_s < duration_s);
    for (k, s) in shown.enumerate() {
        let (x0, x1) = (x_of(s.start_s.max(0.0)), x_of(s.end_s.min(duration_s)));
        let shade = BLACK.mix(if k % 2 == 0 { 0.6 } else { 0.25 });
        root.draw(&Rectangle::new(
            [(x0, plot_top - 6), (x1, plot_top - 2)],
            shade.filled(),
        ))?;
        if !plot.show_text {
            continue;
        }
        // Text is not measured (SVG needs no font): 0.6 em a character is generous for
        // sans-serif, so labels judged apart do not touch. A label with no free lane is
        // left out: its bar still shows where the segment is.
        let width = text_width(s.label, LABEL_FONT_PX);
        let Some((lane, x)) = lanes.place(x0 + 2, width, w as i32 - 8) else {
            continue;
        };
        root.draw(&Text::new(
            s.label.to_string(),
            (x, plot_top - 8 - (lane as u32 * LANE_HEIGHT) as i32),
            text(LABEL_FONT_PX).pos(Pos::new(HPos::Left, VPos::Bottom)),
        ))?;
    }

    // The colour bar shares the plot's top and bottom margins, so its ends line up
    // with the plot's.
    let mut bar = ChartBuilder::on(&bar_area.margin(top, 8, 8, 0))
        .x_label_area_size(44)
        .right_y_label_area_size(40)
        .build_cartesian_2d(0.0..1.0, -RANGE_DB..0.0)?;
    const STEPS: u32 = 120;
    let step_db = RANGE_DB / f64::from(STEPS);
    bar.draw_series((0..STEPS).map(|i| {
        let lo = -RANGE_DB + f64::from(i) * step_db;
        Rectangle::new(
            [(0.0, lo), (1.0, lo + step_db)],
            level_colour(lo + step_db / 2.0).filled(),
        )
    }))?;
    // The scale's name goes above the bar, level like the segment labels: turned on its
    // side at the image's edge it would be hard to read.
    if plot.show_text {
        let (x0, _) = bar.backend_coord(&(0.0, 0.0));
        root.draw(&Text::new(
            "dB re max",
            (x0, plot_top - 8),
            text(LABEL_FONT_PX).pos(Pos::new(HPos::Left, VPos::Bottom)),
        ))?;
    }
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .label_style(text(13.0))
        .axis_desc_style(text(14.0))
        .y_labels(7)
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::TAU;

    fn tone(rate_hz: u32, seconds: f64, hz: f64) -> Vec<f32> {
        let n = (f64::from(rate_hz) * seconds) as usize;
        (0..n)
            .map(|i| (TAU * hz * i as f64 / f64::from(rate_hz)).sin() as f32)
            .collect()
    }

    /// Two tones one after the other, as two materials of a walk.
    fn two_tones() -> (Vec<f32>, [Segment<'static>; 2]) {
        let mut x = tone(48_000, 1.5, 150.0);
        x.extend(tone(48_000, 1.5, 600.0).iter().map(|v| 0.1 * v));
        let segments = [
            Segment {
                label: "gravel",
                start_s: 0.0,
                end_s: 1.5,
            },
            Segment {
                label: "snow",
                start_s: 1.5,
                end_s: 3.0,
            },
        ];
        (x, segments)
    }

    #[test]
    fn two_tones_render_to_svg_and_png() {
        let dir = tempfile::tempdir().expect("tempdir");
        let (x, segments) = two_tones();
        for name in ["s.svg", "s.png"] {
            let path = dir.path().join(name);
            let drawn = draw_spectrogram(
                &path,
                Scale::default(),
                "walk",
                &x,
                48_000,
                1000.0,
                (20.0, 900.0),
                &segments,
            )
            .expect(name);
            assert_eq!(drawn.problems, Vec::<String>::new(), "{name}");
            assert!(std::fs::metadata(&path).expect(name).len() > 0, "{name}");
        }
        let svg = std::fs::read_to_string(dir.path().join("s.svg")).expect("read");
        assert!(
            svg.contains(">\ngravel\n</text>") && svg.contains(">\nsnow\n</text>"),
            "segment labels"
        );
        assert!(
            svg.contains("time (s)") && svg.contains("dB re max"),
            "axes"
        );
        let png = std::fs::read(dir.path().join("s.png")).expect("read");
        assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"));
    }

    #[test]
    fn png_spectrogram_without_text_needs_no_font() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("s.png");
        let (samples, segments) = two_tones();
        let input = Timeline {
            title: "t",
            samples: &samples,
            rate_hz: 48_000,
            max_hz: 1000.0,
            band: (20.0, 900.0),
            segments: &segments,
        };
        render_spectrogram(&path, Canvas::new(Format::Png, false), &input).expect("png");
        assert!(std::fs::read(&path).expect("read").starts_with(b"\x89PNG"));
    }

    #[test]
    fn empty_and_bad_input_are_errors() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("e.svg");
        // What each bad input is refused with: the spectrogram of `samples` at `rate`
        // up to `top` Hz, with `band` marked and `segments` labelled.
        let refused = |samples: &[f32], rate, top, band, segments: &[Segment<'_>]| {
            draw_spectrogram(
                &path,
                Scale::default(),
                "t",
                samples,
                rate,
                top,
                band,
                segments,
            )
            .expect_err("bad input")
            .to_string()
        };
        let band = (20.0, 900.0);
        let e = refused(&[], 48_000, 1000.0, band, &[]);
        assert!(e.contains("no samples"), "{e}");
        let e = refused(&[0.0, f32::NAN], 48_000, 1000.0, band, &[]);
        assert!(e.contains("sample 1 is NaN"), "{e}");
        let e = refused(&[0.0], 0, 1000.0, band, &[]);
        assert!(e.contains("0 Hz"), "{e}");
        let e = refused(&[0.0], 48_000, 0.0, band, &[]);
        assert!(e.contains("top frequency"), "{e}");
        for bad in [
            (0.0, 900.0),
            (900.0, 20.0),
            (2000.0, 3000.0),
            (f64::NAN, 900.0),
        ] {
            let e = refused(&[0.0], 48_000, 1000.0, bad, &[]);
            assert!(e.contains("the band"), "{bad:?}: {e}");
        }
        let backwards = Segment {
            label: "mud",
            start_s: 2.0,
            end_s: 1.0,
        };
        let e = refused(&[0.0], 48_000, 1000.0, band, &[backwards]);
        assert!(e.contains("\"mud\""), "{e}");
    }

    #[test]
    fn zero_input_is_drawn_at_the_floor() {
        let x = vec![0.0; 20_000];
        let spec = stft(&x, 48_000, 1000.0, PNG_CELLS).expect("stft");
        assert!(spec.db.iter().all(|&v| v == -RANGE_DB));
        let dir = tempfile::tempdir().expect("tempdir");
        for name in ["z.svg", "z.png"] {
            let path = dir.path().join(name);
            let drawn = draw_spectrogram(
                &path,
                Scale::default(),
                "silence",
                &x,
                48_000,
                1000.0,
                (20.0, 900.0),
                &[],
            )
            .expect(name);
            assert_eq!(drawn.problems, Vec::<String>::new(), "{name}");
            assert!(std::fs::metadata(&path).expect(name).len() > 0, "{name}");
        }
        // One sample: a single, mostly zero-padded frame.
        let path = dir.path().join("one.png");
        let drawn = draw_spectrogram(
            &path,
            Scale::default(),
            "one",
            &[1.0],
            48_000,
            1000.0,
            (20.0, 900.0),
            &[],
        )
        .expect("one sample");
        assert_eq!(drawn.problems, Vec::<String>::new());
    }

    /// Relative luminance (sRGB, ITU-R BT.709 weights).
    fn luminance(c: RGBColor) -> f64 {
        let lin = |v: u8| {
            let v = f64::from(v) / 255.0;
            if v <= 0.04045 {
                v / 12.92
            } else {
                ((v + 0.055) / 1.055).powf(2.4)
            }
        };
        0.2126 * lin(c.0) + 0.7152 * lin(c.1) + 0.0722 * lin(c.2)
    }

    #[test]
    fn colour_map_runs_dark_to_light() {
        assert_eq!(colour_map(0.0), RGBColor(0x44, 0x01, 0x54));
        assert_eq!(colour_map(1.0), RGBColor(0xfd, 0xe7, 0x25));
        assert_eq!(colour_map(-3.0), colour_map(0.0));
        assert_eq!(colour_map(f64::NAN), colour_map(0.0));
        assert_eq!(colour_map(7.0), colour_map(1.0));
        assert_eq!(level_colour(-RANGE_DB), colour_map(0.0));
        assert_eq!(level_colour(0.0), colour_map(1.0));
        // Finer steps than this can round to the same 8-bit colour, or one a hair darker.
        let steps = 64;
        let lum: Vec<f64> = (0..=steps)
            .map(|i| luminance(colour_map(f64::from(i) / f64::from(steps))))
            .collect();
        for (i, pair) in lum.windows(2).enumerate() {
            assert!(pair[1] > pair[0], "step {i}: {} then {}", pair[0], pair[1]);
        }
        assert!(lum[steps as usize] > 20.0 * lum[0]);
    }

    #[test]
    fn a_long_walk_stays_bounded() {
        let rate = 48_000;
        let mut noise = underfoot::signal::noise::SplitMix64::new(7);
        let x: Vec<f32> = (0..60 * rate).map(|_| noise.symmetric() as f32).collect();
        let spec = stft(&x, rate, 1000.0, PNG_CELLS).expect("stft");
        assert!(spec.cols() <= PNG_CELLS.0 && spec.rows() <= PNG_CELLS.1);
        let dir = tempfile::tempdir().expect("tempdir");
        let segments = [Segment {
            label: "gravel",
            start_s: 0.0,
            end_s: 60.0,
        }];
        for name in ["long.svg", "long.png"] {
            let path = dir.path().join(name);
            let drawn = draw_spectrogram(
                &path,
                Scale::default(),
                "noise",
                &x,
                rate,
                1000.0,
                (20.0, 900.0),
                &segments,
            )
            .expect(name);
            assert_eq!(drawn.problems, Vec::<String>::new(), "{name}");
            let bytes = std::fs::metadata(&path).expect(name).len();
            // Noise is the worst case for merging SVG cells.
            assert!(bytes < 15_000_000, "{name}: {bytes} bytes");
        }
    }
}
