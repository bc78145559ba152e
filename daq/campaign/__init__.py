"""Headless test campaigns: ``windrig campaign PLAN.toml --config RIG.toml [--simulate] --out DIR``.

A campaign records releases at several wind speeds through the same drivers and engine as the
console, one run file per speed (or per release), identifies E2RFC's model after each speed,
and stops when the plan is done, the flutter speed is known well enough, or going on would not
be safe.

The map of its modules (one job each):

- ``plan``      PLAN.toml parsed and checked (mode, speeds, releases, settle, decay, CALZ,
                the adaptive target, safety fraction, candidates), errors naming key and range;
                checked against the rig's limits before the fan starts.
- ``monitor``   an engine subscriber following each decay's amplitude on the lasers; sets an
                event the moment a decay grows (negative total damping).
- ``adaptive``  the next wind speed: the candidate whose releases most reduce the predicted
                variance of the flutter speed (c-optimal, from the model's covariance), and
                the safety bound ``fraction * (U_F - 3 std)``.
- ``files``     the run files' names (one per speed or one per release) and reading back an
                earlier session's files, grouped by speed (resume).
- ``wind``      the drive's ramp rate, and waiting for a steady wind at a set-point.
- ``releasing`` holding and releasing the model: the PLC, or the operator's hand (prompted on
                the terminal between releases; the instant found in the lasers' signals).
- ``runner``    the loop: device check, fan, settle, arm/release per speed into run files,
                progress lines, modal fits and the flutter speed +- std after each speed;
                stops safely (growth, bound, Ctrl-C: model caught, fan down, file finished);
                resumes from DIR.
- ``outcome``   what a campaign did and found: each speed's step (files, why, estimate,
                wind-on time) and the campaign's outcome (what the report writes).
- ``report``    DIR/campaign.json, the std history, PNG plots and a Markdown page.

Layer: a tool (with ``daq.sim`` and ``daq.offline``): it uses the recorder and the engine below,
and starts a simulated rig (``daq.sim.rig_process``) only with ``--simulate``.
"""
