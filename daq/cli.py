"""The ``windrig`` command line: the operator's and the reprocessing engineer's entry point.

Each subcommand is a thin shell over library calls: argument parsing, printing and file output
live here, numerics live in :mod:`ident` and physics in :mod:`simulators`. Each subcommand
imports what it needs when it runs, so that ``windrig --help`` or ``windrig flutter`` start
without Qt, h5py, Dask or the simulators.

``windrig acquire --simulate`` is the one place that decides to start simulators for a
recording: it hands the rig to :func:`daq.sim.recording.record_simulated_run`; without
``--simulate`` the rig's real URLs go to :func:`daq.recording.run.record_run`.

Longer than 600 lines: one parser holds every subcommand's arguments and help (what ``windrig
--help`` lists); the subcommands' work lives in their own modules.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from daq.errors import UsageError

__all__ = ["main"]


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="windrig",
        description="Wind-tunnel section-model acquisition and flutter identification.",
    )
    parser.add_argument("--version", action="version", version=f"windrig {_version()}")
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an error (default: one 'error:' line)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p_demo = sub.add_parser(
        "demo",
        help="a whole simulated campaign on the default rig: record, identify, compare, plot",
    )
    p_demo.add_argument("--out", type=Path, default=Path("demo_output"),
                        help="output folder (created if missing; default: demo_output)")
    p_demo.add_argument("--config", type=Path, default=None,
                        help="a simulated rig config (default: rig_configs/sim_flat_plate.toml)")

    p_flutter = sub.add_parser(
        "flutter", help="flutter speed of a section (2 or 3 DOF) with a rational-function model "
                        "(JSON) or a flutter-derivative table (CSV)"
    )
    p_flutter.add_argument(
        "--section", type=Path, required=True,
        help="JSON of SectionModel fields (B, m, I, fh, fa, zeta_h, zeta_a, ...; fp, zeta_p, "
             "m_p for sway)",
    )
    aero = p_flutter.add_mutually_exclusive_group(required=True)
    aero.add_argument("--model", type=Path,
                      help='JSON of a RationalFunctionModel ({"A": ..., "d": ...}), or what '
                           "`windrig identify --json` writes")
    aero.add_argument("--table", type=Path,
                      help="CSV flutter-derivative table: K or Ur, then H1..H6, A1..A6, P1..P6")
    p_flutter.add_argument("--convention", choices=("scanlan", "z_up"), default="scanlan",
                           help="sign convention of --table (default: scanlan, windrig's)")
    p_flutter.add_argument("--u-max", type=float, default=None,
                           help="upper wind speed of the search, m/s (default: K down to 0.2)")
    p_flutter.add_argument("--json", type=Path, default=None,
                           help="write the result (both routes, the one it rests on, units, "
                                "warnings), the section and the model to this file")
    p_flutter.add_argument("--out", type=Path, default=None,
                           help="folder of the design report (report.md with its plots)")
    from daq.offline import bridge_commands  # light: imports numerics only when it runs

    bridge_commands.add_parser(sub)
    from daq.exchange import (  # light: import the readers and writers only when they run
        export_command,
        import_command,
    )

    import_command.add_parser(sub)
    export_command.add_parser(sub)
    p_id = sub.add_parser(
        "identify", help="E2RFC on the releases of recorded run files; prints the flutter speed"
    )
    p_id.add_argument("files", type=Path, nargs="+", help="windrig HDF5 run files")
    p_id.add_argument("--json", type=Path, default=None,
                      help="write the model, diagnostics and flutter result to this JSON file")
    p_id.add_argument("--n-lags", type=int, default=None, choices=(0, 1, 2, 3),
                      help="number of lag terms (default: chosen by held-out error)")
    p_id.add_argument("--no-tubing-correction", action="store_true", help="uncorrected forces")
    p_id.add_argument("--detect-releases", action="store_true",
                      help="find the releases in the lasers' signals (files without release "
                           "rows: releases by hand, imported files)")
    p_id.add_argument("--route", choices=("auto", "e2rfc", "displacement"), default="auto",
                      help="E2RFC (forces and displacements) or the displacement-only route "
                           "(flutter derivatives from decays at many wind speeds, then a Roger "
                           "fit; prints its caveats); auto (default): E2RFC when every file "
                           "holds forces")
    p_id.add_argument("--table", type=Path, default=None,
                      help="write the flutter-derivative table (CSV: K, H1..A4, then each "
                           "derivative's std H1_std..) to this file")
    p_id.add_argument("--reduced-velocities", default=None, metavar="START:STOP:STEP",
                      help="rows of --table, U/(f B) (default: the releases' span)")
    p_id.add_argument("--turbulent-estimator", choices=("iv", "ml"),
                      help="in turbulence: closed-loop ML (default) or refined IV")
    p_id.add_argument("--closed-loop-buffeting",
                      choices=("second-order", "fourth-order", "second-order-per-speed",
                               "fourth-order-per-speed", "fourth-order-mixed",
                               "fourth-order-mixed-per-speed", "by-evidence"),
                      help="closed-loop ML's buffeting model: by-evidence (default: "
                           "fourth-order where the second-order one's innovations pooled "
                           "over the records are not white; with sway the better of its two "
                           "forms; with six releases or more at every speed, one filter per "
                           "speed), second-order or fourth-order "
                           "(less biased, about twice the time); one filter for every speed, "
                           "scaled with it, or with -per-speed one per speed (turbulence "
                           "that does not scale with the speed); fourth-order-mixed: "
                           "independent gusts' filters mixed into the forces")

    p_diag = sub.add_parser(
        "diagnose",
        help="find the physical effect the identified model misses in recorded run files, add "
             "it, show the gap shrink (report and plots)")
    p_diag.add_argument("files", type=Path, nargs="+", help="windrig HDF5 run files")
    p_diag.add_argument("--out", type=Path, default=Path("diagnose_output"),
                        help="directory of the plots (default diagnose_output)")
    p_diag.add_argument("--depth", type=float, default=None,
                        help="section depth D, m, for a shedding line's Strouhal number "
                             "(default: the stored rig config's)")
    p_diag.add_argument("--json", type=Path, default=None,
                        help="write the report's numbers to this JSON file")

    p_re = sub.add_parser(
        "reprocess",
        help="reprocess many run files on Dask: per-file modal fits, per-campaign E2RFC, "
             "flutter speed and discrepancy check; tables, plots and an HTML report")
    p_re.add_argument("paths", nargs="*", help="run files, directories or globs")
    p_re.add_argument("--config", type=Path, default=None, metavar="FILE.toml",
                      help="reprocessing config: [reprocess] settings and [campaigns] "
                           "name = [paths or globs] (named campaigns replace the grouping by "
                           "stored section model)")
    p_re.add_argument("--out", type=Path, required=True, help="output directory")
    where = p_re.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="local worker processes (default: the number of cores)")
    where.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786")
    p_re.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                      dest="overrides",
                      help="identification setting (n_lags, with_A3, diagnose, depth); "
                           "repeatable")
    p_re.add_argument("--no-progress", action="store_true", help="no progress bar")

    p_sim = sub.add_parser(
        "simulate",
        help="start the simulated instruments of a rig config and print the URLs to connect to",
    )
    p_sim.add_argument("--config", type=Path, required=True, help="rig config TOML")
    p_sim.add_argument("--serial", choices=("socket", "pty"), default="socket",
                       help="serve serial instruments over socket:// (default) or a pty pair")
    p_sim.add_argument("--duration", type=float, default=None,
                       help="seconds to run, then stop (default: until Ctrl-C)")
    p_sim.add_argument("--write-config", type=Path, metavar="OUT.toml",
                       help="write a rig config of the running simulators' URLs (a real one)")

    p_check = sub.add_parser(
        "check", help="contact every device of a rig config: reachable, identity, rate, clock, "
                      "plausible wind-off readings; exit 1 naming each failing device")
    p_check.add_argument("--config", type=Path, required=True, help="rig config TOML")
    p_check.add_argument("--simulate", action="store_true", help="check the simulated rig")
    p_check.add_argument("--json", type=Path, metavar="OUT.json", help="also write the results")
    p_check.add_argument("--timeout", type=float, default=2.0, help="per device, s (default 2)")

    p_drv = sub.add_parser(
        "drivers", help="list the instrument drivers: built in and from installed plugins, "
                        "with their role and distribution")
    p_drv.add_argument("--json", action="store_true", help="print the list as JSON")

    p_acq = sub.add_parser(
        "acquire",
        help="record a run (all instruments of a rig config) to an HDF5 file; prints a summary",
    )
    p_acq.add_argument("--config", type=Path, required=True, help="rig config TOML")
    p_acq.add_argument("--simulate", action="store_true",
                       help="start the rig's simulated instruments (else: the config's URLs)")
    p_acq.add_argument("--duration", type=float, required=True, help="seconds to record")
    p_acq.add_argument("--out", type=Path, required=True, help="run file to create (.h5)")
    p_acq.add_argument("--notes", default="", help="operator notes stored with the run")
    p_acq.add_argument("--log-file", type=Path, default=None, metavar="FILE.log",
                       help="also write the run's log (device faults, reconnects, dropped "
                            "blocks, clock restarts) to this file, appended to")
    p_acq.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING",
                                                               "ERROR"),
                       help="lowest level written to --log-file (default INFO)")
    p_acq.add_argument("--skip-check", action="store_true", help="no device check first")
    p_acq.add_argument("--manual-releases", action="store_true",
                       help="releases by hand, said with keys on the terminal (Enter: "
                            "released, h: held again, q: stop); the release instant is found "
                            "in the lasers' signals. The default on a rig without a PLC")

    p_rec = sub.add_parser(
        "recover",
        help="make a run file left by a crash (SIGKILL, power cut) readable by any HDF5 tool: "
             "keep every flushed row, trim a partly written last append, mark it recovered")
    p_rec.add_argument("files", type=Path, nargs="+", help="windrig HDF5 run files")

    p_info = sub.add_parser(
        "info",
        help="what a run file holds: rig, section, devices (rates, samples, gaps, clock fits), "
             "releases, events, CALZ, and whether it was closed, crashed or recovered")
    p_info.add_argument("file", type=Path, help="a windrig HDF5 run file")
    p_info.add_argument("--json", action="store_true", help="print JSON instead of text")

    p_camp = sub.add_parser(
        "campaign", help="a headless test campaign from a plan: fixed or adaptive wind speeds, "
                         "safe stop short of flutter, resumable; report in --out")
    p_camp.add_argument("plan", type=Path, help="campaign plan TOML (rig_configs/plans/)")
    p_camp.add_argument("--config", type=Path, required=True, help="rig config TOML")
    p_camp.add_argument("--simulate", action="store_true",
                        help="start the rig's simulated instruments (else: the config's URLs)")
    p_camp.add_argument("--out", type=Path, required=True,
                        help="directory for the run files and the report (resumed if present)")
    p_camp.add_argument("--skip-check", action="store_true", help="do not check every device first")

    p_gui = sub.add_parser(
        "gui", help="the operator console: a live (simulated) rig, or replay of a run file")
    p_gui.add_argument("--replay", type=Path, default=None, metavar="FILE.h5",
                       help="windrig run file to play back")
    p_gui.add_argument("--config", type=Path, default=None, help="rig config TOML (live mode)")
    p_gui.add_argument("--simulate", action="store_true",
                       help="live mode on the config's simulated rig (in a child process)")
    p_gui.add_argument("--fan-rpm", type=float, default=None, metavar="RPM",
                       help="live mode: start the fan at this speed (within the config's "
                            "limits; default: leave it off)")
    p_gui.add_argument("--speed", type=float, default=1.0,
                       help="replay speed, x real time (default 1)")
    p_gui.add_argument("--window", type=float, default=20.0,
                       help="scrolling time window, s (default 20)")
    p_gui.add_argument("--screenshot", type=Path, default=None, metavar="OUT.png",
                       help="render headless, save the window as PNG and exit")
    p_gui.add_argument("--after", type=float, default=3.0,
                       help="seconds to run before the screenshot (default 3)")
    p_gui.add_argument("--size", type=int, nargs=2, default=(1280, 800),
                       metavar=("WIDTH", "HEIGHT"), help="window size, px (default 1280 800)")
    p_gui.add_argument("--record-dir", type=Path, default=None, metavar="DIR",
                       help="live mode: directory of the run files recorded from the console "
                            "(default: the current directory)")
    p_gui.add_argument("--auto-release", type=_rpm_list, default=(), metavar="RPM[,RPM...]",
                       help="simulated rig only: a hands-free session, one release (arm, "
                            "hold, release, decay, arm) at each fan speed in turn")
    p_gui.add_argument("--skip-check", action="store_true", help="live: no device check first")
    return parser


def _rpm_list(text: str) -> tuple[float, ...]:
    """Parse ``"600,850"`` into fan speeds, rpm."""
    try:
        return tuple(float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected fan speeds in rpm separated by "
                                         "commas, e.g. 600,850") from None


def _gui(args: argparse.Namespace) -> int:
    from daq.console.app import GuiOptions, run_gui

    return run_gui(GuiOptions(replay=args.replay, config=args.config, simulate=args.simulate,
                              fan_rpm=args.fan_rpm, speed=args.speed, window_s=args.window,
                              screenshot=args.screenshot, after_s=args.after,
                              size=(args.size[0], args.size[1]), record_dir=args.record_dir,
                              auto_release=args.auto_release,
                              check=not args.skip_check))


def _acquire(args: argparse.Namespace) -> int:
    from daq.config import load_rig_config
    from daq.recording.run import record_run
    from daq.sim.commands import refuse_auto_urls
    from daq.sim.recording import record_simulated_run

    if not args.duration > 0:
        raise UsageError(f"--duration {args.duration:g}: must be > 0 s")
    config = load_rig_config(args.config)
    if not args.simulate:
        refuse_auto_urls(config, args.config)
    from daq.errors import DeviceCheckError, StorageError
    from daq.recording.swmr_file import failed_writes

    keys = None
    if args.manual_releases or not config.by_role("plc"):
        from daq.acquisition.operator_keys import KEYS_HELP, OperatorKeys

        def say(line: str) -> None:
            print(line, file=sys.stderr, flush=True)

        say(KEYS_HELP + ("" if config.by_role("plc") else " (the rig has no PLC)"))
        keys = OperatorKeys(sys.stdin, say=say, until=threading.Event())
    try:
        options: dict[str, Any] = {"operator_notes": args.notes, "check": not args.skip_check,
                                   "progress": sys.stderr.isatty() and keys is None,
                                   "until": None if keys is None else keys.until}
        if args.simulate:  # the instruments in a process of their own, as real ones are
            def simulated_keys(acq: Any, rig: Any) -> None:
                assert keys is not None
                # The simulated operator lets the model go (and holds it) through the tunnel.
                keys.hand = lambda what: rig.hand_release() if what == "release" else \
                    rig.hand_hold()
                keys.start(acq)

            summary = record_simulated_run(config, args.out, duration_s=args.duration,
                                           own_process=True, **options,
                                           actions=None if keys is None else simulated_keys)
        else:
            summary = record_run(config, args.out, duration_s=args.duration, **options,
                                 actions=None if keys is None else keys.start)
    except DeviceCheckError as exc:  # every failing device on a line of its own
        print("\n".join(f"error: {line}" for line in str(exc).splitlines())
              + "\nnothing recorded (--skip-check records anyway)", file=sys.stderr)
        return 1
    except StorageError as exc:
        print(f"error: {exc}", file=sys.stderr)
        if args.log_file is not None:  # else logging's last resort would print it again
            import logging

            logging.getLogger("daq.cli").error("acquire ended with an error: %s", exc,
                                               exc_info=True)
        if failed_writes():  # HDF5 would crash the process at exit (h5py#914)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(1)
        return 1
    print(f"wrote {summary['file']}: {summary['duration_s']:.1f} s ({summary['reason']}), "
          f"{summary['sync_rows']} sync rows at {summary['sync_rate_hz']:g} Hz, "
          f"{summary['releases']} release(s)")
    print(f"{'device':<14} {'samples':>9} {'gaps':>5} {'overflow':>9}  clock fit")
    for name, n in summary["samples"].items():
        fit = summary["clock_fits"].get(name)
        clock = ("" if fit is None else
                 f"offset {fit['offset_s']:.6f} s, drift {fit['drift_ppm']:+.2f} ppm, "
                 f"residual {fit['residual_s'] * 1e6:.1f} us, {int(fit['anchors'])} anchor(s)"
                 + (f" (absolute time +-{fit['anchor_uncertainty_s'] * 1e3:.2f} ms)"
                    if math.isfinite(fit.get("anchor_uncertainty_s", math.nan)) else ""))
        print(f"{name:<14} {n:>9} {summary['gaps'][name]:>5} "
              f"{summary['overflow_samples'][name]:>9}  {clock}")
    clocks = summary.get("alignment", {}).get("clocks", {})
    if clocks.get("clock_error_mean_s"):
        errors = ", ".join(f"{name} {err * 1e3:+.3f} ms"
                           for name, err in clocks["clock_error_mean_s"].items())
        print(f"against the simulators' clocks (after {clocks['settle_s']:g} s): mean error "
              f"{errors}; misalignment between devices {clocks['misalignment_s'] * 1e3:.3f} ms "
              f"mean, {clocks['misalignment_max_s'] * 1e3:.3f} ms largest")
    for warning in summary.get("warnings", []):
        print(f"warning: {warning}", file=sys.stderr)
    for error in summary["errors"]:
        print(f"error: {error}")
    return 0 if not summary["errors"] else 1


def _logged(args: argparse.Namespace, command: Callable[[argparse.Namespace], int]) -> int:
    """Run ``command``, logging to ``args.log_file`` if given (its own errors logged too)."""
    if args.log_file is None:
        return command(args)
    import logging

    from daq.log_file import close_log_file, open_log_file

    handler = open_log_file(args.log_file, args.log_level)
    log = logging.getLogger("daq.cli")
    log.info("windrig %s: %s", _version(), " ".join(args.argv))
    try:
        code = command(args)
    except BaseException:
        log.exception("%s ended with an error", args.command)  # the traceback, in the file
        raise
    else:
        log.info("%s ended, exit status %d", args.command, code)
        return code
    finally:
        close_log_file(handler)


def _reprocess(args: argparse.Namespace) -> int:
    from daq.offline.reprocess import ReprocessSettings, load_reprocess_config, reprocess

    try:
        settings = ReprocessSettings()
        campaigns: dict[str, list[str]] = {}
        if args.config is not None:
            settings, campaigns = load_reprocess_config(args.config)
        settings = ReprocessSettings.parse(args.overrides, base=settings)
        if args.workers is not None and args.workers < 1:
            raise ValueError(f"--workers {args.workers}: must be >= 1")
        if not args.paths and not campaigns:
            raise ValueError("give run files, directories or globs, or --config with "
                             "[campaigns]")
        summary = reprocess(args.paths, args.out, workers=args.workers,
                            scheduler=args.scheduler, settings=settings, campaigns=campaigns,
                            progress=not args.no_progress)
    except (ValueError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{len(summary.files)} file(s): {len(summary.files) - len(summary.failed)} used, "
          f"{len(summary.failed)} not used, {len(summary.reused)} from the cache")
    for path, reason in summary.failed.items():
        print(f"  not used: {reason if reason.startswith(path) else f'{path}: {reason}'}")
    for c in summary.campaigns:
        if "error" in c:
            print(f"{c.get('name')}: {len(c.get('files', []))} file(s): {c['error']}")
        else:
            speed = c.get("flutter_speed")
            flutter_text = ("no flutter found" if speed is None
                            else f"U_F = {speed:.3f} +- {c.get('flutter_std') or 0.0:.3f} m/s")
            low, high = c.get("flutter_speed_low"), c.get("flutter_speed_high")
            if speed is not None and low is not None and high is not None and low < high:
                flutter_text += f" ({low:.3f}-{high:.3f} over the structures within one SE)"
            print(f"{c.get('name')}: {len(c['files'])} file(s), {c['n_releases']} releases at "
                  f"{c['wind_speeds']} m/s: {flutter_text}; effect: {c.get('effect')}")
        for text in c.get("warnings", []):  # as `windrig identify` prints its own
            print(f"warning: {c.get('name')}: {text}")
    print("wall time " + ", ".join(f"{k} {v:.1f} s" for k, v in summary.timings.items()))
    print(f"report: {summary.outputs['report']}")
    return 0


def _recover(args: argparse.Namespace) -> int:
    from daq.recording.recover import recover_run

    for path in args.files:
        report = recover_run(path)
        if not report.recovered:
            print(f"{path}: " + ("closed cleanly by its writer" if report.recovered_before is None
                                 else f"already recovered ({report.recovered_before})")
                  + ", nothing to recover")
            continue
        trimmed = sum(report.trimmed.values())
        print(f"recovered {path}: status flags 0x{report.flags_before:02x} cleared; "
              f"{report.sync_rows} sync rows kept (to {report.end_s:.3f} s); {trimmed} row(s) of "
              f"a partly written last append trimmed; marked recovered")
        for name, n in report.trimmed.items():
            print(f"  trimmed {n:>6} row(s) of {name}")
    return 0


def _drivers(args: argparse.Namespace) -> int:
    """``windrig drivers``: every driver with its role and distribution; 1 if one is broken."""
    import json

    from daq.instruments.registry import GROUP, available_drivers

    drivers = available_drivers()
    broken = [d for d in drivers if d.error]
    if args.json:
        print(json.dumps({"group": GROUP, "drivers": [d.to_dict() for d in drivers],
                          "warnings": [d.error for d in broken]}, indent=2))
    else:
        rows = [("driver", "role", "distribution", "entry point")]
        rows += [(d.name, d.role or "-", d.distribution, d.entry_point or "-") for d in drivers]
        widths = [max(len(row[i]) for row in rows) for i in range(4)]
        for row in rows:
            print("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip())
        for d in broken:
            print(f"error: {d.error}", file=sys.stderr)
    return 1 if broken else 0


def _info(args: argparse.Namespace) -> int:
    from daq.recording.info import format_info, run_info

    info = run_info(args.file)
    print(json.dumps(info, indent=2, allow_nan=False) if args.json else format_info(info))
    return 0


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("windrig")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed)"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``windrig`` command line; returns the process exit code.

    The error boundary of every command: a user's mistake (a missing or malformed file, a bad
    config key or value, data that cannot be identified, an unreachable device, a missing
    optional dependency) is one ``error:`` line on stderr and exit status 1 (2 for a bad
    command-line value; argparse's own usage errors are 2 too); ``--debug`` shows the traceback
    instead. Anything else is a bug and keeps its traceback.
    """
    args = _build_parser().parse_args(argv)
    args.argv = list(sys.argv[1:] if argv is None else argv)  # for a log file's first line
    try:
        return _dispatch(args)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `windrig info RUN.h5 | head`: the reader has gone, not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    except (ValueError, OSError, ModuleNotFoundError) as exc:
        if args.debug:
            raise
        print(f"error: {_describe(exc)}", file=sys.stderr)
        return 2 if _is_usage(exc) else 1
    except Exception as exc:
        from daq.errors import DaqError
        from ident.errors import IdentError

        if args.debug or not isinstance(exc, (DaqError, IdentError)):
            raise
        print(f"error: {_describe(exc)}", file=sys.stderr)
        return 1


