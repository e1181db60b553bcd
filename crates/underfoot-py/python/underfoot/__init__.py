"""underfoot: feel the ground underfoot.

Fit how a ground material vibrates from recordings of footsteps on it, render the
vibration of a walk, and measure steps in time, from Python. The science is the Rust
library's (the same code the ``underfoot`` command line runs, so the same input gives
the same coefficients and the same samples); this package gives it numpy arrays and
Python's conventions.

A tour::

    import numpy as np
    import underfoot

    gravel = underfoot.fit(["step1.wav", "step2.wav"], material="gravel")
    print(gravel.order, gravel.fit["lsd_db"], gravel.sos.shape)

    library = underfoot.Library.builtin()
    library.add(gravel)
    library.save("materials.json")          # atomic, as the CLI writes it

    out = underfoot.render("gravel", gait="steps=6,channels=1", library=library)
    out.samples.shape                       # (channels, frames), float32
    [s.time for s in out.strikes]           # where each step starts, s

    underfoot.summarize_steps(out.samples[0], out.rate,
                              strikes=[s.time for s in out.strikes])

Arrays: recordings and signals are 1-D float arrays; force is ``(channels, samples)``
newtons. Float64 C-contiguous arrays are read without a copy, other float arrays are
converted; integer, boolean and complex arrays are refused (:class:`InputTypeError`):
scale PCM integers to floats yourself. Errors: every exception derives from
:class:`Error`, one class per stage (:mod:`underfoot._errors`).
"""

from __future__ import annotations

import json as _json
import os as _os
from dataclasses import dataclass as _dataclass
from typing import (
    Any,
    Dict,
    Iterator,
    List,
    NamedTuple,
    Optional,
    Sequence,
    Tuple,
    Union,
)

import numpy as _np

from . import _underfoot
from ._errors import (
    AnalysisError,
    EngineError,
    Error,
    FitError,
    ForceError,
    InputError,
    InputTypeError,
    LibraryError,
    MaterialNotFound,
    PoorFitError,
    RecordingError,
    SessionError,
)

__version__: str = _underfoot.__version__

__all__ = [
    "__version__",
    "fit",
    "read_recording",
    "render",
    "measure",
    "steps",
    "summarize_steps",
    "compare_steps",
    "read_session",
    "Material",
    "Library",
    "Recording",
    "Render",
    "Strike",
    "Response",
    "Session",
    "Error",
    "InputError",
    "InputTypeError",
    "RecordingError",
    "AnalysisError",
    "FitError",
    "PoorFitError",
    "LibraryError",
    "MaterialNotFound",
    "ForceError",
    "EngineError",
    "SessionError",
]

PathLike = Union[str, "_os.PathLike[str]"]
ArrayLike = Any  # anything numpy.asarray takes
Recordings = Union[PathLike, ArrayLike, Tuple[ArrayLike, float], Sequence[Any]]


# --- argument checks ---------------------------------------------------------------


def _float_array(x: ArrayLike, what: str, ndims: Tuple[int, ...]) -> _np.ndarray:
    """``x`` as a float64 array of one of ``ndims`` dimensions (no copy when it is one)."""
    if isinstance(x, (str, bytes, _os.PathLike)):
        raise InputTypeError(f"{what}: expected an array, got a path {x!r}")
    try:
        a = _np.asarray(x)
    except (ValueError, TypeError) as e:  # ragged lists and the like
        raise InputError(f"{what}: not an array: {e}") from None
    if a.dtype.kind != "f":
        raise InputTypeError(
            f"{what}: expected an array of floats, got dtype {a.dtype} "
            "(convert with .astype(float); scale PCM integers by their full scale)"
        )
    if a.ndim not in ndims:
        want = " or ".join(f"{n}-D" for n in ndims)
        raise InputError(f"{what}: expected a {want} array, got shape {a.shape}")
    return _np.ascontiguousarray(a, dtype=_np.float64)


