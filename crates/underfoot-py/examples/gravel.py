# %% [markdown]
# # Gravel, from recordings to a walk
#
# Fit a gravel model from the shared footstep recordings, see how close the filter comes
# to what was measured, then render a walk on it and compare its steps, in time, with the
# recorded ones. Run it whole (`python examples/gravel.py`) or cell by cell in an editor
# that knows `# %%` cells. Figures go to `$UNDERFOOT_EXAMPLE_OUT` (default: a new
# temporary folder); they are shown as well when matplotlib has an interactive backend.

# %%
import os
import tempfile
from pathlib import Path

import matplotlib
import matplotlib.ticker
import matplotlib.pyplot as plt
import numpy as np

import underfoot

try:
    HERE = Path(__file__).resolve().parent
except NameError:  # a notebook has no __file__: run it from crates/underfoot-py/examples
    HERE = Path.cwd()
# examples/ -> underfoot-py -> crates -> the repository; the recordings sit beside it.
RECORDINGS = HERE.parents[2].parent / "shared" / "data" / "footsteps" / "gravel"
OUT = Path(os.environ.get("UNDERFOOT_EXAMPLE_OUT") or tempfile.mkdtemp(prefix="underfoot-gravel-"))
OUT.mkdir(parents=True, exist_ok=True)
files = sorted(str(p) for p in RECORDINGS.iterdir() if p.is_file())
print(f"{len(files)} recordings in {RECORDINGS}; figures to {OUT}")

# %% [markdown]
# ## The fit
#
# The same as `underfoot fit --name gravel --library L.json <files>`: each recording's
# heel strike found, their spectra averaged, a filter fitted (its order chosen).

# %%
gravel = underfoot.fit(files, material="gravel")
print(gravel)
print(f"order {gravel.order}, NRMSE {gravel.fit['nrmse']:.3f}, LSD {gravel.fit['lsd_db']:.2f} dB, "
      f"{gravel.fit['strikes']} strikes")

# %%
freqs, measured, model = gravel.response()
reference = np.max(measured)
fig, ax = plt.subplots(figsize=(7.5, 4.2), layout="constrained")
ax.semilogx(freqs, 20 * np.log10(measured / reference), color="black", lw=2, label="measured (mean of strikes)")
ax.semilogx(freqs, 20 * np.log10(model / reference), color="tab:red", lw=1.5,
            label=f"fitted filter, order {gravel.order}")
ax.set_xlim(*gravel.band)
# Plain numbers at round frequencies: the default 3x10^1-style labels crowd each other.
ticks = [t for t in (20, 50, 100, 200, 500, 900) if gravel.band[0] <= t <= gravel.band[1]]
ax.set_xticks(ticks, [str(t) for t in ticks])
ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
ax.set_xlabel("frequency (Hz)")
ax.set_ylabel("magnitude (dB re measured peak)")
ax.set_title(f"gravel: measured vs model (LSD {gravel.fit['lsd_db']:.2f} dB)")
ax.grid(True, which="both", alpha=0.3)
ax.legend(loc="lower left")
fig.savefig(OUT / "gravel-response.png", dpi=120)

# %% [markdown]
# ## A walk on it
#
# A generated walk (one foot, eight steps) played by the real-time engine, as
# `underfoot render --material gravel --gait steps=8,channels=1` would, but with the
# material fitted above rather than the built-in one.

# %%
walk = underfoot.render(gravel, gait="steps=8,channels=1")
times = [s.time for s in walk.strikes]
signal = walk.samples[0]
print(f"{signal.size / walk.rate:.1f} s at {walk.rate} Hz, {len(times)} strikes")

fig, ax = plt.subplots(figsize=(7.5, 3.2), layout="constrained")
t = np.arange(signal.size) / walk.rate
ax.plot(t, signal, color="tab:blue", lw=0.5)
for strike in times:
    ax.axvline(strike, color="tab:orange", lw=1, alpha=0.8)
ax.set_xlabel("time (s)")
ax.set_ylabel("drive (full scale)")
ax.set_title("rendered walk on gravel; heel strikes in orange")
fig.savefig(OUT / "gravel-walk.png", dpi=120)

# %% [markdown]
# ## Steps in time
#
# Each rendered step's decay envelope (energy per 10 ms from its onset, dB re its loudest
# bin), measured at the strikes' times exactly as the recordings' steps were when the
# material was fitted; the recordings' median envelope is kept with the material
# (`gravel.time`).

# %%
steps = underfoot.steps(signal, walk.rate, strikes=times)
rendered = underfoot.summarize_steps(signal, walk.rate, strikes=times)
recorded = gravel.time
bins_ms = 10 * np.arange(len(recorded["decay_db"])) + 5  # bin centres


def audible(decay_db, floor=-120.0):
    """The envelope with the bins nothing reached (a clip that ended, at the library's
    floor of -150 dB) left out of the line."""
    decay_db = np.asarray(decay_db, dtype=float)
    return np.where(decay_db > floor, decay_db, np.nan)


# How far the recordings' envelope reaches: the end of its last bin above the floor.
reach_ms = 10 * (np.flatnonzero(~np.isnan(audible(recorded["decay_db"])))[-1] + 1)

fig, ax = plt.subplots(figsize=(7.5, 4.2), layout="constrained")
for i, step in enumerate(steps):
    ax.plot(bins_ms[: len(step["decay_db"])], audible(step["decay_db"]), color="tab:red", lw=0.7, alpha=0.4,
            label="rendered steps" if i == 0 else None)
ax.plot(bins_ms, audible(rendered["decay_db"]), color="tab:red", lw=2, label="rendered, median")
ax.plot(bins_ms, audible(recorded["decay_db"]), color="black", lw=2, ls="--",
        label=f"recorded, median of {recorded['steps']} (to {reach_ms:.0f} ms, where the clips end)")
ax.set_xlabel("time from onset (ms)")
ax.set_ylabel("energy per 10 ms (dB re loudest bin)")
ax.set_title(f"gravel step envelopes: D90 {recorded['duration_ms']:.0f} ms recorded, "
             f"{rendered['duration_ms']:.0f} ms rendered")
ax.set_ylim(-60, 3)
ax.grid(True, alpha=0.3)
ax.legend(loc="lower left")
fig.savefig(OUT / "gravel-steps.png", dpi=120)

comparison = underfoot.compare_steps(signal, walk.rate, gravel, strikes=times)
print(f"spectrum distance {comparison['spectrum_db']:.2f} dB, level {comparison['level_db']:+.1f} dB")

# %%
def interactive_backend():
    """Whether matplotlib draws to a window (not to files only, as with Agg in CI)."""
    backend = matplotlib.get_backend().lower()
    try:  # matplotlib 3.9 and later
        from matplotlib.backends import BackendFilter, backend_registry

        return backend in backend_registry.list_builtin(BackendFilter.INTERACTIVE)
    except ImportError:
        return backend in [b.lower() for b in matplotlib.rcsetup.interactive_bk]


if interactive_backend():
    plt.show()
print("wrote", ", ".join(sorted(p.name for p in OUT.glob("*.png"))))