#: Optional dependencies and the extra that installs each.
_EXTRAS = {"dask": "dask", "distributed": "dask", "PySide6": "gui", "pyqtgraph": "gui",
           "shiboken6": "gui", "nptdms": "exchange", "xarray": "exchange",
           "h5netcdf": "exchange"}


def _is_usage(exc: BaseException) -> bool:
    """Tell whether an error is in what the user gave: a value, a file or a config (exit 2).

    Everything else failed while running (an unreachable device, data that cannot be
    identified, a full disk: exit 1).
    """
    from daq.errors import ConfigError, NotARunFileError
    from ident.records.run_file import FileFormatError

    return isinstance(exc, (UsageError, ConfigError, FileFormatError, NotARunFileError,
                            FileNotFoundError,
                            IsADirectoryError, NotADirectoryError))


def _describe(exc: BaseException) -> str:
    """One line for a user's error: the file, key or value and what is wrong."""
    if isinstance(exc, ModuleNotFoundError) and exc.name is not None:
        top = exc.name.split(".")[0]
        if top in _EXTRAS:
            return (f"this command needs {top}, which is not installed: pip install "
                    f"'windrig[{_EXTRAS[top]}]'")
        return f"missing Python module {exc.name!r}: {exc}"
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        return f"{exc.filename}: {exc.strerror}"
    text = " ".join(str(exc).split())  # one line
    return text or type(exc).__name__