def _path(x: Any, what: str) -> str:
    if isinstance(x, (str, _os.PathLike)):
        return _os.fspath(x)
    raise InputTypeError(f"{what}: expected a path (str or os.PathLike), got {type(x).__name__}")


def _number(x: Any, what: str) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float, _np.integer, _np.floating)):
        raise InputTypeError(f"{what}: expected a number, got {type(x).__name__}")
    return float(x)


def _int(x: Any, what: str, lo: int, hi: int) -> int:
    """``x`` as an int within ``lo..=hi`` (a numpy integer too, not a bool)."""
    if isinstance(x, bool) or not isinstance(x, (int, _np.integer)):
        raise InputTypeError(f"{what}: expected an int, got {type(x).__name__}")
    if not lo <= x <= hi:
        raise InputError(f"{what} {x}: need {lo} to {hi}")
    return int(x)


_U32 = 2**32 - 1
_U64 = 2**64 - 1


def _is_array(x: Any) -> bool:
    return isinstance(x, _np.ndarray) or (
        isinstance(x, (list, tuple)) and len(x) > 0 and isinstance(x[0], (int, float))
    )


def _sources(recordings: Recordings, rate: Optional[float]) -> List[Any]:
    """Each recording as the native side takes it: a path, or ``(name, rate, array)``."""
    if isinstance(recordings, (str, _os.PathLike, _np.ndarray)):
        items: List[Any] = [recordings]
    elif (
        isinstance(recordings, tuple)
        and len(recordings) == 2
        and _is_array(recordings[0])
        and not _is_array(recordings[1])
    ):
        items = [recordings]
    elif isinstance(recordings, (list, tuple)):
        items = list(recordings)
    else:
        raise InputTypeError(
            "recordings: expected a path, an array, or a list of them, "
            f"got {type(recordings).__name__}"
        )
    if not items:
        raise InputError("recordings: the list is empty")
    sources: List[Any] = []
    for i, item in enumerate(items):
        name = f"recording {i}"
        if isinstance(item, (str, _os.PathLike)):
            sources.append(_os.fspath(item))
            continue
        if isinstance(item, tuple) and len(item) == 2 and not isinstance(item[1], _np.ndarray):
            array, item_rate = item
            item_rate = _number(item_rate, f"{name}: rate")
        else:
            array, item_rate = item, rate
        if item_rate is None:
            raise InputError(f"{name}: an array needs its rate (rate=..., or (array, rate))")
        samples = _float_array(array, name, (1,))
        sources.append((name, _number(item_rate, "rate"), samples))
    return sources


def _band(band: Tuple[float, float]) -> Tuple[float, float]:
    try:
        lo, hi = band
    except (TypeError, ValueError):
        raise InputTypeError(f"band: expected (lo, hi) in Hz, got {band!r}") from None
    return _number(lo, "band"), _number(hi, "band")


# --- materials and libraries ---------------------------------------------------------


