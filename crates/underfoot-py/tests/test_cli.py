"""The package against the command line, from outside: the same recordings fit to the same
coefficients, the same force renders to the same samples, and each reads the library files
the other writes. What the command line wrote is read with `json` and a RIFF walk
(conftest), never through the package, so a shared bug in both readers cannot hide.
"""

import json
import re

import numpy as np
import pytest

import underfoot

# The fit record's wall-clock time: the only figure of a fit that two runs may differ in.
TIMING_KEYS = {"fit_seconds"}


def without_timing(entry):
    """A library entry without the fit's wall-clock time."""
    entry = json.loads(json.dumps(entry))
    for key in TIMING_KEYS:
        entry["fit"].pop(key, None)
    return entry


# --- fit ------------------------------------------------------------------------------


def test_fit_gives_the_command_lines_sections_bit_for_bit(gravel, cli_gravel):
    sos = np.array(cli_gravel["filter"]["sos"], dtype=np.float64)
    assert gravel.sos.dtype == np.float64
    assert gravel.sos.shape == sos.shape
    # Exact: the same file decoding, analysis and search, not a close re-implementation.
    assert np.array_equal(gravel.sos, sos)
    assert np.array_equal(np.array(json.loads(gravel.to_json())["filter"]["sos"]), sos)


def test_fit_gives_the_command_lines_order_and_fit_figures(gravel, cli_gravel):
    assert gravel.order == cli_gravel["order"]
    assert gravel.analysis_rate == cli_gravel["sample_rate"]
    assert list(gravel.band) == cli_gravel["band_hz"]
    assert gravel.level_db == cli_gravel["level_db"]
    assert gravel.poor_fit is bool(cli_gravel["fit"].get("poor_fit", False))
    for key in ("nrmse", "lsd_db", "strikes", "grid_hz", "measured", "model", "worst"):
        assert gravel.fit[key] == cli_gravel["fit"][key], key


def test_fit_gives_the_command_lines_whole_library_entry(gravel, cli_gravel):
    # Excitation, recorded steps in time, physical model, sources: everything a library
    # file keeps of a material, so that a material fitted in Python plays as the CLI's.
    assert without_timing(json.loads(gravel.to_json())) == without_timing(cli_gravel)


def test_fit_response_is_the_fit_records_grid(gravel, cli_gravel):
    freqs, measured, model = gravel.response()
    assert np.array_equal(freqs, cli_gravel["fit"]["grid_hz"])
    assert np.array_equal(measured, cli_gravel["fit"]["measured"])
    assert np.array_equal(model, cli_gravel["fit"]["model"])


# --- render ---------------------------------------------------------------------------


def cli_render(run_cli, read_wav, tmp_path, *args):
    """Renders with the command line; the WAV as ((channels, frames), rate) and the
    strike count it printed."""
    out = tmp_path / "cli.wav"
    done = run_cli("render", "--out", out, *args)
    strikes = re.search(r"(\d+) strike\(s\)", done.stdout)
    assert strikes, f"no strike count in the CLI's summary: {done.stdout!r}"
    samples, rate = read_wav(out)
    return samples, rate, int(strikes.group(1))


def assert_same_render(render, cli_samples, cli_rate, cli_strikes):
    assert render.rate == cli_rate
    assert render.samples.dtype == np.float32
    assert render.samples.shape == cli_samples.shape
    assert len(render.strikes) == cli_strikes == render.telemetry["strikes"]
    # A silent render would make every comparison below pass.
    assert np.max(np.abs(render.samples)) > 0
    assert np.array_equal(render.samples, cli_samples)


@pytest.mark.parametrize(
    "force_rate, sensor_rate, cli_sensor_rate",
    [
        (500.0, None, 500),  # Python's default sensor rate is the force's rate
        (1000.0, 1000.0, 1000),
        (1000.0, None, 1000),
        # A sensor rate other than the force's: proves it is passed on, not defaulted.
        (1000.0, 250.0, 250),
    ],
)
def test_render_of_a_force_array_is_the_command_lines_render_of_its_csv(
    tmp_path, run_cli, read_wav, force_csv, synthetic_walk, force_rate, sensor_rate, cli_sensor_rate
):
    force = synthetic_walk(2, 4.0, force_rate, load=800.0, stance=0.6, period=1.1)
    csv = force_csv(tmp_path / "force.csv", force, force_rate)
    samples, rate, strikes = cli_render(
        run_cli, read_wav, tmp_path,
        "--material", "gravel,sand", "--force", csv, "--sensor-rate", cli_sensor_rate,
    )
    kwargs = {} if sensor_rate is None else {"sensor_rate": sensor_rate}
    render = underfoot.render(["gravel", "sand"], force, force_rate, **kwargs)
    assert strikes > 0
    assert_same_render(render, samples, rate, strikes)


