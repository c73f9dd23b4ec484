"""Tests of the fidelity benchmark (pectoral_gym.scaling.validation.fidelity).

And of the averaged model's transitional-stroke forcing.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import quad

from pectoral_gym.model.averaging import averaged_forcing, half_stroke_mean_force, ripple_offset
from pectoral_gym.model.dynamics import fin_force_right, stroke_kinematics
from pectoral_gym.model.kloading import select_yaw_damping
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.params import FinBeat, FishParams
from pectoral_gym.model.spec import AVERAGED, AVERAGED_ENV, AVERAGED_PAPER, FULL_FAST, PRESETS, AveragedSpec
from pectoral_gym.scaling.cli import main as scaling_main
from pectoral_gym.scaling.validation import fidelity as fd
from pectoral_gym.scaling.validation.comparison import REST, as_run, steady_pair

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _quadrature_mean(angle_from: float, angle_to: float, duration: float, params: FishParams):
    """Mean of eqs. (16)-(17) over one half-stroke by adaptive quadrature, inertial terms included."""
    k, inertia = params.fin_drag_constant, params.fin_inertia_constant

    def force(t: float, j: int) -> float:
        return fin_force_right(*stroke_kinematics(t, duration, angle_from, angle_to), k, inertia)[j]

    return tuple(quad(force, 0.0, duration, args=(j,), epsabs=1e-14, limit=200)[0] / duration for j in (0, 1))


@pytest.mark.parametrize("angle_from, angle_to, duration", [
    (math.radians(90), math.radians(68), 0.3),  # from rest at 90 deg to a recovery turning point
    (math.radians(40), math.radians(150), 0.21),  # a wide power stroke
    (math.radians(160), math.radians(20), 1.7),  # a wide slow recovery (negative half-width)
    (math.radians(70), math.radians(71), 0.05),
])
def test_half_stroke_mean_matches_quadrature(angle_from, angle_to, duration):
    params = FishParams()
    fx, fy = half_stroke_mean_force(angle_from, angle_to, duration, params.fin_drag_constant)
    qx, qy = _quadrature_mean(angle_from, angle_to, duration, params)
    assert fx == pytest.approx(qx, rel=1e-9, abs=1e-15)
    assert fy == pytest.approx(qy, rel=1e-9, abs=1e-15)


def test_two_regular_half_strokes_average_to_the_cycle_mean():
    params = FishParams()
    beat = FinBeat.from_degrees(75, 25, 1.3, 3.5)
    b, a, T, z = beat.bias, beat.amplitude, beat.period, beat.ratio
    d1, d2 = T / (z + 1), z * T / (z + 1)  # eq. (21)
    p = half_stroke_mean_force(b - a, b + a, d1, params.fin_drag_constant)
    r = half_stroke_mean_force(b + a, b - a, d2, params.fin_drag_constant)
    fx, fy, tau = averaged_forcing(beat, params)  # K = 1
    assert (d1 * p[0] + d2 * r[0]) / T == pytest.approx(fx, rel=1e-12)
    assert (d1 * p[1] + d2 * r[1]) / T == pytest.approx(fy, rel=1e-12)
    assert params.fin_offset * fx == pytest.approx(tau, rel=1e-12)  # eq. (18)


def test_transitions_change_nothing_on_regular_strokes():
    right, left = FinBeat.from_degrees(100, 25, 1.0, 3.0), FinBeat.from_degrees(85, 20, 1.2, 3.5)
    runs = []
    for transitions in (False, True):
        model = AveragedModel(2, transitions=transitions)
        model.reset(right=right, left=left)  # on the pattern: every half-stroke is regular
        model.advance(13.7)
        runs.append(model.state.copy())
    np.testing.assert_array_equal(runs[0], runs[1])


@pytest.mark.parametrize("offsets", [False, True])
@pytest.mark.parametrize("transitions", [False, True])
def test_first_stroke_from_rest_applies_the_sweep_forcing(transitions, offsets):
    """From rest the right fin sweeps 90 -> 105 deg (pattern 80 +- 25 deg): the force the averaged model
    (K = 1) applies is the cycle mean plus, with transitions, the sweep's mean minus the regular stroke's
    (from 55 deg), plus, with ripple offsets, the pattern's offset M spread over the stroke (docs/model.md 3.8).
    Read off the body's initial acceleration, where drag and Munk terms are still negligible."""
    params = FishParams()
    beat = FinBeat.from_degrees(80, 25, 1.2, 3.0)
    d = beat.period / (beat.ratio + 1.0)  # power stroke, eq. (21)
    fx, fy, _ = averaged_forcing(beat, params)
    if transitions:
        swept = half_stroke_mean_force(math.radians(90), math.radians(105), d, params.fin_drag_constant)
        regular = half_stroke_mean_force(math.radians(55), math.radians(105), d, params.fin_drag_constant)
        fx, fy = fx + swept[0] - regular[0], fy + swept[1] - regular[1]
    if offsets:
        mx, my = ripple_offset(beat.bias, beat.amplitude, beat.period, beat.ratio, params.fin_drag_constant)
        fx, fy = fx + mx / d, fy + my / d
    model = AveragedModel(1, params, scaling="none", transitions=transitions, ripple_offsets=offsets)
    model.reset()
    model.command(right=beat)
    dt = 1e-4
    model.advance(dt)
    assert model.state[0, 3] * params.m1 / dt == pytest.approx(fx, rel=1e-3)
    assert model.state[0, 4] * params.m2 / dt == pytest.approx(fy, rel=1e-3)