class Material:
    """A material model: the fitted filter, its fit, the recorded steps' statistics and
    the physical model. Made by :func:`fit`, or taken from a :class:`Library`.
    """

    __slots__ = ("_native",)

    def __init__(self, native: "_underfoot.Material") -> None:
        self._native = native

    @property
    def name(self) -> str:
        """The material's name."""
        return self._native.name

    @property
    def order(self) -> int:
        """The order of the fitted filter."""
        return self._native.order

    @property
    def analysis_rate(self) -> int:
        """The rate the filter was fitted at, Hz."""
        return self._native.analysis_rate

    @property
    def band(self) -> Tuple[float, float]:
        """The band of interest, Hz."""
        return self._native.band

    @property
    def level_db(self) -> float:
        """The playback level, dB: a nominal step plays at the recorded loudness."""
        return self._native.level_db

    @property
    def poor_fit(self) -> bool:
        """Whether the fit is above the quality bound (kept with ``accept_poor_fit``)."""
        return self._native.poor_fit

    @property
    def sos(self) -> _np.ndarray:
        """The filter as second-order sections, shape ``(n, 6)``, rows
        ``[b0, b1, b2, 1, a1, a2]`` (``scipy.signal.sosfilt``'s layout), at
        :attr:`analysis_rate`."""
        return self._native.sos

    @property
    def fit(self) -> Dict[str, Any]:
        """The fit record: ``nrmse``, ``lsd_db``, ``strikes``, ``grid_hz``, ``measured``..."""
        return _json.loads(self._native.fit_json())

    @property
    def time(self) -> Optional[Dict[str, Any]]:
        """The recorded steps in time (``duration_ms``, ``events``, ``crest_db``,
        ``spread_db``, ``decay_db``...); ``None`` for a model fitted before they were kept."""
        return _json.loads(self._native.time_json())

    @property
    def physical(self) -> Optional[Dict[str, Any]]:
        """The physical model estimated from the same recordings, or ``None``."""
        return _json.loads(self._native.physical_json())

    def response(self) -> Tuple[_np.ndarray, _np.ndarray, _np.ndarray]:
        """The fit grid (Hz), the measured magnitude and the filter's magnitude on it."""
        return self._native.response()

    def to_json(self) -> str:
        """The model as the JSON object a library file holds."""
        return self._native.to_json()

    @staticmethod
    def from_json(text: str) -> "Material":
        """A material from one material's JSON object, checked as a library's are."""
        if not isinstance(text, str):
            raise InputTypeError(f"expected the JSON text of a material, got {type(text).__name__}")
        return Material(_underfoot.Material.from_json(text))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Material) and self.to_json() == other.to_json()

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        f = self.fit
        return (
            f"<underfoot.Material {self.name!r}: order {self.order}, "
            f"LSD {f.get('lsd_db', float('nan')):.2f} dB, {f.get('strikes', 0)} strikes>"
        )


class Library:
    """A library of materials, as the command line keeps them in a file.

    ``Library()`` is empty; :meth:`load` reads a file and :meth:`builtin` gives the
    built-in materials. ``library["gravel"]``, ``"gravel" in library``, ``len``, and
    iteration over the names work as for a dict.
    """

    __slots__ = ("_native",)

    def __init__(self, _native: Optional["_underfoot.Library"] = None) -> None:
        self._native = _native if _native is not None else _underfoot.Library()

    @staticmethod
    def load(path: PathLike) -> "Library":
        """Reads and validates a library file (older formats are upgraded on read)."""
        return Library(_underfoot.Library.load(_path(path, "path")))

    @staticmethod
    def builtin() -> "Library":
        """The built-in materials."""
        return Library(_underfoot.Library.builtin())

    @property
    def names(self) -> List[str]:
        """The materials' names, in the library's order."""
        return self._native.names()

    def __getitem__(self, name: str) -> Material:
        if not isinstance(name, str):
            raise InputTypeError(f"a material's name is a str, got {type(name).__name__}")
        return Material(self._native.get(name))

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and name in self._native.names()

    def __len__(self) -> int:
        return len(self._native.names())

    def __iter__(self) -> Iterator[str]:
        return iter(self._native.names())

    def add(self, material: Material) -> bool:
        """Adds ``material``, replacing one of the same name; True if it replaced one."""
        if not isinstance(material, Material):
            raise InputTypeError(f"expected an underfoot.Material, got {type(material).__name__}")
        return self._native.add(material._native)

    def remove(self, name: str) -> Material:
        """Removes the material ``name`` and returns it."""
        return Material(self._native.remove(name))

    def save(self, path: PathLike) -> None:
        """Validates the library and writes it to ``path``: to a temporary file renamed
        over ``path``, under the file's edit lock, as the command line writes libraries.
        On any error the file is left as it was."""
        self._native.save(_path(path, "path"))

    def to_json(self) -> str:
        """The text of the library's file."""
        return self._native.to_json()

    def __repr__(self) -> str:
        return f"<underfoot.Library of {len(self)} materials: {', '.join(self.names)}>"


# --- recordings and fitting ---------------------------------------------------------


