"""``windrig campaign PLAN.toml --config RIG.toml [--simulate] --out DIR``: the command itself.

Responsibility: :func:`run_command` loads the plan and the rig config (their errors are
:class:`~daq.errors.ConfigError`: one ``error:`` line, exit 2, from the command line's error
boundary), refuses a real rig whose URLs are still ``"auto"`` (a
:class:`~daq.errors.UsageError`), runs the campaign (:func:`daq.campaign.runner.run_plan`),
writes the report (:mod:`daq.campaign.report`, also after Ctrl-C or a safety stop) and prints
the result. Before anything moves, every device is checked (``windrig check``; ``--skip-check``
skips it): a failing device is named on an ``error:`` line of its own, nothing is recorded and
no report written. Exit status 0 when the campaign ended for a planned reason (plan done,
target met, no gain, a safety stop), 1 when interrupted or a device failed its check.

Not responsible for: the command-line parser (:mod:`daq.cli`, which imports this module only
for this subcommand).
"""

from __future__ import annotations

import sys
from pathlib import Path

from daq.campaign.plan import load_plan
from daq.campaign.report import read_previous, write_report
from daq.campaign.runner import CHECK_FAILED, CampaignOutcome, run_plan
from daq.config import load_rig_config
from daq.errors import DeviceCheckError, UsageError

__all__ = ["run_command"]


def _say(line: str) -> None:
    print(line, flush=True)  # one line per step: a log file shows progress as it happens


def run_command(plan_path: Path, config_path: Path, out: Path, *, simulate: bool,
                check: bool = True) -> int:
    """Run the command (module docstring); return the exit status."""
    plan = load_plan(plan_path)
    config = load_rig_config(config_path)
    if simulate and config.simulation is None:
        raise UsageError(f"{config_path}: --simulate needs a simulated rig ([simulation])")
    if not simulate:
        auto = [inst.name for inst in config.instruments if inst.url == "auto"]
        if auto:
            raise UsageError(f"{config_path}: instrument(s) {auto} have url = 'auto' (a "
                             "simulated rig): pass --simulate, or give their real URLs")
    plan.check_against(config)
    plan.check_rig(config)  # it can release and identify: one line, before anything moves
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out}: exists and is not a directory")
    truth = None
    if simulate:
        from daq.sim.campaign import simulated_truth  # the truth exists for a simulated rig only

        truth = simulated_truth(config)
    outcome = CampaignOutcome()
    try:
        run_plan(plan, config, out, simulate=simulate, say=_say, previous=read_previous(out),
                 outcome=outcome, check=check)
    except DeviceCheckError as exc:  # every failing device on a line of its own
        print("\n".join(f"error: {line}" for line in str(exc).splitlines())
              + "\nnothing recorded (--skip-check runs anyway)", file=sys.stderr)
        return 1
    finally:
        # Not after a failed check (nothing ran): an earlier session's report stays as it was.
        if out.is_dir() and not outcome.stopped_because.startswith(CHECK_FAILED):
            paths = write_report(outcome, out, truth=truth)
            _say(f"report: {paths['json']}, {paths['markdown']}")
    _say(f"stopped because: {outcome.stopped_because}")
    if outcome.flutter_speed is not None and outcome.flutter_std is not None:
        line = f"flutter speed {outcome.flutter_speed:.3f} +- {outcome.flutter_std:.3f} m/s"
        if outcome.truth_flutter_speed is not None:
            err = outcome.flutter_speed / outcome.truth_flutter_speed - 1.0
            line += f" (truth {outcome.truth_flutter_speed:.3f} m/s, {100 * err:+.2f} %)"
        _say(line)
    _say(f"speeds {', '.join(f'{s.U:.2f}' for s in outcome.steps)} m/s; wind on "
         f"{outcome.wind_on_s:.1f} s, wall {outcome.wall_s:.1f} s")
    if outcome.stopped_because.startswith("interrupted"):
        print("interrupted", file=sys.stderr)
        return 1
    return 0
