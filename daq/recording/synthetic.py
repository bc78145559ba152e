"""Run files written from releases: the file readers' test and benchmark data.

Responsibility: :func:`write_release_run` writes :class:`~ident.records.release.Release` objects
(e.g. simulated ones) back to back into a run file with the acquisition's own recorder
(:class:`~daq.recording.recorder.RunRecorder`), for the tests and benchmarks of the file
readers (``windrig identify``, ``diagnose``, ``reprocess``, the console's replay), and for
``windrig import`` (:mod:`daq.exchange.importing`), whose lab files become run files this way.

Not responsible for: recording a rig (:mod:`daq.recording.run`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from daq.recording.recorder import RunRecorder
from daq.tubing_config import tubing_metadata

__all__ = ["write_release_run"]


def write_release_run(path: str | Path, config: Any, releases: Sequence[Any],
                      pressures: Sequence[Any] | None = None, *,
                      release_rows: bool = True,
                      metadata: Mapping[str, Any] | None = None) -> None:
    """Write releases back to back into a run file, with the acquisition's own recorder.

    Parameters
    ----------
    path : str or Path
        The run file to create.
    config : RigConfig
        Stored verbatim (its section and rig name are the file's).
    releases : sequence of Release or SimulatedRelease
        One row of ``/entry/releases`` each; the sync view holds their samples one after the
        other on one time base (the tap pressures are zero: not simulated here), U constant
        and the release's air density (1.2 kg/m^3 when it has none). Samples before a
        release's ``t = 0`` (a simulated hold, ``pre_s``) are written before its release row's
        start; its ``h0``/``alpha0`` are the release's own when it has them, else the samples
        at ``t = 0``. A config with three degrees of freedom (``[section] fp``) writes each
        release's ``p`` and ``drag`` (and ``p0``) too; its releases must have them.
    pressures : sequence of array_like, optional
        Each release's tap pressures, Pa, shape ``(len(r.t), n_taps)`` (default zeros). The
        config's tubing (``[[taps.tubing]]``) is recorded as ``/entry/metadata/tubing``, as the
        run writer does; these pressures are taken as measured behind it. The config's
        calibrations (dead taps, ...) are recorded under ``/entry/calibration`` too.
    release_rows : bool
        Write ``/entry/releases`` rows (default). False: the samples only, as a file of
        releases made by hand without the operator's keys (``windrig identify
        --detect-releases`` finds them).
    metadata : mapping, optional
        Stored under ``/entry/metadata/<name>`` (:meth:`RunRecorder.add_metadata`), e.g. where
        an imported file came from (``daq.exchange.importing``).
    """
    sway = config.section.n_dof == 3
    rec = RunRecorder(path, config_text=config.text, rig_name=config.name, min_free_bytes=0,
                      reserve_bytes=0, sway=sway)
    rec.open()
    n_taps = config.taps.n_taps
    if getattr(config, "tubing", ()):
        rec.add_metadata("tubing", tubing_metadata(config.tubing, n_taps))
    for name, value in (metadata or {}).items():
        rec.add_metadata(name, value)
    rec.add_sync([f"tap{i:03d}" for i in range(n_taps)])
    if hasattr(config, "calibration"):  # /entry/calibration, as the run writer records it
        rec.add_calibrations(config.calibration.records(n_taps))
    rec.start()
    rows, t0 = 0, 0.0
    for index, r in enumerate(releases):
        t = t0 - float(r.t[0]) + r.t  # the release's first sample (held or free) at t0
        n = t.size
        first = int(np.searchsorted(r.t, 0.0))  # the release instant, t = 0
        rho = 1.2 if r.rho is None else float(r.rho)
        rec.append_sync(t, h=r.h, alpha=r.alpha, lift=r.lift, moment=r.moment,
                        pressure=(np.zeros((n, n_taps), dtype=np.float32) if pressures is None
                                  else np.asarray(pressures[index], dtype=np.float32)),
                        U=np.full(n, r.U),
                        rho=np.full(n, rho), **({"p": r.p, "drag": r.drag} if sway else {}))
        if release_rows:
            rec.add_release(release_time=float(t[first]), start_index=rows + first,
                            stop_index=rows + n, U=r.U,
                            h0=float(getattr(r, "h0", r.h[first])),
                            alpha0=float(getattr(r, "alpha0", r.alpha[first])),
                            **({"p0": float(getattr(r, "p0", r.p[first]))} if sway else {}))
        rows += n
        t0 = float(t[-1]) + float(r.t[1] - r.t[0])
    rec.close()
