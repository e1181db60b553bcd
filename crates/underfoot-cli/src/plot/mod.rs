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
//! | `axes.rs` | the log-frequency magnitude frame shared by spectra and responses; axis labels; a panel's title and legend, placed so they never overlap |
//! | `spectra.rs` | [`draw_spectra`]: measured against model, a panel per material |
//! | `spectrogram.rs` | [`draw_spectrogram`]: a signal's spectrogram with its segments and colour bar |
//! | `responses.rs` | [`draw_responses`]: magnitude responses in one panel |
//! | `steps.rs` | [`draw_steps`]: steps in time, recorded against rendered, a panel per material |
//! | `timeline.rs` | [`draw_timeline`]: a recorded session's force, strikes, output envelope and markers on one time axis |

mod axes;
mod font;
mod responses;
mod spectra;
mod spectrogram;
mod steps;
mod timeline;

use std::path::Path;

use anyhow::{Context, bail};
use plotters::coord::Shift;
use plotters::prelude::*;

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

const PANEL_SIZE: (u32, u32) = (720, 420);
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
}

/// Draws into `path` in the format its extension names: `render(format, show_text)`
/// checks its input and draws, with text only when it can be drawn (always in SVG; in PNG
/// only with a font). Says whether the text had to be left out.
fn draw(
    path: &Path,
    render: impl FnOnce(Format, bool) -> anyhow::Result<()>,
) -> anyhow::Result<Omitted> {
    let format = Format::of(path)?;
    let show_text = format == Format::Svg || font::font()?.is_some();
    render(format, show_text)?;
    Ok(if show_text {
        Omitted::Nothing
    } else {
        Omitted::Text
    })
}

/// Draws `figure`, `size` pixels, into `path` on the backend of `format`, and writes the
/// file.
fn write_figure(
    path: &Path,
    format: Format,
    size: (u32, u32),
    figure: &impl Figure,
) -> anyhow::Result<()> {
    fn on<DB: DrawingBackend>(
        root: &DrawingArea<DB, Shift>,
        figure: &impl Figure,
    ) -> Result<(), String> {
        figure
            .draw_on(root)
            .and_then(|()| root.present())
            .map_err(|e| e.to_string())
    }
    let drawn = match format {
        Format::Svg => on(&SVGBackend::new(path, size).into_drawing_area(), figure),
        Format::Png => {
            let mut rgb = vec![0_u8; 3 * size.0 as usize * size.1 as usize];
            let drawn = on(
                &BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area(),
                figure,
            );
            drawn.and_then(|()| write_png(path, size, &rgb).map_err(|e| e.to_string()))
        }
    };
    drawn
        .map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))
        .with_context(|| format!("writing plot {}", path.display()))
}

/// Writes 8-bit RGB pixels, row by row, as a PNG. plotters draws into the buffer; the
/// encoding is the `png` crate's, called here rather than through plotters' own encoder,
/// which would bring the whole `image` crate (JPEG, BMP...) into every build for this.
fn write_png(
    path: &Path,
    (width, height): (u32, u32),
    rgb: &[u8],
) -> Result<(), png::EncodingError> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
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
        write_png(&path, (width, height), &rgb).expect("write");
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
