//! The font that PNG text is drawn with.
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

use anyhow::bail;
use plotters::style::FontStyle;

/// The family every text of a plot is drawn in.
pub(super) const FAMILY: &str = "sans-serif";

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
pub(super) fn font() -> anyhow::Result<Option<&'static Path>> {
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
