//! A compensation session end to end, on the simulated tile and simulated users: equalize
//! the unloaded tile, fit a user's limb from one loaded sweep, compensate them with the
//! engine's chain, and start a new user from the table of users without a sweep.
//!
//! The submodules hold the stage's own tests that need the simulators, which the unit
//! tests of `underfoot::compensation` cannot use (`sim` is above it).

mod adapt;
mod equalizer;
mod limb;
mod sweep;

use underfoot::compensation::CompensationError;
use underfoot::compensation::chain::{Compensation, CompensationChain};
use underfoot::compensation::equalizer::{
    EqualizerConfig, Realisation, SpectralWeights, equalize, flatness,
};
use underfoot::compensation::limb::{DEFAULT_G2, LimbFitConfig, LimbModel, LimbParams, fit_limb};
use underfoot::compensation::sweep::{Device, FrequencyResponse, Sweep, SweepConfig, measure};
use underfoot::compensation::table::{UserEntry, UserTable};
use underfoot::sim::{SimulatedTile, SimulatedUser, TileConfig};
use underfoot::units::{Band, Decibels, SampleRate};

const RATE: SampleRate = SampleRate(48_000);
const BAND: Band = Band::new(40.0, 1024.0);

fn tile() -> TileConfig {
    TileConfig {
        noise: Some(Decibels(-40.0)),
        ..TileConfig::default()
    }
}

fn user(params: LimbParams, seed: u64) -> SimulatedUser {
    let cfg = TileConfig { seed, ..tile() };
    SimulatedUser::new(&cfg, LimbModel::new(params, DEFAULT_G2, 1.0).unwrap(), RATE).unwrap()
}

/// A device heard through the engine's compensation chain.
struct Through<'a, D: Device> {
    chain: CompensationChain,
    device: &'a mut D,
}

impl<D: Device> Device for Through<'_, D> {
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
        self.chain.reset();
        let mut x: Vec<f32> = excitation.iter().map(|&v| v as f32).collect();
        self.chain.process(&mut x);
        let drive: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
        self.device.play(&drive)
    }
}

fn through<D: Device>(
    device: &mut D,
    compensation: &Compensation,
    sweep: &Sweep,
) -> FrequencyResponse {
    let chain = CompensationChain::new(compensation, RATE, 64).unwrap();
    measure(&mut Through { chain, device }, sweep).unwrap()
}

/// The user's equalizer curve: the device's weights plus the inverse of their limb.
fn curve(device: &SpectralWeights, params: LimbParams) -> Vec<f64> {
    let zc = LimbModel::new(params, DEFAULT_G2, 1.0)
        .unwrap()
        .compensation(RATE, BAND)
        .unwrap();
    let mut w = device.clone();
    w.add_in_band(|f| 20.0 * zc.response(RATE.omega(f)).norm().log10());
    w.gains_db
}

#[test]
fn a_session_compensates_simulated_users() {
    let sweep = Sweep::new(SweepConfig::new(RATE)).unwrap();
    let mut unloaded = SimulatedTile::new(&tile(), RATE).unwrap();
    let eq = equalize(
        &mut unloaded,
        &sweep,
        EqualizerConfig::default(),
        Realisation::default(),
        3,
        false,
    )
    .unwrap();
    let device_only = Compensation {
        equalizer: Some((eq.weights.clone(), Realisation::default())),
        limb: None,
    };

    // Anna stands on the tile: one sweep through the equalizer, then her limb fit.
    let anna = LimbParams::TABLE1_MEAN;
    let loaded = through(&mut user(anna, 11), &device_only, &sweep);
    let before = flatness(&loaded).unwrap().0.0;
    let db: Vec<f64> = loaded.magnitude_db().iter().map(|d| d.0).collect();
    let fit = fit_limb(&loaded.freqs, &db, &LimbFitConfig::default()).unwrap();
    let got = fit.model.params.to_array();
    for (g, t) in got.iter().zip(anna.to_array()) {
        assert!((g / t - 1.0).abs() < 0.05, "fitted {got:?} for {anna:?}");
    }

    // The engine's cascade (the compensation paper's Fig. 3): equalizer, then her Z_c.
    let compensated = Compensation {
        equalizer: device_only.equalizer.clone(),
        limb: Some(fit.model.compensation(RATE, BAND).unwrap()),
    };
    let after = flatness(&through(&mut user(anna, 12), &compensated, &sweep)).unwrap();
    eprintln!(
        "Anna: {before:.2} dB from flat with the device equalizer, {:.2} dB RMS ({:.2} peak) with her Z_c",
        after.0.0, after.1.0
    );
    assert!(before > 5.0);
    assert!(after.0.0 < 0.5 && after.1.0 < 1.5, "{after:?}");

    // A table of two users, and Carol between them, who starts without a sweep.
    let bob = LimbParams {
        b3_k3: 0.0055,
        k2_m2: 2.5e6,
        b2_m2: 1200.0,
    };
    let mut table = UserTable::new(eq.weights.frequencies()).unwrap();
    for (name, params) in [("anna", fit.model.params), ("bob", bob)] {
        table
            .add(UserEntry {
                name: name.into(),
                params,
                weights_db: curve(&eq.weights, params),
            })
            .unwrap();
    }
    let carol = LimbParams {
        b3_k3: 0.0045,
        k2_m2: 4.0e6,
        b2_m2: 1800.0,
    };
    let mut from_table = eq.weights.clone();
    from_table.gains_db = table.interpolate(&carol).unwrap();
    let a = &table.entries[0].weights_db;
    let b = &table.entries[1].weights_db;
    for ((v, x), y) in from_table.gains_db.iter().zip(a).zip(b) {
        assert!(*v >= x.min(*y) - 1e-9 && *v <= x.max(*y) + 1e-9);
    }
    let plain = flatness(&through(&mut user(carol, 13), &device_only, &sweep)).unwrap();
    let looked_up = Compensation {
        equalizer: Some((from_table, Realisation::default())),
        limb: None,
    };
    let table_eq = flatness(&through(&mut user(carol, 14), &looked_up, &sweep)).unwrap();
    eprintln!(
        "Carol: {:.2} dB from flat with the device equalizer, {:.2} dB RMS with the table's",
        plain.0.0, table_eq.0.0
    );
    assert!(
        plain.0.0 > 5.0 && table_eq.0.0 < 0.5,
        "{table_eq:?} vs {plain:?}"
    );
}
