"""The analysis functions (those `underfoot compare` uses) and session records, from Python:
each checked against what the same library said another way (the fit's strike count, a
material's recorded step statistics, a session folder read with csv/json).
"""

import csv
import json

import numpy as np
import pytest

import underfoot


@pytest.fixture(scope="module")
def walk():
    """A rendered walk on built-in gravel, one channel, and its strikes' times."""
    render = underfoot.render("gravel", gait="steps=5,channels=1")
    assert len(render.strikes) == 5
    return render, [s.time for s in render.strikes]


# --- measure --------------------------------------------------------------------------


def test_measure_finds_one_strike_in_each_gravel_recording(gravel_files, gravel):
    response = underfoot.measure(gravel_files)
    # One heel strike per file (the recordings' layout), as many as the fit averaged.
    assert sorted(index for index, _ in response.strikes) == list(range(len(gravel_files)))
    assert len(response.strikes) == gravel.fit["strikes"]
    assert all(np.isfinite(onset) and onset >= 0 for _, onset in response.strikes)


def test_measure_gives_a_spectrum_up_to_half_the_analysis_rate(gravel_files):
    response = underfoot.measure(gravel_files, analysis_rate=2000)
    freqs = np.asarray(response.freqs)
    assert freqs[0] == 0 and freqs[-1] == pytest.approx(1000.0)
    assert np.all(np.diff(freqs) > 0)
    assert np.shape(response.magnitude) == freqs.shape == np.shape(response.raw)
    assert np.all(np.isfinite(response.magnitude)) and np.max(response.magnitude) > 0
    # `magnitude` is `raw` smoothed over fractions of an octave.
    assert not np.array_equal(response.magnitude, response.raw)
    # The option reaches the analysis: without the time-domain denoiser the spectrum differs.
    plain = underfoot.measure(gravel_files, analysis_rate=2000, savgol="off")
    assert not np.array_equal(plain.raw, response.raw)


def test_measure_of_an_array_finds_its_strike(walk):
    render, times = walk
    response = underfoot.measure(render.samples[0], render.rate)
    assert all(index == 0 for index, _ in response.strikes)
    # Every step the engine played is found where it starts (a long crackle may be
    # taken for a strike of its own as well: a detector for recordings, not renders).
    onsets = np.array([onset for _, onset in response.strikes])
    for strike in times:
        assert np.min(np.abs(onsets - strike)) < 0.025, (strike, onsets)


# --- steps ----------------------------------------------------------------------------


def test_steps_at_known_strikes_are_one_per_strike_each_just_after_it(walk):
    render, times = walk
    steps = underfoot.steps(render.samples[0], render.rate, strikes=times)
    assert len(steps) == len(times)
    for step, strike in zip(steps, times):
        # A render's vibration starts on its strike's frame; the onset is where the
        # band-limited envelope rises, which the zero-phase band-pass rings ahead of that
        # (the search starts 50 ms ahead: `onsets_near`), never after the 5 ms envelope.
        assert strike - 0.05 <= step["onset_s"] <= strike + 0.005, (step["onset_s"], strike)
        assert step["energy"] > 0
        assert 0 < step["duration_ms"] < 650  # a step's stretch is 50 ms + 600 ms
        assert max(step["decay_db"]) == 0.0  # dB re its loudest bin
        assert all(level <= 0 for _, level in step["events"])


def test_steps_found_without_strikes_are_the_same_steps(walk):
    render, times = walk
    found = underfoot.steps(render.samples[0], render.rate)
    told = underfoot.steps(render.samples[0], render.rate, strikes=times)
    assert len(found) == len(told)
    for a, b in zip(found, told):
        assert a["onset_s"] == pytest.approx(b["onset_s"], abs=0.02)


def test_summarize_steps_is_a_step_summary_like_a_materials_recorded_one(walk):
    render, times = walk
    summary = underfoot.summarize_steps(render.samples[0], render.rate, strikes=times)
    recorded = underfoot.Library.builtin()["gravel"].time
    # The same record as the library keeps for the recordings, so the two compare.
    assert set(summary) == set(recorded)
    assert summary["steps"] == len(times)
    assert len(summary["decay_db"]) == len(recorded["decay_db"])
    assert summary["bands_hz"] == recorded["bands_hz"]
    # It summarises the steps that `steps` measures: the median of their durations.
    steps = underfoot.steps(render.samples[0], render.rate, strikes=times)
    assert summary["duration_ms"] == pytest.approx(np.median([s["duration_ms"] for s in steps]))


def test_compare_steps_of_a_render_against_its_material(walk):
    render, times = walk
    gravel = underfoot.Library.builtin()["gravel"]
    result = underfoot.compare_steps(render.samples[0], render.rate, gravel, strikes=times)
    assert set(result) >= {"rendered", "spectrum_db", "level_db"}
    assert set(result["rendered"]) == set(gravel.time)
    assert np.isfinite(result["spectrum_db"]) and result["spectrum_db"] >= 0
    assert np.isfinite(result["level_db"])
    # The level is the render's against the material's level: rendered 6 dB quieter
    # and told so, it compares the same.
    quiet = underfoot.render("gravel", gait="steps=5,channels=1", gain_db=-6.0)
    told = underfoot.compare_steps(
        quiet.samples[0], quiet.rate, gravel, strikes=[s.time for s in quiet.strikes], gain_db=-6.0
    )
    assert told["level_db"] == pytest.approx(result["level_db"], abs=0.2)


