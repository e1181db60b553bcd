//! Spectra plots: measured against model magnitude, in dB on a log-frequency axis, one
//! panel per material, drawn from each model's fit record.
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

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{Context, bail};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use underfoot::material::FitRecord;

/// One panel: a title and the fit record to draw.
pub struct Panel<'a> {
    pub title: String,
    pub fit: &'a FitRecord,
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
    if show_text {
        area.draw(&Text::new(
            panel.title.clone(),
            (12, row_y),
            text(17.0).pos(Pos::new(HPos::Left, VPos::Center)),
        ))?;
        for (i, (label, style)) in [("measured", measured_style), ("model", model_style)]
            .into_iter()
            .enumerate()
        {
            let x = w as i32 - 210 + 105 * i as i32;
            area.draw(&PathElement::new(vec![(x, row_y), (x + 24, row_y)], style))?;
            area.draw(&Text::new(
                label,
                (x + 30, row_y),
                text(14.0).pos(Pos::new(HPos::Left, VPos::Center)),
            ))?;
        }
    }

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
    chart.draw_series(LineSeries::new(series(&fit.measured), measured_style))?;
    chart.draw_series(LineSeries::new(series(&fit.model), model_style))?;
    Ok(())
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
            strikes: 4,
            fit_seconds: 1.0,
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
            },
            Panel {
                title: "snow".into(),
                fit: &fit,
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
            }],
            true,
        )
        .expect_err("one point");
        assert!(e.to_string().contains("fewer than 2 points"));
    }
}
