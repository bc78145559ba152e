"""The rig config loader on random and mutated input: a ConfigError naming it, or a config.

Hypothesis mutates the shipped config's text: a byte changed, dropped or repeated, a line
removed, a value replaced by another of any TOML type, arbitrary text. Whatever it makes,
:func:`daq.config.parse_rig_config` returns a validated config or raises
:class:`~daq.errors.ConfigError` (the ``error:`` line of every command that takes a config),
never another exception.
"""

from __future__ import annotations

import re
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from daq.config import RigConfig, parse_rig_config
from daq.errors import ConfigError

CONFIGS = Path(__file__).resolve().parents[2] / "daq" / "rig_configs"
TEXTS = [p.read_text(encoding="utf-8") for p in sorted(CONFIGS.glob("*.toml"))]
#: ``key = value`` lines of the shipped configs (the values hypothesis replaces).
ASSIGNMENT = re.compile(r"^(\s*[A-Za-z_][A-Za-z0-9_]*\s*=\s*)(.*)$", re.M)

toml_values = st.one_of(
    st.integers(-10**20, 10**20).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(
        lambda x: {"nan": "nan", "inf": "inf", "-inf": "-inf"}.get(repr(x), repr(x))),
    st.text(max_size=20).map(lambda s: '"' + s.replace("\\", "").replace('"', "") + '"'),
    st.sampled_from(["true", "false", "[]", "[1, 2]", "{}", '{a = 1}', "1979-05-27", '""',
                     "-0.0", "0", "1e400", '"auto"', '"tcp://127.0.0.1:1"']),
)


def check(text: str) -> None:
    try:
        config = parse_rig_config(text, "fuzz.toml")
    except ConfigError as exc:
        assert str(exc).startswith("fuzz.toml"), str(exc)  # names the file
    else:
        assert isinstance(config, RigConfig)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(base=st.sampled_from(TEXTS), data=st.data())
def test_a_value_replaced_by_any_toml_value(base, data):
    lines = list(ASSIGNMENT.finditer(base))
    match = data.draw(st.sampled_from(lines))
    value = data.draw(toml_values)
    check(base[:match.start(2)] + value + base[match.end(2):])


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(base=st.sampled_from(TEXTS), data=st.data())
def test_lines_removed_or_bytes_changed(base, data):
    lines = base.splitlines(keepends=True)
    for _ in range(data.draw(st.integers(0, 3))):
        lines.pop(data.draw(st.integers(0, len(lines) - 1)))
    text = bytearray("".join(lines).encode())
    for _ in range(data.draw(st.integers(0, 4))):
        i = data.draw(st.integers(0, len(text) - 1))
        action = data.draw(st.sampled_from(["set", "drop", "repeat"]))
        if action == "set":
            text[i] = data.draw(st.integers(0, 255))
        elif action == "drop":
            del text[i]
        else:
            text[i:i] = text[i:i + data.draw(st.integers(1, 40))]
    check(text.decode("utf-8", "replace"))


@settings(max_examples=200, deadline=None)
@given(st.text(max_size=400))
def test_arbitrary_text(text):
    check(text)


def test_the_checks_can_fail_both_ways():
    """A replaced value is refused or taken on its merits (the fuzz reaches both outcomes)."""
    base = (CONFIGS / "sim_flat_plate.toml").read_text(encoding="utf-8")
    assert "\nm = 3.0" in base
    check(base.replace("\nm = 3.0", "\nm = 4.0"))
    assert parse_rig_config(base.replace("\nm = 3.0", "\nm = 4.0"), "x").section.m == 4.0
    for bad in ('"3.0"', "-3.0", "nan", "[]"):
        text = base.replace("\nm = 3.0", f"\nm = {bad}")
        try:
            parse_rig_config(text, "fuzz.toml")
        except ConfigError as exc:
            assert "m" in str(exc)
        else:
            raise AssertionError(f"m = {bad} was accepted")


def test_a_huge_tap_count_is_refused_before_anything_is_allocated():
    """Found by this fuzz: taps_per_face = 1e9 made the loader allocate until the OOM killer."""
    for text in TEXTS:
        (match,) = re.finditer(r"^(\s*(?:taps_per_face|n_taps)\s*=\s*)(\d+)", text, re.M)
        huge = text[:match.start(2)] + "1000000000" + text[match.end(2):]
        try:
            parse_rig_config(huge, "fuzz.toml")
        except ConfigError as exc:
            assert "too many: at most" in str(exc), str(exc)
        else:
            raise AssertionError("a billion taps was accepted")
