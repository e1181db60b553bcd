//! `underfoot compare`: Table I on the shared recordings, and its agreement with `fit`.

use std::fs;
use std::path::{Path, PathBuf};

use crate::common::{assert_error, assert_ok, footsteps_dir, run, s, stdout};

#[test]
#[ignore = "slow tier: real recordings"]
fn compare_prints_table_one_for_the_papers_five_materials() {
    let Some(data) = footsteps_dir() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let json = dir.path().join("table.json");
    let plots = dir.path().join("fig4");
    // The IIR paper's broken stone, concrete, sand, earth and snow.
    let pairs: Vec<String> = ["gravel", "hard", "sand", "dirt", "snow"]
        .iter()
        .map(|m| format!("{m}={}", data.join(m).display()))
        .collect();
    let mut args = vec![
        "compare",
        "--json-out",
        json.to_str().unwrap(),
        "--plot-dir",
        plots.to_str().unwrap(),
    ];
    args.extend(pairs.iter().map(String::as_str));
    let o = run(&args);
    assert_ok(&o);
    let out = stdout(&o);
    eprintln!("{out}");
    let (table, in_time) = out
        .split_once("\n\n")
        .expect("Table I, then the steps in time");
    assert_eq!(table.lines().count(), 6, "a header and five rows:\n{table}");
    // The steps in time: an introduction, a blank line, a header, a rule and a row per
    // material.
    assert_eq!(in_time.lines().count(), 9, "{in_time}");
    let parsed: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&json).expect("json written")).expect("json");
    let rows = parsed["materials"].as_array().expect("materials");
    assert_eq!(rows.len(), 5);
    for row in rows {
        let name = row["name"].as_str().expect("name");
        for model in ["iir", "physical"] {
            let nrmse = row[model]["nrmse"].as_f64().expect("nrmse");
            let lsd = row[model]["lsd_db"].as_f64().expect("lsd_db");
            assert!(nrmse.is_finite() && nrmse >= 0.0, "{name} {model}");
            assert!(
                table.contains(&format!("{lsd:.2}")),
                "{name} {model} in the table"
            );
        }
        // The fitted filter is the closer of the two, as in the IIR paper; both are close.
        assert!(row["iir"]["lsd_db"].as_f64().unwrap() <= 1.0, "{name}");
        assert!(row["physical"]["lsd_db"].as_f64().unwrap() <= 3.0, "{name}");
        // In time: the recordings' steps and each model's, with the figures printed.
        let time = &row["time"];
        let recorded = time["recorded"]["duration_ms"]
            .as_f64()
            .expect("recorded D90");
        let line = in_time
            .lines()
            .find(|l| l.starts_with(name))
            .expect("a row in time");
        assert!(line.contains(&format!("{recorded:.0} / ")), "{line}");
        for model in ["iir", "physical"] {
            let steps = &time[model]["steps"];
            assert_eq!(steps["steps"].as_u64(), Some(48), "{name} {model}");
            let d90 = steps["duration_ms"].as_f64().expect("rendered D90");
            assert!(d90 > 0.0 && d90.is_finite(), "{name} {model}");
            assert!(time[model]["spectrum_db"].as_f64().expect("spectrum") < 4.0);
        }
        let svg = fs::read_to_string(plots.join(format!("{name}.svg"))).expect("plot");
        assert!(
            svg.contains("physical") && svg.contains("IIR"),
            "{name}: legend"
        );
    }
    // A folder without recordings is an error that names it.
    let empty = dir.path().join("empty");
    fs::create_dir(&empty).unwrap();
    let arg = format!("x={}", empty.display());
    let err = assert_error(&run(&["compare", &arg]));
    assert!(err.contains("holds no recording"), "{err}");
}

/// `fit` and `compare` on the same recordings print the same figures for the same
/// metric, and `compare`'s held-out figure is named apart from the calibration's.
#[test]
#[ignore = "slow tier: real recordings"]
fn fit_and_compare_agree_on_the_same_recordings() {
    let Some(data) = footsteps_dir() else {
        return;
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let (lib, report, json) = (
        dir.path().join("lib.json"),
        dir.path().join("report.json"),
        dir.path().join("table.json"),
    );
    let folder = data.join("gravel");
    let mut files: Vec<PathBuf> = fs::read_dir(&folder)
        .expect("gravel folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "ogg"))
        .collect();
    files.sort();
    let mut args = vec![
        "fit".to_string(),
        "--name".into(),
        "gravel".into(),
        "--library".into(),
        lib.display().to_string(),
        "--report".into(),
        report.display().to_string(),
    ];
    args.extend(files.iter().map(|f| f.display().to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let fitted = run(&args);
    assert_ok(&fitted);
    let pair = format!("gravel={}", folder.display());
    let compared = run(&["compare", "--json-out", s(&json), &pair]);
    assert_ok(&compared);

    let read = |p: &Path| -> serde_json::Value {
        serde_json::from_slice(&fs::read(p).expect("written")).expect("json")
    };
    let (r, t) = (read(&report), read(&json));
    let (fit, cmp) = (&r["materials"][0], &t["materials"][0]);
    for (a, b) in [
        (&fit["lsd_db"], &cmp["iir"]["lsd_db"]),
        (&fit["nrmse"], &cmp["iir"]["nrmse"]),
        (&fit["physical"]["lsd_db"], &cmp["physical"]["lsd_db"]),
        (&fit["physical"]["nrmse"], &cmp["physical"]["nrmse"]),
    ] {
        let (a, b) = (
            a.as_f64().expect("fit figure"),
            b.as_f64().expect("compare figure"),
        );
        assert_eq!(a, b, "fit {fit}\ncompare {cmp}");
    }
    // And as printed.
    let lsd = fit["physical"]["lsd_db"].as_f64().expect("physical LSD");
    let printed = format!("LSD {lsd:.2} dB (calibration render)");
    assert!(stdout(&fitted).contains(&printed), "{}", stdout(&fitted));
    assert!(stdout(&compared).contains(&format!("{lsd:.2}")));
    let held_out = cmp["physical"]["held_out_lsd_db"]
        .as_f64()
        .expect("held-out");
    assert!(held_out.is_finite() && held_out <= 3.0, "{held_out}");
    assert!(stdout(&compared).contains("held-out"));
}
