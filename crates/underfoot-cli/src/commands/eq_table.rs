//! `underfoot eq-table`: the table of users' equalizers, for sessions without a sweep.

use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use underfoot::compensation::files::{EqualizerFile, LimbFile};
use underfoot::compensation::table::{UserEntry, UserTable};
use underfoot::document;

use underfoot::atomic_file::OutputFile;

use crate::output::emit;
use crate::report::{Align, table};

/// Edit and inspect a table of users.
#[derive(Debug, Subcommand)]
pub enum EqTableCommand {
    /// Add a user (their fitted limb model) with their equalizer: the device's, then the
    /// inverse of their limb. Creates the table if it does not exist.
    Add(AddArgs),
    /// List the users of a table.
    Show(ShowArgs),
}

/// `underfoot eq-table add`.
#[derive(Debug, Clone, Args)]
pub struct AddArgs {
    /// The user's limb model (a `calibrate limb` file).
    #[arg(long, value_name = "FILE")]
    pub user: PathBuf,
    /// The table file.
    #[arg(long, value_name = "FILE")]
    pub table: PathBuf,
    /// The device equalizer the user's curve starts from (a `calibrate equalize` file).
    #[arg(long, value_name = "FILE")]
    pub eq: PathBuf,
    /// The user's name in the table (default: the limb file's name without extension).
    #[arg(long, value_name = "NAME")]
    pub name: Option<String>,
}

/// `underfoot eq-table show`.
#[derive(Debug, Clone, Args)]
pub struct ShowArgs {
    /// The table file.
    #[arg(long, value_name = "FILE")]
    pub table: PathBuf,
}

pub fn run(cmd: &EqTableCommand) -> anyhow::Result<()> {
    match cmd {
        EqTableCommand::Add(args) => add(args),
        EqTableCommand::Show(args) => show(args),
    }
}

fn add(args: &AddArgs) -> anyhow::Result<()> {
    // The table is edited in place: checked against the output policy
    // (underfoot::atomic_file) first, then read, changed and written under its edit lock.
    let out = OutputFile::check(&args.table, &[&args.eq, &args.user])?;
    let eq: EqualizerFile = document::load(&args.eq)?;
    let user: LimbFile = document::load(&args.user)?;
    let name = match &args.name {
        Some(n) => n.clone(),
        None => args
            .user
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .context("--user names no file; give --name")?,
    };
    let rate = eq.weights.rate;
    let zc = user
        .model
        .compensation(rate, user.band)
        .with_context(|| format!("the compensation filter of {}", args.user.display()))?;
    let mut weights = eq.weights.clone();
    weights.add_in_band(|f| 20.0 * zc.response(rate.omega(f)).norm().log10());
    let freqs = weights.frequencies();
    let _lock = out.lock()?;
    let mut users = if args.table.exists() {
        let t = document::load::<UserTable>(&args.table)?;
        anyhow::ensure!(
            t.freqs == freqs,
            "{} holds curves on another grid than {} (another rate or bank size)",
            args.table.display(),
            args.eq.display()
        );
        t
    } else {
        UserTable::new(freqs)?
    };
    let replaced = users.add(UserEntry {
        name: name.clone(),
        params: user.model.params,
        weights_db: weights.gains_db,
    })?;
    document::save_to(&out, &users)?;
    emit(&format!(
        "{} {name} in {}: {} user(s)\n",
        if replaced.is_some() {
            "replaced"
        } else {
            "added"
        },
        args.table.display(),
        users.entries.len()
    ))
}

fn show(args: &ShowArgs) -> anyhow::Result<()> {
    let users = document::load::<UserTable>(&args.table)?;
    let rows: Vec<Vec<String>> = users
        .entries
        .iter()
        .map(|e| {
            vec![
                e.name.clone(),
                format!("{:.5}", e.params.b3_k3),
                format!("{:.3e}", e.params.k2_m2),
                format!("{:.0}", e.params.b2_m2),
            ]
        })
        .collect();
    emit(&table(
        &[
            ("user", Align::Left),
            ("b3/k3 (s)", Align::Right),
            ("k2/m2 (s^-2)", Align::Right),
            ("b2/m2 (s^-1)", Align::Right),
        ],
        &rows,
    ))
}