@_dataclass(frozen=True)
class Recording:
    """A recording as underfoot reads it: mono ``samples`` (channels averaged, float64,
    full scale about 1) at ``rate`` Hz, the file's ``name`` and the SHA-256 of its
    bytes (what a material's ``sources`` keep)."""

    samples: _np.ndarray
    rate: int
    name: str
    sha256: str


def read_recording(
    path: PathLike, *, csv_column: Optional[str] = None, csv_rate: Optional[float] = None
) -> Recording:
    """Reads a recording (WAV, FLAC, Ogg Vorbis, or CSV with ``csv_column`` and
    ``csv_rate``) as :func:`fit` reads it, checked the same way (not empty, silent,
    too short or non-finite), whole: a long file is not cut into excerpts here."""
    samples, rate, name, sha256 = _underfoot.read_recording(
        _path(path, "path"),
        csv_column,
        None if csv_rate is None else _number(csv_rate, "csv_rate"),
    )
    return Recording(samples=samples, rate=rate, name=name, sha256=sha256)


def fit(
    recordings: Recordings,
    rate: Optional[float] = None,
    material: str = "material",
    *,
    analysis_rate: int = 2000,
    band: Tuple[float, float] = (20.0, 900.0),
    order: Optional[int] = None,
    max_order: int = 16,
    savgol: Union[str, Tuple[int, int]] = "auto",
    target_lsd: float = 0.5,
    longest_decay: float = 0.5,
    accept_poor_fit: bool = False,
    csv_column: Optional[str] = None,
    csv_rate: Optional[float] = None,
) -> Material:
    """Fits a material to recordings of heel strikes on it, as ``underfoot fit`` does.

    ``recordings``: a path (WAV, FLAC, Ogg Vorbis, CSV), a 1-D float array at ``rate``
    Hz, an ``(array, rate)`` pair, or a list of them. Files are read exactly as the
    command line reads them, so the same files give the same coefficients.

    The filter order is the lowest up to ``max_order`` that meets ``target_lsd`` (dB),
    or exactly ``order``. ``savgol`` is ``"auto"``, ``"off"`` or ``(window, polyorder)``;
    ``longest_decay`` bounds the poles' e-fold decay (s). CSV recordings need
    ``csv_column`` and ``csv_rate``.

    Raises :class:`PoorFitError` when the fit is above the quality bound, unless
    ``accept_poor_fit`` (the material is then marked :attr:`Material.poor_fit`);
    :class:`RecordingError`, :class:`AnalysisError`, :class:`FitError` for recordings
    that cannot be read, hold no strike, or cannot be fitted.
    """
    if not isinstance(material, str):
        raise InputTypeError(f"material: expected a name (str), got {type(material).__name__}")
    if rate is not None:
        rate = _number(rate, "rate")
    sources = _sources(recordings, rate)
    lo, hi = _band(band)
    # The library bounds each of these again, with its own ranges; here they only have
    # to fit the native types.
    analysis_rate = _int(analysis_rate, "analysis_rate", 1, _U32)
    max_order = _int(max_order, "max_order", 1, _U32)
    if order is not None:
        order = _int(order, "order", 1, _U32)
    native = _underfoot.fit(
        sources,
        material,
        analysis_rate,
        lo,
        hi,
        order,
        max_order,
        savgol,
        _number(target_lsd, "target_lsd"),
        _number(longest_decay, "longest_decay"),
        bool(accept_poor_fit),
        csv_column,
        None if csv_rate is None else _number(csv_rate, "csv_rate"),
    )
    return Material(native)


# --- rendering ------------------------------------------------------------------------


class Strike(NamedTuple):
    """A step the engine played."""

    channel: int
    """The channel, from 0."""
    frame: int
    """The output frame its sound starts on."""
    time: float
    """``frame`` in seconds."""
    intensity: float
    """Strength relative to a nominal step."""
    material: Optional[str]
    """The material the channel played."""


