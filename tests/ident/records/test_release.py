"""The Release container refuses malformed data with specific, named errors."""

from __future__ import annotations

import numpy as np
import pytest

from ident import InsufficientDataError, NonUniformSamplingError, Release


def decay(n: int = 2000, fs: float = 200.0) -> dict[str, np.ndarray]:
    t = np.arange(n) / fs
    x = np.exp(-0.2 * t) * np.cos(2 * np.pi * 2.0 * t)
    return {"t": t, "h": 0.004 * x, "alpha": 0.02 * x, "lift": 3.0 * x, "moment": 0.1 * x}


def test_a_good_release_is_stored_read_only_with_its_sampling():
    """Valid data is accepted, copied, frozen, and its rate and duration are derived."""
    data = decay()
    rel = Release(**data, U=6.0, rho=1.2, meta={"file": "run.h5"})
    assert rel.fs == pytest.approx(200.0) and rel.duration == pytest.approx(1999 / 200.0)
    data["h"][0] = 99.0
    assert rel.h[0] == pytest.approx(0.004)  # a private copy
    with pytest.raises(ValueError):
        rel.h[0] = 1.0  # read-only
    assert rel.meta == {"file": "run.h5"}


@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        ({"h": np.zeros((2000, 2))}, ValueError, "h must be a 1-D array"),
        ({"lift": np.zeros(1999)}, ValueError, "equal lengths"),
        ({"moment": "nan"}, ValueError, "moment contains 1 non-finite"),
        ({"U": 0.0}, ValueError, "U must be > 0"),
        ({"rho": -1.0}, ValueError, "rho must be > 0"),
    ],
)
def test_malformed_releases_are_refused(change, error, match):
    """Shapes, lengths, NaN gaps and non-positive U or rho raise ValueError naming the field."""
    data = decay()
    kwargs = {"U": 6.0} | data
    if change.get("moment") == "nan":
        kwargs["moment"] = data["moment"].copy()
        kwargs["moment"][100] = np.nan
    else:
        kwargs |= change
    with pytest.raises(error, match=match):
        Release(**kwargs)


def test_non_uniform_or_non_increasing_time_is_refused():
    """A jittered or repeated time stamp is a NonUniformSamplingError (and a ValueError)."""
    data = decay()
    jitter = data["t"].copy()
    jitter[500] += 1e-4  # 2 % of a step: far beyond the 1e-6 tolerance
    with pytest.raises(NonUniformSamplingError, match="not uniformly sampled"):
        Release(**(data | {"t": jitter}), U=6.0)
    repeated = data["t"].copy()
    repeated[10] = repeated[9]
    with pytest.raises(ValueError, match="strictly increasing"):
        Release(**(data | {"t": repeated}), U=6.0)


def test_too_short_releases_are_refused():
    """Fewer than 64 samples, or fewer than 3 periods, is InsufficientDataError."""
    with pytest.raises(InsufficientDataError, match="at least 64 samples"):
        Release(**decay(n=50), U=6.0)
    # 2 Hz for 0.8 s: 1.6 periods.
    with pytest.raises(InsufficientDataError, match="at least 3 oscillation periods"):
        Release(**decay(n=160), U=6.0)


@pytest.mark.parametrize("offset", [100.0, 0.51, -0.01], ids=["clock", "late", "before"])
def test_a_time_axis_that_does_not_start_at_the_release_is_refused(offset):
    """A clock's time (100 s) or samples before the instant are refused, naming the start.

    Unguarded, a decay at t of 100 s stopped the fit with "Eigenvalues did not converge".
    """
    data = decay()
    with pytest.raises(ValueError, match=f"t starts at {offset:g} s: a release's time"):
        Release(**(data | {"t": data["t"] + offset}), U=6.0)


def test_a_first_sample_just_after_the_instant_is_accepted():
    """A first sample up to 0.5 s after the instant, or nearest it (under a step before it)."""
    data = decay()
    for offset in (0.03, 0.5, -0.5 / 200.0, -0.9 / 200.0):
        assert Release(**(data | {"t": data["t"] + offset}), U=6.0).t[0] == pytest.approx(offset)
