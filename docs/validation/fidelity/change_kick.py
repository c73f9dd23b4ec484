"""The heading kick of one pattern change: how far the averaged model's turn departs from the full model's.

The measurement behind docs/validation/fidelity/README.md, "Where the error with changing commands comes
from": ``PYTHONPATH=. python docs/validation/fidelity/change_kick.py`` (~2 min; 512 one-fin pattern pairs
of a development seed, not the benchmark's).

Each fish beats one fin (the left at rest) on a pattern ``A`` from the envs' action ranges, started on
it (no transitional stroke), and is switched to a pattern ``B`` at a random time between 12 and 14 s
(so at a random stroke phase). One fin's periodic steady states agree between the models to 0.2 %
(``python -m pectoral_gym.scaling validate``), so before the switch and a few seconds after it both models turn at
the same rate and their heading difference is constant up to the full model's in-beat ripple. The
*kick error* is that difference (averaged minus full), averaged over one period of ``B`` 3 s after
the switch, minus the same over one period of ``A`` just before it: the heading the averaged model
gains or loses through one change. Rows: the default model, without the ripple offset
(docs/model.md 3.8), without the transitional forcing either (3.7), and a control in which ``B = A``
(the command changes nothing: the noise floor of the measurement).

``--only-default`` prints the default model's row alone: with ``change_kick_scales.patch`` applied in a
worktree, environment variables scale each yaw term of the transitions and the ripple offset (the scans
of the README named above; each run needs a fresh ``NUMBA_CACHE_DIR``, the scales are compile-time constants).
``--linear-world``, with ``linear_damping.patch`` applied and ``LINEAR_YAW_DAMPING`` set: both models with a
linear yaw damping, equal surge and sway masses (no Munk moment) and K = 1, where the transitional
forcing and the ripple offset should leave no kick at all. ``--coefficients PATH``: another coefficients file.
"""

import math
import sys

import numpy as np

from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import AveragedModel, FullModel
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.scaling.validation.fidelity import DURATION, SEED_SETS, draw_patterns

N, DT = 512, 0.01
START, WINDOW, AFTER = 10.0, 10.0, 3.0  # record [START, START + WINDOW); measure 3 s after the switch
params, scaling = FishParams(), ScalingFunctions.load()
if "--coefficients" in sys.argv[1:]:  # another coefficients file (e.g. one identified for another robot)
    scaling = ScalingFunctions.load(sys.argv[sys.argv.index("--coefficients") + 1])
if "--linear-world" in sys.argv[1:]:  # with linear_damping.patch: no Munk moment (m1 = m2), K = 1
    params, scaling = params.replace(added_mass_y=params.added_mass_x), ScalingFunctions.unit()
rng = np.random.default_rng(SEED_SETS["dev"].seed + 77)
pairs = draw_patterns(rng, N, 2)  # (N, 2 patterns, 2 fins, 4)
pairs[:, :, 1] = FinBeat.rest().as_array()
switch = 12.0 + rng.uniform(0.0, 2.0, N)


def record(model, patterns):
    """States ``(N, samples, 6)`` every DT s over the recorded window and each fish's switch time on that grid.

    Fish ``i`` is started on ``patterns[i, 0]`` and switched to ``patterns[i, 1]`` at ``switch[i]``.
    """
    model.reset(right=patterns[:, 0, 0], left=patterns[:, 0, 1])
    model.advance(START)
    switched, at, out = np.zeros(N, dtype=bool), np.zeros(N), []
    for k in range(round(WINDOW / DT)):
        due = ~switched & (switch <= START + k * DT + 1e-9)
        if due.any():
            model.command_array(np.ascontiguousarray(patterns[:, 1]), mask=due)
            switched |= due
            at[due] = START + k * DT
        out.append(model.state.copy())
        model.advance(DT)
    return np.stack(out, axis=1), at


def window_mean(x, t, start, period):
    """Mean of each row of ``x`` (sampled at times ``t``) over ``[start, start + period)`` (per row)."""
    inside = (t >= start[:, None] - 1e-9) & (t < (start + period)[:, None] - 1e-9)
    return np.sum(x * inside, axis=1) / np.sum(inside, axis=1)


def kick(gap, t, patterns, index=slice(None)):
    """The kick [rad] in a heading gap: its mean over a period of B AFTER s after the switch minus that before it."""
    before = window_mean(gap, t, switch[index] - patterns[index, 0, 0, 2], patterns[index, 0, 0, 2])
    after = window_mean(gap, t, switch[index] + AFTER, patterns[index, 1, 0, 2])
    return after - before


def kick_errors(patterns, **options):
    """Kick error [deg] per fish of ``AveragedModel(**options)`` against the full model."""
    full, _ = record(FullModel(N, params), patterns)
    averaged, _ = record(AveragedModel(N, params, scaling=scaling, **options), patterns)
    grid = START + DT * np.arange(full.shape[1])
    return np.degrees(kick(averaged[:, :, 2] - full[:, :, 2], grid, patterns))


def main() -> None:
    """Print the table of the module docstring."""
    same = pairs.copy()
    same[:, 1] = same[:, 0]
    variants = {
        "control: B = A (no change)": (same, {}),
        "default model": (pairs, {}),
        "without the ripple offset": (pairs, {"ripple_offsets": False}),
        "cycle averages alone (no transitions, no offset)": (pairs, {"transitions": False, "ripple_offsets": False}),
    }
    if "--only-default" in sys.argv[1:]:
        variants = {"default model": variants["default model"]}
    rows = {name: kick_errors(patterns, **options) for name, (patterns, options) in variants.items()}
    print("| model | kick error median abs | p90 | rms | signed median | random walk over 80 changes, rms |")
    print("|---|---|---|---|---|---|")
    for name, e in rows.items():
        rms = math.sqrt(np.mean(e**2))
        print(f"| {name} | {np.median(np.abs(e)):.2f} deg | {np.percentile(np.abs(e), 90):.2f} deg | {rms:.2f} deg | "
              f"{np.median(e):+.2f} deg | {rms * math.sqrt(DURATION / 0.5):.0f} deg |")


if __name__ == "__main__":
    main()
