"""Speed of the full-bridge flutter analysis: state space against frequency domain (not a test).

A simply supported deck (the IABSE section: B = 31 m, m = 22740 kg/m, I = 2.47e6 kg m^2/m) of
1200 m with ``n`` sine modes, a third each vertical (0.085 Hz + 0.03 Hz per half-wave), torsional
(0.28 Hz + 0.09 Hz) and lateral (0.05 Hz + 0.04 Hz, with 0.002 rad/m of torsion), damping 0.5 %,
generalised masses of the deck; the flat plate's aerodynamics (Jones's two lags) with
quasi-steady sway terms. For each number of modes and deck nodes: the state-space flutter
analysis (:func:`ident.bridge.flutter.analyze`, 120 wind speeds: eigenvalues of a matrix of
``n (2 + 2)`` states, bracket and Brent) and the frequency-domain one
(:func:`ident.bridge.flutter.frequency_domain`, 400 reduced frequencies: a quadratic eigenvalue
problem of ``2 n``), wall time and flutter speeds.

A second table times the buffeting analysis of the same decks at ``--buffeting-U`` (default
40 m/s) in the wind of ``rig_configs/bridges/example_wind.toml`` (u and w, span-wise coherence,
Davenport admittance): the frequency domain (:func:`ident.bridge.buffeting.frequency_domain`,
its default grid) by its eigen route (the default: one eigen decomposition of the state space,
the load matrices splined in frequency), with its spectra and without (RMS only), and with
``--direct`` by the direct route beside it (an inverse and the exact load matrix at every
frequency: the route of before, kept as ``route="direct"``), with the speed-up and the largest
relative difference of the RMS of every response (h, alpha, p at every node); and a seeded
time-domain record of ``--record`` s (:func:`ident.bridge.buffeting_time.simulate`: the
multi-point field at every node, then the state space; ``--record 0`` skips it), with the
largest RMS heave of each and their difference against the stated relative standard deviation
of the record's RMS. ``--no-flutter`` prints the buffeting table only.

Measured on the shared two-core host (load average 5 to 7 from the other users), 200 modes
at 1000 nodes, 5514 frequencies: the direct route 102 s (profiled before the eigen route
existed: 107 s, 54 % in the coherent load matrices, 22 % in the inverses, 17 % in the
products), the eigen route 10.7 s with spectra (9.6 times faster) and 1.9 s without; RMS within
9.9e-6 of the direct route.

With ``--fast`` the flutter table is the fast route (:func:`ident.bridge.fast_flutter.analyze`:
the modal rational eigenproblem, screened branches followed in U, the flutter point solved by
Newton) beside the dense state-space sweep on the same model, with the relative difference of
their flutter speeds; ``--dense-max`` is the most modes the dense sweep is run for (it grows as
``n^3`` per wind speed: 200 modes took 21 s to 42 s here). The fast route's wall time and its
CPU time are printed: the analysis runs on one core (single-threaded BLAS), so its CPU time is
its time on an idle core even when the host is busy. The fast route's time includes its
certification where the state space has at most 600 states (150 modes with two lags).
``--fast --fd`` prints the frequency-domain routes alike (:func:`ident.bridge.fast_flutter_fd.
frequency_domain` beside :func:`ident.bridge.flutter.frequency_domain`, ``2 n`` states).

Run: ``.venv/bin/python benchmarks/bridge_speed.py [--modes 12,50,200] [--nodes 100,1000]
[--buffeting-U 40] [--record 600] [--direct] [--no-buffeting | --no-flutter]
[--fast [--dense-max 200] [--fd]]``. The buffeting case of issue 40 alone:
``--modes 200 --nodes 1000 --no-flutter --record 0 --direct``.

``--quick`` (CI): 12 modes on 100 nodes and a record of 60 s (what is given still wins).
``--results DIR`` also writes the tables to ``DIR/<name>.json`` and ``.md`` (:mod:`result_files`):
``bridge_speed`` for both tables, ``bridge_speed_flutter`` (``--no-buffeting``),
``bridge_speed_buffeting`` (``--no-flutter``), ``bridge_speed_fast`` (``--fast``), each with
``_direct``, ``_fd`` or ``_coupled`` appended when those options are given (:func:`result_name`).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from ident.bridge import fast_flutter, fast_flutter_fd
from ident.bridge import flutter as bf
from ident.bridge.aero import aero_from_model
from ident.bridge.model import BridgeModel
from ident.model import flat_plate

sys.path.insert(0, str(Path(__file__).resolve().parent))
import result_files  # noqa: E402 - beside this script

B, M, I, SPAN = 31.0, 22740.0, 2.47e6, 1200.0
STATIC = {"C_D": 0.08, "C_L": -0.1, "C_M": 0.02, "dC_D": 0.0, "dC_L": -5.0, "dC_M": 1.2}


def sine_bridge(n_modes: int, n_nodes: int, coupled: bool = False) -> BridgeModel:
    """Return the benchmark's deck with ``n_modes`` sine modes on ``n_nodes`` nodes.

    ``coupled``: every shape tapered by ``1 + 0.3 x / L`` (no longer orthogonal to the other
    wave numbers) and every mode given 5 % of its shape in the two other coordinates, so that
    the aerodynamic forces couple each mode to most others, as in a finite-element model of an
    unsymmetric deck (the plain sines couple each branch to about three modes).
    """
    x = np.linspace(0.0, SPAN, n_nodes)
    modes = []
    for r in range(n_modes):
        kind, k = r % 3, r // 3 + 1
        shape = np.sin(k * np.pi * x / SPAN) * ((1.0 + 0.3 * x / SPAN) if coupled else 1.0)
        if kind == 0:
            modes.append({"name": f"V{k}", "frequency": 0.085 + 0.03 * (k - 1),
                          "damping": 0.005, "generalised_mass": M * SPAN / 2,
                          "h": shape.tolist()})
        elif kind == 1:
            modes.append({"name": f"T{k}", "frequency": 0.28 + 0.09 * (k - 1),
                          "damping": 0.005, "generalised_mass": I * SPAN / 2,
                          "alpha": shape.tolist()})
        else:
            modes.append({"name": f"L{k}", "frequency": 0.05 + 0.04 * (k - 1),
                          "damping": 0.005,
                          "generalised_mass": (M + I * 0.002**2) * SPAN / 2,
                          "p": shape.tolist(), "alpha": (0.002 * shape).tolist()})
    if coupled:
        for mode in modes:
            # The mode's own shape as a length (a torsional one times B).
            main = (np.asarray(mode["h"]) if "h" in mode else np.asarray(mode["p"])
                    if "p" in mode else B * np.asarray(mode["alpha"]))
            for key in ("h", "alpha", "p"):
                if key not in mode:
                    mode[key] = (0.05 * main / (B if key == "alpha" else 1.0)).tolist()
    return BridgeModel.from_dict({"name": f"{n_modes} sine modes", "B": B, "rho": 1.22,
                                  "nodes_x": x.tolist(), "modes": modes, "static": STATIC})


def _ints(text: str) -> list[int]:
    return [int(part) for part in text.split(",") if part.strip()]


#: Defaults of a full run and of ``--quick`` (options not given).
DEFAULTS = {"modes": ([12, 50, 200], [12]), "nodes": ([100, 1000], [100]),
            "record": (600.0, 60.0)}


def result_name(args: argparse.Namespace) -> str:
    """Return the result file's name for the tables the options ask (module docstring)."""
    if args.fast:
        parts = ["fast"] + (["fd"] if args.fd else []) + (["coupled"] if args.coupled else [])
    else:
        parts = (["buffeting"] if args.no_flutter else ["flutter"] if args.no_buffeting
                 else [])
        if args.direct and not args.no_buffeting:
            parts.append("direct")
    return "_".join(["bridge_speed", *parts])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", type=_ints, default=None, help="12,50,200 (--quick: 12)")
    parser.add_argument("--nodes", type=_ints, default=None, help="100,1000 (--quick: 100)")
    parser.add_argument("--buffeting-U", type=float, default=40.0)
    parser.add_argument("--record", type=float, default=None,
                        help="s of time-domain record (600; --quick: 60; 0: none)")
    parser.add_argument("--no-buffeting", action="store_true")
    parser.add_argument("--no-flutter", action="store_true",
                        help="the buffeting table only")
    parser.add_argument("--direct", action="store_true",
                        help="time the direct buffeting route beside the eigen route")
    parser.add_argument("--fast", action="store_true",
                        help="the fast flutter route beside the dense sweep (flutter only)")
    parser.add_argument("--dense-max", type=int, default=200,
                        help="most modes the dense sweep runs for with --fast")
    parser.add_argument("--fd", action="store_true",
                        help="with --fast: the frequency-domain routes, not the state space")
    parser.add_argument("--coupled", action="store_true",
                        help="with --fast: tapered shapes in all three coordinates "
                             "(sine_bridge's coupled deck)")
    result_files.add_arguments(parser)
    args = parser.parse_args()
    result_files.resolve_defaults(args, DEFAULTS)
    parameters = {"modes": args.modes, "nodes": args.nodes}
    tables = []
    if args.fast:
        tables.append(fast_rows(args.modes, args.nodes, args.dense_max, args.fd, args.coupled))
        parameters.update({"dense max": args.dense_max, "frequency domain": args.fd,
                           "coupled": args.coupled})
    elif args.no_flutter:
        tables.append(buffeting_rows(args.modes, args.nodes, args.buffeting_U, args.record,
                                     args.direct))
    else:
        tables.append(flutter_rows(args.modes, args.nodes))
        if not args.no_buffeting:
            tables.append(buffeting_rows(args.modes, args.nodes, args.buffeting_U,
                                         args.record, args.direct))
    if not args.fast and not args.no_buffeting:
        parameters.update({"buffeting U (m/s)": args.buffeting_U, "record (s)": args.record,
                           "direct": args.direct})
    result_files.write(
        result_name(args), "Speed of the full-bridge analyses", tables, results=args.results,
        quick=args.quick, script="bridge_speed", parameters=parameters,
        notes=["Wall times on a shared host move with its load."] + (
            ["The fast route's CPU time is its time on one idle core (single-threaded BLAS)."]
            if args.fast else []))


