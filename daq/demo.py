"""``windrig demo``: the numerical core on the embedded flat-plate section.

Until the acquisition layers exist, the demo shows what the rest of windrig builds on: the
state-space flutter analysis of a flat plate with the closed-form Jones RFC model, cross-checked by
the classical frequency-domain solution with the exact Theodorsen flutter derivatives, and
simulated releases below and just above the flutter speed. It writes a plot and a JSON summary.
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: the demo must run on a machine without a screen
import matplotlib.pyplot as plt  # noqa: E402 - the backend must be chosen first
import numpy as np  # noqa: E402

from ident import SectionModel, flat_plate, flutter  # noqa: E402
from simulators import SimulatedRelease, simulate_release  # noqa: E402

#: The embedded default section: a 0.3 m flat-plate section model on a typical spring rig.
DEMO_SECTION = SectionModel(B=0.3, m=3.0, I=0.03, fh=2.0, fa=4.0, zeta_h=0.005, zeta_a=0.005)


def run(out: Path) -> int:
    """Run the demo, write ``flutter.png``, ``releases.png`` and ``summary.json`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    section = DEMO_SECTION
    model = flat_plate.jones_model()

    t0 = time.perf_counter()
    td = flutter.analyze(section, model)
    t_td = time.perf_counter() - t0
    t0 = time.perf_counter()
    fd = flutter.frequency_domain(section, flat_plate.flutter_derivatives)
    t_fd = time.perf_counter() - t0
    if td.speed is None or fd.speed is None:
        print(f"demo: unexpected: {td.summary()} / {fd.summary()}")
        return 1

    print("windrig demo: flat plate, B = 0.3 m, m = 3 kg/m, I = 0.03 kg m^2/m, "
          "fh = 2 Hz, fa = 4 Hz, zeta = 0.5 %")
    print(f"{'method':<44}{'U_F (m/s)':>10}{'f_F (Hz)':>10}{'K_F':>8}{'time (s)':>10}")
    for label, res, dt in (
        ("state-space, Jones RFC model (windrig)", td, t_td),
        ("frequency-domain, exact Theodorsen (Scanlan)", fd, t_fd),
    ):
        print(f"{label:<44}{res.speed:>10.3f}{res.frequency:>10.3f}"
              f"{res.reduced_frequency:>8.3f}{dt:>10.3f}")
    gap = td.speed / fd.speed - 1.0
    print(f"difference {100 * gap:+.2f} % (the Jones approximation of Theodorsen's function)")
    print(td.summary())

    releases = {
        label: simulate_release(section, model, factor * td.speed, 0.0, 0.02,
                                duration=12.0, fs=200.0)
        for label, factor in (("0.8 U_F", 0.8), ("1.02 U_F", 1.02))
    }
    _plot_modes(td, out / "flutter.png")
    _plot_releases(releases, out / "releases.png")
    summary = {
        "section": section.to_dict(),
        "model": model.to_dict(),
        "flutter_speed_state_space": td.speed,
        "flutter_frequency_state_space": td.frequency,
        "flutter_speed_frequency_domain": fd.speed,
        "critical_mode": td.critical_mode,
        "divergence_speed": td.divergence_speed,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    print(f"wrote {out / 'flutter.png'}, {out / 'releases.png'}, {out / 'summary.json'}")
    return 0


def _plot_modes(result: flutter.FlutterResult, path: Path) -> None:
    fig, (ax_f, ax_z) = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    for j, name in enumerate(result.mode_names):
        ax_f.plot(result.U, result.frequencies[:, j], label=name)
        ax_z.plot(result.U, 100 * result.damping[:, j], label=name)
    for ax in (ax_f, ax_z):
        ax.axvline(result.speed, color="k", ls="--", lw=0.8)
        ax.grid(True, alpha=0.3)
    ax_z.axhline(0.0, color="k", lw=0.8)
    ax_f.set_ylabel("frequency (Hz)")
    ax_z.set_ylabel("damping ratio (%)")
    ax_z.set_xlabel("wind speed U (m/s)")
    ax_z.set_ylim(-5, max(10.0, float(np.nanmax(100 * result.damping[: len(result.U) // 2]))))
    ax_f.legend()
    ax_f.set_title(f"Flat plate: flutter at {result.speed:.2f} m/s, {result.frequency:.2f} Hz")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _plot_releases(releases: Mapping[str, SimulatedRelease], path: Path) -> None:
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
    for label, rel in releases.items():
        axes[0].plot(rel.t, 1000 * rel.h, lw=0.8, label=label)
        axes[1].plot(rel.t, np.degrees(rel.alpha), lw=0.8, label=label)
    axes[0].set_ylabel("h (mm)")
    axes[1].set_ylabel("alpha (deg)")
    axes[1].set_xlabel("time after release (s)")
    axes[0].legend()
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
