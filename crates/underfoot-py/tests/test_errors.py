"""Bad input raises the exception of its stage, with a message that says what and where:
every exception is an `underfoot.Error`, and the ones a Python user expects from the
built-ins (ValueError, TypeError, KeyError) are those too.
"""

import json
import subprocess

import numpy as np
import pytest

import underfoot

RATE = 8000.0


def heel_strike(seconds=0.5, rate=RATE, seed=0):
    """A recording-like float64 array: quiet noise, then a decaying burst (a strike)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    x = 1e-4 * rng.standard_normal(t.size)
    on = t >= 0.1
    x[on] += np.exp(-(t[on] - 0.1) / 0.03) * np.sin(2 * np.pi * 180 * t[on])
    return x


def fit_array(x):
    return underfoot.fit(x, RATE)


def render_array(x):
    return underfoot.render("gravel", x, 500.0)


def measure_array(x):
    return underfoot.measure(x, RATE)


def steps_array(x):
    return underfoot.steps(x, RATE)


ARRAY_TAKERS = [fit_array, render_array, measure_array, steps_array]


def raises(kind, call, *args, **kwargs):
    """The exception `call` raised, checked to be `kind` and an `underfoot.Error`."""
    with pytest.raises(kind) as caught:
        call(*args, **kwargs)
    assert isinstance(caught.value, underfoot.Error)
    return caught.value


@pytest.mark.parametrize("taker", ARRAY_TAKERS, ids=lambda f: f.__name__)
@pytest.mark.parametrize(
    "dtype, make",
    [
        ("int64", lambda x: (x * 1000).astype(np.int64)),
        ("int16", lambda x: (x * 1000).astype(np.int16)),
        ("bool", lambda x: x > 0),
        ("complex128", lambda x: x.astype(np.complex128)),
        ("object", lambda x: x.astype(object)),
    ],
)
def test_an_array_of_the_wrong_dtype_is_an_input_type_error_naming_it(taker, dtype, make):
    # Converting silently would give counts or truth values the meaning of pascals or
    # newtons; the user must say what the numbers are.
    e = raises(underfoot.InputTypeError, taker, make(np.abs(heel_strike()) * 1000))
    assert isinstance(e, TypeError) and isinstance(e, ValueError)
    assert dtype in str(e), str(e)


def test_something_that_is_not_a_recording_is_an_input_type_error():
    e = raises(underfoot.InputTypeError, underfoot.fit, {"file": "gravel.ogg"})
    assert "dict" in str(e), str(e)


def test_nan_in_a_recording_array_is_a_recording_error_naming_the_recording_and_sample():
    bad = heel_strike(seed=1)
    bad[1234] = np.nan
    e = raises(underfoot.RecordingError, underfoot.fit, [(heel_strike(), RATE), (bad, RATE)])
    message = str(e)
    # The second array, by its index in the list, and the sample, by its index.
    assert "recording 1" in message and "1234" in message, message
    assert "nan" in message.lower() or "finite" in message, message


def test_nan_in_force_is_an_input_error_saying_so():
    force = np.full((1, 1000), 700.0)
    force[0, 321] = np.nan
    e = raises(underfoot.InputError, underfoot.render, "gravel", force, 500.0)
    assert "nan" in str(e).lower() or "finite" in str(e), str(e)
    assert "321" in str(e), str(e)


@pytest.mark.parametrize("taker", ARRAY_TAKERS, ids=lambda f: f.__name__)
def test_a_3d_array_is_an_input_error_naming_its_shape(taker):
    e = raises(underfoot.InputError, taker, np.ones((2, 3, 400)))
    assert any(s in str(e) for s in ("(2, 3, 400)", "3-D", "3 dimensions")), str(e)


@pytest.mark.parametrize(
    "call",
    [
        lambda: underfoot.fit([]),
        lambda: underfoot.measure([]),
        lambda: underfoot.render([], gait="steps=2"),
        lambda: underfoot.render("gravel", np.zeros((1, 0)), 500.0),
    ],
    ids=["fit []", "measure []", "render no material", "render empty force"],
)
def test_nothing_to_work_on_is_an_input_error(call):
    e = raises(underfoot.InputError, call)
    assert str(e), "an empty message"


def test_an_empty_recording_array_is_a_recording_error_naming_it():
    # A recording that holds nothing, like an empty file: the recording's fault, by name.
    e = raises(underfoot.RecordingError, underfoot.fit, [(heel_strike(), RATE), (np.zeros(0), RATE)])
    assert "recording 1" in str(e), str(e)


def test_an_array_without_its_rate_is_an_input_error_asking_for_it():
    e = raises(underfoot.InputError, underfoot.fit, heel_strike())
    assert "rate" in str(e), str(e)


def test_a_missing_recording_file_is_a_recording_error_naming_it(tmp_path):
    missing = tmp_path / "no-such-step.ogg"
    e = raises(underfoot.RecordingError, underfoot.fit, [str(missing)])
    assert "no-such-step.ogg" in str(e), str(e)
    # os.PathLike as well as str.
    e = raises(underfoot.RecordingError, underfoot.measure, missing)
    assert "no-such-step.ogg" in str(e), str(e)


def test_a_library_of_an_unknown_format_is_a_library_error_naming_the_format(
    tmp_path, cli_library
):
    with open(cli_library, encoding="utf-8") as f:
        library = json.load(f)
    library["format"] = "underfoot.library/99"
    path = tmp_path / "future.json"
    path.write_text(json.dumps(library), encoding="utf-8")
    e = raises(underfoot.LibraryError, underfoot.Library.load, path)
    assert "underfoot.library/99" in str(e), str(e)
    # A render that names the file refuses it the same way.
    e = raises(underfoot.LibraryError, underfoot.render, "gravel", gait="steps=2", library=path)
    assert "underfoot.library/99" in str(e), str(e)


def test_an_absent_material_is_a_library_error_and_a_key_error():
    library = underfoot.Library.builtin()
    with pytest.raises(underfoot.LibraryError) as caught:
        library["lava"]
    assert isinstance(caught.value, KeyError)
    assert "lava" in str(caught.value)
    # A render of it is the same error, naming it.
    e = raises(underfoot.LibraryError, underfoot.render, "lava", gait="steps=2")
    assert "lava" in str(e), str(e)


@pytest.mark.parametrize(
    "option", [{"model": "foo"}, {"drive": "foo"}, {"excitation": "foo"}], ids=lambda o: next(iter(o))
)
def test_an_unknown_option_value_is_an_input_error_naming_it(option):
    e = raises(underfoot.InputError, underfoot.render, "gravel", gait="steps=2", **option)
    assert "foo" in str(e), str(e)


def test_force_and_gait_together_is_an_input_error():
    raises(underfoot.InputError, underfoot.render, "gravel", np.zeros((1, 10)), 500.0, gait="steps=2")


def test_a_bad_gait_spec_is_a_force_error_naming_the_key():
    e = raises(underfoot.ForceError, underfoot.render, "gravel", gait="steps=2,cadence=99")
    assert "cadence" in str(e), str(e)


def test_a_poor_fit_is_refused_unless_accepted(gravel_files):
    # Order 1 cannot follow gravel's response: the quality gate must stop it (the default
    # fit of the same recordings passes, test_cli).
    with pytest.raises(underfoot.PoorFitError) as caught:
        underfoot.fit(gravel_files, material="gravel", order=1)
    refused = caught.value
    assert isinstance(refused, underfoot.FitError) and isinstance(refused, underfoot.Error)
    # The message says how to keep it, in Python's words.
    assert "accept_poor_fit" in str(refused), str(refused)

    kept = underfoot.fit(gravel_files, material="gravel", order=1, accept_poor_fit=True)
    assert kept.poor_fit is True
    assert kept.order == 1
    # The refusal's figures are those of the fit it refused.
    assert refused.lsd_db == kept.fit["lsd_db"]
    assert refused.nrmse == kept.fit["nrmse"]
    assert json.loads(kept.to_json())["fit"]["poor_fit"] is True


def cli_error(cli, *args):
    """The message the command line fails with (its "underfoot: error: " line)."""
    done = subprocess.run([cli, *map(str, args)], capture_output=True, text=True)
    assert done.returncode != 0, f"underfoot {' '.join(map(str, args))} succeeded"
    prefix = "underfoot: error: "
    lines = [line for line in done.stderr.splitlines() if line.startswith(prefix)]
    assert lines, done.stderr
    return lines[-1][len(prefix):]


@pytest.mark.parametrize(
    "case", ["missing recording", "directory as recording", "text as recording", "missing library"]
)
def test_a_failure_reads_as_the_command_lines_message(case, tmp_path, cli):
    # The contract: the messages are the CLI's, why included (the OS's reason, the
    # decoder's), so a user never has to run the CLI to learn what went wrong.
    library = tmp_path / "library.json"
    if case == "missing library":
        path = tmp_path / "missing.json"
        expected = cli_error(cli, "library", "list", "--library", path)
        call = lambda: underfoot.Library.load(path)  # noqa: E731
    else:
        path = {
            "missing recording": tmp_path / "missing.ogg",
            "directory as recording": tmp_path,
            "text as recording": tmp_path / "notes.ogg",
        }[case]
        if case == "text as recording":
            path.write_text("not a recording\n", encoding="utf-8")
        expected = cli_error(cli, "fit", "--name", "gravel", "--library", library, path)
        call = lambda: underfoot.fit([path], material="gravel")  # noqa: E731
    with pytest.raises(underfoot.Error) as caught:
        call()
    assert str(caught.value) == expected


@pytest.mark.parametrize(
    "call, kind, name",
    [
        (lambda: underfoot.fit(heel_strike(), RATE, order=2**70), underfoot.InputError, "order"),
        (lambda: underfoot.render("gravel", gait="steps=2", seed=2**70), underfoot.InputError, "seed"),
        (lambda: underfoot.steps(heel_strike(), RATE, strikes="abc"), underfoot.InputTypeError, "strikes"),
        (lambda: underfoot.Material.from_json(5), underfoot.InputTypeError, "int"),
    ],
    ids=["order 2**70", "seed 2**70", "strikes a str", "from_json an int"],
)
def test_an_argument_python_cannot_convert_is_an_underfoot_error_naming_it(call, kind, name):
    # Python's own OverflowError or ValueError would escape `except underfoot.Error`.
    e = raises(kind, call)
    assert name in str(e), str(e)
    # One culprit named, not a list of suspects.
    assert " or " not in str(e).split(":")[0], str(e)


def test_a_force_beyond_float32_is_an_input_error_naming_the_sample():
    # The engine reads force as float32: 1e300 N would become infinity there. The message
    # is about the array the user passed, not about a CSV they never wrote.
    force = np.full((1, 100), 700.0)
    force[0, 5] = 1e300
    e = raises(underfoot.InputError, underfoot.render, "gravel", force, 500.0)
    assert "force[0, 5]" in str(e) and "line" not in str(e), str(e)


def test_a_rate_is_written_readably_in_a_message():
    e = raises(underfoot.InputError, underfoot.fit, heel_strike(), 1e-300)
    assert "1e-300" in str(e) and len(str(e)) < 200, str(e)
