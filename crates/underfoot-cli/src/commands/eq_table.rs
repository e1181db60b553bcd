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
    /// List the users of a table: name and limb parameters.
    List(ListArgs),
    /// Show one user: limb parameters and their equalizer curve.
    Show(ShowArgs),
    /// Remove a user from a table.
    Remove(RemoveArgs),
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

/// `underfoot eq-table list`.
#[derive(Debug, Clone, Args)]
pub struct ListArgs {
    /// The table file.
    #[arg(long, value_name = "FILE")]
    pub table: PathBuf,
}

/// `underfoot eq-table show`.
#[derive(Debug, Clone, Args)]
pub struct ShowArgs {
    /// The user's name.
    pub name: String,
    /// The table file.
    #[arg(long, value_name = "FILE")]
    pub table: PathBuf,
}

/// `underfoot eq-table remove`.
#[derive(Debug, Clone, Args)]
pub struct RemoveArgs {
    /// The user's name.
    pub name: String,
    /// The table file.
    #[arg(long, value_name = "FILE")]
    pub table: PathBuf,
}

pub fn run(cmd: &EqTableCommand) -> anyhow::Result<()> {
    match cmd {
        EqTableCommand::Add(args) => add(args),
        EqTableCommand::List(args) => list(args),
        EqTableCommand::Show(args) => show(args),
        EqTableCommand::Remove(args) => remove(args),
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
    let user = users.get(&args.name).with_context(|| {
        format!(
            "no user \"{}\" in {} (users: {})",
            args.name,
            args.table.display(),
            names(&users)
        )
    })?;
    let mut text = format!(
        "{}: b3/k3 {:.5} s, k2/m2 {:.3e} s^-2, b2/m2 {:.0} s^-1\n",
        user.name, user.params.b3_k3, user.params.k2_m2, user.params.b2_m2
    );
    // The curve at about a third of an octave: enough to see its shape in a terminal.
    let rows: Vec<Vec<String>> = users
        .freqs
        .iter()
        .zip(&user.weights_db)
        .scan(0.0_f64, |last, (f, w)| {
            let keep = f.0 >= *last * 2f64.powf(1.0 / 3.0);
            if keep {
                *last = f.0.max(1.0);
            }
            Some(keep.then(|| vec![format!("{:.0}", f.0), format!("{w:+.2}")]))
        })
        .flatten()
        .collect();
    text.push_str(&table(
        &[("Hz", Align::Right), ("equalizer (dB)", Align::Right)],
        &rows,
    ));
    emit(&text)
}

fn remove(args: &RemoveArgs) -> anyhow::Result<()> {
    let out = OutputFile::check(&args.table, &[])?;
    let _lock = out.lock()?;
    let mut users = document::load::<UserTable>(&args.table)?;
    let removed = users.remove(&args.name);
    anyhow::ensure!(
        removed.is_some(),
        "no user \"{}\" in {} (users: {})",
        args.name,
        args.table.display(),
        names(&users)
    );
    document::save_to(&out, &users)?;
    emit(&format!(
        "removed {} from {}: {} user(s)\n",
        args.name,
        args.table.display(),
        users.entries.len()
    ))
}

fn names(users: &UserTable) -> String {
    if users.entries.is_empty() {
        return "none".to_owned();
    }
    users
        .entries
        .iter()
        .map(|e| e.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

fn list(args: &ListArgs) -> anyhow::Result<()> {
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