def test_render_of_a_one_channel_1d_force_is_the_command_lines(
    tmp_path, run_cli, read_wav, force_csv, synthetic_walk
):
    force = synthetic_walk(1, 3.0, 500.0)[0]
    csv = force_csv(tmp_path / "force.csv", force, 500.0)
    expected = cli_render(run_cli, read_wav, tmp_path, "--material", "snow", "--force", csv)
    assert_same_render(underfoot.render("snow", force, 500.0), *expected)


def test_render_of_a_gait_is_the_command_lines(tmp_path, run_cli, read_wav):
    expected = cli_render(
        run_cli, read_wav, tmp_path, "--material", "gravel", "--gait", "steps=4,channels=1"
    )
    assert_same_render(underfoot.render("gravel", gait="steps=4,channels=1"), *expected)


def test_render_of_the_physical_model_with_its_settings_is_the_command_lines(
    tmp_path, run_cli, read_wav
):
    gait = "steps=3,channels=2,seed=5"
    expected = cli_render(
        run_cli, read_wav, tmp_path,
        "--material", "gravel,snow", "--gait", gait, "--model", "physical",
        "--seed", "7", "--gain-db", "-4.5",
    )
    render = underfoot.render(["gravel", "snow"], gait=gait, model="physical", seed=7, gain_db=-4.5)
    assert_same_render(render, *expected)
    # The settings reach the engine: the default seed and gain play something else.
    default = underfoot.render(["gravel", "snow"], gait=gait, model="physical")
    assert not np.array_equal(default.samples, render.samples)


def test_render_unpacks_to_samples_and_strikes():
    render = underfoot.render("gravel", gait="steps=2,channels=1")
    samples, strikes = render
    assert np.array_equal(samples, render.samples)
    assert list(strikes) == list(render.strikes)
    strike = strikes[0]
    assert strike.channel == 0
    assert strike.material == "gravel"
    assert strike.time == pytest.approx(strike.frame / render.rate)


# --- library files, both ways ---------------------------------------------------------


@pytest.fixture
def python_library(tmp_path, gravel):
    """A library saved by the package: two built-in materials and the fitted gravel."""
    library = underfoot.Library.builtin()
    kept = ["sand", "snow"]
    for name in list(library.names):
        if name not in kept:
            library.remove(name)
    assert library.names == kept
    assert library.add(gravel) is False  # gravel was removed above: added, not replaced
    path = tmp_path / "python-library.json"
    library.save(path)
    return path, kept + ["gravel"]


def test_a_library_saved_by_python_is_listed_by_the_command_line(python_library, run_cli):
    path, names = python_library
    listed = json.loads(run_cli("library", "list", "--library", path, "--json").stdout)
    assert sorted(m["name"] for m in listed) == sorted(names)
    table = run_cli("library", "list", "--library", path).stdout
    for name in names:
        assert re.search(rf"^{name}\s", table, re.M), f"{name} not in:\n{table}"


def test_a_library_saved_by_python_holds_the_material_as_to_json_gives_it(python_library, gravel):
    path, _ = python_library
    with open(path, encoding="utf-8") as f:
        saved = json.load(f)
    assert saved["format"] == "underfoot.library/3"
    (entry,) = [m for m in saved["materials"] if m["name"] == "gravel"]
    assert entry == json.loads(gravel.to_json())


def test_a_library_saved_by_python_renders_in_the_command_line_as_in_python(
    python_library, gravel, tmp_path, run_cli, read_wav
):
    path, _ = python_library
    gait = "steps=3,channels=2"
    expected = cli_render(
        run_cli, read_wav, tmp_path,
        "--library", path, "--material", "gravel,sand", "--gait", gait,
    )
    assert_same_render(underfoot.render(["gravel", "sand"], gait=gait, library=path), *expected)
    # The Material object itself plays as the file does.
    sand = underfoot.Library.load(path)["sand"]
    assert_same_render(underfoot.render([gravel, sand], gait=gait), *expected)


def test_a_library_written_by_the_command_line_loads_in_python(cli_library, cli_gravel):
    library = underfoot.Library.load(cli_library)
    assert library.names == ["gravel"]
    assert "gravel" in library and len(library) == 1
    # The whole entry, the fit's timing included: it is the same file.
    assert json.loads(library["gravel"].to_json()) == cli_gravel
    assert json.loads(library.to_json())["materials"] == [cli_gravel]
