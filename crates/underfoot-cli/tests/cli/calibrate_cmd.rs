//! `underfoot calibrate` (and `eq-table`): the compensation session on the simulated tile, a sound card without the `audio` feature, the force sensors.

use std::fs;

use crate::common::{assert_error, assert_ok, run, s, stderr, stdout};

/// The README's compensation session on the simulated tile: measure, equalize, fit a
/// user, tabulate users, and render through the compensation.
#[test]
#[ignore = "slow tier: refits"]
fn a_compensation_session_on_the_simulated_tile() {
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);
    let unloaded = p("tile-unloaded.json");
    let o = run(&["calibrate", "sweep", "--out", s(&unloaded)]);
    assert_ok(&o);
    assert!(stdout(&o).contains("2.83 dB from flat"), "{}", stdout(&o));

    let eq = p("tile-eq.json");
    let plot = p("eq.svg");
    let o = run(&[
        "calibrate",
        "equalize",
        "--device-under-test",
        s(&unloaded),
        "--passes",
        "3",
        "--out",
        s(&eq),
        "--plot",
        s(&plot),
    ]);
    assert_ok(&o);
    // Pass 3's RMS deviation, from the table: below the compensation paper's 0.28 dB.
    let last = stdout(&o)
        .lines()
        .find(|l| l.trim_start().starts_with("3 "))
        .map(|l| l.split_whitespace().nth(1).unwrap().parse::<f64>().unwrap())
        .expect("a row for pass 3");
    assert!(last < 0.28, "{}", stdout(&o));
    assert!(fs::metadata(&plot).unwrap().len() > 1000);

    // Two users stand on the tile; their limb models go into a table.
    let table = p("users.json");
    for (name, load) in [("anna", "table1"), ("bob", "0.0055,2.5e6,1200")] {
        let sweep = p(&format!("{name}-sweep.json"));
        assert_ok(&run(&[
            "calibrate",
            "sweep",
            "--load",
            load,
            "--eq",
            s(&eq),
            "--out",
            s(&sweep),
        ]));
        let limb = p(&format!("{name}.json"));
        let o = run(&[
            "calibrate",
            "limb",
            "--sweeps",
            s(&sweep),
            "--out",
            s(&limb),
        ]);
        assert_ok(&o);
        assert!(stdout(&o).contains("b3/k3"), "{}", stdout(&o));
        assert_ok(&run(&[
            "eq-table",
            "add",
            "--user",
            s(&limb),
            "--table",
            s(&table),
            "--eq",
            s(&eq),
        ]));
    }
    let o = run(&["eq-table", "list", "--table", s(&table)]);
    assert_ok(&o);
    assert!(stdout(&o).contains("anna") && stdout(&o).contains("bob"));
    // The verbs of `library`: list, show NAME, remove NAME (issue 16).
    let o = run(&["eq-table", "show", "anna", "--table", s(&table)]);
    assert_ok(&o);
    assert!(stdout(&o).contains("b3/k3") && stdout(&o).contains("equalizer (dB)"));
    // The curve is measured over 40-1024 Hz: above it, it never boosts (it held +12 dB
    // at 1125-1418 Hz before).
    let above: Vec<(f64, f64)> = stdout(&o)
        .lines()
        .filter_map(|l| {
            let mut cols = l.split_whitespace().map(str::parse::<f64>);
            Some((cols.next()?.ok()?, cols.next()?.ok()?))
        })
        .filter(|&(hz, _)| hz > 1100.0)
        .collect();
    assert!(above.len() > 5, "{}", stdout(&o));
    assert!(above.iter().all(|&(_, db)| db <= 0.0), "{above:?}");
    let copy = p("users-copy.json");
    fs::copy(&table, &copy).unwrap();
    assert_ok(&run(&["eq-table", "remove", "bob", "--table", s(&copy)]));
    let o = run(&["eq-table", "list", "--table", s(&copy)]);
    assert!(stdout(&o).contains("anna") && !stdout(&o).contains("bob"));
    let e = assert_error(&run(&["eq-table", "remove", "bob", "--table", s(&copy)]));
    assert!(
        e.contains("no user \"bob\"") && e.contains("users: anna"),
        "{e}"
    );

    // Rendering through the equalizer and Anna's limb filter, and through the table; a
    // table of one user cannot interpolate, which is said, not silently Anna's curve for
    // all.
    for (extra, one_user) in [
        (vec!["--user", s(&p("anna.json"))], false),
        (
            vec!["--eq-table", s(&table), "--user", "0.0045,4e6,1800"],
            false,
        ),
        (
            vec!["--eq-table", s(&copy), "--user", "0.0045,4e6,1800"],
            true,
        ),
    ] {
        let wav = p("walk.wav");
        let mut args = vec![
            "render",
            "--material",
            "snow",
            "--gait",
            "steps=2",
            "--out",
            s(&wav),
            "--eq",
            s(&eq),
        ];
        args.extend(extra);
        let o = run(&args);
        assert_ok(&o);
        assert!(fs::metadata(&wav).unwrap().len() > 1000);
        if one_user {
            assert!(
                stderr(&o).contains("holds one user (anna): it cannot interpolate"),
                "{}",
                stderr(&o)
            );
        } else {
            assert!(!stderr(&o).contains("holds one user"), "{}", stderr(&o));
        }
    }

    // Another command's file, a missing file and a newer version are clean errors, and a
    // failed run leaves the files alone.
    let before = fs::read(&eq).unwrap();
    let err = assert_error(&run(&[
        "calibrate",
        "equalize",
        "--device-under-test",
        s(&eq),
        "--out",
        s(&p("eq-again.json")),
    ]));
    assert!(err.contains("format \"underfoot.equalizer/1\""), "{err}");
    assert_eq!(fs::read(&eq).unwrap(), before);
    let newer = p("newer.json");
    fs::write(
        &newer,
        fs::read_to_string(&unloaded)
            .unwrap()
            .replace("frequency-response/1", "frequency-response/2"),
    )
    .unwrap();
    let err = assert_error(&run(&[
        "calibrate",
        "limb",
        "--sweeps",
        s(&newer),
        "--out",
        s(&p("x.json")),
    ]));
    assert!(err.contains("version 2"), "{err}");
    assert_error(&run(&[
        "render",
        "--material",
        "snow",
        "--gait",
        "steps=2",
        "--out",
        s(&p("w.wav")),
        "--eq",
        s(&p("missing.json")),
    ]));
}

