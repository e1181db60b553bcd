//! Spectra plots: measured against model magnitude, in dB on a log-frequency axis, one
//! panel per material, drawn from each model's fit record; and spectrograms of a signal,
//! with labelled segments of its timeline (the materials of a walk).
//!
//! The format follows the file extension: `.svg` or `.png`.
//!
//! # Fonts
//!
//! plotters is built without system font discovery (no fontconfig/freetype), so text is
//! drawn with a TrueType font file registered at run time. The font is, in order:
//!
//! 1. the file named by `UNDERFOOT_FONT`; an empty `UNDERFOOT_FONT` means "no font";
//! 2. the first of a few well-known system paths (DejaVu Sans, Liberation Sans, Arial).
//!
//! Without a font, SVG plots still have all their text: SVG stores text as `<text>`
//! elements and the viewer renders it, so the layout here never measures text. PNG plots
//! are then drawn without any text (axes, grid and curves only) and a warning says so.
//! On Debian, `apt-get install fonts-dejavu-core` provides a font.

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{Context, bail};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use underfoot::material::FitRecord;
use underfoot::signal::spectrum::SpectrumPlan;

/// One panel: a title and the fit record to draw.
pub struct Panel<'a> {
    pub title: String,
    pub fit: &'a FitRecord,
    /// A second model on the same grid (the physical model of `compare`), drawn in blue.
    pub physical: Option<&'a [f64]>,
}

/// The image formats a plot can be written in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Svg,
    Png,
}

impl Format {
    /// The format named by the extension of `path`.
    pub fn of(path: &Path) -> anyhow::Result<Self> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("svg") => Ok(Self::Svg),
            Some("png") => Ok(Self::Png),
            _ => bail!("plot file {}: use a .svg or .png extension", path.display()),
        }
    }
}

/// What a finished plot could not include.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Omitted {
    Nothing,
    /// A PNG without a font: drawn without text.
    Text,
}

const FAMILY: &str = "sans-serif";
const PANEL_SIZE: (u32, u32) = (720, 420);
const TITLE_HEIGHT: u32 = 34;
/// Magnitudes more than this far below the top of a panel are drawn at its floor, so
/// that one deep notch does not flatten everything else.
const FLOOR_DB: f64 = 90.0;

const FONT_CANDIDATES: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/liberation-sans/LiberationSans-Regular.ttf",
    "/System/Library/Fonts/Supplemental/Arial.ttf",
    "/Library/Fonts/Arial.ttf",
    "C:\\Windows\\Fonts\\arial.ttf",
];

/// Finds and registers a font once per process; `Ok(None)` when there is none.
fn font() -> anyhow::Result<Option<&'static Path>> {
    static FONT: OnceLock<Result<Option<PathBuf>, String>> = OnceLock::new();
    let found = FONT.get_or_init(|| match std::env::var_os("UNDERFOOT_FONT") {
        Some(p) if p.is_empty() => Ok(None),
        Some(p) => {
            let p = PathBuf::from(p);
            register(&p)
                .map(|()| Some(p.clone()))
                .map_err(|e| format!("UNDERFOOT_FONT={}: {e}", p.display()))
        }
        None => Ok(FONT_CANDIDATES
            .iter()
            .map(PathBuf::from)
            .find(|p| register(p).is_ok())),
    });
    match found {
        Ok(p) => Ok(p.as_deref()),
        Err(e) => bail!("{e}"),
    }
}

fn register(path: &Path) -> Result<(), String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read the font: {e}"))?;
    // plotters keeps fonts for the life of the process and wants them `'static`; this
    // runs at most once per process, so the leak is bounded by one font file.
    let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
    plotters::style::register_font(FAMILY, FontStyle::Normal, bytes)
        .map_err(|_| "not a TrueType/OpenType font".to_string())
}

