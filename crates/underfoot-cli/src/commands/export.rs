//! `underfoot export`: a library (the built-in one by default) as a C99 header for
//! firmware, with the fixed-point check's figures per material.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};
use underfoot::export::{self, ExportConfig, c};
use underfoot::units::Decibels;

use underfoot::atomic_file::OutputFile;

use crate::output::emit;
use crate::report::{Align, table};

/// What to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// One C99 header: tables in float and fixed point, and (under
    /// `UNDERFOOT_IMPLEMENTATION`) the reference per-sample loop.
    C,
}

/// A fixed-point format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Fixed {
    /// 16-bit coefficients, 16-bit input and output, 32-bit signal between sections,
    /// 64-bit accumulator.
    Q15,
    /// 32-bit data and coefficients, 64-bit accumulator.
    Q31,
}

/// `underfoot export` arguments.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Output format.
    #[arg(long, value_enum, default_value = "c")]
    pub format: Format,
    /// The header to write (replaced atomically), or `-` for standard output (the table
    /// then goes to standard error).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Library file [default: the built-in library].
    #[arg(long, value_name = "FILE")]
    pub library: Option<PathBuf>,
    /// Only these materials (comma-separated) [default: all].
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    pub materials: Vec<String>,
    /// Fixed-point formats to export, each checked (comma-separated); the table shows the
    /// figures of a format left out too.
    #[arg(long, value_enum, value_delimiter = ',', default_values = ["q15", "q31"])]
    pub fixed: Vec<Fixed>,
    /// Largest deviation from the float response allowed over the band, in dB.
    #[arg(long, default_value_t = 0.5, value_name = "DB")]
    pub tolerance_db: f64,
}

/// Runs `underfoot export`.
pub fn run(args: &ExportArgs) -> anyhow::Result<()> {
    let Format::C = args.format;
    // The output policy (underfoot::atomic_file) before anything is read: never the
    // library it exports, never a device.
    let out = OutputFile::check_or_stdout(
        &args.out,
        &[args.library.as_deref()]
            .into_iter()
            .flatten()
            .collect::<Vec<_>>(),
    )?;
    let library = super::library::open(args.library.as_deref())?;
    let origin = args.library.as_ref().map_or_else(
        || "built-in library".to_string(),
        |p| p.display().to_string(),
    );
    if args.tolerance_db.is_nan() || args.tolerance_db <= 0.0 {
        anyhow::bail!("--tolerance-db must be positive, not {}", args.tolerance_db);
    }
    let config = ExportConfig {
        tolerance: Decibels(args.tolerance_db),
        q15: args.fixed.contains(&Fixed::Q15),
        q31: args.fixed.contains(&Fixed::Q31),
        ..ExportConfig::default()
    };
    let exported = export::export_library(&library, &origin, &args.materials, &config)
        .with_context(|| format!("exporting {origin}"))?;
    export::write_to(&out, &c::header(&exported))?;

    let db = |check: &export::FormatCheck, on: bool| {
        let d = check.worst_db();
        // Q31 and f32 deviations are far below a milli-dB: keep their digits visible.
        let v = if d < 1e-3 {
            format!("{d:.1e}")
        } else {
            format!("{d:.3}")
        };
        if on { v } else { format!("({v})") }
    };
    let rows: Vec<Vec<String>> = exported
        .materials
        .iter()
        .map(|m| {
            vec![
                m.name.clone(),
                m.sections.len().to_string(),
                format!("{}", m.gain),
                db(&m.f32_check, true),
                db(&m.q15_check, m.with_q15),
                db(&m.q31_check, m.with_q31),
                format!("{:.6}", m.pole_margin),
                format!(
                    "{:.6}",
                    m.q15_check.pole_margin.min(m.q31_check.pole_margin)
                ),
            ]
        })
        .collect();
    let levels = config
        .levels
        .iter()
        .map(|l| format!("{}", l.0))
        .collect::<Vec<_>>()
        .join(", ");
    let mut text = format!(
        "wrote {} ({} materials at their model rates; worst deviation from the float model \
         over each band and over impulses at {levels} dBFS, dB; in parentheses: not exported)\n",
        args.out.display(),
        exported.materials.len()
    );
    text.push_str(&table(
        &[
            ("material", Align::Left),
            ("sections", Align::Right),
            ("gain", Align::Right),
            ("f32 dB", Align::Right),
            ("Q15 dB", Align::Right),
            ("Q31 dB", Align::Right),
            ("pole margin", Align::Right),
            ("fixed margin", Align::Right),
        ],
        &rows,
    ));
    if out.is_stdout() {
        // Standard output holds the header.
        eprint!("{text}");
        Ok(())
    } else {
        emit(&text)
    }
}
