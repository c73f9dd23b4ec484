"""The liveness check's batched predictions: each fish of a batch follows the path a model of it alone gives."""

import math

import numpy as np
import pytest

from pectoral_gym.hardware.safety.geofence import SpeedBound
from pectoral_gym.hardware.safety.liveness import LivenessWatch
from pectoral_gym.hardware.safety.liveness_predictions import Predictions, batches, paths
from pectoral_gym.model import forcing_cache, strokes
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.servo import ServoLimits
from pectoral_gym.model.spec import FULL_REFERENCE

P = FishParams()


def _one_fish_path(snapshots, state, t_c, times, model=None):
    """The reference: a fresh one-fish model (blade-element unless given) stepped through the snapshots segment by
    segment, one model call per segment (what ``paths`` did before it ran the segments in one compiled call)."""
    model = FULL_REFERENCE.build(1, P) if model is None else model
    model.reset(state[None])
    snaps = [s for s in snapshots if s[0] <= times[-1]]
    first = max(k for k, s in enumerate(snaps) if s[0] <= t_c)
    now, out, pending = t_c, [], list(times)
    for k in range(first, len(snaps)):
        model.fins[:], model.pending[:] = snaps[k][1], snaps[k][2]
        forcing_cache.invalidate(model.forcing_cache)
        until = snaps[k + 1][0] if k + 1 < len(snaps) else math.inf
        while pending and pending[0] <= until:
            model.advance(max(pending[0] - now, 0.0))
            now = max(pending.pop(0), now)
            out.append(model.state[0, :3].copy())
        if not pending:
            break
        model.advance(max(until - now, 0.0))
        now = max(until, now)
    return np.array(out)


def test_batched_paths_are_bit_identical_to_one_fish_paths():
    bound = SpeedBound(P, ServoLimits())
    bound.reset(0.0)
    watch = LivenessWatch(P, bound, pose_noise=0.005)
    watch.command(0.0, np.array([[math.pi / 2, math.radians(60), 0.6, 3.0]] * 2))
    watch.command(0.7, np.array([[math.pi / 2, math.radians(40), 0.8, 2.0], [math.pi / 2, math.radians(60), 0.6, 3.0]]))
    watch._advance_shadows(1.6)
    snapshots = list(watch._early.snapshots)
    rng = np.random.default_rng(5)
    states = np.array([1.0, 0.5, 0.3, 0.05, 0.0, 0.1]) + rng.normal(0.0, 0.02, size=(4, 6))
    times = tuple(0.21 + k / 30 for k in range(36))  # between snapshots and on none of them
    batched = paths(snapshots, states, 0.21, times, FULL_REFERENCE.build(4, P))
    assert batched.shape == (len(times), 4, 3)
    for row in range(4):
        alone = _one_fish_path(snapshots, states[row], 0.21, times)
        assert np.array_equal(batched[:, row], alone), row  # the same floats, not merely close
    assert np.ptp(batched[-1, :, 0]) > 0.0  # the fish differ: the batch did not repeat one path


@pytest.mark.parametrize("rows", [1, 2])
def test_averaged_paths_in_one_call_are_bit_identical_to_model_calls_segment_by_segment(rows):
    """The averaged model (its forcing cache marked stale at every snapshot), snapshots of one fish or of groups."""
    bound = SpeedBound(P, ServoLimits())
    bound.reset(0.0)
    watch = LivenessWatch(P, bound, pose_noise=0.005)
    watch.command(0.0, np.array([[math.pi / 2, math.radians(60), 0.6, 3.0]] * 2))
    watch.command(0.9, np.array([[math.pi / 2, math.radians(20), 0.5, 1.0], [1.2, math.radians(50), 0.7, 2.0]]))
    watch._advance_shadows(2.5)
    snapshots = list(watch._early.snapshots)
    if rows == 2:  # the second group's fins: the first's with the right fin's amplitude halved
        other = [(t, fins.copy(), pending.copy()) for t, fins, pending in snapshots]
        for _, fins, pending in other:
            fins[0, 0, strokes.AMPLITUDE] *= 0.5
            pending[0, 0, 1] *= 0.5
        snapshots = [(a[0], np.concatenate([a[1], b[1]]), np.concatenate([a[2], b[2]]))
                     for a, b in zip(snapshots, other, strict=True)]
    rng = np.random.default_rng(7)
    states = np.array([1.0, 0.5, 0.3, 0.05, 0.0, 0.1]) + rng.normal(0.0, 0.02, size=(4, 6))
    times = (0.4, 0.4, 1.37, 2.5)  # a repeated time, one between snapshots, one on the last snapshot
    model = AveragedModel(n=4, params=P)
    batched = paths(snapshots, states, 0.33, times, model)
    assert batched.shape == (len(times), 4, 3)
    for fish in range(4):
        group = fish // (4 // rows)
        own = [(t, fins[group:group + 1], pending[group:group + 1]) for t, fins, pending in snapshots]
        alone = _one_fish_path(own, states[fish], 0.33, times, AveragedModel(n=1, params=P))
        assert np.array_equal(batched[:, fish], alone), fish
    assert model.time == pytest.approx(2.5 - 0.33, abs=1e-12)  # the clock of the advances one by one
    assert np.ptp(batched[-1, :, 0]) > 0.0