/// Draws `panels` into `path` (two columns when there is more than one panel).
pub fn draw_spectra(path: &Path, panels: &[Panel<'_>]) -> anyhow::Result<Omitted> {
    let format = Format::of(path)?;
    let show_text = format == Format::Svg || font()?.is_some();
    render(path, format, panels, show_text)?;
    Ok(if show_text {
        Omitted::Nothing
    } else {
        Omitted::Text
    })
}

/// Draws without looking for a font: with `show_text` false, every text is transparent,
/// which the bitmap backend skips before it would need a font.
fn render(
    path: &Path,
    format: Format,
    panels: &[Panel<'_>],
    show_text: bool,
) -> anyhow::Result<()> {
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
    let failed = |e: String| anyhow::anyhow!("drawing {}: {e}", path.display());
    match format {
        Format::Svg => {
            let root = SVGBackend::new(path, size).into_drawing_area();
            draw_grid(&root, panels, (rows, cols), show_text).map_err(failed)
        }
        Format::Png => {
            let root = BitMapBackend::new(path, size).into_drawing_area();
            draw_grid(&root, panels, (rows, cols), show_text).map_err(failed)
        }
    }
    .with_context(|| format!("writing plot {}", path.display()))
}

fn draw_grid<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    panels: &[Panel<'_>],
    (rows, cols): (usize, usize),
    show_text: bool,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(e)?;
    for (area, panel) in root.split_evenly((rows, cols)).iter().zip(panels) {
        draw_panel(area, panel, show_text).map_err(e)?;
    }
    root.present().map_err(e)
}

/// Labels a log axis only at 1, 2 and 5 times a power of ten: a label at every grid line
/// runs the upper decade's labels into each other.
fn one_two_five(f: f64) -> String {
    let mantissa = f / 10f64.powf(f.log10().floor());
    if [1.0, 2.0, 5.0].iter().any(|m| (mantissa - m).abs() < 1e-6) {
        format!("{f:.0}")
    } else {
        String::new()
    }
}

fn db(m: f64) -> f64 {
    20.0 * m.log10()
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &Panel<'_>,
    show_text: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let fit = panel.fit;
    let ink = if show_text {
        BLACK.to_rgba()
    } else {
        TRANSPARENT
    };
    let text = |size: f64| (FAMILY, size).into_font().color(&ink);

    let all_db = fit
        .measured
        .iter()
        .chain(&fit.model)
        .chain(panel.physical.unwrap_or_default())
        .map(|&m| db(m))
        .filter(|v| v.is_finite());
    let top = all_db.clone().fold(f64::NEG_INFINITY, f64::max);
    let (top, floor) = if top.is_finite() {
        let low = all_db.fold(f64::INFINITY, f64::min).max(top - FLOOR_DB);
        (top + 3.0, low - 3.0)
    } else {
        // All magnitudes are zero: an empty frame is the honest picture.
        (0.0, -FLOOR_DB)
    };
    let series = |values: &[f64]| -> Vec<(f64, f64)> {
        fit.grid_hz
            .iter()
            .zip(values)
            .map(|(&f, &m)| (f, db(m).max(floor)))
            .collect()
    };
    let (lo, hi) = (fit.grid_hz[0], fit.grid_hz[fit.grid_hz.len() - 1]);

    // Title and legend share the top row and are placed by hand: plotters' caption and
    // legend measure text, which needs a font even for SVG.
    let (w, _) = area.dim_in_pixel();
    let row_y = (TITLE_HEIGHT / 2) as i32;
    let measured_style = BLACK.stroke_width(2);
    let model_style = RED.stroke_width(2);
    let physical_style = BLUE.stroke_width(2);
    if show_text {
        area.draw(&Text::new(
            panel.title.clone(),
            (12, row_y),
            text(17.0).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
        let legend: &[(&str, ShapeStyle)] = if panel.physical.is_some() {
            &[
                ("measured", measured_style),
                ("IIR", model_style),
                ("physical", physical_style),
            ]
        } else {
            &[("measured", measured_style), ("model", model_style)]
        };
        let first = w as i32 - 105 * legend.len() as i32;
        for (i, &(label, style)) in legend.iter().enumerate() {
            let x = first + 105 * i as i32;
            area.draw(&PathElement::new(vec![(x, row_y), (x + 24, row_y)], style))?;
            area.draw(&Text::new(
                label,
                (x + 30, row_y),
                text(14.0).pos(Pos::new(HPos::Left, VPos::Center)),
            ))?;
        }
    }

    let mut chart = magnitude_chart(area, (lo, hi), (floor, top), ink)?;
    chart.draw_series(LineSeries::new(series(&fit.measured), measured_style))?;
    chart.draw_series(LineSeries::new(series(&fit.model), model_style))?;
    if let Some(physical) = panel.physical {
        chart.draw_series(LineSeries::new(series(physical), physical_style))?;
    }
    Ok(())
}

type MagnitudeChart<'a, DB> =
    ChartContext<'a, DB, Cartesian2d<LogCoord<f64>, plotters::coord::types::RangedCoordf64>>;

/// The frame of a magnitude plot: dB against log-frequency from `lo` to `hi`, with its
/// mesh and labels drawn.
fn magnitude_chart<'a, DB: DrawingBackend>(
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

/// One labelled stretch of the timeline (e.g. a material of a walk).
#[allow(
    dead_code,
    reason = "the walk rendering command that draws these comes separately"
)]
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

/// Levels of a short-time Fourier transform on a grid of time columns and frequency rows.
struct Spectrogram {
    /// The FFT (and Hann window) length, in samples.
    window: usize,
    bin_hz: f64,
    /// Column `c` spans `c * col_s ..= (c + 1) * col_s`; its frame is centred in between.
    col_s: f64,
    /// Row `r` spans `edges_hz[r] ..= edges_hz[r + 1]`, from 0 Hz to the top of the plot.
    edges_hz: Vec<f64>,
    /// dB re the loudest cell, in `[-RANGE_DB, 0]`, column after column.
    db: Vec<f64>,
}

impl Spectrogram {
    fn rows(&self) -> usize {
        self.edges_hz.len() - 1
    }

    fn cols(&self) -> usize {
        self.db.len() / self.rows()
    }

    fn column(&self, c: usize) -> &[f64] {
        let rows = self.rows();
        &self.db[c * rows..(c + 1) * rows]
    }
}

/// The STFT length at `rate_hz`: bins of 4 to 6 Hz, fine enough to part the resonances of
/// a material below 1 kHz, while a frame (~0.17 s at 48 kHz) stays about one footstep long.
fn window_len(rate_hz: u32) -> usize {
    (rate_hz as usize / 6).next_power_of_two().max(16)
}

/// The spectrogram of `samples` from 0 to `top_hz` (at most the Nyquist frequency), with
/// at most `max_cols` columns and `max_rows` rows. `samples` must not be empty.
fn stft(
    samples: &[f32],
    rate_hz: u32,
    top_hz: f64,
    (max_cols, max_rows): (usize, usize),
) -> anyhow::Result<Spectrogram> {
    let n = window_len(rate_hz);
    let len = samples.len();
    // Frames overlapping by more than 7/8 of a Hann window are nearly alike: a shorter hop
    // would add columns but no detail.
    let hop = len.div_ceil(max_cols).max(n / 8);
    let cols = len.div_ceil(hop);
    let bin_hz = f64::from(rate_hz) / n as f64;
    let bins = ((top_hz / bin_hz).round() as usize).min(n / 2) + 1;
    let rows = bins.min(max_rows);
    let first_bin = |r: usize| r * bins / rows;
    let edges_hz = (0..=rows)
        .map(|r| ((first_bin(r) as f64 - 0.5) * bin_hz).clamp(0.0, top_hz))
        .collect();

    let window: Vec<f64> = (0..n)
        .map(|i| 0.5 - 0.5 * (TAU * i as f64 / n as f64).cos())
        .collect();
    let mut plan = SpectrumPlan::new(n);
    let mut frame = vec![0.0; n];
    let mut magnitude = vec![0.0; plan.bins()];
    let mut power = vec![0.0; bins];
    let mut cells = Vec::with_capacity(cols * rows);
    let pad = n / 2;
    // A column wider than half a window (a long signal) gets several frames with their
    // power summed, so that no stretch of the signal, and no footstep, goes unseen.
    let frames = hop.div_ceil(n / 2);
    for c in 0..cols {
        power.fill(0.0);
        for k in 0..frames {
            // The frame spans `centre - pad .. centre - pad + n` in the signal, zero
            // where that reaches past either end.
            let centre = c * hop + (2 * k + 1) * hop / (2 * frames);
            let (skip, from) = match centre.checked_sub(pad) {
                Some(from) => (0, from.min(len)),
                None => (pad - centre, 0),
            };
            let to = (centre + (n - pad)).clamp(from, len);
            frame.fill(0.0);
            for ((f, w), x) in frame[skip..]
                .iter_mut()
                .zip(&window[skip..])
                .zip(&samples[from..to])
            {
                *f = f64::from(*x) * w;
            }
            plan.magnitude(&frame, &mut magnitude)?;
            for (p, m) in power.iter_mut().zip(&magnitude) {
                *p += m * m;
            }
        }
        // A row over several bins takes the loudest: averaged, a tone narrower than the
        // row would fade by the number of bins it shares the row with.
        cells.extend((0..rows).map(|r| {
            power[first_bin(r)..first_bin(r + 1)]
                .iter()
                .fold(0.0, |a: f64, &b| a.max(b))
        }));
    }
    let loudest = cells.iter().fold(0.0, |a: f64, &b| a.max(b));
    for p in &mut cells {
        // All-zero input has no loudest cell: everything is at the floor.
        *p = if *p > 0.0 {
            (10.0 * (*p / loudest).log10()).max(-RANGE_DB)
        } else {
            -RANGE_DB
        };
    }
    Ok(Spectrogram {
        window: n,
        bin_hz,
        col_s: hop as f64 / f64::from(rate_hz),
        edges_hz,
        db: cells,
    })
}

/// Draws the spectrogram of `samples` (mono, at `rate_hz`) from 0 to `max_hz`, with the
/// segments marked (vertical lines at their starts, labels along the top), into `path`
/// (.svg or .png).
///
/// Levels are in dB re the loudest time-frequency cell, over the 60 dB below it; a colour
/// bar gives the scale. `max_hz` above the Nyquist frequency is lowered to it. Segments
/// may reach past either end of the signal; the parts outside are not drawn.
///
/// # Errors
/// A wrong extension, no samples, a zero rate, a `max_hz` that is not positive, a sample
/// that is not finite, a segment whose ends are not finite or in order, or a failure to
/// draw or write the file.
#[allow(
    dead_code,
    reason = "the walk rendering command that calls this comes separately"
)]
pub fn draw_spectrogram(
    path: &Path,
    title: &str,
    samples: &[f32],
    rate_hz: u32,
    max_hz: f64,
    segments: &[Segment<'_>],
) -> anyhow::Result<Omitted> {
    let format = Format::of(path)?;
    let show_text = format == Format::Svg || font()?.is_some();
    let input = Timeline {
        title,
        samples,
        rate_hz,
        max_hz,
        segments,
    };
    render_spectrogram(path, format, &input, show_text)?;
    Ok(if show_text {
        Omitted::Nothing
    } else {
        Omitted::Text
    })
}

/// The arguments of [`draw_spectrogram`], as they came.
struct Timeline<'a> {
    title: &'a str,
    samples: &'a [f32],
    rate_hz: u32,
    max_hz: f64,
    segments: &'a [Segment<'a>],
}

