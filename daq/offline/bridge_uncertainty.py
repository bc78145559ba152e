"""``windrig bridge --uncertainty``: the section test's uncertainty carried to the bridge.

From the ``--aero`` file: an identified model's ``model_covariance`` (``windrig identify
--json``) gives the delta method and a Monte Carlo over the parameters; a flutter-derivative
table's std columns give a Monte Carlo over the table (:mod:`ident.bridge.uncertainty` says how
each works and why). The samples run serially, or on Dask (:func:`daq.offline.cluster.dask_client`:
``--workers N`` a local cluster, ``--scheduler ADDRESS`` an existing one, as ``windrig
reprocess``). Without either option the rule is :func:`executor_rule`: serial when the samples
would take less than :data:`SERIAL_BELOW_S` on one core (one sample timed on the client, times
the samples), a local cluster of every core otherwise (starting one costs a few seconds).

The samples are drawn on the client from ``--seed`` before any task runs, and each task is
:func:`ident.bridge.uncertainty.flutter_speeds` (or its table form) of the bridge model and a
chunk of samples: plain picklable values, no file paths, so the result is the same serially,
locally or on a multi-machine cluster.

The identify JSON's other parts of the section's std (structure, extrapolation, one lag more,
release scatter, below a decaying release) are not parameters of one model: they are carried
to the bridge scaled by the ratio of the flutter speeds (stated in the JSON), and the total
combines them as the section's does (:class:`ident.identification.uncertainty.FlutterUncertainty`).

Not responsible for: the numerics (:mod:`ident.bridge.uncertainty`), the rest of ``windrig
bridge`` (:mod:`daq.offline.bridge_commands`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from daq.errors import UsageError
from daq.offline.cluster import dask_client, describe
from daq.offline.flutter_commands import read_json, read_model

__all__ = ["DEFAULT_SAMPLES", "PLOT_NAME", "SERIAL_BELOW_S", "UncertaintyInput",
           "executor_rule", "read_uncertainty_input", "run_uncertainty"]

#: Monte Carlo samples by default: the std of a std from N normal samples is about
#: ``1 / sqrt(2 (N - 1))`` of it, 2.2 % at 1000.
DEFAULT_SAMPLES = 1000
#: Estimated serial time (s) below which no cluster is started by default.
SERIAL_BELOW_S = 30.0
#: Tasks per worker at least: enough for the load to balance when some samples take longer.
TASKS_PER_WORKER = 4
#: Work per task at most, s (estimated): the last tasks leave a worker idle for about this long
#: while another finishes, so it is kept small against the whole (1000 samples of the example
#: bridge in chunks of 125 left 10 s tails out of 80 s on two workers; a task's own overhead
#: is a few milliseconds).
TASK_SECONDS = 2.0
#: The histogram written into ``--out``.
PLOT_NAME = "bridge_flutter_uncertainty.png"
#: The identify JSON's parts of the section's std (``flutter_speed_std_parts``) that are not
#: the parameter covariance's.
OTHER_PARTS = ("structure", "extrapolation", "one_lag_more", "release_scatter",
               "below_decaying_release", "other_estimator")


@dataclass(frozen=True, eq=False)
class UncertaintyInput:
    """What ``--aero`` gives the uncertainty: a model with its covariance, or a table's std.

    Attributes
    ----------
    path : Path
    model : RationalFunctionModel or None
        The section's model (with ``covariance``).
    covariance : ModelCovariance or None
    section_speed : float or None
        The section's flutter speed in the identify JSON, m/s.
    parts : dict
        Its other std parts (:data:`OTHER_PARTS`), m/s at the section.
    """

    path: Path
    model: Any = None
    covariance: Any = None
    section_speed: float | None = None
    parts: dict[str, float] | None = None


def read_uncertainty_input(path: Path, aero: Any) -> UncertaintyInput:
    """Check that ``--aero`` carries an uncertainty and read it (a usage error if not)."""
    from ident.identification.covariance import ModelCovariance

    if aero.table is not None:
        if not aero.table.std:
            raise UsageError(f"--uncertainty: {path} has no std column (H1_std, ...): a table "
                             "without standard deviations has no uncertainty to carry")
        return UncertaintyInput(path)
    data = read_json(path, "model")
    if not isinstance(data, dict) or "model_covariance" not in data:
        raise UsageError(f"--uncertainty: {path} holds no model_covariance: give the JSON that "
                         "`windrig identify --json` writes (a bare model has no uncertainty), or "
                         "a table with std columns")
    model = read_model(path)
    try:
        covariance = ModelCovariance.from_dict(data["model_covariance"])
        covariance.check_model(model)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"{path}: model_covariance: {exc}") from exc
    parts_in = data.get("flutter_speed_std_parts") or {}
    speed = data.get("flutter_speed")
    parts: dict[str, float] = {}
    for name in OTHER_PARTS:
        value = parts_in.get(name, 0.0) if isinstance(parts_in, dict) else None
        if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise UsageError(f"{path}: flutter_speed_std_parts.{name} = {value!r}: expected a "
                             "std >= 0 in m/s")
        parts[name] = float(value)
    if speed is not None and not (isinstance(speed, (int, float)) and speed > 0):
        raise UsageError(f"{path}: flutter_speed = {speed!r}: expected a speed > 0 in m/s")
    return UncertaintyInput(path, model, covariance, None if speed is None else float(speed),
                            parts)


def executor_rule(n_samples: int, seconds_each: float, workers: int | None,
                  scheduler: str | None) -> tuple[bool, str]:
    """Return ``(serial, why)``: where the samples run (module docstring)."""
    if scheduler is not None or workers is not None:
        return False, "asked for"
    estimate = n_samples * seconds_each
    if estimate < SERIAL_BELOW_S:
        return True, (f"about {estimate:.3g} s on one core, below {SERIAL_BELOW_S:g} s: no "
                      "cluster")
    return False, f"about {estimate:.3g} s on one core, above {SERIAL_BELOW_S:g} s"


def _run_tasks(task: Callable[..., list[Any]], bridge: Any, items: Sequence[Any],
               args: tuple[Any, ...], serial: bool, workers: int | None,
               scheduler: str | None, timings: dict[str, float],
               seconds_each: float) -> list[Any]:
    """Run ``task(bridge, chunk, *args)`` over chunks of ``items``; outcomes in their order.

    Chunks of at most :data:`TASK_SECONDS` of estimated work (``seconds_each`` per item), and
    at least :data:`TASKS_PER_WORKER` per worker. ``timings`` receives ``cluster_start``: the
    seconds until the client is connected.
    """
    from tqdm import tqdm

    if serial:
        out: list[Any] = []
        for item in tqdm(items, unit="sample", mininterval=0.5, desc="samples"):
            out.extend(task(bridge, [item], *args))
        return out
    from dask.distributed import as_completed  # the dask extra, needed only here

    started = time.perf_counter()
    with dask_client(workers, scheduler) as client:
        timings["cluster_start"] = time.perf_counter() - started
        slots = max(1, sum(client.nthreads().values()))
        size = max(1, min(math.ceil(len(items) / (TASKS_PER_WORKER * slots)),
                          math.floor(TASK_SECONDS / max(seconds_each, 1e-9))))
        chunks = [list(items[i:i + size]) for i in range(0, len(items), size)]
        # The bridge once to every worker, not with every chunk.
        remote = client.scatter(bridge, broadcast=True)
        futures = [client.submit(task, remote, chunk, *args, pure=False) for chunk in chunks]
        index = {future.key: i for i, future in enumerate(futures)}
        results: list[list[Any]] = [[] for _ in chunks]
        with tqdm(total=len(items), unit="sample", mininterval=0.5, desc="samples") as bar:
            for future in as_completed(futures):
                # A worker's failure is not a sample's: it ends the command (error boundary).
                results[index[future.key]] = future.result()
                bar.update(len(chunks[index[future.key]]))
    return [outcome for chunk in results for outcome in chunk]


def run_uncertainty(bridge: Any, aero: Any, source: UncertaintyInput, *, U_max: float,
                    samples: int, seed: int, workers: int | None, scheduler: str | None,
                    out: Path | None) -> dict[str, Any]:
    """Carry the section's uncertainty to the bridge; print it; return the JSON entry.

    Parameters
    ----------
    bridge : BridgeModel
    aero : BridgeAero
        The aerodynamics the bridge's flutter routes used (a table's: the table sampled).
    source : UncertaintyInput
    U_max : float
        The nominal search's top, m/s.
    samples, seed : int
        Monte Carlo samples and the seed they are drawn from.
    workers, scheduler : optional
        Where they run (module docstring).
    out : Path, optional
        Folder of the histogram.
    """
    from ident.bridge import uncertainty as bu

    started = time.perf_counter()
    if source.covariance is not None:
        delta = bu.delta_method(bridge, source.model, source.covariance, U_max=U_max)
        if delta is None:
            return _no_flutter(U_max)
        items: Sequence[Any] = bu.sample_models(bridge, source.model, source.covariance,
                                                samples, seed)
        top = bu.search_top(U_max, delta)
        task: Callable[..., list[Any]] = bu.flutter_speeds
        args: tuple[Any, ...] = (top,)
        speed: float | None = delta.speed
        kind = "model covariance"
        method = (f"delta method: the gradient of U_F with respect to the section's "
                  f"{source.covariance.size} parameters (A entries, log d) from the flutter "
                  "point's left and right null vectors of the modal rational eigenproblem, std "
                  "= sqrt(g^T C g); Monte Carlo: parameter vectors drawn from the covariance, "
                  "each model through the fast flutter route")
    else:
        from ident.bridge.fast_flutter import analyze

        nominal = analyze(bridge, aero.model, U_max=U_max)
        if nominal.speed is None:
            return _no_flutter(U_max)
        delta, speed, top = None, nominal.speed, U_max
        items = bu.sample_tables(aero.table, samples, seed)
        print(f"uncertainty: the Roger structure of the sampled tables (the structure search "
              f"on {bu.STRUCTURE_PROBES} of them)")
        n_lags, with_A3 = bu.noisy_structure(items[:bu.STRUCTURE_PROBES])
        task, args = bu.table_flutter_speeds, (n_lags, with_A3, top)
        kind = "table std columns"
        method = (f"Monte Carlo only: every tabulated derivative with a std drawn independently "
                  f"(normal), each table Roger-fitted with one structure ({n_lags} lag(s), "
                  f"A3 {'fitted' if with_A3 else 'zero'}: the structure search's most frequent "
                  f"choice on {bu.STRUCTURE_PROBES} samples) and through the fast flutter "
                  "route; no delta method for a table")
    # One sample on the client, timed (and discarded): the rule's and the chunks' estimate.
    # The nominal analysis is no measure: it pays the first call's costs (0.75 s in one
    # benchmark run on the example bridge, where a sample takes 0.06 to 0.1 s).
    t_one = time.perf_counter()
    task(bridge, list(items[:1]), *args)
    seconds_each = time.perf_counter() - t_one
    serial, why = executor_rule(samples, seconds_each, workers, scheduler)
    executor = "serial" if serial else describe(workers, scheduler)
    print(f"uncertainty ({kind}): {samples} samples, {executor} ({why})")
    t_mc = time.perf_counter()
    timings: dict[str, float] = {}
    outcomes = _run_tasks(task, bridge, items, args, serial, workers, scheduler, timings,
                          seconds_each)
    mc_time = time.perf_counter() - t_mc
    result = bu.summarise(kind, speed, delta, outcomes, top, seed)
    entry = result.to_dict()
    entry.update({"method": method, "executor": executor, "executor_rule": why,
                  "wall_time_s": {"monte_carlo": mc_time, **timings,
                                  "total": time.perf_counter() - started}})
    mc_std = result.mc_std
    if source.parts is not None and speed is not None:
        _add_other_parts(entry, source, speed, mc_std if mc_std is not None else delta.std
                         if delta is not None else 0.0)
    mc = entry["monte_carlo"]
    if delta is not None:
        print(f"  delta method: U_F = {delta.speed:.4f} +- {delta.std:.4g} m/s")
    if mc["std"] is not None:
        q = mc["quantiles"]
        print(f"  Monte Carlo: {mc['fluttering']} of {mc['n']} samples flutter below "
              f"{top:.4g} m/s: mean {mc['mean']:.4f} m/s, std {mc['std']:.4g} m/s, 95 % "
              f"within {q['0.025']:.4f}-{q['0.975']:.4f} m/s ({mc_time:.3g} s)")
    if "total_std" in entry:
        print(f"  with the section's other parts (scaled): std {entry['total_std']:.4g} m/s")
    for warning in entry["warnings"]:
        print(f"warning: {warning}")
    if out is not None and result.speeds.size >= 2:
        entry["plot"] = str(_plot(out, result))
        print(f"wrote {entry['plot']}")
    return entry


def _no_flutter(U_max: float) -> dict[str, Any]:
    warning = (f"--uncertainty: the nominal model does not flutter below {U_max:.4g} m/s: no "
               "flutter speed to carry the uncertainty to (raise --u-max)")
    print(f"warning: {warning}")
    return {"flutter_speed": None, "delta_std": None, "monte_carlo": None,
            "units": {"flutter_speed": "m/s"}, "warnings": [warning]}


def _add_other_parts(entry: dict[str, Any], source: UncertaintyInput, speed: float,
                     noise_std: float) -> None:
    """Add the identify JSON's other std parts, scaled to the bridge, and the total."""
    parts = source.parts or {}
    if source.section_speed is None:
        entry["warnings"].append(f"{source.path} gives no section flutter speed: its other std "
                                 "parts (structure, extrapolation, ...) are not carried")
        return
    scale = speed / source.section_speed
    scaled = {name: value * scale for name, value in parts.items()}
    # As the section's (FlutterUncertainty): with a random response the release scatter
    # replaces the covariance's noise as the statistical part.
    statistical = scaled["release_scatter"] or noise_std
    systematic = math.sqrt(sum(v**2 for k, v in scaled.items() if k != "release_scatter"))
    if scaled["release_scatter"]:
        entry["warnings"].append(
            "the section's releases held a random response (turbulence): its parameter "
            "covariance does not measure the noise; the total takes the release scatter, "
            "scaled, as the statistical part instead of the Monte Carlo std")
    entry.update({"section_flutter_speed": source.section_speed,
                  "section_other_parts": scaled,
                  "section_other_parts_note": (
                      f"the section's std parts that are not parameter noise, scaled by the "
                      f"ratio of the flutter speeds ({scale:.5g}): not propagated"),
                  "total_std": math.sqrt(statistical**2 + systematic**2)})
    entry["units"].update({"section_flutter_speed": "m/s", "section_other_parts": "m/s",
                           "total_std": "m/s"})


