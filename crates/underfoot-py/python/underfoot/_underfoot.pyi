"""Type stubs of the native module ``underfoot._underfoot`` (Rust, pyo3).

The public API is the package ``underfoot``, which checks its arguments and calls these
with plain types; call them directly only if you need to skip those checks.
"""

from typing import Any, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
BUILD_PROFILE: str
"""The cargo profile the module was built with: "release" (pip's default) or "dev"."""

class Material:
    """A material model (wrapped by ``underfoot.Material``)."""

    @property
    def name(self) -> str: ...
    @property
    def order(self) -> int: ...
    @property
    def analysis_rate(self) -> int: ...
    @property
    def band(self) -> Tuple[float, float]: ...
    @property
    def level_db(self) -> float: ...
    @property
    def poor_fit(self) -> bool: ...
    @property
    def sos(self) -> npt.NDArray[np.float64]: ...
    def response(
        self,
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]: ...
    def to_json(self) -> str: ...
    def fit_json(self) -> str: ...
    def time_json(self) -> str: ...
    def physical_json(self) -> str: ...
    @staticmethod
    def from_json(text: str) -> "Material": ...

class Library:
    """A library of materials (wrapped by ``underfoot.Library``)."""

    def __init__(self) -> None: ...
    @staticmethod
    def load(path: str) -> "Library": ...
    @staticmethod
    def builtin() -> "Library": ...
    def get(self, name: str) -> Material: ...
    def names(self) -> List[str]: ...
    def add(self, material: Material) -> bool: ...
    def remove(self, name: str) -> Material: ...
    def save(self, path: str) -> None: ...
    def to_json(self) -> str: ...

Source = Union[str, Tuple[str, float, npt.NDArray[np.float64]]]
"""A recording: a file path, or ``(name, rate, samples)``."""

def fit(
    sources: Sequence[Source],
    material: str,
    analysis_rate: int,
    band_lo: float,
    band_hi: float,
    order: Optional[int],
    max_order: int,
    savgol: Union[str, Tuple[int, int]],
    target_lsd: float,
    longest_decay: float,
    accept_poor_fit: bool,
    csv_column: Optional[str],
    csv_rate: Optional[float],
) -> Material: ...
def read_recording(
    path: str, csv_column: Optional[str], csv_rate: Optional[float]
) -> Tuple[npt.NDArray[np.float64], int, str, str]:
    """Returns ``(samples, rate, name, sha256)``."""

def render(
    materials: Sequence[Union[str, Material]],
    library: Optional[Library],
    force: Optional[npt.NDArray[np.float64]],
    force_rate: Optional[float],
    gait: Optional[str],
    model: str,
    drive: str,
    excitation: str,
    audio_rate: int,
    gain_db: float,
    ceiling_db: float,
    perturbation: Optional[float],
    seed: int,
    lowpass_order: int,
    weight: float,
    step_threshold: float,
    sensor_rate: float,
    tail: float,
    block: int,
) -> Tuple[
    npt.NDArray[np.float32], List[Tuple[int, int, float, Optional[str]]], str
]:
    """Returns the interleaved output ``(frames, channels)``, the strikes
    ``(channel, frame, intensity, material)`` and the telemetry as JSON."""

def measure(
    sources: Sequence[Source],
    analysis_rate: int,
    band_lo: float,
    band_hi: float,
    savgol_setting: Union[str, Tuple[int, int]],
) -> Tuple[float, npt.NDArray[np.float64], npt.NDArray[np.float64], List[Tuple[int, float]]]:
    """Returns ``(bin_hz, magnitude, raw, strikes)``."""

def steps(
    samples: npt.NDArray[np.float64],
    rate: float,
    strikes: Optional[List[float]],
    band_lo: float,
    band_hi: float,
) -> str:
    """Returns the steps as JSON."""

def summarize_steps(
    samples: npt.NDArray[np.float64],
    rate: float,
    strikes: Optional[List[float]],
    band_lo: float,
    band_hi: float,
) -> str:
    """Returns the summary as JSON."""

def compare_steps(
    samples: npt.NDArray[np.float64],
    rate: float,
    material: Material,
    strikes: Optional[List[float]],
    gain_db: float,
) -> str:
    """Returns the comparison as JSON (``null`` without recorded statistics)."""

def read_session(
    path: str,
) -> Tuple[
    str,
    Optional[
        Tuple[
            npt.NDArray[np.float64],
            npt.NDArray[np.float64],
            npt.NDArray[np.float64],
            List[str],
            List[str],
        ]
    ],
    Optional[Tuple[npt.NDArray[np.float32], float]],
]:
    """Returns the record's JSON, its force ``(times, totals, readings, columns, channels)`` and
    its output ``(samples (channels, frames), rate)``."""