def flutter_rows(modes: list[int], nodes: list[int]) -> result_files.Table:
    """Print the flutter table (state space against frequency domain) and return it."""
    print("| modes | nodes | states | SS time (s) | SS U_F (m/s) | FD time (s) | FD U_F (m/s) "
          "| FD - SS |")
    print("|---|---|---|---|---|---|---|---|")
    rows = []
    for n_modes in modes:
        for n_nodes in nodes:
            start = time.perf_counter()
            bridge = sine_bridge(n_modes, n_nodes)
            aero = aero_from_model(bridge, flat_plate.jones_model())
            t0 = time.perf_counter()
            ss = bf.analyze(bridge, aero.model)
            t1 = time.perf_counter()
            fd = bf.frequency_domain(bridge, aero.flutter_derivatives, U_max=ss.U_max)
            t2 = time.perf_counter()
            states = n_modes * (2 + aero.model.n_lags)
            diff = ("-" if ss.speed is None or fd.speed is None
                    else f"{100 * (fd.speed / ss.speed - 1):+.3f} %")
            print(f"| {n_modes} | {n_nodes} | {states} | {t1 - t0 + (t0 - start):.2f} | "
                  f"{ss.speed or float('nan'):.3f} | {t2 - t1:.2f} | "
                  f"{fd.speed or float('nan'):.3f} | {diff} |", flush=True)
            rows.append((n_modes, n_nodes, states, t1 - start, ss.speed, t2 - t1, fd.speed,
                         None if diff == "-" else 100 * (fd.speed / ss.speed - 1)))
    return result_files.Table(
        "Flutter of the sine-mode deck: the state-space analysis (120 wind speeds, its time "
        "including the model's set-up) against the frequency-domain one (400 reduced "
        "frequencies), wall times and flutter speeds.",
        ("modes", "nodes", "states", "SS time (s)", "SS U_F (m/s)", "FD time (s)",
         "FD U_F (m/s)", "FD - SS (%)"), rows,
        formats={"SS time (s)": ".2f", "SS U_F (m/s)": ".3f", "FD time (s)": ".2f",
                 "FD U_F (m/s)": ".3f", "FD - SS (%)": "+.3f"})


