//! What `render`, `run` and `demo` share: the library, the material bank and the engine
//! settings, from the command line.

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use underfoot::compensation::equalizer::Realisation;
use underfoot::compensation::files::EqualizerFile;
use underfoot::compensation::table::UserTable;
use underfoot::document;
use underfoot::engine::{EngineConfig, MaterialBank, PlaySettings};
use underfoot::force::drive::DriveKind;
use underfoot::material::Library;
use underfoot::synthesis::{ExcitationChoice, SynthModel, VoiceConfig};
use underfoot::units::{Decibels, Hz, Newtons, SampleRate};

use crate::commands::calibrate::{UserArg, parse_user};
use crate::commands::library::open;

/// A gain of -120 to +60 dB: beyond it a float gain overflows, and every sample is
/// silenced as non-finite.
fn parse_gain_db(s: &str) -> Result<f64, underfoot::io::spec::SpecError> {
    underfoot::io::spec::parse_number(s, "gain (dB)", -120.0, 60.0)
}

/// `--step-threshold`: a total force a heel strike rises through, from 1 N (a noise-free
/// sensor and a light foot) to 5000 N (seven times a 70 kg walker's weight).
fn parse_step_threshold(s: &str) -> Result<f64, underfoot::io::spec::SpecError> {
    underfoot::io::spec::parse_number(s, "step threshold (N)", 1.0, 5000.0)
}

/// Synthesis settings.
#[derive(Debug, Clone, Args)]
pub struct SynthArgs {
    /// Set by `panel`: a `--library` that does not exist yet plays the built-in
    /// materials, and the first fit from the page creates it.
    #[arg(skip)]
    pub library_created_by_fits: bool,
    /// Library file to take materials from (default: the built-in library).
    #[arg(long, value_name = "FILE")]
    pub library: Option<PathBuf>,
    /// What drives the material filter: impulse (one per heel strike; reproduces the
    /// recorded strikes), force, or force-rate (the tile paper's v_F).
    #[arg(long, default_value = "impulse", value_name = "KIND")]
    pub drive: DriveKind,
    /// Which model plays: iir (the fitted filter) or physical (the calibrated
    /// Hunt-Crossley impacts and aggregate of the material's `physical` entry).
    #[arg(long, default_value = "iir", value_name = "MODEL")]
    pub model: SynthModel,
    /// Audio sample rate, in Hz.
    #[arg(long = "audio-rate", default_value_t = 48_000, value_name = "HZ")]
    pub rate: u32,
    /// Output gain before the limiter, in dB, on top of each material's playback level.
    #[arg(
        long = "gain-db",
        default_value_t = 0.0,
        value_name = "DB",
        allow_hyphen_values = true,
        value_parser = parse_gain_db
    )]
    pub gain_db: f64,
    /// Limiter ceiling in dB relative to full scale (at most 0). Materials are levelled
    /// so that a nominal step peaks 3 dB under the default.
    #[arg(long = "ceiling-db", default_value_t = underfoot::safety::DEFAULT_CEILING.0, value_name = "DB", allow_hyphen_values = true)]
    pub ceiling_db: f64,
    /// Standard deviation of the per-step numerator perturbation. Default: each
    /// material's own, sized from how much its recorded steps differ; 0.01 is the IIR
    /// paper's 1%.
    #[arg(long, value_name = "SIGMA")]
    pub perturbation: Option<f32>,
    /// What drives each step: fitted (the heel impact and its train of micro-impacts,
    /// fitted from the material's recordings) or heel (one impulse per step, the IIR
    /// paper's).
    #[arg(long, default_value = "fitted", value_name = "KIND")]
    pub excitation: ExcitationChoice,
    /// Seed of the perturbation (the same seed gives the same output).
    #[arg(long, default_value_t = 0x5EED, value_name = "N")]
    pub seed: u64,
    /// Order of the low-pass at the top of the band that removes fitting artefacts (0: none).
    #[arg(long = "lowpass-order", default_value_t = 4, value_name = "N")]
    pub lowpass_order: usize,
    /// Nominal body mass the force drives are normalised for, in kg.
    #[arg(long = "weight", default_value_t = 70.0, value_name = "KG")]
    pub weight_kg: f64,
    /// Total force, in newtons, that a heel strike rises through: a strike is found where
    /// the summed sensors cross it upwards, and the detector re-arms below half of it.
    /// Lower it for a light participant or insensitive sensors, raise it above a noisy
    /// sensor's floor.
    #[arg(
        long = "step-threshold",
        default_value_t = underfoot::force::steps::DEFAULT_THRESHOLD.0,
        value_name = "N",
        value_parser = parse_step_threshold
    )]
    pub step_threshold_n: f64,
    /// About how often force readings arrive, in Hz (sets the force interpolation).
    #[arg(long = "sensor-rate", default_value_t = 500.0, value_name = "HZ")]
    pub sensor_rate: f64,
    /// Equalize the device with this equalizer (a `calibrate equalize` file).
    /// Default: no equalizer.
    #[arg(long, value_name = "FILE")]
    pub eq: Option<PathBuf>,
    /// Compensate this user's limb after the equalizer: a `calibrate limb` file, `table1`
    /// (Table 1's mean user) or `B3K3,K2M2,B2M2`.
    /// Default: no limb compensation.
    #[arg(long, value_name = "USER", value_parser = parse_user)]
    pub user: Option<UserArg>,
    /// Instead of the limb filter, take the user's equalizer from this table of users
    /// (`eq-table`), interpolated for their parameters; needs --eq and --user.
    /// Default: no table.
    #[arg(long = "eq-table", value_name = "FILE", requires_all = ["eq", "user"])]
    pub eq_table: Option<PathBuf>,
}

