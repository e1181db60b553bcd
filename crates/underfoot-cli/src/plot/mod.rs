//! Plots: spectra (measured against model magnitude, in dB on a log-frequency axis, one
//! panel per material, drawn from each model's fit record), spectrograms of a signal with
//! labelled segments of its timeline (the materials of a walk), magnitude responses
//! (a device's passes, a limb model), and steps in time (recorded against rendered decay
//! envelopes and micro-events, one panel per material). The computation behind each is
//! the library's (the fit record, `underfoot::signal::spectrum::Spectrogram`, the step
//! summaries of `underfoot::analysis::steps`); this module only draws.
//!
//! The format follows the file extension: `.svg` or `.png`. Every plot goes through one
//! backend helper, [`draw`], which picks the backend and decides whether text can be drawn
//! (see [`font`]).
//!
//! | file | what it draws |
//! |---|---|
//! | `font.rs` | finding and registering the font PNG text needs |
//! | `scaled.rs` | drawing a figure laid out at its base size onto a backend `k` times larger (`--plot-scale`) |
//! | `layout.rs` | the layout check every figure passes before it is written: texts that overlap or run off the figure, empty axes |
//! | `axes.rs` | the log-frequency magnitude frame shared by spectra and responses; axis labels; a panel's title and legend, placed so they never overlap |
//! | `spectra.rs` | [`draw_spectra`]: measured against model, a panel per material |
//! | `spectrogram.rs` | [`draw_spectrogram`]: a signal's spectrogram with its segments and colour bar |
//! | `responses.rs` | [`draw_responses`]: magnitude responses in one panel |
//! | `steps.rs` | [`draw_steps`]: steps in time, recorded against rendered, a panel per material |
//! | `timeline.rs` | [`draw_timeline`]: a recorded session's force, strikes, output envelope and markers on one time axis |

mod axes;
mod font;
mod layout;
mod responses;
mod scaled;
mod spectra;
mod spectrogram;
mod steps;
mod timeline;

use std::path::Path;

use anyhow::{Context, bail};
use plotters::coord::Shift;
use plotters::prelude::*;
use scaled::Scaled;

pub use responses::{Curve, draw_responses};
pub use spectra::{Panel, YRange, draw_spectra};
pub use spectrogram::{Segment, draw_spectrogram};
pub use steps::{StepPanel, draw_steps};
pub use timeline::{Timeline, TimelineMarker, draw_timeline};

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

/// A written figure: what it could not include, and what its layout check found.
#[derive(Debug, Clone, PartialEq, Eq)]
#[must_use = "a figure's omissions and layout problems are for the user to hear"]
pub struct Drawn {
    pub omitted: Omitted,
    /// Texts that overlap or run off the figure, empty axes: one sentence each (see
    /// `layout`). Empty for every figure the tests draw; a problem here is a bug in the
    /// figure's layout, reported rather than fatal because the figure still holds its
    /// data.
    pub problems: Vec<String>,
}

impl Drawn {
    /// Says on stderr what the figure written to `path` lacks, if anything.
    pub fn report(&self, path: &Path) {
        if self.omitted == Omitted::Text {
            eprintln!(
                "underfoot: warning: no font found, so {} has no text (set UNDERFOOT_FONT to a .ttf file, or plot to .svg)",
                path.display()
            );
        }
        for problem in &self.problems {
            eprintln!("underfoot: warning: figure {}: {problem}", path.display());
        }
    }
}

const PANEL_SIZE: (u32, u32) = (720, 420);
/// The resolution a figure is laid out for: a 720-pixel panel is 7.5 inches wide.
const BASE_DPI: f64 = 96.0;
const TITLE_HEIGHT: u32 = 34;
/// Magnitudes more than this far below the top of a panel are drawn at its floor, so
/// that one deep notch does not flatten everything else.
const FLOOR_DB: f64 = 90.0;

/// A picture that can be drawn on either backend.
trait Figure {
    /// Draws onto `root`, which is white-filled by the figure itself.
    fn draw_on<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>;

    /// The ranges of the figure's axes, for the layout check.
    fn axes(&self) -> Vec<layout::AxisSpan>;
}

/// How large a figure is drawn: `k` times its base size, lines, text and pixels alike.
/// The layout is the base size's, so a figure scaled is the same figure, sharper.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scale(f64);