def fast_rows(modes: list[int], nodes: list[int], dense_max: int, fd: bool = False,
              coupled: bool = False) -> result_files.Table:
    """Print the fast route beside the dense sweep (module docstring); ``fd``: both FD.

    Return the table.
    """
    print("| modes | nodes | states | fast time (s) | fast CPU (s) | fast U_F (m/s) "
          "| branches followed | certified | dense time (s) | dense U_F (m/s) "
          "| fast / dense - 1 |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for n_modes in modes:
        for n_nodes in nodes:
            bridge = sine_bridge(n_modes, n_nodes, coupled)
            aero = aero_from_model(bridge, flat_plate.jones_model())
            model = aero.model
            U_max = bf.default_U_max(bridge)
            t0, c0 = time.perf_counter(), time.process_time()
            fast = (fast_flutter_fd.frequency_domain(bridge, aero.flutter_derivatives,
                                                     U_max=U_max) if fd
                    else fast_flutter.analyze(bridge, model))
            t1, c1 = time.perf_counter(), time.process_time()
            note = fast.certification or ""
            followed = note.split(": ", 1)[1].split(" branches")[0] if ": " in note else "-"
            certified = "no" if "not certified" in note else "yes"
            dense_time = dense_speed = diff = "-"
            values = [None, None, None]  # dense time, dense speed, relative difference
            if n_modes <= dense_max:
                t2 = time.perf_counter()
                dense = (bf.frequency_domain(bridge, aero.flutter_derivatives, U_max=U_max)
                         if fd else bf.analyze(bridge, model))
                values[0] = time.perf_counter() - t2
                dense_time = f"{values[0]:.2f}"
                dense_speed = f"{dense.speed or float('nan'):.6f}"
                values[1] = dense.speed
                if dense.speed is not None and fast.speed is not None:
                    values[2] = fast.speed / dense.speed - 1
                    diff = f"{values[2]:+.1e}"
            states = 2 * n_modes if fd else n_modes * (2 + model.n_lags)
            print(f"| {n_modes} | {n_nodes} | {states} | {t1 - t0:.2f} | {c1 - c0:.2f} | "
                  f"{fast.speed or float('nan'):.6f} | {followed} | {certified} | {dense_time} | "
                  f"{dense_speed} | {diff} |", flush=True)
            rows.append((n_modes, n_nodes, states, t1 - t0, c1 - c0, fast.speed,
                         None if followed == "-" else followed, certified, *values))
    routes = "frequency-domain" if fd else "state-space"
    return result_files.Table(
        f"The fast {routes} flutter route beside the dense one on the same "
        f"{'coupled ' if coupled else ''}sine-mode deck (the dense one up to {dense_max} "
        "modes): wall and CPU time, flutter speeds, the branches followed, whether the dense "
        "check certified it, and the relative difference of the flutter speeds.",
        ("modes", "nodes", "states", "fast time (s)", "fast CPU (s)", "fast U_F (m/s)",
         "branches followed", "certified", "dense time (s)", "dense U_F (m/s)",
         "fast / dense - 1"), rows,
        formats={"fast time (s)": ".2f", "fast CPU (s)": ".2f", "fast U_F (m/s)": ".6f",
                 "dense time (s)": ".2f", "dense U_F (m/s)": ".6f", "fast / dense - 1": "+.1e"})


def buffeting_rows(modes: list[int], nodes: list[int], U: float, record: float,
                   direct: bool = False) -> result_files.Table:
    """Print the buffeting table (module docstring) for every number of modes and nodes.

    Return the table.
    """
    from pathlib import Path

    from ident.bridge import buffeting, buffeting_time
    from ident.bridge.statespace import BridgeStateSpace
    from ident.bridge.wind import read_wind

    wind = read_wind(Path(__file__).resolve().parents[1] / "rig_configs" / "bridges"
                     / "example_wind.toml")
    print(f"\nbuffeting at U = {U:g} m/s, time-domain record {record:g} s\n")
    print("| modes | nodes | FD frequencies | direct (s) | eigen (s) | eigen RMS only (s) "
          "| speed-up | max RMS rel. diff | TD time (s) | RMS h FD (m) | RMS h TD (m) "
          "| TD - FD | stated std |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = []
    for n_modes in modes:
        for n_nodes in nodes:
            bridge = sine_bridge(n_modes, n_nodes)
            ss = BridgeStateSpace(bridge, aero_from_model(bridge, flat_plate.jones_model()).model)
            t0 = time.perf_counter()
            fd = buffeting.frequency_domain(ss, wind, U)
            t1 = time.perf_counter()
            buffeting.frequency_domain(ss, wind, U, spectra=False)
            t2 = time.perf_counter()
            direct_time = speed_up = diff = "-"
            direct_values = [None, None, None]  # direct time, speed-up, worst difference
            if direct:
                ref = buffeting.frequency_domain(ss, wind, U, route="direct")
                t3 = time.perf_counter()
                direct_time = f"{t3 - t2:.2f}"
                speed_up = f"{(t3 - t2) / (t1 - t0):.1f}"
                worst = 0.0
                for name in ("h", "alpha", "p"):
                    a, b = getattr(fd, f"rms_{name}"), getattr(ref, f"rms_{name}")
                    moving = b > 0.0
                    if np.any(moving):
                        worst = max(worst, float(np.max(np.abs(a[moving] / b[moving] - 1.0))))
                diff = f"{worst:.1e}"
                direct_values = [t3 - t2, (t3 - t2) / (t1 - t0), worst]
            j = int(np.argmax(fd.rms_h[fd.spectrum_nodes]))
            k = int(fd.spectrum_nodes[j])
            td_cols = "- | - | -"
            td_time = "-"
            td_values = [None, None, None, None]  # time, RMS h, difference (%), stated std (%)
            if record > 0.0:
                t4 = time.perf_counter()
                td, _ = buffeting_time.simulate(ss, wind, U, record, rng=0)
                td_values[0] = time.perf_counter() - t4
                td_time = f"{td_values[0]:.2f}"
                std = fd.rms_relative_std(td.duration)["h"][j]
                td_cols = (f"{td.rms_h[k]:.4g} | {100 * (td.rms_h[k] / fd.rms_h[k] - 1):+.1f} % | "
                           f"{100 * std:.1f} %")
                td_values[1:] = [td.rms_h[k], 100 * (td.rms_h[k] / fd.rms_h[k] - 1), 100 * std]
            print(f"| {n_modes} | {n_nodes} | {fd.f.size} | {direct_time} | {t1 - t0:.2f} | "
                  f"{t2 - t1:.2f} | {speed_up} | {diff} | {td_time} | {fd.rms_h[k]:.4g} | "
                  f"{td_cols} |", flush=True)
            rows.append((n_modes, n_nodes, fd.f.size, direct_values[0], t1 - t0, t2 - t1,
                         direct_values[1], direct_values[2], td_values[0], fd.rms_h[k],
                         *td_values[1:]))
    return result_files.Table(
        f"Buffeting of the sine-mode deck at U = {U:g} m/s in the example wind: the frequency "
        "domain by its eigen route (with spectra, and RMS only) and by the direct route, their "
        "largest relative RMS difference, and "
        + (f"a seeded time-domain record of {record:g} s against the frequency domain at the "
           "node of largest RMS heave, with the stated relative std of the record's RMS."
           if record > 0.0 else "the largest RMS heave (no time-domain record)."),
        ("modes", "nodes", "FD frequencies", "direct (s)", "eigen (s)", "eigen RMS only (s)",
         "speed-up", "max RMS rel. diff", "TD time (s)", "RMS h FD (m)", "RMS h TD (m)",
         "TD - FD (%)", "stated std (%)"), rows,
        formats={"direct (s)": ".2f", "eigen (s)": ".2f", "eigen RMS only (s)": ".2f",
                 "speed-up": ".1f", "max RMS rel. diff": ".1e", "TD time (s)": ".2f",
                 "TD - FD (%)": "+.1f", "stated std (%)": ".1f"})


if __name__ == "__main__":
    main()
