//! `underfoot calibrate`: measure the device, equalize it, fit a user's limb model, and
//! calibrate the force sensors.
//!
//! | file | what it holds |
//! |---|---|
//! | `sweep.rs` | `calibrate sweep`, and the sweep settings `sweep` and `equalize` share |
//! | `device.rs` | where sweeps are played and recorded: the simulated tile, a replayed measurement, a sound card |
//! | `equalize.rs` | `calibrate equalize`: the device equalizer, pass by pass |
//! | `limb.rs` | `calibrate limb`: a user's limb model from loaded sweeps |
//! | `sensors.rs` | `calibrate sensors`: each force sensor's curve from known loads |
//! | `user.rs` | a user as an argument (`--load`, `--user`): a limb file, Table 1's mean, or three parameters |

mod device;
mod equalize;
mod limb;
mod sensors;
mod sweep;
mod user;

use std::path::Path;

use clap::Subcommand;
use underfoot::atomic_file::OutputFile;

use crate::output::emit;
use crate::plot::Drawn;

pub use equalize::EqualizeArgs;
pub use limb::LimbArgs;
pub use sensors::SensorsArgs;
pub use sweep::SweepArgs;
pub use user::{UserArg, parse_user};

/// The calibration steps, in the order a session runs them.
#[derive(Debug, Subcommand)]
pub enum CalibrateCommand {
    /// Measure a device's frequency response with exponential sine sweeps.
    Sweep(SweepArgs),
    /// Tune the device equalizer by successive sweeps (the compensation paper's equations 4-5).
    Equalize(EqualizeArgs),
    /// Fit a user's rheological limb model (equations 1-3) to loaded sweeps.
    Limb(LimbArgs),
    /// Fit each force sensor's curve from readings under known loads (a lab scale).
    Sensors(SensorsArgs),
}

pub fn run(cmd: &CalibrateCommand) -> anyhow::Result<()> {
    match cmd {
        CalibrateCommand::Sweep(args) => sweep::run(args),
        CalibrateCommand::Equalize(args) => equalize::run(args),
        CalibrateCommand::Limb(args) => limb::run(args),
        CalibrateCommand::Sensors(args) => sensors::run(args),
    }
}

/// `--out` and `--plot` of a calibrate command against the output policy
/// (`underfoot::atomic_file`) with the files the command reads, before anything is
/// measured or written.
fn check_outputs(
    out: &Path,
    plot: Option<&Path>,
    inputs: &[&Path],
) -> anyhow::Result<(OutputFile, Option<OutputFile>)> {
    let out = OutputFile::check(out, inputs)?;
    let plot = match plot {
        Some(p) => {
            let o = OutputFile::check(p, inputs)?;
            o.distinct_from(&out)?;
            Some(o)
        }
        None => None,
    };
    Ok((out, plot))
}

fn plotted(path: &Path, drawn: Drawn) -> anyhow::Result<()> {
    drawn.report(path);
    emit(&format!("drew {}\n", path.display()))
}