impl Scale {
    /// The smallest and largest scales: a quarter of the base size (a thumbnail), and
    /// eight times it (a 720-pixel panel at 5,760 pixels, 19 inches at 300 dpi).
    pub const RANGE: (f64, f64) = (0.25, 8.0);

    /// `k` times the base size.
    ///
    /// # Errors
    /// `k` is not a finite number within [`Scale::RANGE`].
    pub fn new(k: f64) -> Result<Self, String> {
        let (lo, hi) = Self::RANGE;
        if k.is_finite() && (lo..=hi).contains(&k) {
            Ok(Self(k))
        } else {
            Err(format!(
                "a figure's scale must be from {lo} to {hi}, not {k}"
            ))
        }
    }

    pub fn get(self) -> f64 {
        self.0
    }

    /// `(width, height)` pixels at this scale.
    fn apply(self, (w, h): (u32, u32)) -> (u32, u32) {
        let k = |v: u32| (f64::from(v) * self.0).round().max(1.0) as u32;
        (k(w), k(h))
    }
}

impl Default for Scale {
    fn default() -> Self {
        Self(1.0)
    }
}

impl std::str::FromStr for Scale {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let k = text
            .trim()
            .parse::<f64>()
            .map_err(|_| format!("a figure's scale is a number such as 2.5, not {text:?}"))?;
        Self::new(k)
    }
}

/// `--plot-scale K`, the same on every command that draws.
#[derive(Debug, Clone, clap::Args)]
pub struct PlotScale {
    /// Draw figures K times their base size, lines, text and pixels alike (2.5: a
    /// 720x420 panel at 1800x1050; a PNG records 96 x K dpi, so it prints at the base
    /// size, sharper).
    #[arg(long = "plot-scale", value_name = "K", default_value = "1")]
    scale: Scale,
}

impl PlotScale {
    pub fn get(&self) -> Scale {
        self.scale
    }
}

/// How a figure is drawn: its file's format, whether text can be drawn, and its scale.
#[derive(Debug, Clone, Copy)]
struct Canvas {
    format: Format,
    show_text: bool,
    scale: Scale,
}

impl Canvas {
    #[cfg(test)]
    fn new(format: Format, show_text: bool) -> Self {
        Self {
            format,
            show_text,
            scale: Scale::default(),
        }
    }
}

/// Draws into `path` in the format its extension names, `scale` times the base size:
/// `render(canvas)` checks its input and draws, with text only when it can be drawn
/// (always in SVG; in PNG only with a font), and returns its layout's problems. Says
/// whether the text had to be left out.
fn draw(
    path: &Path,
    scale: Scale,
    render: impl FnOnce(Canvas) -> anyhow::Result<Vec<String>>,
) -> anyhow::Result<Drawn> {
    let format = Format::of(path)?;
    let show_text = format == Format::Svg || font::font()?.is_some();
    let problems = render(Canvas {
        format,
        show_text,
        scale,
    })?;
    let omitted = if show_text {
        Omitted::Nothing
    } else {
        Omitted::Text
    };
    Ok(Drawn { omitted, problems })
}

/// Draws `figure`, laid out on `size` pixels and drawn at the canvas's scale, into
/// `path` on the backend of the canvas's format, and writes the file; returns what the
/// layout check found.
fn write_figure(
    path: &Path,
    canvas: Canvas,
    size: (u32, u32),
    figure: &impl Figure,
) -> anyhow::Result<Vec<String>> {
    let problems = layout::Layout::of(figure, size).problems();
    let (scale, pixels) = (canvas.scale, canvas.scale.apply(size));
    fn on<DB: DrawingBackend>(
        root: &DrawingArea<DB, Shift>,
        figure: &impl Figure,
    ) -> Result<(), String> {
        figure
            .draw_on(root)
            .and_then(|()| root.present())
            .map_err(|e| e.to_string())
    }
    let drawn = match canvas.format {
        Format::Svg => on(
            &Scaled::new(SVGBackend::new(path, pixels), size, scale).into_drawing_area(),
            figure,
        ),
        Format::Png => {
            let mut rgb = vec![0_u8; 3 * pixels.0 as usize * pixels.1 as usize];
            let drawn = on(
                &Scaled::new(BitMapBackend::with_buffer(&mut rgb, pixels), size, scale)
                    .into_drawing_area(),
                figure,
            );
            drawn.and_then(|()| write_png(path, pixels, scale, &rgb).map_err(|e| e.to_string()))
        }
    };
    drawn
        .map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))
        .with_context(|| format!("writing plot {}", path.display()))?;
    Ok(problems)
}

