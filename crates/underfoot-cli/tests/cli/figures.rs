//! Every figure every plot command draws, as SVG and as PNG with text, passes the layout
//! check the binary runs before it writes a figure: no text over another, none past the
//! figure's edge, no empty axis. The binary reports a failed check as a warning naming
//! the figure ("underfoot: warning: figure F: ..."); here any such warning fails.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::common::{assert_ok, bin, footsteps_dir, s, stderr};

/// Fonts the binary looks for by itself (see its `plot::font`): the first found draws
/// the PNGs' text here too.
const FONTS: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
];

/// A font for PNG text, or `None` (with a note) when the machine has none and
/// `UNDERFOOT_REQUIRE_FONT` is not `1` (CI installs one and sets it).
fn font() -> Option<PathBuf> {
    let found = FONTS.iter().map(PathBuf::from).find(|p| p.is_file());
    if found.is_none() {
        assert!(
            std::env::var("UNDERFOOT_REQUIRE_FONT")
                .ok()
                .is_none_or(|v| v != "1"),
            "UNDERFOOT_REQUIRE_FONT=1 but none of {FONTS:?} exists"
        );
        eprintln!("note: no font found: PNG figures are checked without their text");
    }
    found
}

fn run_with_font(args: &[&str], font: Option<&Path>) -> Output {
    Command::new(bin())
        .args(args)
        .env("UNDERFOOT_FONT", font.map_or("", s))
        .output()
        .expect("run underfoot")
}

/// Runs a plot command and checks that it wrote `figures` and its layout check passed.
fn check(args: &[&str], figures: &[&Path], font: Option<&Path>) {
    let o = run_with_font(args, font);
    assert_ok(&o);
    let err = stderr(&o);
    let problems: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("underfoot: warning: figure") || l.contains("no font found"))
        .collect();
    assert!(problems.is_empty(), "{args:?}:\n{}", problems.join("\n"));
    for f in figures {
        let bytes = std::fs::read(f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        let magic: &[u8] = if f.extension().is_some_and(|e| e == "png") {
            b"\x89PNG"
        } else {
            b"<svg"
        };
        assert!(
            bytes.starts_with(magic),
            "{} is not what it says",
            f.display()
        );
    }
}

#[test]
#[ignore = "slow tier: fits and sweeps"]
fn every_figure_of_every_plot_command_passes_the_layout_check() {
    let font = font();
    let font = font.as_deref();
    let dir = tempfile::tempdir().unwrap();
    let p = |name: &str| dir.path().join(name);

    // demo's spectrogram, spectra and steps, for both models, in both formats.
    for (model, ext) in [("iir", "svg"), ("physical", "svg"), ("iir", "png")] {
        let out = p(&format!("demo-{model}-{ext}"));
        check(
            &[
                "demo",
                "--out-dir",
                s(&out),
                "--model",
                model,
                "--steps",
                "4",
                "--plot-format",
                ext,
            ],
            &[
                &out.join(format!("walk.{ext}")),
                &out.join(format!("spectra.{ext}")),
                &out.join(format!("steps.{ext}")),
            ],
            font,
        );
    }

    // A short recorded session for `session show`.
    let session = p("session");
    assert_ok(&run_with_font(
        &[
            "run",
            "--input",
            "gait:steps=3",
            "--output",
            "null",
            "--record",
            s(&session),
        ],
        font,
    ));

    for ext in ["svg", "png"] {
        let f = |name: &str| p(&format!("{name}.{ext}"));
        let tile = p(&format!("tile-{ext}.json"));
        check(
            &[
                "calibrate",
                "sweep",
                "--out",
                s(&tile),
                "--plot",
                s(&f("tile")),
            ],
            &[&f("tile")],
            font,
        );
        let eq = p(&format!("eq-{ext}.json"));
        check(
            &[
                "calibrate",
                "equalize",
                "--device-under-test",
                s(&tile),
                "--passes",
                "3",
                "--out",
                s(&eq),
                "--plot",
                s(&f("eq")),
            ],
            &[&f("eq")],
            font,
        );
        let sweeps = p(&format!("anna-sweeps-{ext}.json"));
        assert_ok(&run_with_font(
            &[
                "calibrate",
                "sweep",
                "--load",
                "table1",
                "--eq",
                s(&eq),
                "--out",
                s(&sweeps),
            ],
            font,
        ));
        check(
            &[
                "calibrate",
                "limb",
                "--sweeps",
                s(&sweeps),
                "--out",
                s(&p(&format!("anna-{ext}.json"))),
                "--plot",
                s(&f("limb")),
            ],
            &[&f("limb")],
            font,
        );
        check(
            &["session", "show", s(&session), "--plot", s(&f("session"))],
            &[&f("session")],
            font,
        );

        let Some(data) = footsteps_dir() else {
            continue;
        };
        let gravel: Vec<String> = std::fs::read_dir(data.join("gravel"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "ogg"))
            .map(|p| s(&p).to_owned())
            .collect();
        let library = p(&format!("lib-{ext}.json"));
        let mut args = vec!["fit", "--name", "gravel", "--library", s(&library)];
        let plot = f("fit");
        args.extend(["--plot", s(&plot)]);
        args.extend(gravel.iter().map(String::as_str));
        check(&args, &[&plot], font);
        if ext == "png" {
            // At 2.5 times: the same figure at 1800x1050, saying 240 dpi so that it
            // prints at the base figure's 7.5 inches.
            let (big, library) = (p("fit-x2.5.png"), p("lib-x2.5.json"));
            let mut scaled = vec!["fit", "--name", "gravel", "--library", s(&library)];
            scaled.extend(["--plot", s(&big), "--plot-scale", "2.5"]);
            scaled.extend(gravel.iter().map(String::as_str));
            check(&scaled, &[&big], font);
            let reader =
                png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&big).unwrap()))
                    .read_info()
                    .unwrap();
            let info = reader.info();
            assert_eq!((info.width, info.height), (1800, 1050));
            let dims = info.pixel_dims.expect("a resolution");
            assert_eq!(dims.unit, png::Unit::Meter);
            assert!(
                (f64::from(dims.xppu) * 0.0254 - 240.0).abs() < 0.1,
                "{dims:?}"
            );
        }

        let figs = p(&format!("fig4-{ext}"));
        let hard = format!("hard={}", s(&data.join("hard")));
        let snow = format!("snow={}", s(&data.join("snow")));
        check(
            &[
                "compare",
                "--plot-dir",
                s(&figs),
                "--plot-format",
                ext,
                "--steps",
                "8",
                &hard,
                &snow,
            ],
            &[
                &figs.join(format!("hard.{ext}")),
                &figs.join(format!("snow.{ext}")),
            ],
            font,
        );
    }
}