def _plot(out: Path, result: Any) -> Path:
    """Histogram of the samples' flutter speeds with the delta method's normal; its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    speeds = result.speeds
    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    bins = int(np.clip(math.sqrt(speeds.size), 10, 60))
    ax.hist(speeds, bins=bins, density=True, color="0.75", edgecolor="0.4",
            label=f"Monte Carlo, {speeds.size} samples (std {np.std(speeds, ddof=1):.3g} m/s)")
    if result.delta is not None and result.delta.std > 0.0:
        d = result.delta
        x = np.linspace(min(speeds.min(), d.speed - 4 * d.std),
                        max(speeds.max(), d.speed + 4 * d.std), 400)
        pdf = np.exp(-0.5 * ((x - d.speed) / d.std) ** 2) / (d.std * math.sqrt(2 * math.pi))
        ax.plot(x, pdf, "C3-", label=f"delta method: {d.speed:.4g} +- {d.std:.3g} m/s")
    if result.speed is not None:
        ax.axvline(result.speed, color="k", lw=0.8, label="nominal flutter speed")
    ax.set_xlabel("bridge flutter speed (m/s)")
    ax.set_ylabel("probability density (s/m)")
    ax.set_title(f"the section's uncertainty at the bridge ({result.source})")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / PLOT_NAME
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