/// Writes 8-bit RGB pixels, row by row, as a PNG that says it is `96 × scale` dots per
/// inch, so that a scaled figure prints at the base figure's size, only sharper.
/// plotters draws into the buffer; the encoding is the `png` crate's, called here rather
/// than through plotters' own encoder, which would bring the whole `image` crate (JPEG,
/// BMP...) into every build for this.
fn write_png(
    path: &Path,
    (width, height): (u32, u32),
    scale: Scale,
    rgb: &[u8],
) -> Result<(), png::EncodingError> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let per_metre = (BASE_DPI * scale.get() / 0.0254).round() as u32;
    encoder.set_pixel_dims(Some(png::PixelDimensions {
        xppu: per_metre,
        yppu: per_metre,
        unit: png::Unit::Meter,
    }));
    // A filter per row, picked for how well it compresses (plots are flat colour and thin
    // lines: a third smaller than one filter for all). With the default compression this
    // writes the same bytes as plotters' encoder did.
    encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()
}

/// The colour of text: black, or transparent when no text is drawn (the bitmap backend
/// skips transparent text before it would need a font).
fn ink(show_text: bool) -> RGBAColor {
    if show_text {
        BLACK.to_rgba()
    } else {
        TRANSPARENT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The longest name a material may have: titles built on it must still fit.
    fn long_name() -> String {
        "a-very-long-material-name-that-a-user-might-well-give-it-64-char".to_owned()
    }

    /// Every figure at its most crowded passes the layout check, as SVG and as PNG (with
    /// text when the machine has a font).
    fn assert_clean(name: &str, draw: impl Fn(&Path) -> anyhow::Result<Drawn>) {
        let dir = tempfile::tempdir().expect("tempdir");
        for ext in ["svg", "png"] {
            let path = dir.path().join(format!("{name}.{ext}"));
            let drawn = draw(&path).expect(name);
            assert_eq!(drawn.problems, Vec::<String>::new(), "{name}.{ext}");
        }
    }

    fn fit_record(scale: f64) -> underfoot::material::FitRecord {
        let mut record = spectra::tests::record();
        record.measured.iter_mut().for_each(|m| *m *= scale);
        record.model = record.measured.iter().map(|m| m * 1.1).collect();
        record
    }

    #[test]
    fn crowded_spectra_pass_the_layout_check() {
        let fits: Vec<_> = (0..11).map(|i| fit_record(0.5f64.powi(i))).collect();
        let physical: Vec<f64> = fits[0].model.iter().map(|m| m * 0.7).collect();
        let each: Vec<Vec<f64>> = (1..=5)
            .map(|k| {
                fits[0]
                    .measured
                    .iter()
                    .map(|m| m * f64::from(k) / 3.0)
                    .collect()
            })
            .collect();
        let title = format!(
            "{}: IIR LSD 0.61 dB, physical LSD 2.38 dB (held-out render)",
            long_name()
        );
        let panels: Vec<Panel<'_>> = fits
            .iter()
            .map(|fit| Panel {
                title: title.clone(),
                fit,
                physical: Some(&physical),
                recordings: &each,
            })
            .collect();
        assert_clean("one", |p| {
            draw_spectra(p, Scale::default(), &panels[..1], YRange::Own)
        });
        assert_clean("eleven", |p| {
            draw_spectra(p, Scale::default(), &panels, YRange::Shared)
        });
    }

    #[test]
    fn crowded_responses_pass_the_layout_check() {
        let freqs: Vec<f64> = (0..64)
            .map(|i| 40.0 * 25.6f64.powf(f64::from(i) / 63.0))
            .collect();
        let db: Vec<Vec<f64>> = (0..6)
            .map(|k| {
                freqs
                    .iter()
                    .map(|f| f64::from(k) * (f / 100.0).ln())
                    .collect()
            })
            .collect();
        let curves: Vec<Curve<'_>> = db
            .iter()
            .enumerate()
            .map(|(k, db)| Curve {
                label: format!("pass {k}: after equalizing, measured again"),
                freqs_hz: &freqs,
                db,
            })
            .collect();
        let title = format!("{} against flat, pass by pass", long_name());
        assert_clean("responses", |p| {
            draw_responses(
                p,
                Scale::default(),
                &title,
                "magnitude (dB re its mean in the band)",
                &curves,
            )
        });
    }

    #[test]
    fn crowded_steps_pass_the_layout_check() {
        let summary = steps::tests::summary(60, 1000.0);
        let title = format!("{}: D90 262 ms recorded, 240 ms rendered", long_name());
        let panels: Vec<StepPanel<'_>> = (0..11)
            .map(|_| StepPanel {
                title: title.clone(),
                recorded: Some(&summary),
                rendered: Some(&summary),
            })
            .collect();
        assert_clean("steps", |p| draw_steps(p, Scale::default(), &panels));
    }

    #[test]
    fn a_crowded_spectrogram_passes_the_layout_check() {
        let rate = 2000;
        let x: Vec<f32> = (0..20 * rate)
            .map(|n| (f64::from(n) * 0.3).sin() as f32)
            .collect();
        let name = long_name();
        // Many short segments with long labels: the label lanes must keep them apart.
        let segments: Vec<Segment<'_>> = (0..40)
            .map(|i| Segment {
                label: &name,
                start_s: f64::from(i) * 0.5,
                end_s: f64::from(i) * 0.5 + 0.4,
            })
            .collect();
        let title = format!("A walk across {name}, played by the physical models");
        assert_clean("walk", |p| {
            draw_spectrogram(
                p,
                Scale::default(),
                &title,
                &x,
                rate as u32,
                1000.0,
                (20.0, 900.0),
                &segments,
            )
        });
    }

    #[test]
    fn a_crowded_timeline_passes_the_layout_check() {
        let channels = 16;
        let force: Vec<Vec<(f64, f64)>> = (0..channels)
            .map(|c| {
                (0..200)
                    .map(|k| (f64::from(k) * 0.05, f64::from(c * 40 + k % 50)))
                    .collect()
            })
            .collect();
        let envelope: Vec<Vec<(f64, f64)>> = (0..channels)
            .map(|_| (0..200).map(|k| (f64::from(k) * 0.05, -40.0)).collect())
            .collect();
        let timeline = Timeline {
            title: format!("session {}", long_name()),
            force,
            strikes: (0..20)
                .map(|k| (f64::from(k) * 0.5, 1 + k as usize % 16))
                .collect(),
            envelope,
            // Close markers with long labels.
            markers: (0..12)
                .map(|k| TimelineMarker {
                    time: f64::from(k) * 0.8,
                    label: format!("condition {k}: soft sole, gravel, trial 3"),
                })
                .collect(),
        };
        assert_clean("timeline", |p| {
            draw_timeline(p, Scale::default(), &timeline)
        });
    }

    #[test]
    fn extension_picks_format() {
        assert_eq!(Format::of(Path::new("a/b.SVG")).ok(), Some(Format::Svg));
        assert_eq!(Format::of(Path::new("b.png")).ok(), Some(Format::Png));
        let e = Format::of(Path::new("b.jpg")).expect_err("jpg");
        assert!(e.to_string().contains("b.jpg"));
    }

    #[test]
    fn png_holds_the_pixels_row_by_row() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("p.png");
        let (width, height) = (5_u32, 3_u32);
        // Every pixel different, so a swapped axis or channel would show.
        let rgb: Vec<u8> = (0..width * height * 3)
            .map(|i| (i * 7 % 251) as u8)
            .collect();
        write_png(&path, (width, height), Scale::default(), &rgb).expect("write");
        let decoder = png::Decoder::new(std::io::BufReader::new(
            std::fs::File::open(&path).expect("open"),
        ));
        let mut reader = decoder.read_info().expect("header");
        let mut back = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut back).expect("frame");
        assert_eq!((info.width, info.height), (width, height));
        assert_eq!(info.color_type, png::ColorType::Rgb);
        assert_eq!(&back[..info.buffer_size()], &rgb[..]);
    }
}
