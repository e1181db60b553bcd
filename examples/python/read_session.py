#!/usr/bin/env python3
"""Read a recorded underfoot session (`underfoot run --record DIR`) with the standard
library and numpy only, into arrays and plain Python structures.

    python3 examples/python/read_session.py DIR

The folder's layout (see `underfoot::live::record`):

    manifest.json   what ran, when it started (UTC, Unix time, monotonic clock), how it ended
    force.csv       every force reading: time_s (the sensor's), then one column per sensor
    strikes.csv     every strike: time_s on the output, frame, channel (from 1), intensity,
                    material, sensor_time_s
    events.jsonl    one JSON object a line: start, markers, material and gain changes, end
    status.jsonl    the session's status, one JSON object a second
    output.wav      the drive of every channel, 32-bit float (output.partial-PID.wav when
                    the process was killed before it finished)

Every time in events and markers is `t` (seconds since the session started, monotonic)
and `frame` (the output sample, so frame / rate is the time in output.wav).
"""

import csv
import glob
import json
import os
import struct
import sys

import numpy as np


def read_wav_float(path):
    """A WAV file's samples as a (frames, channels) float32 array, and its rate.

    The standard library's `wave` reads integer PCM only; underfoot writes IEEE float
    (format 3), so the RIFF chunks are walked here. A partial file (a killed session)
    reads up to the size its header says.
    """
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise ValueError(f"{path}: not a WAV file")
    pos, channels, rate, bits = 12, None, None, None
    while pos + 8 <= len(data):
        chunk, size = data[pos:pos + 4], struct.unpack("<I", data[pos + 4:pos + 8])[0]
        body = data[pos + 8:pos + 8 + size]
        if chunk == b"fmt ":
            fmt, channels, rate = struct.unpack("<HHI", body[:8])
            bits = struct.unpack("<H", body[14:16])[0]
            if fmt not in (3, 0xFFFE) or bits != 32:
                raise ValueError(f"{path}: not 32-bit float")
        elif chunk == b"data":
            usable = len(body) - len(body) % (4 * channels)
            samples = np.frombuffer(body[:usable], dtype="<f4")
            return samples.reshape(-1, channels), rate
        pos += 8 + size + (size & 1)
    raise ValueError(f"{path}: no data chunk")


def complete_lines(path):
    """The file's lines, without a last line cut short by a killed process."""
    if not os.path.exists(path):
        return []
    with open(path, encoding="utf-8") as f:
        text = f.read()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    return text.splitlines()


def read_session(folder):
    """The record in `folder` as a dict of numpy arrays and Python structures."""
    with open(os.path.join(folder, "manifest.json"), encoding="utf-8") as f:
        manifest = json.load(f)
    if manifest.get("format") != "underfoot session record" or manifest.get("version") != 1:
        raise ValueError(f"{folder}: not a version-1 underfoot session record")

    lines = [l for l in complete_lines(os.path.join(folder, "force.csv")) if not l.startswith("#")]
    columns = lines[0].split(",") if lines else ["time_s"]
    force = np.array([[float(v) for v in l.split(",")] for l in lines[1:]]).reshape(-1, len(columns))

    strikes = list(csv.DictReader(complete_lines(os.path.join(folder, "strikes.csv"))))
    for s in strikes:
        s["time_s"], s["frame"] = float(s["time_s"]), int(s["frame"])
        s["channel"], s["intensity"] = int(s["channel"]), float(s["intensity"])

    events = [json.loads(l) for l in complete_lines(os.path.join(folder, "events.jsonl"))]
    status = [json.loads(l) for l in complete_lines(os.path.join(folder, "status.jsonl"))]

    wavs = [os.path.join(folder, "output.wav")] + sorted(glob.glob(os.path.join(folder, "output.partial-*.wav")))
    wavs = [w for w in wavs if os.path.exists(w)]
    output, rate = read_wav_float(wavs[0]) if wavs else (np.zeros((0, 1), "f4"), manifest["rate_hz"])

    return {
        "manifest": manifest,
        "force_columns": columns,
        "force": force,
        "strikes": strikes,
        "markers": [e for e in events if e["kind"] == "marker"],
        "events": events,
        "status": status,
        "output": output,
        "rate": rate,
    }


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    s = read_session(sys.argv[1])
    m, rate = s["manifest"], s["rate"]
    ended = m.get("ended") or {}
    print(f"started {m['started']['utc']}; ended: {ended.get('reason', 'did not finish')}")
    print(f"force: {s['force'].shape[0]} readings x {s['force'].shape[1] - 1} sensors "
          f"({', '.join(s['force_columns'][1:])})")
    print(f"strikes: {len(s['strikes'])}; markers: {len(s['markers'])}; "
          f"output: {s['output'].shape[0] / rate:.2f} s x {s['output'].shape[1]} channel(s)")
    for marker in s["markers"]:
        trial = f" (trial {marker['trial']})" if "trial" in marker else ""
        print(f"  marker at {marker['frame'] / rate:8.3f} s: {marker['text']}{trial}")
    # Each step's peak on the output, from its strike's frame on (350 ms).
    window = int(0.35 * rate)
    for s_ in s["strikes"]:
        x = s["output"][s_["frame"]:s_["frame"] + window, s_["channel"] - 1]
        peak = float(np.max(np.abs(x))) if x.size else 0.0
        level = f"{20 * np.log10(peak):6.1f} dBFS" if peak > 2.0 ** -24 else "silent"
        print(f"  step at {s_['time_s']:8.3f} s, channel {s_['channel']}, "
              f"{s_['material']}: peak {level}")
    if "strikes" in ended and ended["strikes"] != len(s["strikes"]):
        sys.exit(f"the record lists {len(s['strikes'])} strikes, the engine counted {ended['strikes']}")


if __name__ == "__main__":
    main()