@_dataclass(frozen=True)
class Render:
    """A render: ``samples`` (float32, ``(channels, frames)``), the audio ``rate``, the
    ``strikes`` played and the engine's ``telemetry`` (``peak``, ``limited``,
    ``non_finite``...). Unpacks as ``samples, strikes``."""

    samples: _np.ndarray
    rate: int
    strikes: List[Strike]
    telemetry: Dict[str, Any]

    def __iter__(self) -> Iterator[Any]:
        return iter((self.samples, self.strikes))


def render(
    materials: Union[str, Material, Sequence[Union[str, Material]]],
    force: Optional[ArrayLike] = None,
    force_rate: Optional[float] = None,
    *,
    gait: Optional[str] = None,
    library: Union["Library", PathLike, None] = None,
    model: str = "iir",
    drive: str = "impulse",
    excitation: str = "fitted",
    audio_rate: int = 48000,
    gain_db: float = 0.0,
    ceiling_db: float = -6.0,
    perturbation: Optional[float] = None,
    seed: int = 0x5EED,
    lowpass_order: int = 4,
    weight: float = 70.0,
    step_threshold: float = 60.0,
    sensor_rate: Optional[float] = None,
    tail: float = 1.0,
    block: int = 256,
) -> Render:
    """Renders the vibration of force on materials, as ``underfoot render`` does.

    ``materials``: a name or :class:`Material`, or one per channel (the last serves the
    rest); names are looked up in ``library`` (a :class:`Library`, a path, or ``None``
    for the built-in materials).

    ``force``: total force per channel in newtons, shape ``(channels, samples)`` (1-D
    for one channel), sample ``k`` at ``k / force_rate`` seconds. Or ``gait``: a walk
    generated from a spec such as ``"steps=12,cadence=1.8,weight=70"`` (the command
    line's ``--gait``).

    The other arguments are ``underfoot render``'s flags: ``model`` ("iir" or
    "physical"), ``drive`` ("impulse", "force", "force-rate"), ``excitation`` ("fitted"
    or "heel"), ``gain_db`` and ``ceiling_db`` (the hard limiter's, re full scale),
    ``perturbation`` (per-step numerator noise; ``None``: each material's own), ``seed``,
    ``lowpass_order``, ``weight`` (kg, the nominal step's), ``step_threshold`` (N),
    ``tail`` (s of output after the last reading), ``block`` (frames per engine call;
    the output does not depend on it). ``sensor_rate`` sets the force interpolation:
    by default ``force_rate`` for an array and 500 Hz for a gait (the command line's
    ``--sensor-rate`` is 500 unless given).

    Returns a :class:`Render`; the output went through the hard limiter, as a device's
    would.
    """
    if isinstance(materials, (str, Material)):
        materials = [materials]
    if not isinstance(materials, (list, tuple)):
        raise InputTypeError(
            f"materials: expected a name, a Material or a list of them, got "
            f"{type(materials).__name__}"
        )
    if len(materials) == 0:
        raise InputError("materials: the list is empty")
    played = []
    for m in materials:
        if isinstance(m, Material):
            played.append(m._native)
        elif isinstance(m, str):
            played.append(m)
        else:
            raise InputTypeError(f"materials: {m!r} is neither a name nor an underfoot.Material")
    if library is None:
        native_library = None
    elif isinstance(library, Library):
        native_library = library._native
    else:
        native_library = _underfoot.Library.load(_path(library, "library"))
    if (force is None) == (gait is None):
        raise InputError("give force (with force_rate) or gait, one of the two")
    array = None
    if force is not None:
        array = _float_array(force, "force", (1, 2))
        if array.ndim == 1:
            array = array[_np.newaxis, :]
        if force_rate is None:
            raise InputError("force needs its force_rate (Hz)")
        force_rate = _number(force_rate, "force_rate")
    if gait is not None and not isinstance(gait, str):
        raise InputTypeError(f"gait: expected a spec string, got {type(gait).__name__}")
    if sensor_rate is None:
        # The readings arrive at the force's rate; the interpolation tops out at 10 kHz.
        sensor_rate = min(force_rate, 10_000.0) if force_rate is not None else 500.0
    audio_rate = _int(audio_rate, "audio_rate", 1, _U32)
    seed = _int(seed, "seed", 0, _U64)
    lowpass_order = _int(lowpass_order, "lowpass_order", 0, _U32)
    block = _int(block, "block", 1, 65_536)
    tail = _number(tail, "tail")
    if not 0.0 <= tail <= 60.0:
        raise InputError(f"tail {tail!r} s: need 0 to 60")
    for what, v in (("model", model), ("drive", drive), ("excitation", excitation)):
        if not isinstance(v, str):
            raise InputTypeError(f"{what}: expected a str, got {type(v).__name__}")
    interleaved, strikes, telemetry = _underfoot.render(
        played,
        native_library,
        array,
        force_rate,
        gait,
        model,
        drive,
        excitation,
        audio_rate,
        _number(gain_db, "gain_db"),
        _number(ceiling_db, "ceiling_db"),
        None if perturbation is None else _number(perturbation, "perturbation"),
        seed,
        lowpass_order,
        _number(weight, "weight"),
        _number(step_threshold, "step_threshold"),
        _number(sensor_rate, "sensor_rate"),
        tail,
        block,
    )
    rate = audio_rate
    return Render(
        # The engine writes frames interleaved; its transpose is (channels, frames), a
        # view of the same memory.
        samples=interleaved.T,
        rate=rate,
        strikes=[Strike(c, f, f / rate, i, m) for (c, f, i, m) in strikes],
        telemetry=_json.loads(telemetry),
    )