#: Options that name a file a command writes whole (``info --json`` and ``drivers --json``
#: are flags, not paths).
_OUTPUT_FILES = ("json", "write_bridge")


def _refuse_run_file_as_output(args: argparse.Namespace) -> None:
    """Raise UsageError if an output option names an existing HDF5 file: a run is kept.

    ``windrig info --json`` is a flag, so ``windrig identify --json RUN.h5 ...`` reads like
    one and would have written the JSON over the run file.
    """
    for option in _OUTPUT_FILES:
        path = getattr(args, option, None)
        if isinstance(path, Path) and path.is_file():
            import h5py  # only when the path exists: --help stays fast

            if h5py.is_hdf5(path):
                raise UsageError(
                    f"--{option.replace('_', '-')} {path}: an HDF5 file (a run file?) that the "
                    "output would overwrite; the option takes the path of the file to write "
                    "(unlike windrig info --json, a flag)")


def _dispatch(args: argparse.Namespace) -> int:
    _refuse_run_file_as_output(args)
    if args.command == "demo":
        from daq.sim import demo

        return demo.run(args.out, args.config)
    if args.command == "flutter":
        from daq.offline.flutter_commands import run_flutter

        return run_flutter(args.section, model_path=args.model, table_path=args.table,
                           convention=args.convention, u_max=args.u_max, json_path=args.json,
                           out=args.out)
    if args.command == "bridge":
        from daq.offline.bridge_commands import run as run_bridge

        return run_bridge(args)
    if args.command == "campaign":
        from daq.campaign.command import run_command  # per-subcommand import: fast --help

        return run_command(args.plan, args.config, args.out, simulate=args.simulate,
                           check=not args.skip_check)
    if args.command == "simulate":
        from daq.sim.commands import run_simulate

        return run_simulate(args.config, serial=args.serial, duration_s=args.duration,
                            write_config=args.write_config)
    if args.command == "check":
        from daq.sim.commands import run_check

        return run_check(args.config, simulate=args.simulate, json_path=args.json,
                         timeout_s=args.timeout, debug=args.debug)
    if args.command == "identify":
        from daq.offline.flutter_commands import run_identify

        return run_identify(args.files, json_path=args.json, n_lags=args.n_lags,
                            tubing_correction=not args.no_tubing_correction, route=args.route,
                            detect_releases=args.detect_releases, table_path=args.table,
                            reduced_velocities=args.reduced_velocities,
                            turbulent_estimator=args.turbulent_estimator,
                            closed_loop_buffeting=args.closed_loop_buffeting)
    if args.command == "reprocess":
        return _reprocess(args)
    if args.command == "diagnose":
        from daq.offline.diagnosis import run_diagnose

        return run_diagnose(args.files, args.out, depth=args.depth, json_path=args.json)
    if args.command == "acquire":
        return _logged(args, _acquire)
    if args.command == "gui":
        return _gui(args)
    if args.command == "drivers":
        return _drivers(args)
    if args.command == "recover":
        return _recover(args)
    if args.command == "info":
        return _info(args)
    if args.command == "import":
        from daq.exchange.import_command import run as run_import

        return run_import(args)
    if args.command == "export":
        from daq.exchange.export_command import run as run_export

        return run_export(args)
    raise AssertionError(f"unhandled command {args.command!r}")  # argparse rejects unknown ones


if __name__ == "__main__":  # pragma: no cover - exercised through the console script
    sys.exit(main())