/// `--device-under-test audio` in a build without the `audio` feature says so, rather than treating
/// `audio` as a file name.
#[cfg(not(feature = "audio"))]
#[test]
fn calibrate_on_a_sound_card_needs_the_audio_feature() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("tile.json");
    let o = run(&[
        "calibrate",
        "sweep",
        "--device-under-test",
        "audio",
        "--output-device",
        "hw:1",
        "--out",
        s(&out),
    ]);
    let message = assert_error(&o);
    assert!(message.contains("no audio support"), "{message}");
    assert!(message.contains("hw:1"), "{message}");
    assert!(!out.exists());
}

#[test]
fn calibrate_sensors_fits_saves_and_reports_residuals() {
    let dir = tempfile::tempdir().unwrap();
    let readings = dir.path().join("scale.csv");
    let mut csv = String::from("# lab scale session\nsensor,raw,load_n\n");
    for i in 0..30 {
        let load = 30.0 * f64::from(i);
        for (name, r0) in [("heel", 200.0), ("toe", 150.0)] {
            let raw = r0 + (load / 0.0119_f64).powf(1.0 / 1.4);
            csv.push_str(&format!("{name},{raw:.1},{load}\n"));
        }
    }
    fs::write(&readings, csv).unwrap();
    let out = dir.path().join("sensors.json");
    for kind in ["power", "piecewise"] {
        let o = run(&[
            "calibrate",
            "sensors",
            "--readings",
            s(&readings),
            "--out",
            s(&out),
            "--kind",
            kind,
        ]);
        assert_ok(&o);
        let text = stdout(&o);
        assert!(
            text.contains("heel") && text.contains("toe") && text.contains("rms N"),
            "{text}"
        );
        let cal = underfoot::force::calibration::SensorCalibration::load(&out).unwrap();
        assert_eq!(cal.sensors.len(), 2);
    }

    fs::write(&readings, "sensor,raw,load_n\nheel,200,0\nheel,oops,10\n").unwrap();
    let message = assert_error(&run(&[
        "calibrate",
        "sensors",
        "--readings",
        s(&readings),
        "--out",
        s(&out),
    ]));
    assert!(
        message.contains("scale.csv") && message.contains("line 3"),
        "{message}"
    );
}

/// A measured-response file of a device as uneven as the compensation paper's tile (a
/// +24 dB mid-band resonance between steep roll-offs, 13 dB RMS from flat), as a user
/// would bring one.
fn steep_device(path: &std::path::Path) {
    use underfoot::compensation::files::ResponseFile;
    use underfoot::compensation::sweep::FrequencyResponse;
    use underfoot::sim::{SimulatedTile, TileConfig, TileResonance};
    use underfoot::units::{Band, Decibels, Hz, SampleRate};
    let rate = SampleRate(48_000);
    let band = Band::new(40.0, 1024.0);
    let tile = SimulatedTile::new(
        &TileConfig {
            modes: vec![TileResonance {
                freq: Hz(250.0),
                q: 1.4,
                gain: Decibels(24.0),
            }],
            highpass: Hz(240.0),
            lowpass: Hz(280.0),
            ..TileConfig::default()
        },
        rate,
    )
    .unwrap();
    let freqs = band.log_grid(128);
    let response = freqs.iter().map(|&f| tile.true_response(f)).collect();
    let file = ResponseFile::new(
        &FrequencyResponse { freqs, response },
        rate,
        band,
        1,
        "a steep device",
    );
    underfoot::document::save(path, &file).unwrap();
}

