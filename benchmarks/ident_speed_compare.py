"""E2RFC's identification time in this checkout and in others, on the same data (not a test).

Issue 16's speed target (5 releases x 30 s at 500 Hz in under 0.5 s on one core, structure chosen
by evidence) was set on one host; the shared hosts this project runs on differ by a factor of
three and more from day to day. Timing another checkout of windrig (the code at the issue's
start, say) next to this one, on the same releases, in turns, gives a ratio that does not depend
on the host.

The releases are those of ``ident_accuracy.py --part timing`` (flat-plate section, 0.4-0.8 of the
flutter speed, 2 % noise), simulated once by this checkout and handed to every checkout as
arrays; each checkout builds its own ``Release`` objects and runs its own ``e2rfc.identify``, in
a process of its own with BLAS on one thread. The checkouts take turns (``--rounds``), so that a
slow spell of the host falls on all of them; each turn times ``--repeats`` identifications after
one untimed warm-up. Printed: per checkout and structure option, the minimum and median of the
process's CPU time over all turns, and the ratio of each minimum to this checkout's.

Run: ``git worktree add /tmp/start 789df70`` (issue 16's start), then
``.venv/bin/python benchmarks/ident_speed_compare.py --tree /tmp/start [--tree ...]
[--rounds 3] [--repeats 5] [--quick] [--results DIR]`` (``--quick``: one turn of one timed run;
``--results``: also write ``DIR/ident_speed_compare.json`` and ``.md``, :mod:`result_files`).
Without ``--tree`` only this checkout is timed.

``--flow turbulent`` times the closed-loop branch instead: the tunnel benchmark's plate in 1 %
turbulence (``ident_accuracy.py --part tunnel``, seed 0: 3 speeds x 2 releases of 20 s at
500 Hz, no holds), identification and its uncertainty (which refits without the highest
speed), with the second-order buffeting model and with the model chosen by evidence (the
default), and the latter's identification alone. A checkout from before the evidence's choice
fails on that option.
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy: one-core timings

import argparse
import dataclasses
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import result_files  # noqa: E402 - beside this script

#: Where a checkout keeps E2RFC (in ident's subpackages, or flat as before them).
E2RFC_PATHS = ("identification/e2rfc.py", "e2rfc.py")

#: Run inside each checkout: build the releases from the arrays, time identify (and, where
#: asked, the uncertainty), print JSON. argv: data, section JSON, repeats, options JSON
#: (label -> [identify's keyword arguments, whether to time the uncertainty too]).
_TIMER = r"""
import json, os, sys, time
os.environ["OPENBLAS_NUM_THREADS"] = "1"
import numpy as np
from ident import Release, SectionModel
try:  # ident in subpackages (the facade names identify)
    from ident import identify
except ImportError:  # a checkout from before
    from ident.e2rfc import identify
data = np.load(sys.argv[1])
section = SectionModel(**json.loads(sys.argv[2]))
releases = [Release(t=data[f"t{i}"], h=data[f"h{i}"], alpha=data[f"alpha{i}"],
                    lift=data[f"lift{i}"], moment=data[f"moment{i}"], U=float(data["U"][i]),
                    rho=float(data["rho"][i]))
            for i in range(data["U"].size)]

def run(kwargs, with_uncertainty):
    model = identify(releases, section, **kwargs)
    if with_uncertainty:
        model.uncertainty(section)

out = {}
for label, (kwargs, with_uncertainty) in json.loads(sys.argv[4]).items():
    run(kwargs, with_uncertainty)  # warm-up
    times = []
    for _ in range(int(sys.argv[3])):
        start = time.process_time()
        run(kwargs, with_uncertainty)
        times.append(time.process_time() - start)
    out[label] = times
