"""``--params`` checked against the robot: the probe before the first episode (lockstep) and its statistic.

Before: the geofence's stopping distance and the fish's outline came from ``--params`` with only finite / positive
checks, so a description 30 % off in drag or fin size was used beside a policy without a word.
"""

import json
import math

import pytest

from pectoral_gym.hardware import deploy
from pectoral_gym.hardware.emurig import RigConditions
from pectoral_gym.hardware.params_probe import EXCESS_LIMIT, ProbeResult, check_on_lockstep_rig
from pectoral_gym.model.params import params_dict
from pectoral_gym.scaling.calibration.synth import perturbed_params

ROBOT = perturbed_params(101)  # an emulated robot drawn +-30 % around Table 1 (the calibration benchmark's seed)


def test_statistic_by_hand():
    # noise 1 mm, chi2 5 over 1000 dof: the model misses by 1 mm x sqrt(4) = 2 mm beyond the noise
    r = ProbeResult(chi2=5.0, dof=1000, sigma=0.001, duration=12.0, rms=0.003)
    assert r.excess == pytest.approx(0.002) and r.significant
    assert r.accepted == (0.002 <= EXCESS_LIMIT)
    noise = ProbeResult(chi2=1.2, dof=1000, sigma=0.005, duration=12.0, rms=0.007)  # 0.2 < 5 x 1.45 / sqrt(1000)
    assert noise.excess == pytest.approx(0.005 * math.sqrt(0.2)) and not noise.significant and noise.accepted
    short = ProbeResult(chi2=0.5, dof=100, sigma=0.001, duration=3.0, rms=0.001, stop="geofence")
    assert not short.accepted and "geofence" in short.why()


def test_true_params_accepted_and_drag_30_percent_off_refused():
    accepted = check_on_lockstep_rig(101, RigConditions(), ROBOT, params=ROBOT)
    assert accepted.excess < EXCESS_LIMIT / 2 and accepted.duration >= 11.0
    with pytest.raises(ValueError, match="--params does not describe this robot"):
        check_on_lockstep_rig(101, RigConditions(), ROBOT, params=ROBOT.replace(drag_coef=ROBOT.drag_coef * 1.3))


def test_deploy_refuses_params_off_in_fin_size_before_the_first_episode(tmp_path, capsys):
    robot, told = tmp_path / "robot.json", tmp_path / "told.json"
    robot.write_text(json.dumps(params_dict(ROBOT)))
    told.write_text(json.dumps(params_dict(ROBOT.replace(fin_span=ROBOT.fin_span * 0.7,
                                                         fin_chord=ROBOT.fin_chord * 0.7))))
    import dataclasses

    from pectoral_gym.model.kfunctions import ScalingFunctions
    from pectoral_gym.model.params import load_params

    k = ScalingFunctions.load(None)  # the shipped K labelled as the told fish's: the hand law's check passes
    k.metadata["model_parameters"] = dataclasses.asdict(load_params(told))
    k.save(tmp_path / "k.json")
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as ended:
        deploy.main(["--controller", "hand", "--emulate", "--lockstep", "--emulate-params", str(robot),
                     "--params", str(told), "--scaling", str(tmp_path / "k.json"), "--episodes", "1",
                     "--no-progress", "--out", str(out)])
    err = capsys.readouterr().err
    assert ended.value.code == 2 and "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("pectoral-deploy: error: --params does not describe this robot")
    assert not out.exists()


@pytest.mark.slow
def test_fin_size_30_percent_off_refused():
    for factor in (0.7, 1.3):
        with pytest.raises(ValueError, match="--params does not describe this robot"):
            check_on_lockstep_rig(101, RigConditions(), ROBOT, params=ROBOT.replace(
                fin_span=ROBOT.fin_span * factor, fin_chord=ROBOT.fin_chord * factor))


def test_trimmed_chi2_is_one_under_noise_with_the_stated_spread():
    # the probe's chi2 from the squared unit normal deviates without their largest 2 %: unbiased, and its spread
    # (the significance test's unit, from closed forms) as a simulation finds it
    import numpy as np

    from pectoral_gym.hardware import params_probe as pp

    mean, spread = pp._trimmed_chi2_1()
    rng = np.random.default_rng(0)
    n = 1428
    squares = np.sort(rng.standard_normal((2000, n)) ** 2, axis=1)[:, :int(0.98 * n)]
    estimates = squares.mean(axis=1) / mean
    assert np.mean(estimates) == pytest.approx(1.0, abs=0.01)
    assert np.std(estimates) * math.sqrt(n) == pytest.approx(spread, rel=0.05)