/// A spectrogram ready to draw.
struct SpectrogramPlot<'a> {
    title: &'a str,
    spec: Spectrogram,
    duration_s: f64,
    top_hz: f64,
    segments: &'a [Segment<'a>],
    show_text: bool,
    /// Cells as one bitmap (PNG) rather than rectangles (SVG).
    raster: bool,
}

/// Like [`render`], draws without looking for a font.
fn render_spectrogram(
    path: &Path,
    format: Format,
    input: &Timeline<'_>,
    show_text: bool,
) -> anyhow::Result<()> {
    let &Timeline {
        title,
        samples,
        rate_hz,
        max_hz,
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
    let cells = match format {
        Format::Svg => SVG_CELLS,
        Format::Png => PNG_CELLS,
    };
    let plot = SpectrogramPlot {
        title,
        spec: stft(samples, rate_hz, top_hz, cells)?,
        duration_s: samples.len() as f64 / f64::from(rate_hz),
        top_hz,
        segments,
        show_text,
        raster: format == Format::Png,
    };
    let failed = |e: String| anyhow::anyhow!("drawing {}: {e}", path.display());
    match format {
        Format::Svg => {
            let root = SVGBackend::new(path, SPECTROGRAM_SIZE).into_drawing_area();
            draw_spectrogram_on(&root, &plot)
                .and_then(|()| root.present())
                .map_err(|e| failed(e.to_string()))
        }
        Format::Png => {
            let root = BitMapBackend::new(path, SPECTROGRAM_SIZE).into_drawing_area();
            draw_spectrogram_on(&root, &plot)
                .and_then(|()| root.present())
                .map_err(|e| failed(e.to_string()))
        }
    }
    .with_context(|| format!("writing plot {}", path.display()))
}

/// Decimals enough to tell apart the labels of a time axis `span_s` long.
fn time_decimals(span_s: f64) -> usize {
    (1.0 - span_s.log10().floor()).clamp(0.0, 4.0) as usize
}

fn draw_spectrogram_on<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    plot: &SpectrogramPlot<'_>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let spec = &plot.spec;
    let (duration_s, top_hz) = (plot.duration_s, plot.top_hz);
    let ink = if plot.show_text {
        BLACK.to_rgba()
    } else {
        TRANSPARENT
    };
    let text = |size: f64| (FAMILY, size).into_font().color(&ink);
    root.fill(&WHITE)?;

    let (w, _) = root.dim_in_pixel();
    let row_y = (TITLE_HEIGHT / 2) as i32;
    if plot.show_text {
        root.draw(&Text::new(
            plot.title.to_string(),
            (12, row_y),
            text(17.0).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
        root.draw(&Text::new(
            format!(
                "Hann window of {} samples ({:.1} Hz bins), {:.0} ms columns",
                spec.window,
                spec.bin_hz,
                spec.col_s * 1e3
            ),
            (w as i32 - 12, row_y),
            text(13.0).pos(Pos::new(HPos::Right, VPos::Center)),
        ))?;
    }

    let top = TITLE_HEIGHT + 2 * LANE_HEIGHT + 10;
    let (main, bar_area) = root.split_horizontally(w - COLOUR_BAR_WIDTH);
    let mut chart = ChartBuilder::on(&main.margin(top, 16, 8, 18))
        .x_label_area_size(44)
        .y_label_area_size(58)
        .build_cartesian_2d(0.0..duration_s, 0.0..top_hz)?;

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
            let f = top_hz * (1.0 - (f64::from(j) + 0.5) / f64::from(ph));
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
                cells.push(Rectangle::new(
                    [(t0, spec.edges_hz[r]), (t1, spec.edges_hz[end])],
                    level_colour(f64::from(level) * SVG_STEP_DB).filled(),
                ));
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
            starts().map(|s| PathElement::new(vec![(s.start_s, 0.0), (s.start_s, top_hz)], style)),
        )?;
    }

    let decimals = time_decimals(duration_s);
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("time (s)")
        .y_desc("frequency (Hz)")
        .label_style(text(13.0))
        .axis_desc_style(text(14.0))
        .x_labels(12)
        .y_labels(11)
        .x_label_formatter(&|t| format!("{t:.decimals$}"))
        .y_label_formatter(&|f| format!("{f:.0}"))
        .draw()?;

    // Each segment's extent is a bar along the top of the plot, shaded alternately so
    // that neighbours part; its label sits above, in the first of two lanes it fits in.
    let plot_top = chart.backend_coord(&(0.0, top_hz)).1;
    let x_of = |t: f64| chart.backend_coord(&(t, top_hz)).0;
    let mut lane_free = [i32::MIN; 2];
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
        let lane = lane_free
            .iter()
            .position(|&free| free <= x0)
            .unwrap_or(usize::from(lane_free[1] < lane_free[0]));
        // Text is not measured (SVG needs no font): 0.6 em a character is generous for
        // sans-serif, so labels judged apart do not touch.
        let width = (0.6 * LABEL_FONT_PX * s.label.chars().count() as f64).ceil() as i32;
        lane_free[lane] = x0 + width + 10;
        root.draw(&Text::new(
            s.label.to_string(),
            (x0 + 2, plot_top - 8 - (lane as u32 * LANE_HEIGHT) as i32),
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
    let format = Format::of(path)?;
    let show_text = format == Format::Svg || font()?.is_some();
    if curves.is_empty() || curves.iter().any(|c| c.freqs_hz.len() < 2) {
        bail!("nothing to plot in {}", path.display());
    }
    let failed = |e: String| anyhow::anyhow!("drawing {}: {e}", path.display());
    match format {
        Format::Svg => {
            let root = SVGBackend::new(path, PANEL_SIZE).into_drawing_area();
            draw_response_panel(&root, title, curves, show_text).map_err(failed)
        }
        Format::Png => {
            let root = BitMapBackend::new(path, PANEL_SIZE).into_drawing_area();
            draw_response_panel(&root, title, curves, show_text).map_err(failed)
        }
    }
    .with_context(|| format!("writing plot {}", path.display()))?;
    Ok(if show_text {
        Omitted::Nothing
    } else {
        Omitted::Text
    })
}

fn draw_response_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    title: &str,
    curves: &[Curve<'_>],
    show_text: bool,
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    area.fill(&WHITE).map_err(e)?;
    let ink = if show_text {
        BLACK.to_rgba()
    } else {
        TRANSPARENT
    };
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
        ))
        .map_err(e)?;
        let first = w as i32 - 150 * curves.len() as i32;
        for (i, c) in curves.iter().enumerate() {
            let x = first + 150 * i as i32;
            area.draw(&PathElement::new(
                vec![(x, row_y), (x + 20, row_y)],
                style(i),
            ))
            .map_err(e)?;
            area.draw(&Text::new(
                c.label.clone(),
                (x + 25, row_y),
                text(13.0).pos(Pos::new(HPos::Left, VPos::Center)),
            ))
            .map_err(e)?;
        }
    }
    let mut chart = magnitude_chart(area, (lo, hi), (floor, top), ink).map_err(e)?;
    for (i, c) in curves.iter().enumerate() {
        let points: Vec<(f64, f64)> = c
            .freqs_hz
            .iter()
            .zip(c.db)
            .filter(|(_, v)| v.is_finite())
            .map(|(&f, &v)| (f, v.clamp(floor, top)))
            .collect();
        chart
            .draw_series(LineSeries::new(points, style(i)))
            .map_err(e)?;
    }
    area.present().map_err(e)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record() -> FitRecord {
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
    fn log_axis_labels_only_one_two_five() {
        let labels: Vec<String> = [20.0, 30.0, 50.0, 100.0, 400.0, 500.0]
            .map(one_two_five)
            .to_vec();
        assert_eq!(labels, ["20", "", "50", "100", "", "500"]);
    }

    #[test]
    fn extension_picks_format() {
        assert_eq!(Format::of(Path::new("a/b.SVG")).ok(), Some(Format::Svg));
        assert_eq!(Format::of(Path::new("b.png")).ok(), Some(Format::Png));
        let e = Format::of(Path::new("b.jpg")).expect_err("jpg");
        assert!(e.to_string().contains("b.jpg"));
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
            },
            Panel {
                title: "snow".into(),
                fit: &fit,
                physical: None,
            },
        ];
        // No font was registered under this family by this path: SVG must not need one.
        render(&path, Format::Svg, &panels, true).expect("svg");
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
            Format::Png,
            &[Panel {
                title: "x".into(),
                fit: &fit,
                physical: None,
            }],
            false,
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
        let omitted = draw_spectra(
            &path,
            &[Panel {
                title: "x".into(),
                fit: &fit,
                physical: None,
            }],
        )
        .expect("png");
        let expected = if font().expect("font lookup").is_some() {
            Omitted::Nothing
        } else {
            Omitted::Text
        };
        assert_eq!(omitted, expected);
        assert!(std::fs::read(&path).expect("read").starts_with(b"\x89PNG"));
    }

    #[test]
    fn short_fit_record_is_an_error() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut fit = record();
        fit.grid_hz.truncate(1);
        let e = render(
            &dir.path().join("x.svg"),
            Format::Svg,
            &[Panel {
                title: "m".into(),
                fit: &fit,
                physical: None,
            }],
            true,
        )
        .expect_err("one point");
        assert!(e.to_string().contains("fewer than 2 points"));
    }

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
            draw_spectrogram(&path, "walk", &x, 48_000, 1000.0, &segments).expect(name);
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
            segments: &segments,
        };
        render_spectrogram(&path, Format::Png, &input, false).expect("png");
        assert!(std::fs::read(&path).expect("read").starts_with(b"\x89PNG"));
    }

    #[test]
    fn empty_and_bad_input_are_errors() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("e.svg");
        let e = draw_spectrogram(&path, "t", &[], 48_000, 1000.0, &[]).expect_err("empty");
        assert!(e.to_string().contains("no samples"), "{e}");
        let x = [0.0, f32::NAN];
        let e = draw_spectrogram(&path, "t", &x, 48_000, 1000.0, &[]).expect_err("NaN");
        assert!(e.to_string().contains("sample 1 is NaN"), "{e}");
        let e = draw_spectrogram(&path, "t", &[0.0], 0, 1000.0, &[]).expect_err("rate");
        assert!(e.to_string().contains("0 Hz"), "{e}");
        let e = draw_spectrogram(&path, "t", &[0.0], 48_000, 0.0, &[]).expect_err("top");
        assert!(e.to_string().contains("top frequency"), "{e}");
        let backwards = Segment {
            label: "mud",
            start_s: 2.0,
            end_s: 1.0,
        };
        let e = draw_spectrogram(&path, "t", &[0.0], 48_000, 1000.0, &[backwards])
            .expect_err("segment");
        assert!(e.to_string().contains("\"mud\""), "{e}");
    }

    #[test]
    fn zero_input_is_drawn_at_the_floor() {
        let x = vec![0.0; 20_000];
        let spec = stft(&x, 48_000, 1000.0, PNG_CELLS).expect("stft");
        assert!(spec.db.iter().all(|&v| v == -RANGE_DB));
        let dir = tempfile::tempdir().expect("tempdir");
        for name in ["z.svg", "z.png"] {
            let path = dir.path().join(name);
            draw_spectrogram(&path, "silence", &x, 48_000, 1000.0, &[]).expect(name);
            assert!(std::fs::metadata(&path).expect(name).len() > 0, "{name}");
        }
        // One sample: a single, mostly zero-padded frame.
        let path = dir.path().join("one.png");
        draw_spectrogram(&path, "one", &[1.0], 48_000, 1000.0, &[]).expect("one sample");
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
    fn a_sine_peaks_in_its_row() {
        let x = tone(48_000, 2.0, 200.0);
        for max_rows in [300, 40] {
            let spec = stft(&x, 48_000, 1000.0, (1200, max_rows)).expect("stft");
            assert_eq!(spec.window, 8192);
            assert!(spec.rows() <= max_rows && spec.cols() <= 1200);
            assert_eq!(spec.edges_hz[0], 0.0);
            assert_eq!(spec.edges_hz[spec.rows()], 1000.0);
            // A column in the middle, where the frame lies wholly inside the signal.
            let column = spec.column(spec.cols() / 2);
            let peak = (0..spec.rows())
                .max_by(|&a, &b| column[a].total_cmp(&column[b]))
                .expect("rows");
            let (lo, hi) = (spec.edges_hz[peak], spec.edges_hz[peak + 1]);
            assert!(
                lo - spec.bin_hz <= 200.0 && 200.0 <= hi + spec.bin_hz,
                "rows of at most {max_rows}: peak in {lo}..{hi} Hz"
            );
            if max_rows == 300 {
                let centre = (lo + hi) / 2.0;
                assert!((centre - 200.0).abs() <= spec.bin_hz, "peak at {centre} Hz");
            }
            // Columns differ only in the tone's phase against the window.
            assert!(column[peak] > -0.1, "{} dB", column[peak]);
            // Far from the tone, the Hann window's side lobes are far below the floor.
            assert_eq!(column[spec.rows() - 1], -RANGE_DB);
        }
    }

    #[test]
    fn wide_columns_miss_nothing() {
        // 600 Hz: a 128-sample window. Four columns of 1000 samples each, and a burst
        // at 150 Hz in the first 100 samples only, far from the first column's centre.
        let mut x = vec![0.0f32; 4000];
        for (i, v) in x[..100].iter_mut().enumerate() {
            *v = (TAU * 150.0 * i as f64 / 600.0).sin() as f32;
        }
        let spec = stft(&x, 600, 300.0, (4, 300)).expect("stft");
        assert_eq!((spec.window, spec.cols()), (128, 4));
        let column = spec.column(0);
        let peak = (0..spec.rows())
            .max_by(|&a, &b| column[a].total_cmp(&column[b]))
            .expect("rows");
        let centre = (spec.edges_hz[peak] + spec.edges_hz[peak + 1]) / 2.0;
        assert!((centre - 150.0).abs() <= spec.bin_hz, "peak at {centre} Hz");
        assert_eq!(column[peak], 0.0);
        assert!(spec.column(3).iter().all(|&v| v == -RANGE_DB));
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
            draw_spectrogram(&path, "noise", &x, rate, 1000.0, &segments).expect(name);
            let bytes = std::fs::metadata(&path).expect(name).len();
            // Noise is the worst case for merging SVG cells.
            assert!(bytes < 15_000_000, "{name}: {bytes} bytes");
        }
    }
}