def test_differs_with_a_memo_gives_the_verdicts_of_a_fresh_comparison():
    from pectoral_gym.hardware.safety.shadow_fins import ShadowFins
    from pectoral_gym.model.finrules import FirmwareConfig

    config = FirmwareConfig(limits=ServoLimits())
    send, ack = ShadowFins(P, config, 0.0), ShadowFins(P, config, 1.0)
    beat = np.array([[math.pi / 2, math.radians(60), 0.6, 3.0]] * 2)
    other = np.array([[math.pi / 2, math.radians(30), 0.6, 2.0]] * 2)
    for shadow in (send, ack):
        shadow.reset(0.0)
        shadow.queue.append((0.0, beat, None))
        shadow.queue.append((2.0, other, lambda: 2.4))  # taken 0.4 s later by the acknowledging replay
    memo: dict = {}
    verdicts = []
    for to in np.arange(0.5, 4.0, 0.1):
        send.advance(to)
        ack.advance(to)
        mine, theirs = list(send.snapshots), ack.view(to)
        fresh = ShadowFins.differs(mine, theirs, to - 1.0)
        assert ShadowFins.differs(mine, theirs, to - 1.0, memo) == fresh
        assert ShadowFins.differs(mine, theirs, to - 1.0, memo) == fresh  # a second time, all from the memo
        verdicts.append(fresh)
    assert not verdicts[0] and verdicts[-1]  # the same fins before the second command, different after it
    mine = list(send.snapshots)
    changed = [(t, fins + (t == mine[-1][0]), pending) for t, fins, pending in mine]  # new objects, one differs
    assert ShadowFins.differs(mine, changed, mine[-3][0], memo)


