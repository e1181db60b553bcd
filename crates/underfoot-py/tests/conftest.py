"""Shared fixtures of the Python package's tests: the shared recordings, the `underfoot`
command line the package is compared with, and the file formats the two exchange (force
CSV in, 32-bit float WAV out) read and written here with the standard library and numpy,
never through the package under test.
"""

import json
import os
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest

import underfoot

# tests/ -> underfoot-py -> crates -> the repository.
REPO = Path(__file__).resolve().parents[3]

# What the command line is built from: a binary older than any of these may not be the
# program the package is compared with.
CLI_CRATES = ["underfoot", "underfoot-cli", "underfoot-fft"]


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "speed: times the package against the release command line "
        "(skipped without a fresh target/release/underfoot unless UNDERFOOT_REQUIRE_SPEED=1)",
    )


def target_dir():
    """Where cargo builds: $CARGO_TARGET_DIR, else the workspace's target/."""
    return Path(os.environ.get("CARGO_TARGET_DIR") or REPO / "target")


def newest_source_mtime():
    """The newest modification time among the files the command line is built from."""
    files = [REPO / "Cargo.toml", REPO / "Cargo.lock"]
    for crate in CLI_CRATES:
        files.append(REPO / "crates" / crate / "Cargo.toml")
        files.extend((REPO / "crates" / crate / "src").rglob("*.rs"))
    return max(path.stat().st_mtime for path in files if path.is_file())


@pytest.fixture(scope="session")
def data_dir():
    """The shared footstep recordings, beside the repository (never copied into it)."""
    path = REPO.parent / "shared" / "data" / "footsteps"
    if not path.is_dir():
        message = "the shared recordings ../shared/data/footsteps are missing"
        if os.environ.get("UNDERFOOT_REQUIRE_DATA") == "1":
            pytest.fail(f"{message} (UNDERFOOT_REQUIRE_DATA=1 makes them mandatory)")
        pytest.skip(message)
    return path


@pytest.fixture(scope="session")
def gravel_files(data_dir):
    """The gravel recordings, one heel strike a file, in the order `ls` gives them."""
    files = sorted(str(p) for p in (data_dir / "gravel").iterdir() if p.is_file())
    assert files, f"{data_dir / 'gravel'} holds no recording"
    return files


@pytest.fixture(scope="session")
def gravel(gravel_files):
    """Gravel fitted by the package from the shared recordings (fitted once: a fit takes
    about a second)."""
    return underfoot.fit(gravel_files, material="gravel")


@pytest.fixture(scope="session")
def cli():
    """The `underfoot` command line: $UNDERFOOT_CLI, else the workspace's debug build,
    else its release build. A build older than the sources is rebuilt (debug), since the
    comparisons need the command line of the same sources as the package."""
    if os.environ.get("UNDERFOOT_CLI"):
        path = Path(os.environ["UNDERFOOT_CLI"])
        assert path.is_file(), f"UNDERFOOT_CLI={path} does not exist"
        return str(path)
    candidates = [target_dir() / "debug" / "underfoot", target_dir() / "release" / "underfoot"]
    newest = newest_source_mtime()
    for path in candidates:
        if path.is_file() and path.stat().st_mtime >= newest:
            return str(path)
    # None, or only stale ones: what CI has built already, so usually a no-op there.
    subprocess.run(["cargo", "build", "-q", "-p", "underfoot-cli"], cwd=REPO, check=True)
    return str(candidates[0])


@pytest.fixture(scope="session")
def speed_cli(cli):
    """The command line of the package's own build profile, for the speed check
    (test_speed): the same library code, optimised alike, on both sides. The package
    built by pip is optimised (release), and CI builds it in the tests' profile (dev),
    beside target/debug/underfoot. Without a release command line of these sources the
    check skips, or fails with UNDERFOOT_REQUIRE_SPEED=1."""
    if os.environ.get("UNDERFOOT_SPEED_CLI"):
        return os.environ["UNDERFOOT_SPEED_CLI"]
    if underfoot._underfoot.BUILD_PROFILE == "dev":
        path = target_dir() / "debug" / "underfoot"
        assert Path(cli) == path, f"the debug command line {path} is not the one found: {cli}"
        return cli
    path = target_dir() / "release" / "underfoot"
    if path.is_file() and path.stat().st_mtime >= newest_source_mtime():
        return str(path)
    why = (
        f"{path} is missing or older than the sources: the speed check of a release package "
        "needs a release command line of these sources (cargo build --release -p "
        "underfoot-cli, or UNDERFOOT_SPEED_CLI=PATH)"
    )
    if os.environ.get("UNDERFOOT_REQUIRE_SPEED") == "1":
        pytest.fail(why + " (UNDERFOOT_REQUIRE_SPEED=1)")
    pytest.skip(why)


