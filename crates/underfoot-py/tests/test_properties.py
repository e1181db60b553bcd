"""Whatever array and rate a caller passes, each entry point returns or raises an
`underfoot.Error`: never another exception, and never a Rust panic (pyo3's
PanicException derives from BaseException, so `except Exception` would let it through:
BaseException is caught here and fails the test).
"""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import underfoot

# About 60 examples a target keeps the four under ~30 s; no example database, so that a
# run leaves nothing behind in the repository.
SETTINGS = settings(
    max_examples=60,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow],
)

MAX_SIZE = 5000
SPECIAL = [np.nan, np.inf, -np.inf, 1e308, -1e308, 5e-324, -0.0, 1e30]


@st.composite
def arrays(draw):
    """An array of any dtype the package might be given, 0-D to 3-D, up to MAX_SIZE
    elements: noise, decaying bursts (strike-like), silence or a constant, at a scale from
    denormal to huge, with special values (NaN, infinities, extremes) planted in it."""
    # Weighted towards what reaches the library (1-D and 2-D floats at ordinary rates):
    # most of the rest is refused in Python before it gets there.
    ndim = draw(st.sampled_from([1, 1, 1, 1, 2, 2, 0, 3]))
    shape = []
    room = MAX_SIZE
    for _ in range(ndim):
        # Hypothesis favours small integers; the sizes worth trying are spread to MAX_SIZE.
        side = draw(st.one_of(st.integers(0, room), st.integers(room // 2, room)))
        shape.append(side)
        room = room // side if side else MAX_SIZE
    shape = tuple(shape)
    size = math.prod(shape)
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    kind = draw(st.sampled_from(["noise", "bursts", "zeros", "constant"]))
    scale = draw(st.sampled_from([1e-300, 1e-6, 1.0, 800.0, 1e6, 1e300]))
    if kind == "noise":
        x = rng.standard_normal(size)
    elif kind == "bursts":
        t = np.arange(size)
        x = np.sin(0.3 * t) * np.exp(-(t % 700) / 80.0) * (rng.random(size) < 0.9)
    elif kind == "zeros":
        x = np.zeros(size)
    else:
        x = np.ones(size)
    with np.errstate(over="ignore", invalid="ignore"):
        x = x * scale
    if size:
        # Half the arrays are finite: a planted NaN is refused before any analysis.
        for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2, 3]))):
            x[draw(st.integers(0, size - 1))] = draw(st.sampled_from(SPECIAL))
    dtype = draw(
        st.sampled_from(["float64"] * 4 + ["float32"] * 2 + ["int64", "int32", "bool"])
    )
    with np.errstate(over="ignore", invalid="ignore"):
        if dtype.startswith("int"):
            info = np.iinfo(dtype)
            x = np.nan_to_num(x, nan=0.0, posinf=info.max, neginf=info.min)
            x = np.clip(x, info.min, info.max)
        x = x.astype(dtype)
    x = x.reshape(shape)
    if draw(st.booleans()) and x.ndim >= 1:
        x = x[..., ::-1]  # not C-contiguous: no copy-free path
    return x


# Rates: the special ones, fractional ones, and ordinary whole hertz (what recordings
# have) most often; not so low that a legal render of 5000 readings would take minutes
# (an hour of output is allowed and would be slow, not wrong).
rates = st.one_of(
    st.sampled_from([500.0, 1000.0, 2000.0, 8000.0, 22050.0, 44100.0, 48000.0]),
    st.integers(100, 200_000).map(float),
    st.floats(100.0, 200_000.0),
    st.sampled_from([0.0, -1.0, np.nan, np.inf, -np.inf, 1e-300, 1e300, 2.0**64, 2000.5]),
)


def returns_or_raises_underfoot_error(call, *args, **kwargs):
    try:
        call(*args, **kwargs)
        event("returned")
    except underfoot.Error as e:
        # Which stage refused it (--hypothesis-show-statistics): how deep the inputs reach.
        event(type(e).__name__)
    except BaseException as e:  # noqa: BLE001 - a panic is a BaseException
        described = [
            f"{a.dtype}{a.shape}" if isinstance(a, np.ndarray) else repr(a) for a in args
        ]
        pytest.fail(
            f"{call.__name__}({', '.join(described)}, {kwargs}) raised "
            f"{type(e).__module__}.{type(e).__qualname__}: {e}"
        )


@SETTINGS
@given(x=arrays(), rate=rates)
def test_fit_returns_or_raises_an_underfoot_error(x, rate):
    returns_or_raises_underfoot_error(underfoot.fit, x, rate)


@SETTINGS
@given(x=arrays(), rate=rates)
def test_render_of_any_force_returns_or_raises_an_underfoot_error(x, rate):
    # A short tail: the property is about the input, and ringing out adds only time.
    returns_or_raises_underfoot_error(underfoot.render, "gravel", x, rate, tail=0.05)


@SETTINGS
@given(x=arrays(), rate=rates)
def test_measure_returns_or_raises_an_underfoot_error(x, rate):
    returns_or_raises_underfoot_error(underfoot.measure, x, rate)


@SETTINGS
@given(x=arrays(), rate=rates, with_strikes=st.booleans())
def test_steps_returns_or_raises_an_underfoot_error(x, rate, with_strikes):
    strikes = [0.0, 0.05, -1.0, np.nan, 1e300] if with_strikes else None
    returns_or_raises_underfoot_error(underfoot.steps, x, rate, strikes=strikes)
