//! `underfoot library`: list, show and remove materials of a library file, or of the
//! built-in library when no file is given.

use std::borrow::Cow;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Subcommand;
use underfoot::material::builtin::builtin;
use underfoot::material::{Library, MaterialModel};

use underfoot::atomic_file::OutputFile;

use crate::output::emit;
use crate::report::{ListEntry, list_table};

/// The `library` subcommands.
#[derive(Debug, Subcommand)]
pub enum LibraryCommand {
    /// List the materials: name, rate, band, order, NRMSE, LSD, strikes.
    List {
        /// Library file [default: the built-in library].
        #[arg(long, value_name = "FILE", conflicts_with = "builtin")]
        library: Option<PathBuf>,
        /// List the built-in library.
        #[arg(long)]
        builtin: bool,
        /// Print JSON instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// Show one material: its fit, sources, sections and poles.
    Show {
        /// The material's name.
        name: String,
        /// Library file [default: the built-in library].
        #[arg(long, value_name = "FILE")]
        library: Option<PathBuf>,
        /// Print the material as stored (JSON).
        #[arg(long)]
        json: bool,
    },
    /// Remove a material from a library file (saved atomically).
    Remove {
        /// The material's name.
        name: String,
        /// Library file to edit.
        #[arg(long, value_name = "FILE")]
        library: PathBuf,
    },
}

/// The library file, or the built-in library without a file.
pub fn open(file: Option<&Path>) -> anyhow::Result<Cow<'static, Library>> {
    Ok(match file {
        Some(path) => Cow::Owned(Library::load(path)?),
        None => Cow::Borrowed(builtin()),
    })
}

fn origin(file: Option<&Path>) -> String {
    file.map_or_else(
        || "built-in library".to_string(),
        |p| p.display().to_string(),
    )
}

fn pretty<T: serde::Serialize + ?Sized>(value: &T) -> anyhow::Result<String> {
    let mut s = serde_json::to_string_pretty(value)?;
    s.push('\n');
    Ok(s)
}

/// Runs a `library` subcommand.
pub fn run(cmd: &LibraryCommand) -> anyhow::Result<()> {
    match cmd {
        LibraryCommand::List { library, json, .. } => {
            let lib = open(library.as_deref())?;
            if *json {
                let entries: Vec<ListEntry<'_>> = lib.materials.iter().map(ListEntry::of).collect();
                emit(&pretty(&entries)?)
            } else if lib.materials.is_empty() {
                emit("(no materials)\n")
            } else {
                emit(&list_table(&lib.materials))
            }
        }
        LibraryCommand::Show {
            name,
            library,
            json,
        } => {
            let lib = open(library.as_deref())?;
            let m = lib.get(name).with_context(|| origin(library.as_deref()))?;
            if *json {
                emit(&pretty(m)?)
            } else {
                emit(&describe(m))
            }
        }
        LibraryCommand::Remove { name, library } => {
            // Read, remove and write under the library's edit lock, so that a `fit` into
            // the same library at the same time is not lost (underfoot::atomic_file).
            let out = OutputFile::check(library, &[])?;
            let left = Library::edit(&out, false, |lib| {
                lib.remove(name)?;
                Ok(lib.materials.len())
            })
            .with_context(|| origin(Some(library)))?;
            emit(&format!(
                "removed {name:?} from {} ({left} materials left)\n",
                library.display(),
            ))
        }
    }
}

/// A human-readable account of one material.
fn describe(m: &MaterialModel) -> String {
    let mut s = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(s, "{}", m.name);
    let _ = writeln!(s, "  sample rate  {}", m.sample_rate);
    let _ = writeln!(s, "  band         {}", m.band_hz);
    let _ = writeln!(
        s,
        "  order        {} ({} sections)",
        m.order,
        m.filter.sos.len()
    );
    let _ = writeln!(
        s,
        "  fit          NRMSE {:.4}, LSD {:.2} dB over {} points",
        m.fit.nrmse,
        m.fit.lsd_db,
        m.fit.grid_hz.len()
    );
    if m.fit.poor_fit {
        let _ = writeln!(
            s,
            "  quality      POOR FIT: above the quality bound, kept with --accept-poor-fit"
        );
    }
    let _ = writeln!(
        s,
        "  evidence     {} strikes\n  method       {}\n  fit time     {:.2} s (computing, not recording)",
        m.fit.strikes,
        if m.fit.method.is_empty() {
            "(not recorded)"
        } else {
            &m.fit.method
        },
        m.fit.fit_seconds,
    );
    let _ = writeln!(s, "  sources");
    for src in &m.sources {
        let _ = writeln!(s, "    {}  sha256 {}", src.file, src.sha256);
    }
    let _ = writeln!(s, "  sections     b0 b1 b2 a0 a1 a2");
    for row in &m.filter.sos {
        let cells: Vec<String> = row.iter().map(|c| format!("{c:+.6e}")).collect();
        let _ = writeln!(s, "    {}", cells.join(" "));
    }
    // Poles as resonances: what a person tuning a material thinks in.
    if let Some(sos) = m.sos() {
        let _ = writeln!(s, "  poles        radius, frequency (from the lowest)");
        let mut poles: Vec<(f64, f64)> = sos
            .poles()
            .iter()
            .filter(|p| p.im >= 0.0 && p.norm() > 0.0)
            .map(|p| {
                let f = p.arg() * m.sample_rate.hz() / (2.0 * std::f64::consts::PI);
                (f, p.norm())
            })
            .collect();
        poles.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        for (f, radius) in poles {
            let _ = writeln!(s, "    {radius:.6}  {f:.1} Hz");
        }
    }
    s
}