/// A library, a bank prepared from it, and the engine settings.
pub struct Setup {
    pub library: Library,
    pub origin: String,
    pub bank: MaterialBank,
    pub config: EngineConfig,
    /// How the bank's materials were prepared, and the nominal step their force drives
    /// were normalised with: a material added later is prepared the same way.
    #[cfg_attr(
        not(feature = "panel"),
        expect(
            dead_code,
            reason = "the panel prepares its bank and its fits with them"
        )
    )]
    pub voice: VoiceConfig,
    #[cfg_attr(
        not(feature = "panel"),
        expect(
            dead_code,
            reason = "the panel prepares its bank and its fits with them"
        )
    )]
    pub nominal_step: Vec<f64>,
}

impl SynthArgs {
    /// The library's settings of a render or session, from these flags.
    pub fn play_settings(&self) -> PlaySettings {
        PlaySettings {
            rate: SampleRate(self.rate),
            drive: self.drive,
            model: self.model,
            excitation: self.excitation,
            gain: Decibels(self.gain_db),
            ceiling: Decibels(self.ceiling_db),
            perturbation: self.perturbation,
            seed: self.seed,
            lowpass_order: self.lowpass_order,
            weight_kg: self.weight_kg,
            step_threshold: Newtons(self.step_threshold_n),
            sensor_rate: Hz(self.sensor_rate),
        }
    }

    /// The files these settings read (library, equalizer, limb file, table): a command's
    /// outputs must not be any of them.
    pub fn input_files(&self) -> Vec<PathBuf> {
        let user = match &self.user {
            Some(UserArg::File(p)) => Some(p.clone()),
            _ => None,
        };
        [
            self.library.clone(),
            self.eq.clone(),
            self.eq_table.clone(),
            user,
        ]
        .into_iter()
        .flatten()
        .collect()
    }

    /// Loads the library, prepares every material and fills in the engine settings.
    pub fn setup(&self, channels: usize) -> anyhow::Result<Setup> {
        self.setup_playing(channels, None)
    }