# --- analysis -------------------------------------------------------------------------


@_dataclass(frozen=True)
class Response:
    """A measured response: the RMS strike spectrum, smoothed (``magnitude``) and raw,
    on ``freqs`` (Hz, bins 0 to N/2 at the analysis rate), and the ``strikes`` averaged
    as ``(recording index, onset s)``."""

    freqs: _np.ndarray
    magnitude: _np.ndarray
    raw: _np.ndarray
    strikes: List[Tuple[int, float]]


def measure(
    recordings: Recordings,
    rate: Optional[float] = None,
    *,
    analysis_rate: int = 2000,
    band: Tuple[float, float] = (20.0, 900.0),
    savgol: Union[str, Tuple[int, int]] = "auto",
) -> Response:
    """The measured response of recordings (as :func:`fit` measures it before fitting):
    conditioning, strike detection, the RMS strike spectrum. ``recordings`` as for
    :func:`fit`."""
    if rate is not None:
        rate = _number(rate, "rate")
    sources = _sources(recordings, rate)
    lo, hi = _band(band)
    analysis_rate = _int(analysis_rate, "analysis_rate", 1, _U32)
    bin_hz, magnitude, raw, strikes = _underfoot.measure(sources, analysis_rate, lo, hi, savgol)
    freqs = _np.arange(len(magnitude)) * bin_hz
    return Response(freqs=freqs, magnitude=magnitude, raw=raw, strikes=list(strikes))


def _strikes(strikes: Optional[Sequence[float]]) -> Optional[List[float]]:
    if strikes is None:
        return None
    if isinstance(strikes, (str, bytes)):
        raise InputTypeError(f"strikes: expected times in seconds, got {strikes!r}")
    try:
        times = _np.asarray(strikes, dtype=float)
    except (ValueError, TypeError) as e:
        raise InputTypeError(f"strikes: expected times in seconds: {e}") from None
    return [float(t) for t in _float_array(times, "strikes", (1,))]


def steps(
    samples: ArrayLike,
    rate: float,
    *,
    strikes: Optional[Sequence[float]] = None,
    band: Tuple[float, float] = (20.0, 900.0),
) -> List[Dict[str, Any]]:
    """Each step of a signal measured in time, as ``compare`` measures them: its onset
    (s), energy, duration (``duration_ms``, 5 to 95% of the energy), micro-events
    (``(time s, level dB)``), crest factor, decay envelope (dB per 10 ms) and band
    spectrum. ``strikes`` (s): where the steps are known to land (a render's); else
    the steps are found in the signal."""
    x = _float_array(samples, "samples", (1,))
    lo, hi = _band(band)
    return _json.loads(_underfoot.steps(x, _number(rate, "rate"), _strikes(strikes), lo, hi))


