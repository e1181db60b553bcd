#!/usr/bin/env python3
"""An independent check of the steps in time, with numpy and scipy (not part of the build).

Usage: scripts/step-stats.py RECORDINGS_DIR RENDER.wav [RECORDINGS_DIR RENDER.wav ...]

For each pair, measures the recordings in the folder (Ogg/WAV/FLAC) and the steps of the
WAV `underfoot render` wrote, as the README's "What a step is made of" defines them, and
prints median D90 (ms), median micro-event count, median crest factor (dB), the spread
between steps (dB) and the gain-aligned distance between the two sets' average spectra (dB).
Written from the definitions, apart from both the library's analysis and the tests' (Rust):
scipy's Butterworth and find_peaks, numpy's FFT. Needs numpy, scipy and soundfile
(`pip install numpy scipy soundfile`).
"""
import glob
import itertools
import os
import sys

import numpy as np
import soundfile as sf
from scipy import signal

BAND = (20.0, 900.0)


def band_limited(x, fs):
    sos = signal.butter(4, BAND, btype="bandpass", fs=fs, output="sos")
    pad = int(fs)
    y = signal.sosfiltfilt(sos, np.concatenate([np.zeros(pad), x, np.zeros(pad)]), padtype=None)
    return y[pad:pad + len(x)]


def rms(x, fs, seconds):
    n = max(1, int(round(seconds * fs)))
    return np.sqrt(np.maximum(np.convolve(x * x, np.ones(n) / n, mode="same"), 0))


def steps(path):
    x, fs = sf.read(path)
    if x.ndim > 1:
        x = x.mean(axis=1)
    y = band_limited(x, fs)
    env = rms(y, fs, 0.005)
    above = np.flatnonzero(env > env.max() * 10 ** (-40 / 20))
    onsets, last = [], None
    for i in above:
        if last is None or i - last > 0.3 * fs:
            onsets.append(i)
        last = i
    out = []
    for o in onsets:
        a, b = o - int(0.05 * fs), o + int(0.6 * fs)
        seg = np.zeros(b - a)
        lo, hi = max(a, 0), min(b, len(y))
        seg[lo - a:hi - a] = y[lo:hi]
        out.append((seg, fs))
    return out


def figures(seg, fs):
    c = np.cumsum(seg ** 2)
    c /= c[-1]
    d90 = (np.searchsorted(c, 0.95) - np.searchsorted(c, 0.05)) / fs * 1e3
    db = 20 * np.log10(rms(seg, fs, 0.0015) + 1e-30)
    peaks, _ = signal.find_peaks(db, height=db.max() - 25, distance=max(1, int(round(0.003 * fs))),
                                 prominence=6)
    w = seg[:int(0.35 * fs)]
    crest = 20 * np.log10(np.abs(w).max() / np.sqrt(np.mean(w ** 2)))
    return d90, len(peaks), crest


def bands(seg, fs):
    n = 1 << int(np.ceil(np.log2(len(seg) * 4)))
    power = (np.abs(np.fft.rfft(seg, n)) / fs) ** 2
    f = np.fft.rfftfreq(n, 1 / fs)
    half = 2 ** (1 / 12)
    out, c = [], BAND[0] * half
    while c * half <= BAND[1] * (1 + 1e-9):
        out.append(power[(f >= c / half) & (f < c * half)].mean())
        c *= half * half
    return np.array(out)


def distance(a, b):
    d = 10 * np.log10(a / b)
    return float(np.sqrt(np.mean((d - d.mean()) ** 2)))


def summary(all_steps):
    f = np.array([figures(s, fs) for s, fs in all_steps])
    b = [bands(s, fs) for s, fs in all_steps]
    spread = np.mean([distance(x, y) for x, y in itertools.combinations(b, 2)]) if len(b) > 1 else np.nan
    return np.median(f, axis=0), spread, np.mean(b, axis=0)


def main(args):
    if len(args) < 2 or len(args) % 2:
        sys.exit(__doc__)
    print("material  D90 ms rec/render  micro-events  crest dB      spread dB     spectrum dB")
    for folder, wav in zip(args[::2], args[1::2]):
        files = sorted(p for p in glob.glob(os.path.join(folder, "*"))
                       if p.lower().endswith((".ogg", ".wav", ".flac")))
        recorded = [s for f in files for s in steps(f)]
        rendered = steps(wav)
        (rd, re, rc), rs, rb = summary(recorded)
        (gd, ge, gc), gs, gb = summary(rendered)
        name = os.path.basename(os.path.normpath(folder))
        print(f"{name:<9} {rd:6.0f} / {gd:<6.0f}  {re:4.0f} / {ge:<4.0f}   {rc:4.1f} / {gc:<4.1f}   "
              f"{rs:4.2f} / {gs:<4.2f}   {distance(rb, gb):.2f}")


if __name__ == "__main__":
    main(sys.argv[1:])