def test_open_loop_errors_by_hand():
    full = np.zeros((3, 3, 3))
    full[:, 1, 0], full[:, 2, 0] = 0.3, 0.6  # straight 0.6 m along X
    full[2, :, :2] = 0.0  # a fish that does not move
    full[1, -1, 2] = math.radians(175)
    averaged = full.copy()
    averaged[0, -1, 1] = 0.06  # 6 cm off
    averaged[1, -1, 2] = math.radians(-175)  # 10 deg across the wrap
    averaged[2, -1, 0] = 0.05  # 5 cm off a fish at rest: normalised by 0.25 m
    err = fd.open_loop_errors(full, averaged)
    np.testing.assert_allclose(err["position"], [0.1, 0.0, 0.2], atol=1e-12)
    np.testing.assert_allclose(err["heading_deg"], [0.0, 10.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(err["path_m"], [0.6, 0.6, 0.0])


def test_repeating_the_same_pattern_is_the_constant_scenario():
    rng = np.random.default_rng(3)
    constant = fd.draw_patterns(rng, 3, 1)
    repeated = np.repeat(constant, 4, axis=1)
    from pectoral_gym.model.kfunctions import ScalingFunctions

    scaling = ScalingFunctions.unit()
    a = fd.open_loop("full", constant, None, 4.0, FishParams(), scaling)
    b = fd.open_loop("full", repeated, 1.0, 4.0, FishParams(), scaling)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (3, 9, 3)


@pytest.mark.parametrize("kind", ["full", "averaged"])
def test_mirrored_fins_keep_the_heading(kind):
    """Mirrored fins have no net moment or sway force (eq. 18 mirrored): a fish from rest swims straight."""
    from pectoral_gym.model.kfunctions import ScalingFunctions

    schedule = fd.split_fins(fd.draw_patterns(np.random.default_rng(5), 4, 6), "mirrored")
    np.testing.assert_array_equal(schedule[:, :, 1], schedule[:, :, 0])
    poses = fd.open_loop(kind, schedule, 0.5, 3.0, FishParams(), ScalingFunctions.load())
    assert np.all(np.abs(poses[:, :, 0]).max(axis=1) > 1e-3)  # they do swim
    np.testing.assert_allclose(poses[:, :, 1:], 0.0, atol=1e-12)


def test_one_fin_split_parks_the_left_fin():
    schedule = fd.draw_patterns(np.random.default_rng(6), 3, 4)
    one = fd.split_fins(schedule, "one_fin")
    np.testing.assert_array_equal(one[:, :, 0], schedule[:, :, 0])
    assert np.all(one[:, :, 1, 1] == 0.0)
    with pytest.raises(ValueError, match="split must be one of"):
        fd.split_fins(schedule, "left")


def test_draw_patterns_inside_the_env_ranges():
    from pectoral_gym.envs.core import EnvConfig

    r = EnvConfig().ranges
    beats = fd.draw_patterns(np.random.default_rng(0), 50, 3)
    assert beats.shape == (50, 3, 2, 4)
    assert np.all(beats >= r[:, 0]) and np.all(beats <= r[:, 1])
    assert np.all(beats[..., 0] - beats[..., 1] >= 0) and np.all(beats[..., 0] + beats[..., 1] <= math.pi)


def test_quick_cli_end_to_end(tmp_path, capsys):
    assert scaling_main(["fidelity", "--quick", "--out", str(tmp_path), "--no-progress",
                         "--candidate", "averaged-env"]) == 0
    data = json.loads((tmp_path / "fidelity_dev_averaged_env.json").read_text())
    assert data["candidate"] == "averaged-env" and data["spec"] == AVERAGED_ENV.to_dict()  # the spec it ran
    assert not data["spec"]["transitions"] and not data["spec"]["ripple_offsets"]
    assert data["quick"] and data["seed_set"] == "dev"
    assert set(data["scenarios"]) == set(fd.SCENARIOS) and set(data["decomposition"]) == set(fd.DECOMPOSITION)
    assert set(data["by_fins"]) == set(fd.SCENARIOS)
    assert all(set(v) == set(fd.FIN_SPLITS) for v in data["by_fins"].values())
    assert len(data["targets"]) == 16
    for name in data["plots"]:
        assert (tmp_path / name).read_bytes()[:8] == PNG_MAGIC
    report = (tmp_path / "fidelity_dev_averaged_env.md").read_text()
    assert "## Decomposition" in report and "changed every 0.5 s" in report and "## Each scenario by fins" in report
    assert '"transitions": false' in report  # the spec, recorded
    assert "preset averaged-env (transitions off, ripple offsets off" in capsys.readouterr().out
    for argv in (["--set", "tuning"], ["--candidate", "full"], ["--no-transitions"], ["--no-ripple-offsets"]):
        with pytest.raises(SystemExit):  # one spelling: the presets' names; the spec's options are no flags
            scaling_main(["fidelity", *argv])


def test_the_default_candidate_is_the_averaged_model_with_both_corrections():
    # the model of the published report (docs/validation/fidelity/README.md)
    assert PRESETS[fd.DEFAULT_CANDIDATE] == AveragedSpec(transitions=True, ripple_offsets=True)
    import argparse

    sub = argparse.ArgumentParser().add_subparsers()
    fd.add_parser(sub)
    parser = sub.choices["fidelity"]
    assert parser.parse_args([]).candidate == fd.DEFAULT_CANDIDATE
    assert set(next(a for a in parser._actions if a.dest == "candidate").choices) == set(PRESETS)


def test_every_section_runs_the_candidates_spec():
    """The candidate runs as its spec in every section: K keeps the spec's yaw-damping section only, so the steady
    states of averaged-paper run without the oscillation-averaged damping, and K without a section the spec
    needs is refused before any work."""
    from pectoral_gym.model.kfunctions import ScalingFunctions

    with pytest.raises(ValueError, match="no yaw_oscillation section"):
        fd.fidelity(ScalingFunctions.unit(), candidate="averaged", plots=False, progress=False)
    with pytest.raises(ValueError, match="candidate must be a model preset"):
        fd.fidelity(ScalingFunctions.load(), candidate="full-slow")
    beats = np.array([[REST, FinBeat.from_degrees(90, 22, 1, 4).as_array()]])
    k = ScalingFunctions.load()
    paper = steady_pair(beats, k, None, AVERAGED_PAPER.replace(yaw_damping="sinusoid"))["averaged"]["omega"]
    plain = steady_pair(beats, select_yaw_damping(k, "none"), None, AVERAGED_PAPER)["averaged"]["omega"]
    assert as_run(AVERAGED_PAPER, select_yaw_damping(k, "none")) == AVERAGED_PAPER
    assert as_run("averaged", k) == AVERAGED and as_run("full-fast", k) == FULL_FAST
    assert abs(paper[0] - plain[0]) > 1e-3 * abs(plain[0])  # the damping matters for this turn


def test_quick_cli_fast_full_candidate(tmp_path, capsys):
    assert scaling_main(["fidelity", "--quick", "--out", str(tmp_path), "--no-progress", "--no-plots",
                         "--candidate", "full-fast"]) == 0
    data = json.loads((tmp_path / "fidelity_dev_full_fast.json").read_text())
    assert data["candidate"] == "full-fast" and data["spec"] == FULL_FAST.to_dict()
    # the same model at two step sizes: far closer than the averaged model's percent-level errors
    assert data["scenarios"]["constant"]["position"]["worst"] < 0.01
    assert "# Fast full-model fidelity benchmark" in (tmp_path / "fidelity_dev_full_fast.md").read_text()
    assert "fast full model, preset full-fast (fast integration) against the reference integration" in \
        capsys.readouterr().out


def test_transitions_make_the_impulse_exact_with_k_1():
    """Without body drag, lift and yaw damping, and with both fins beating the same patterns (no yaw),
    the surge velocity is the surge impulse / m1. Patterns changing every 0.3 s, then parked: once the fins
    rest, the averaged model (K = 1) with transitional forcing has received the full model's impulse."""
    params = FishParams().replace(drag_coef=1e-9, lift_coef=1e-9, moment_coef=1e-9)
    rng = np.random.default_rng(5)
    patterns = fd.draw_patterns(rng, 4, 10)
    patterns[..., 1, :] = patterns[..., 0, :]  # the left fin mirrors the right: no sway, no yaw
    from pectoral_gym.model.models import FullModel

    speeds = {}
    models = (("full", FullModel(4, params)), ("off", AveragedModel(4, params, scaling="none", transitions=False)),
              ("on", AveragedModel(4, params, scaling="none", transitions=True)))
    for name, model in models:
        model.reset()
        for j in range(10):
            model.command_array(np.ascontiguousarray(patterns[:, j]))
            model.advance(0.3)
        model.command_array(np.broadcast_to(FinBeat.rest().as_array(), (4, 2, 4)).copy())
        model.advance(4.0)  # the last half-stroke and the parking stroke end
        assert np.all(model.fin_angles()[1] == 0.0)
        speeds[name] = model.state[:, 3].copy()
    np.testing.assert_allclose(speeds["on"], speeds["full"], rtol=1e-4, atol=1e-9)
    assert np.max(np.abs(speeds["off"] - speeds["full"])) > 100 * np.max(np.abs(speeds["on"] - speeds["full"]))


def test_re_commanding_a_still_fins_pattern_changes_nothing():
    """A fin that came to rest on a zero-amplitude pattern and is commanded the same pattern again stays
    idle and exerts no force. (Before the transitional forcing was evaluated once per half-stroke, the
    command's reset of the stroke kind made the idle fin's finished stroke read as a recovery stroke after
    another pattern's power stroke: a constant phantom force X(previous) / d2 for as long as it stayed idle.)"""
    beat = FinBeat.from_degrees(120, 30, 1.2, 1.0)
    still = FinBeat.from_degrees(135, 0, 0.6, 1.0)
    states = []
    for again in (False, True):
        model = AveragedModel(1, scaling="none", transitions=True, ripple_offsets=False)
        model.reset()
        model.command(right=beat)
        model.advance(1.5)  # in a power stroke: the still pattern is reached by a recovery stroke
        model.command(right=still)
        model.advance(2.0)  # the fin has reached 135 deg and rests there
        assert model.fin_angles()[1][0, 0] == 0.0
        if again:
            model.command(right=still)
        model.advance(2.0)
        states.append(model.state.copy())
    np.testing.assert_array_equal(states[1], states[0])  # f9b1c08: yaw rate 0.41 against 0.025 rad/s