def summarize_steps(
    samples: ArrayLike,
    rate: float,
    *,
    strikes: Optional[Sequence[float]] = None,
    band: Tuple[float, float] = (20.0, 900.0),
) -> Dict[str, Any]:
    """What the steps of a signal have in common: the statistics a material keeps of its
    recordings (:attr:`Material.time`): median duration, micro-event count and rate,
    crest factor, spread between steps, decay envelope, average spectrum."""
    x = _float_array(samples, "samples", (1,))
    lo, hi = _band(band)
    return _json.loads(
        _underfoot.summarize_steps(x, _number(rate, "rate"), _strikes(strikes), lo, hi)
    )


def compare_steps(
    samples: ArrayLike,
    rate: float,
    material: Material,
    *,
    strikes: Optional[Sequence[float]] = None,
    gain_db: float = 0.0,
) -> Optional[Dict[str, Any]]:
    """A rendered signal's steps against ``material``'s recorded ones, as ``compare``
    and ``fit --report`` print them: ``rendered`` (as :func:`summarize_steps`),
    ``spectrum_db`` (gain-aligned distance of the average spectra) and ``level_db``
    (the rendered level over the recorded, with ``gain_db`` and the playback level
    taken out). ``None`` for a material without recorded step statistics."""
    if not isinstance(material, Material):
        raise InputTypeError(f"material: expected an underfoot.Material, got {type(material).__name__}")
    x = _float_array(samples, "samples", (1,))
    out = _underfoot.compare_steps(
        x, _number(rate, "rate"), material._native, _strikes(strikes), _number(gain_db, "gain_db")
    )
    return _json.loads(out)


# --- sessions -------------------------------------------------------------------------


@_dataclass(frozen=True)
class Session:
    """A recorded session (``underfoot run --record DIR``), read back.

    ``force_times`` (s) and ``force`` (total newtons, ``(channels, rows)``, the channels
    named by ``force_channels``), with every sensor in ``force_readings``
    (``(rows, columns)``, named by ``force_columns``, ``channel.sensor``);
    ``strikes`` (dicts: ``time``, ``frame``, ``channel`` from 0 as the force's rows (the
    folder's ``strikes.csv`` counts from 1), ``intensity``,
    ``material``), ``markers``, ``events``, ``status``, the ``manifest``; the output
    through :meth:`output`. ``finished`` is False for a session whose process was
    killed (its files end where the last flush left them)."""

    path: str
    manifest: Dict[str, Any]
    rate: float
    finished: bool
    force_times: Optional[_np.ndarray]
    force: Optional[_np.ndarray]
    force_readings: Optional[_np.ndarray]
    force_columns: List[str]
    force_channels: List[str]
    strikes: List[Dict[str, Any]]
    markers: List[Dict[str, Any]]
    events: List[Dict[str, Any]]
    status: List[Dict[str, Any]]
    _output: Optional[_np.ndarray]

    def output(self) -> Optional[_np.ndarray]:
        """The output the session played, float32 ``(channels, frames)`` at :attr:`rate`;
        ``None`` when it was not recorded."""
        return self._output


def read_session(path: PathLike) -> Session:
    """Reads a recorded session folder."""
    meta, force, output = _underfoot.read_session(_path(path, "path"))
    meta = _json.loads(meta)
    times = totals = readings = None
    columns: List[str] = []
    channels: List[str] = []
    if force is not None:
        times, totals, readings, columns, channels = force
    return Session(
        path=meta["path"],
        manifest=meta["manifest"],
        rate=meta["rate"],
        finished=meta["finished"],
        force_times=times,
        force=totals,
        force_readings=readings,
        force_columns=list(columns),
        force_channels=list(channels),
        strikes=meta["strikes"],
        markers=meta["markers"],
        events=meta["events"],
        status=meta["status"],
        _output=None if output is None else output[0],
    )
