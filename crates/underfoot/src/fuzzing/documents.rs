//! The JSON documents: a material library, and the compensation files (response,
//! equalizer, limb model, user table).

use super::text;
use crate::compensation::files::{EqualizerFile, LimbFile, ResponseFile};
use crate::compensation::table::{UserEntry, UserTable};
use crate::document;
use crate::material::Library;
use crate::units::{Band, SampleRate};

// ---- material library (JSON) ----

pub(super) fn run_library_json(data: &[u8]) {
    let Ok(library) = Library::from_json(&text(data), "fuzz") else {
        return;
    };
    // What loaded is playable: every filter is stable, and the library saves and reloads.
    for name in library.names() {
        let model = library.get(name).expect("a listed name is in the library");
        if let Some(sos) = model.sos() {
            assert!(sos.is_stable(), "{name}: a loaded filter is unstable");
        }
    }
    let again = Library::from_json(&library.to_json(), "fuzz, saved");
    assert!(again.is_ok(), "a loaded library does not reload: {again:?}");
}

pub(super) fn seeds_library_json() -> Vec<Vec<u8>> {
    vec![
        include_bytes!("../material/builtin.json").to_vec(),
        Library::new().to_json().into_bytes(),
    ]
}

// ---- compensation files: response, equalizer, limb model, user table (JSON) ----

pub(super) fn run_compensation_json(data: &[u8]) {
    let text = text(data);
    let origin = "fuzz.json";
    let _ = document::from_json::<ResponseFile>(&text, origin).map(|r| r.response());
    let _ = document::from_json::<EqualizerFile>(&text, origin);
    let _ = document::from_json::<LimbFile>(&text, origin);
    if let Ok(table) = document::from_json::<UserTable>(&text, origin)
        && let Some(first) = table.entries.first()
    {
        let _ = table.interpolate(&first.params);
    }
}

pub(super) fn seeds_compensation_json() -> Vec<Vec<u8>> {
    use crate::compensation::equalizer::{EqualizerConfig, Realisation, SpectralWeights};
    use crate::compensation::limb::{LimbModel, LimbParams};
    use crate::compensation::sweep::FrequencyResponse;
    use crate::units::Hz;
    use num_complex::Complex64;

    let rate = SampleRate(8000);
    let band = Band::new(40.0, 1024.0);
    let response = FrequencyResponse {
        freqs: vec![Hz(40.0), Hz(100.0), Hz(1000.0)],
        response: vec![
            Complex64::new(1.0, 0.0),
            Complex64::new(0.0, 2.0),
            Complex64::new(-0.5, 0.0),
        ],
    };
    let weights =
        SpectralWeights::flat(EqualizerConfig::default(), rate).expect("the default config");
    let limb = LimbModel::new(LimbParams::TABLE1_MEAN, 0.5, 1.0).expect("Table 1's mean");
    let grid = band.log_grid(8);
    let table = UserTable {
        entries: vec![UserEntry {
            name: "a".into(),
            params: LimbParams::TABLE1_MEAN,
            weights_db: (0..grid.len()).map(|i| i as f64 * 0.5).collect(),
        }],
        freqs: grid,
    };
    let json = |v: Result<String, document::DocumentError>| v.expect("valid").into_bytes();
    let response = ResponseFile::new(&response, rate, band, 3, "seed");
    // A file of the first version, with `"kind"` and `"version"` instead of the tag, so
    // that the legacy header is explored too.
    let legacy = document::to_json(&response, "seed")
        .expect("valid")
        .replace(
            "\"format\": \"underfoot.frequency-response/1\"",
            "\"kind\": \"frequency-response\",\n  \"version\": 1",
        );
    vec![
        json(document::to_json(&response, "seed")),
        json(document::to_json(
            &EqualizerFile::new(weights, Realisation::LowDelay { taps: 64 }, vec![], "seed"),
            "seed",
        )),
        json(document::to_json(
            &LimbFile::new(limb, band, 0.3, "seed"),
            "seed",
        )),
        json(document::to_json(&table, "seed")),
        legacy.into_bytes(),
    ]
}
