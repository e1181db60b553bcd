//! `underfoot`: fit ground-material models from footstep recordings, manage library
//! files, and show what the built-in materials look like.
//!
//! Results go to stdout, progress bars and warnings to stderr (bars only when stderr is a
//! terminal). Any error ends the program with a message on stderr and exit status 1;
//! command-line mistakes exit with status 2.

mod commands;
mod message;
mod output;
mod plot;
mod report;
mod steps;
mod vocabulary;

use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

/// Learn how the ground vibrates underfoot, from recordings of footsteps.
#[derive(Debug, Parser)]
#[command(name = "underfoot", version, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Fit a material model to recordings and store it in a library file.
    Fit(commands::fit::FitArgs),
    /// Inspect and edit library files (or the built-in library).
    #[command(subcommand)]
    Library(commands::library::LibraryCommand),
    /// Table I: how close the IIR filter and the calibrated physical model come to recordings.
    Compare(commands::compare::CompareArgs),
    /// Measure the device, equalize it, and fit a user's limb model.
    #[command(subcommand)]
    Calibrate(commands::calibrate::CalibrateCommand),
    /// The table of users' equalizers: add a user, list them.
    #[command(subcommand, name = "eq-table")]
    EqTable(commands::eq_table::EqTableCommand),
    /// Render force (a CSV track or a generated walk) to a WAV file of vibration.
    Render(commands::render::RenderArgs),
    /// Run the live engine: force from a replay, serial port or OSC, to a device.
    Run(commands::run::RunArgs),
    /// Recorded sessions (`run --record DIR`): summarise one, plot its timeline.
    #[command(subcommand)]
    Session(commands::session::SessionCommand),
    /// `run` with a control panel in a web page: live meters, materials, gain, stop, fits.
    Panel(commands::panel::PanelArgs),
    /// A library as a C99 header for firmware: float, Q15/Q31 sections (checked), the loop.
    Export(commands::export::ExportArgs),
    /// A walk across every built-in material: walk.wav, its spectrogram, the fit table.
    Demo(commands::demo::DemoArgs),
}

/// The command line, every command of it taking negative numbers as values: `--tail -1`
/// is then refused for its value (with the range the flag takes), not as an unknown
/// argument `-1`, and `--gain-db -20` needs no `=`. No flag of underfoot is a number, so
/// a leading `-` and a digit can only be a value.
fn command_line() -> clap::Command {
    fn negatives(c: clap::Command) -> clap::Command {
        c.allow_negative_numbers(true).mut_subcommands(negatives)
    }
    negatives(Cli::command())
}

fn main() -> ExitCode {
    // No command replaces a file it has read, whether or not it lists it as an input
    // (underfoot::atomic_file, *Inputs*).
    underfoot::atomic_file::refuse_outputs_over_reads();
    let cli = command_line();
    let (args, renamed) = vocabulary::modernise(&cli, std::env::args_os().collect());
    for warning in renamed {
        eprintln!("{warning}");
    }
    let parsed = cli
        .try_get_matches_from(args)
        .and_then(|m| Cli::from_arg_matches(&m));
    let cli = match parsed {
        Ok(cli) => cli,
        // --help and --version: printed to stdout, status 0.
        Err(e) if !e.use_stderr() => e.exit(),
        Err(e) => {
            // A usage error echoes the offending value; a 100 kB one is cut.
            eprint!("{}", message::shorten(&e.render().to_string()));
            return ExitCode::from(u8::try_from(e.exit_code()).unwrap_or(2));
        }
    };
    let result = match cli.command {
        Command::Fit(args) => commands::fit::run(&args),
        Command::Library(cmd) => commands::library::run(&cmd),
        Command::Compare(args) => commands::compare::run(&args),
        Command::Calibrate(cmd) => commands::calibrate::run(&cmd),
        Command::EqTable(cmd) => commands::eq_table::run(&cmd),
        Command::Render(args) => commands::render::run(&args),
        Command::Run(args) => commands::run::run(&args),
        Command::Panel(args) => commands::panel::run(&args),
        Command::Session(cmd) => commands::session::run(&cmd),
        Command::Demo(args) => commands::demo::run(&args),
        Command::Export(args) => commands::export::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!(
                "underfoot: error: {}",
                message::shorten(&message::chain(&e))
            );
            ExitCode::FAILURE
        }
    }
}