    /// [`Self::setup`] for a command that plays only the materials `only` names (the
    /// others are not prepared: 30 ms each, a minute for a library of 2,000). A name the
    /// library does not hold is refused here, with the library's names.
    pub fn setup_playing(&self, channels: usize, only: Option<&[String]>) -> anyhow::Result<Setup> {
        let settings = self.play_settings();
        settings.check()?;
        let not_yet =
            self.library_created_by_fits && self.library.as_ref().is_some_and(|p| !p.exists());
        let (library, origin) = match &self.library {
            Some(p) if not_yet => (
                open(None)?.into_owned(),
                format!(
                    "the built-in library ({} does not exist yet: the first fit creates it)",
                    p.display()
                ),
            ),
            Some(p) => (open(Some(p))?.into_owned(), p.display().to_string()),
            None => (open(None)?.into_owned(), "the built-in library".to_string()),
        };
        anyhow::ensure!(!library.materials.is_empty(), "{origin} has no materials");
        let rate = settings.rate;
        let names: Option<Vec<&str>> = only.map(|n| n.iter().map(String::as_str).collect());
        let bank = settings
            .prepare(&library, names.as_deref())
            .with_context(|| format!("preparing the materials of {origin}"))?;
        let mut config = settings.engine_config(channels)?;
        if let Some(path) = &self.eq {
            let eq: EqualizerFile = document::load(path)?;
            anyhow::ensure!(
                eq.weights.rate == rate,
                "{} equalizes at {} Hz; use --audio-rate {}",
                path.display(),
                eq.weights.rate.0,
                eq.weights.rate.0
            );
            let mut weights = eq.weights;
            if let (Some(table), Some(user)) = (&self.eq_table, &self.user) {
                let users = document::load::<UserTable>(table)?;
                anyhow::ensure!(
                    users.freqs == weights.frequencies(),
                    "{} holds curves on another grid than {}",
                    table.display(),
                    path.display()
                );
                let (model, _) = user.model()?;
                // One user is no table to interpolate in: everyone gets that user's curve.
                if let [only] = users.entries.as_slice()
                    && only.params != model.params
                {
                    eprintln!(
                        "underfoot: warning: {} holds one user ({}): it cannot interpolate, \
                         so this user gets {}'s curve; add users (eq-table add) to \
                         interpolate between them",
                        table.display(),
                        only.name,
                        only.name
                    );
                }
                weights.gains_db = users
                    .interpolate(&model.params)
                    .with_context(|| format!("looking the user up in {}", table.display()))?;
            }
            eprintln!(
                "underfoot: equalizer {} ({}){}",
                path.display(),
                match eq.realisation {
                    Realisation::Bank => format!(
                        "filter bank, {:.1} ms of delay",
                        (weights.config.bins - 1) as f64 / rate.hz() * 1e3
                    ),
                    Realisation::LowDelay { taps } =>
                        format!("minimum-phase, {taps} taps, no delay"),
                },
                match (&self.eq_table, &self.user) {
                    (Some(table), Some(_)) =>
                        format!(", the user's curve interpolated from {}", table.display()),
                    _ => String::new(),
                }
            );
            config.compensation.equalizer = Some((weights, eq.realisation));
        }
        if let (Some(user), None) = (&self.user, &self.eq_table) {
            let (model, who) = user.model()?;
            eprintln!("underfoot: limb compensation Z_c of {who}");
            config.compensation.limb = Some(
                model
                    .compensation(rate, user.band()?)
                    .with_context(|| format!("the limb compensation of {who}"))?,
            );
        }
        Ok(Setup {
            library,
            origin,
            bank,
            config,
            voice: settings.voice(),
            nominal_step: settings.nominal_step(),
        })
    }
}

impl Setup {
    /// The slot of each name (one per channel, the last repeated for the rest).
    pub fn slots(&self, names: &[String], channels: usize) -> anyhow::Result<Vec<u16>> {
        let slots = names
            .iter()
            .map(|n| {
                self.bank
                    .slot(n)
                    .with_context(|| format!("in {}", self.origin))
            })
            .collect::<anyhow::Result<Vec<u16>>>()?;
        let last = *slots.last().context("no material given")?;
        Ok((0..channels)
            .map(|c| slots.get(c).copied().unwrap_or(last))
            .collect())
    }
}