def test_views_batched_by_their_instants_predict_what_each_view_alone_does():
    from pectoral_gym.hardware.safety.shadow_fins import ShadowFins
    from pectoral_gym.model.finrules import FirmwareConfig

    config = FirmwareConfig(limits=ServoLimits())
    shadows = [ShadowFins(P, config, share) for share in (0.0, 0.5, 1.0)]
    beat = np.array([[math.pi / 2, math.radians(60), 0.6, 3.0]] * 2)
    turn = np.array([[math.pi / 2, math.radians(30), 0.6, 2.0], [math.pi / 2, math.radians(60), 0.8, 2.5]])
    for shadow in shadows:
        shadow.reset(0.0)
        shadow.queue.append((0.0, beat, None))
        shadow.queue.append((0.6, turn, lambda: 0.75))
    for t in np.arange(1 / 30, 2.0, 1 / 30):
        for shadow in shadows:
            shadow.advance(t)
    views = [list(shadows[0].snapshots)] + [s.view(shadows[0].t) for s in shadows[1:]]
    # a copy of the first view on the same instants, its fins other than the first's: a batch of two views
    views.append([(t, fins * 0.9, pending) for t, fins, pending in views[0]])
    groups = batches(views, 0.3, 1.9)
    assert sorted(i for indices, _ in groups for i in indices) == [0, 1, 2, 3]
    assert any(len(indices) > 1 for indices, _ in groups)  # the test batches something
    for indices, stacked in groups:  # member j's rows are its own snapshots' fins at the group's instants
        if isinstance(stacked, list):
            continue
        for j, index in enumerate(indices):
            own = {t: (fins, pending) for t, fins, pending in views[index]}
            rows = own[stacked.times[0]][0].shape[0]
            for k, t in enumerate(stacked.times):
                assert np.array_equal(stacked.fins[k, j * rows:(j + 1) * rows], own[t][0])
                assert np.array_equal(stacked.pending[k, j * rows:(j + 1) * rows], own[t][1])
    rng = np.random.default_rng(3)
    before = np.array([(t, 1.0 + 0.2 * t, 0.5 + 0.01 * t, 0.02 * t) for t in np.arange(0.3, 1.1, 1 / 30)])
    before[:, 1:3] += rng.normal(0.0, 0.002, size=(len(before), 2))
    start = np.array([1.0, 0.5, 0.0, 0.2, 0.0, 0.0])
    predictions = Predictions(P, 4)
    for indices, stacked in groups:
        motion = predictions.motion(stacked, len(indices), start, 0.7, (1.2, 1.9))
        blade = predictions.motion(stacked, len(indices), start, 0.7, (1.2, 1.9), blade_element=True)
        fitted = predictions.fitted(stacked, len(indices), before, 0.1, (1.9,))
        for row, index in enumerate(indices):  # each view alone, in a model of one fish, with all its snapshots
            alone = Predictions(P, 1)
            assert np.array_equal(motion[:, row], alone.motion(views[index], 1, start, 0.7, (1.2, 1.9))[:, 0])
            assert np.array_equal(blade[:, row], alone.motion(views[index], 1, start, 0.7, (1.2, 1.9), True)[:, 0])
            assert not np.allclose(blade[:, row], motion[:, row])  # two models indeed
            assert np.array_equal(fitted[:, row], alone.fitted(views[index], 1, before, 0.1, (1.9,))[:, 0])


def test_the_second_windows_verdict_from_the_firsts_is_a_fresh_comparisons():
    """A view compared over one window's span, then over another's: the verdicts of fresh comparisons, always."""
    from pectoral_gym.hardware.safety.shadow_fins import ShadowFins

    bound = SpeedBound(P, ServoLimits())
    bound.reset(0.0)
    watch = LivenessWatch(P, bound, pose_noise=0.005)
    watch.command(0.0, np.array([[math.pi / 2, math.radians(60), 0.6, 3.0]] * 2))
    watch._advance_shadows(4.0)
    mine = list(watch._early.snapshots)
    rng = np.random.default_rng(11)
    checked = {True: 0, False: 0}
    for case in range(60):
        other = [(t, fins.copy(), pending.copy()) for t, fins, pending in mine]  # equal, other objects
        if case % 3:  # one snapshot differs (or is missing)
            j = int(rng.integers(len(other)))
            if case % 3 == 1:
                other[j][1][0, 0, strokes.AMPLITUDE] += 1e-3
            else:
                other[j] = (other[j][0] + 0.01, *other[j][1:])
        watch._views = ((float(case), 0, 0), [mine, other], {})
        for _ in range(3):  # spans in any order: inside, round, overlapping the ones compared before
            since, window = float(rng.uniform(0.0, 4.0)), bool(rng.integers(2))
            expected = ShadowFins.differs(mine, other, since)
            assert watch._differs(0, mine, other, since, window) == expected, (case, since)
            checked[expected] += 1
    assert checked[True] > 20 and checked[False] > 20  # both verdicts met
    for j in range(5, len(mine) - 5, 7):  # a difference just before the span found the same: the next one sees it
        other = [(t, fins.copy(), pending.copy()) for t, fins, pending in mine]
        other[j][1][0, 0, strokes.AMPLITUDE] += 1e-3
        for first, second in ((0.06, 0.04), (0.06, -0.9)):
            watch._views = ((100.0 + j + first + second, 0, 0), [mine, other], {})
            assert not watch._differs(0, mine, other, mine[j][0] + first, True)
            assert watch._differs(0, mine, other, mine[j][0] + second, False)
