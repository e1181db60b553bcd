//! `underfoot demo`: the built-in materials at a glance, as in the paper's Table I and
//! Fig. 4: a fit table on stdout and a spectra plot on disk.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use crate::commands::library::open;
use crate::output::emit;
use crate::plot::{self, Omitted, Panel};
use crate::report::fit_table;

/// Arguments of `underfoot demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Directory to write spectra.svg into (created if missing).
    #[arg(long, value_name = "DIR", default_value = ".")]
    out_dir: PathBuf,
    /// Use this library file instead of the built-in library.
    #[arg(long, value_name = "FILE")]
    library: Option<PathBuf>,
}

/// Runs `underfoot demo`.
pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let lib = open(args.library.as_deref())?;
    let which = match &args.library {
        Some(p) => p.display().to_string(),
        None => "the built-in library".to_string(),
    };
    if lib.materials.is_empty() {
        emit(&format!("{which} has no materials yet: nothing to show\n"))?;
        return Ok(());
    }
    emit(&format!(
        "Fit of the materials of {which} (cf. Table I)\n\n{}",
        fit_table(&lib.materials)
    ))?;

    std::fs::create_dir_all(&args.out_dir)
        .with_context(|| format!("creating output directory {}", args.out_dir.display()))?;
    let path = args.out_dir.join("spectra.svg");
    let panels: Vec<Panel<'_>> = lib
        .materials
        .iter()
        .map(|m| Panel {
            title: format!("{}: order {}, LSD {:.2} dB", m.name, m.order, m.fit.lsd_db),
            fit: &m.fit,
        })
        .collect();
    // SVG never omits text (see the plot module), so there is nothing to warn about.
    let omitted = plot::draw_spectra(&path, &panels)?;
    debug_assert_eq!(omitted, Omitted::Nothing);
    emit(&format!("\nspectra: {}\n", path.display()))
}