print(json.dumps(out))
"""

#: Per flow: what the table says of the releases, and the options timed (label -> identify's
#: keyword arguments, whether the uncertainty is timed too, the table's name of the option).
FLOWS = {
    "smooth": ("5 releases of 30 s at 500 Hz in smooth flow", {
        "chosen": ({}, False, "chosen by evidence"),
        "given": ({"n_lags": 2, "with_A3": True}, False, "given (2 lags, A3)"),
    }),
    "turbulent": ("3 x 2 releases of 20 s at 500 Hz in 1 % turbulence, with the uncertainty "
                  "unless said", {
                      "second-order": ({"closed_loop_buffeting": "second-order"}, True,
                                       "second-order buffeting model"),
                      "by-evidence": ({"closed_loop_buffeting": "by-evidence"}, True,
                                      "buffeting model by evidence"),
                      "by-evidence alone": ({"closed_loop_buffeting": "by-evidence"}, False,
                                            "buffeting model by evidence, identification "
                                            "alone"),
                  }),
}

#: The tunnel benchmark's row and seed the turbulent flow's releases come from.
TURBULENT_ROW, TURBULENT_SEED = "plate, Jones, Iw 1 %", 0

SECTION = {"B": 0.3, "m": 3.0, "I": 0.03, "fh": 2.0, "fa": 4.0, "zeta_h": 0.005,
           "zeta_a": 0.005, "rho": 1.225}


def write_releases(path: Path, flow: str) -> dict[str, float]:
    """Simulate the flow's releases with this checkout, save their arrays to ``path``.

    Returns the section's parameters (:class:`~ident.SectionModel`'s keywords).
    """
    sys.path.insert(0, str(HERE))
    sys.path.insert(0, str(ROOT))
    import ident_accuracy as accuracy

    from ident import SectionModel
    from ident.model import flutter as fl

    if flow == "turbulent":
        section = accuracy.row_spec(TURBULENT_ROW)[0]
        releases = [dataclasses.replace(r, hold=None)
                    for r in accuracy.tunnel_releases(TURBULENT_ROW, TURBULENT_SEED)]
    else:
        section = SectionModel(**SECTION)
        U_F = fl.analyze(section, accuracy.TRUTH).speed
        releases = accuracy.make_releases(section, U_F, (0.4, 0.5, 0.6, 0.7, 0.8), 0.02, 0,
                                          duration=30.0)
    arrays = {f"{name}{i}": getattr(r, name) for i, r in enumerate(releases)
              for name in ("t", "h", "alpha", "lift", "moment")}
    rho = [section.rho if r.rho is None else r.rho for r in releases]
    np.savez(path, U=np.array([r.U for r in releases]), rho=np.array(rho), **arrays)
    return {k: v for k, v in dataclasses.asdict(section).items() if v is not None}


def time_tree(tree: Path, data: Path, section: dict[str, float], repeats: int, flow: str
              ) -> dict[str, list[float]]:
    """Run the timer in ``tree`` (its own ``ident``) and return its CPU times per option."""
    env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1")
    options = {label: [kwargs, timed] for label, (kwargs, timed, _) in FLOWS[flow][1].items()}
    done = subprocess.run(
        [sys.executable, "-c", _TIMER, str(data), json.dumps(section), str(repeats),
         json.dumps(options)],
        cwd=tree, env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        raise SystemExit(f"ident_speed_compare: the checkout {tree} failed: {last}")
    result: dict[str, list[float]] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tree", action="append", default=[], type=Path,
                        help="another windrig checkout to time (repeatable)")
    parser.add_argument("--flow", choices=tuple(FLOWS), default="smooth",
                        help="smooth-flow releases (default) or the closed-loop branch's "
                             "turbulent ones")
    parser.add_argument("--rounds", type=int, default=None,
                        help="turns of every checkout (3; --quick: 1)")
    parser.add_argument("--repeats", type=int, default=None,
                        help="timed runs per turn (5, turbulent 1; --quick: 1)")
    result_files.add_arguments(parser)
    args = parser.parse_args()
    rounds = args.rounds if args.rounds is not None else (1 if args.quick else 3)
    repeats = args.repeats if args.repeats is not None else (
        1 if args.quick or args.flow == "turbulent" else 5)
    trees = [ROOT, *(t.resolve() for t in args.tree)]
    for tree in trees[1:]:
        if not any((tree / "ident" / p).is_file() for p in E2RFC_PATHS):
            parser.error(f"--tree {tree}: not a windrig checkout (no e2rfc.py in ident)")
    if rounds < 1 or repeats < 1:
        parser.error("--rounds and --repeats must be at least 1")
    what, options = FLOWS[args.flow]
    times: dict[Path, dict[str, list[float]]] = {t: {o: [] for o in options} for t in trees}
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "releases.npz"
        section = write_releases(data, args.flow)
        for _ in range(rounds):
            for tree in trees:
                for label, values in time_tree(tree, data, section, repeats, args.flow).items():
                    times[tree][label].extend(values)
    print(f"E2RFC CPU time, {what}, one core; {rounds} turns x {repeats} runs per checkout; "
          f"ratio = this minimum / this checkout's minimum")
    print(f"  {'checkout':<44}{'option':<18}{'min':>8}{'median':>8}{'ratio':>7}")
    rows = []
    for tree in trees:
        commit = _commit(tree)
        name = f"{tree} ({commit})"
        for label, (_, _, option) in options.items():
            values = np.array(times[tree][label])
            ratio = values.min() / np.min(times[ROOT][label])
            print(f"  {name[-44:]:<44}{label:<18}{values.min():>7.3f}s"
                  f"{np.median(values):>7.3f}s{ratio:>7.2f}")
            # Another checkout by its commit: its path is a scratch folder of the run.
            rows.append(("this checkout" if tree == ROOT else f"checkout {commit}", commit, option,
                         float(values.min()), float(np.median(values)), float(ratio)))
    table = result_files.Table(
        f"E2RFC's CPU time on {what} (one core), {rounds} turns x {repeats} timed runs per "
        f"checkout, and each minimum over this checkout's.",
        ("checkout", "commit", "structure" if args.flow == "smooth" else "buffeting model",
         "CPU min (s)", "CPU median (s)", "ratio to this checkout"),
        rows, formats={"CPU min (s)": ".3f", "CPU median (s)": ".3f",
                       "ratio to this checkout": ".2f"})
    notes = ["Each checkout runs its own identification in a process of its own on the same "
             "simulated releases; the checkouts take turns, so a slow spell of the host falls "
             "on all of them, and the ratios hold where the absolute times do not."]
    warnings = []
    if len(trees) == 1:
        warnings.append("No other checkout was given (--tree): the table times this checkout "
                        "alone, and its ratios are one by definition.")
    name = "ident_speed_compare" + ("" if args.flow == "smooth" else f"_{args.flow}")
    result_files.write(
        name, "E2RFC's identification time against other checkouts"
        + ("" if args.flow == "smooth" else f" ({args.flow} flow)"),
        [table], results=args.results, quick=args.quick, script="ident_speed_compare",
        parameters={"flow": args.flow, "rounds": rounds, "repeats": repeats,
                    "trees": [_commit(t) for t in trees[1:]]},
        notes=notes, warnings=warnings)


def _commit(tree: Path) -> str:
    """Return a checkout's short commit (``+`` when tracked files changed), or ``?``."""
    head = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True, check=False)
    if head.returncode != 0:
        return "?"
    dirty = subprocess.run(["git", "-C", str(tree), "diff", "--quiet", "HEAD"], check=False)
    return head.stdout.strip() + ("+" if dirty.returncode else "")


if __name__ == "__main__":
    main()
