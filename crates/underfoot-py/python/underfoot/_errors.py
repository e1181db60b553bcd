"""The exceptions underfoot raises: one class per stage of the pipeline.

Every exception the package raises on purpose derives from :class:`Error`; a message is
the one the command line prints for the same fault.
"""

from __future__ import annotations

__all__ = [
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


class Error(Exception):
    """Base class of every error underfoot raises."""


class InputError(Error, ValueError):
    """An argument from Python is wrong: a shape, an empty list, a NaN, an unknown option."""


class InputTypeError(InputError, TypeError):
    """An argument has the wrong type or dtype (underfoot takes float arrays)."""


class RecordingError(Error):
    """A recording cannot be read or decoded, or is empty, silent, too short or not finite."""


class AnalysisError(Error):
    """Recordings or a signal cannot be analysed (no strike found, a band that does not fit)."""


class FitError(Error):
    """A material cannot be fitted to the recordings."""


class PoorFitError(FitError):
    """The fit is above the quality bound; ``accept_poor_fit=True`` keeps it.

    Attributes ``lsd_db`` and ``nrmse`` give the best fit's figures.
    """

    lsd_db: float
    nrmse: float


class LibraryError(Error):
    """A library file cannot be read or written, or breaks a rule of the format."""


class MaterialNotFound(LibraryError, KeyError):
    """The library holds no material of that name."""

    def __str__(self) -> str:
        # KeyError quotes its argument; the message reads better as it is.
        return str(self.args[0]) if self.args else ""


class ForceError(Error):
    """A force track or a gait specification is invalid."""


class EngineError(Error):
    """The engine cannot play: a setting out of range, a material that cannot be played."""


class SessionError(Error):
    """A recorded session folder cannot be read."""