#[test]
fn an_uneven_device_says_where_the_boost_is_capped_and_flattens_when_allowed() {
    let dir = tempfile::tempdir().unwrap();
    let device = dir.path().join("steep.json");
    steep_device(&device);
    let eq = dir.path().join("eq.json");
    let rows = |out: &str| -> Vec<f64> {
        out.lines()
            .filter(|l| l.trim_start().starts_with(|c: char| c.is_ascii_digit()))
            .map(|l| l.split_whitespace().nth(1).unwrap().parse::<f64>().unwrap())
            .collect()
    };
    // The default +12 dB cap binds at the low roll-off: said, with what it leaves.
    let o = run(&[
        "calibrate",
        "equalize",
        "--device-under-test",
        s(&device),
        "--out",
        s(&eq),
    ]);
    assert_ok(&o);
    let out = stdout(&o);
    assert!(
        out.contains("capped by the +12 dB boost bound at 47-59 Hz"),
        "{out}"
    );
    assert!(
        out.contains("dB RMS of the deviation is left there"),
        "{out}"
    );
    // Allowed 40 dB: no pass worse than the one before, within 0.3 dB after pass 3 (the
    // compensation paper: 15.3, 0.90, 0.28), and nothing capped.
    let o = run(&[
        "calibrate",
        "equalize",
        "--device-under-test",
        s(&device),
        "--out",
        s(&eq),
        "--max-boost-db",
        "40",
    ]);
    assert_ok(&o);
    let out = stdout(&o);
    let passes = rows(&out);
    assert_eq!(passes.len(), 3, "{out}");
    assert!(passes[0] > 12.0, "{out}");
    assert!(passes.windows(2).all(|w| w[1] <= w[0]), "{out}");
    assert!(passes[2] <= 0.3, "{out}");
    assert!(!out.contains("capped"), "{out}");
    assert!(out.contains("sized automatically"), "{out}");
    // The file keeps each pass's figures and whether it was kept.
    let text = fs::read_to_string(&eq).unwrap();
    assert!(text.contains("\"kept\": true"), "{text}");
}

/// A replayed measurement is an input like any other: naming it (or a symlink to it) as the
/// output is refused, and the measurement stays as it was. Both commands replaced it.
#[test]
fn a_replayed_device_is_never_its_own_output() {
    let dir = tempfile::tempdir().expect("tempdir");
    let device = dir.path().join("x.json");
    assert_ok(&run(&["calibrate", "sweep", "--out", s(&device)]));
    let before = fs::read(&device).expect("read the measurement");
    let link = dir.path().join("link.json");
    #[cfg(unix)]
    std::os::unix::fs::symlink(&device, &link).expect("symlink");
    #[cfg(not(unix))]
    fs::copy(&device, &link).expect("copy");
    for command in ["sweep", "equalize"] {
        for out in [&device, &link] {
            let o = run(&[
                "calibrate",
                command,
                "--device-under-test",
                s(&device),
                "--out",
                s(out),
            ]);
            let message = assert_error(&o);
            assert!(
                message.contains("which this command reads"),
                "{command} --out {}: {message}",
                out.display()
            );
            assert_eq!(
                fs::read(&device).unwrap(),
                before,
                "{command} changed x.json"
            );
        }
    }
}

/// `--bins` states the range it enforces, the equalizer's own (it named `taps` and
/// 1-65536, and refused 2^20, which the equalizer takes).
#[test]
fn bins_are_refused_with_the_range_the_equalizer_takes() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("eq.json");
    for bad in ["0", "100", "2097152"] {
        let o = run(&[
            "calibrate",
            "equalize",
            "--device-under-test",
            "simulated",
            "--bins",
            bad,
            "--out",
            s(&out),
        ]);
        assert_eq!(o.status.code(), Some(2), "--bins {bad}");
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(
            e.contains(&format!(
                "--bins \"{bad}\": expected a power of two from 16 to 1048576"
            )),
            "{e}"
        );
    }
    assert_ok(&run(&[
        "calibrate",
        "equalize",
        "--device-under-test",
        "simulated",
        "--bins",
        "1048576",
        "--out",
        s(&out),
    ]));
}