def test_compare_steps_without_recorded_steps_is_none(walk):
    render, times = walk
    entry = json.loads(underfoot.Library.builtin()["gravel"].to_json())
    # A format-2 material: fitted before step statistics were kept.
    del entry["time"]
    bare = underfoot.Material.from_json(json.dumps(entry))
    assert bare.time is None
    assert underfoot.compare_steps(render.samples[0], render.rate, bare, strikes=times) is None


# --- sessions -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def session(tmp_path_factory, run_cli):
    """A session recorded by the command line (paced in real time: about 4 s), with one
    marker typed on standard input."""
    folder = tmp_path_factory.mktemp("session") / "record"
    run_cli(
        "run", "--material", "gravel", "--input", "gait:steps=2,channels=2",
        "--output", "null", "--record", folder, "--quiet",
        input=json.dumps({"text": "trial 1", "trial": 1}) + "\n",
    )
    return folder


def read_csv_rows(path):
    with open(path, encoding="utf-8") as f:
        return list(csv.reader(line for line in f if not line.startswith("#")))


def test_read_session_gives_the_force_the_record_holds(session):
    s = underfoot.read_session(session)
    header, *rows = read_csv_rows(session / "force.csv")
    times = np.array([row[0] for row in rows], dtype=np.float64)
    # Readings are the engine's float32s, each written as its shortest decimal: parsed as
    # float32 they are the values the engine summed.
    readings = np.array([row[1:] for row in rows], dtype=np.float32)
    assert np.array_equal(s.force_times, times)
    # Total per channel: the float32 sum of its sensor columns ("ch1.s1", "ch1.s2").
    channels = sorted({name.split(".")[0] for name in header[1:]})
    assert s.force.shape == (len(channels), len(rows))
    assert np.max(s.force) > 0
    for c, name in enumerate(channels):
        columns = [i - 1 for i, h in enumerate(header) if h.split(".")[0] == name]
        assert len(columns) == 2  # a gait's heel and toe: a sum of two is exact either way
        assert np.array_equal(s.force[c], readings[:, columns[0]] + readings[:, columns[1]])


def test_read_session_names_the_force_channels_as_the_record_does(session):
    s = underfoot.read_session(session)
    header, *_ = read_csv_rows(session / "force.csv")
    # "ch1.s1,ch1.s2,ch2.s1,...": a channel is what precedes the sensor's name.
    channels = sorted({name.split(".")[0] for name in header[1:]})
    assert list(s.force_channels) == channels


def test_read_session_gives_the_strikes_of_strikes_csv(session):
    s = underfoot.read_session(session)
    with open(session / "strikes.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 4  # steps=2 per foot, two feet
    assert len(s.strikes) == len(rows)
    for strike, row in zip(s.strikes, rows):
        assert strike["time"] == float(row["time_s"])
        assert strike["frame"] == int(row["frame"])
        # From 0, as the force's rows and a render's strikes; the file counts from 1.
        assert strike["channel"] == int(row["channel"]) - 1
        assert strike["intensity"] == float(row["intensity"])
        assert strike["material"] == row["material"] == "gravel"


def test_read_session_gives_the_output_manifest_and_markers(session, read_wav):
    s = underfoot.read_session(session)
    with open(session / "manifest.json", encoding="utf-8") as f:
        manifest = json.load(f)
    assert s.manifest == manifest
    assert s.finished is True
    assert s.rate == manifest["rate_hz"]
    samples, rate = read_wav(session / "output.wav")
    output = s.output()
    assert output.dtype == np.float32
    assert output.shape == samples.shape == (2, manifest["ended"]["frames"])
    assert np.array_equal(output, samples)
    assert [m["text"] for m in s.markers] == ["trial 1"]
    assert [e["kind"] for e in s.events][-1] == "end"


def test_read_session_of_a_folder_that_is_no_record_is_a_session_error(tmp_path):
    with pytest.raises(underfoot.SessionError) as caught:
        underfoot.read_session(tmp_path)
    assert str(tmp_path) in str(caught.value) or "manifest" in str(caught.value)


def test_a_recording_reads_as_fit_reads_it(gravel_files, cli_gravel):
    first = underfoot.read_recording(gravel_files[0])
    assert first.samples.ndim == 1 and first.samples.dtype == np.float64
    assert first.rate > 0 and np.all(np.isfinite(first.samples))
    # The digest and name a material keeps of its sources, as the command line's fit
    # recorded them.
    sources = {(s["file"], s["sha256"]) for s in cli_gravel["sources"]}
    assert (first.name, first.sha256) in sources
    # Fitting the samples read is fitting the file: the same strikes found.
    from_file = underfoot.measure(gravel_files[0])
    from_array = underfoot.measure(first.samples, first.rate)
    assert [t for _, t in from_file.strikes] == [t for _, t in from_array.strikes]
    np.testing.assert_array_equal(from_file.magnitude, from_array.magnitude)
