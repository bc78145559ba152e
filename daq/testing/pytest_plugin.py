"""The kit's pytest plugin: ``--windrig-device-url`` and the fixtures of a driver's tests.

Loaded in every pytest run of an environment where windrig is installed (entry point
``pytest11``), so that a plugin distribution's tests use it without a ``conftest.py``:

- ``--windrig-device-url URL`` (repeatable as ``--windrig-device-url ROLE=URL``): the address
  of a real device; the fixture ``windrig_device_url`` returns it and skips the test when none
  was given, so hardware tests run only where the hardware is;
- ``windrig_contract``: the module :mod:`daq.testing.contract` (``check_driver`` and the
  problem functions), for tests that take their helpers as fixtures;
- ``windrig_exchange``: :func:`daq.testing.exchange.expected_exchange`.

Imports nothing heavy at load time: it is loaded by every pytest run in the environment.
"""

from __future__ import annotations

from typing import Any

import pytest

__all__ = ["pytest_addoption", "windrig_contract", "windrig_device_url", "windrig_exchange"]


def pytest_addoption(parser: pytest.Parser) -> None:
    """Add ``--windrig-device-url``."""
    group = parser.getgroup("windrig", "windrig driver tests")
    group.addoption("--windrig-device-url", action="append", default=[], metavar="[ROLE=]URL",
                    help="address of a real device for hardware tests of a driver (e.g. "
                         "tcp://192.168.1.20:23, or scanner=tcp://...); without it they skip")


def device_url(config: pytest.Config, role: str | None = None) -> str | None:
    """Return the ``--windrig-device-url`` given (for ``role``, when given as ``ROLE=URL``)."""
    values: list[str] = list(config.getoption("--windrig-device-url") or [])
    plain = [v for v in values if "=" not in v.split("://", 1)[0]]
    if role is not None:
        for value in values:
            key, sep, url = value.partition("=")
            if sep and "://" not in key and key == role:
                return url
    return plain[0] if plain else None


@pytest.fixture
def windrig_device_url(request: pytest.FixtureRequest) -> str:
    """Return the device URL given with ``--windrig-device-url``; skip the test without one.

    A test module may set ``WINDRIG_ROLE = "scanner"`` to take a ``scanner=URL`` value.
    """
    role = getattr(request.module, "WINDRIG_ROLE", None)
    url = device_url(request.config, role)
    if url is None:
        pytest.skip("hardware test: needs --windrig-device-url URL")
    return url


@pytest.fixture
def windrig_contract() -> Any:
    """Return :mod:`daq.testing.contract`."""
    from daq.testing import contract  # here, not at load: every pytest run loads this plugin

    return contract


@pytest.fixture
def windrig_exchange() -> Any:
    """Return :func:`daq.testing.exchange.expected_exchange`."""
    from daq.testing.exchange import expected_exchange

    return expected_exchange
