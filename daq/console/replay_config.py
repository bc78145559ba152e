"""The rig config a replay draws with: the stored one, or one for a file of the sync view alone.

Responsibility: :func:`replay_config` returns the stored rig config when it is a whole one
(:func:`daq.config.parse_rig_config`). A file written from the smallest run file of
``docs/reference/file_format.md`` stores only a ``[section]`` and has no pressures: it is replayed
with a config for display built around that section (its traces, spectra and releases are all
the console draws of it), and the note returned says so in the status line. A file that has
pressures needs its stored ``[taps]`` to place them, so its config must be whole.

Not responsible for: reading the file (:mod:`daq.console.replay`).
"""

from __future__ import annotations

import json
import tomllib
from typing import Any

from daq.config import RigConfig, parse_rig_config
from daq.errors import ConfigError, ReplayError

__all__ = ["replay_config"]

#: What a replay note says of a file without a whole rig config.
NO_RIG_NOTE = "no rig config with taps in the file: traces only, no pressures"


def replay_config(text: str, where: str, *, has_pressure: bool,
                  name: str) -> tuple[RigConfig, str | None]:
    """Return the config a replay draws with, and a note for the status line (or None).

    Parameters
    ----------
    text : str
        The stored ``/entry/config``.
    where : str
        Names it in errors (``FILE:/entry/config``).
    has_pressure : bool
        Whether the file has ``/entry/sync/pressure``.
    name : str
        The rig's name when the config has no ``[rig]`` (the file's stem).

    Raises
    ------
    ReplayError
        The stored config is not TOML, has no valid ``[section]``, or is not a whole rig config
        although the file has pressures to draw.
    """
    try:
        return parse_rig_config(text, where), None
    except ConfigError as exc:
        whole_error = exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ReplayError(f"{where}: the stored rig config is not valid TOML: {exc}") from exc
    section = data.get("section")
    if not isinstance(section, dict):
        raise ReplayError(f"{where}: has no [section]: replay needs at least the section "
                          "model (docs/reference/file_format.md)")
    if has_pressure:
        raise ReplayError(f"{where}: the stored rig config is invalid ({whole_error}); the "
                          "file's pressures need its [taps] to be drawn")
    try:
        return parse_rig_config(_display_text(data, section, name), where), NO_RIG_NOTE
    except ConfigError as exc:  # the [section] itself is wrong: say that, not the stand-in
        raise ReplayError(f"{where}: the stored [section] is invalid: {exc}") from exc


def _display_text(data: dict[str, Any], section: dict[str, Any], name: str) -> str:
    """Return a rig config of the stored ``[section]`` with what the window asks for besides.

    The window asks for a tap layout (the outline and the Cp view, empty here: the file has
    no pressures), limits and a tunnel (used by live controls only, which a replay has not).
    """
    keep = {"B", "m", "I", "fh", "fa", "zeta_h", "zeta_a", "S", "fp", "zeta_p", "m_p",
            "depth"}
    fields = {k: v for k, v in section.items() if k in keep}
    B = fields.get("B", 1.0)
    B = float(B) if isinstance(B, (int, float)) else 1.0  # a bad B: parse_rig_config names it
    # The outline drawn: the section's box (its depth, else a tenth of its width).
    depth = fields.setdefault("depth", 0.1 * B)
    depth = float(depth) if isinstance(depth, (int, float)) else 0.1 * B
    rig: dict[str, Any] = data["rig"] if isinstance(data.get("rig"), dict) else {}
    # JSON's strings and numbers are TOML's too; a value of the wrong type stays as it is,
    # for parse_rig_config to name.
    lines = ["[rig]", f"name = {json.dumps(str(rig.get('name', name)))}", "",
             "[section]", *(f"{k} = {json.dumps(v)}" for k, v in fields.items()), "",
             "[taps]", 'shape = "rectangle"', f"B = {B!r}", f"D = {depth!r}",
             "taps_per_face = 2", "",
             "[limits]", "max_wind_speed = 100.0", "max_fan_rpm = 100000.0", "",
             "[tunnel]", "wind_per_rpm = 0.001", ""]
    return "\n".join(lines)