@pytest.fixture(scope="session")
def run_cli(cli):
    """Runs the command line with the given arguments; a failure fails the test with its
    standard error. Returns the completed process (text output)."""

    def run(*args, input=None, cwd=None):
        done = subprocess.run(
            [cli, *map(str, args)], capture_output=True, text=True, input=input, cwd=cwd
        )
        assert done.returncode == 0, (
            f"underfoot {' '.join(map(str, args))} exited with {done.returncode}:\n{done.stderr}"
        )
        return done

    return run


@pytest.fixture(scope="session")
def cli_library(tmp_path_factory, run_cli, gravel_files):
    """A library written by `underfoot fit` from the gravel recordings: its path."""
    path = tmp_path_factory.mktemp("cli-fit") / "library.json"
    run_cli("fit", "--name", "gravel", "--library", path, *gravel_files)
    return path


@pytest.fixture(scope="session")
def cli_gravel(cli_library):
    """The gravel entry of the command line's library, as the `json` module reads it."""
    with open(cli_library, encoding="utf-8") as f:
        library = json.load(f)
    (entry,) = [m for m in library["materials"] if m["name"] == "gravel"]
    return entry


def write_force_csv(path, force, rate):
    """Writes `force` (channels, samples), newtons at `rate` Hz, as the force track the
    command line reads for the same array: `time_s,c0.f,c1.f,...`, one sensor a channel,
    every number as `repr` writes it (so it parses back to the same float)."""
    force = np.atleast_2d(np.asarray(force, dtype=np.float64))
    header = "time_s," + ",".join(f"c{c}.f" for c in range(force.shape[0]))
    lines = [header]
    for k in range(force.shape[1]):
        lines.append(",".join([repr(k / rate)] + [repr(float(v)) for v in force[:, k]]))
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def read_wav_f32(path):
    """A 32-bit float WAV file as ((channels, frames) float32, rate).

    The standard library's `wave` reads integer PCM only, and underfoot writes IEEE float
    (format 3, in a WAVE_FORMAT_EXTENSIBLE header), so the RIFF chunks are walked here.
    """
    data = Path(path).read_bytes()
    assert data[:4] == b"RIFF" and data[8:12] == b"WAVE", f"{path}: not a WAV file"
    pos, channels, rate = 12, None, None
    while pos + 8 <= len(data):
        chunk, size = data[pos : pos + 4], struct.unpack("<I", data[pos + 4 : pos + 8])[0]
        body = data[pos + 8 : pos + 8 + size]
        if chunk == b"fmt ":
            tag, channels, rate = struct.unpack("<HHI", body[:8])
            bits = struct.unpack("<H", body[14:16])[0]
            if tag == 0xFFFE:
                # The extensible header's sub-format GUID starts with the real tag.
                tag = struct.unpack("<H", body[24:26])[0]
            assert (tag, bits) == (3, 32), f"{path}: format {tag}, {bits} bits, not 32-bit float"
        elif chunk == b"data":
            assert channels, f"{path}: data before fmt"
            samples = np.frombuffer(body, dtype="<f4").reshape(-1, channels)
            return samples.T.astype(np.float32), rate
        pos += 8 + size + (size & 1)
    raise AssertionError(f"{path}: no data chunk")


def walk_force(channels, seconds, rate, load=800.0, stance=0.6, period=1.1):
    """A synthetic walk, (channels, samples) newtons at `rate` Hz: on each channel a
    half-sine load of `load` N lasting `stance` s every `period` s, the channels' steps
    staggered evenly over a period so they do not all strike at once."""
    t = np.arange(int(round(seconds * rate))) / rate
    force = np.zeros((channels, t.size))
    for c in range(channels):
        start = 0.2 + c * period / channels
        phase = (t - start) % period
        on = (t >= start) & (phase < stance)
        force[c, on] = load * np.sin(np.pi * phase[on] / stance)
    return force


@pytest.fixture(scope="session")
def force_csv():
    return write_force_csv


@pytest.fixture(scope="session")
def read_wav():
    return read_wav_f32


@pytest.fixture(scope="session")
def synthetic_walk():
    return walk_force
