"""One model definition (pectoral_gym.model.spec): presets, round trips, the K check, one default per option."""

from __future__ import annotations

import dataclasses
import inspect
import json

import gymnasium as gym
import numpy as np
import pytest

from pectoral_gym.envs.core import EnvConfig
from pectoral_gym.model.kfunctions import ScalingFunctions
from pectoral_gym.model.models import AveragedModel, FullModel
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.spec import (
    AVERAGED,
    AVERAGED_ENV,
    AVERAGED_PAPER,
    AVERAGED_PPO,
    FULL_FAST,
    FULL_REFERENCE,
    PRESETS,
    AveragedSpec,
    FullSpec,
    env_spec,
    spec_from_dict,
)

ROBOT = FishParams(fin_span=0.07)


def _k_file(tmp_path, params: FishParams):
    source = ScalingFunctions.load()
    path = tmp_path / "k.json"
    meta = {**source.metadata, "model_parameters": dataclasses.asdict(params)}
    dataclasses.replace(source, metadata=meta).save(path)
    return path


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_round_trips_through_its_dict_and_json(name):
    spec = PRESETS[name]
    assert spec_from_dict(spec.to_dict()) == spec
    assert spec_from_dict(json.loads(json.dumps(spec.to_dict()))) == spec
    assert spec_from_dict(name) is spec


def test_the_spec_classes_defaults_are_presets_and_the_models_defaults_are_the_specs():
    assert FullSpec() == FULL_REFERENCE and AveragedSpec() == AVERAGED
    avg = inspect.signature(AveragedModel).parameters
    spec = AveragedSpec()
    for name in ("forcing", "dt_max", "transitions", "ripple_offsets", "scaling"):
        assert avg[name].default == getattr(spec, name), name
    full = inspect.signature(FullModel).parameters
    assert full["integration"].default == FullSpec().integration
    assert full["dt_max"].default is FullSpec().dt_max and full["min_substeps"].default is FullSpec().min_substeps


def test_presets_name_the_models_the_envs_and_the_ppo_file_use():
    assert EnvConfig(model="averaged").model_spec() == AVERAGED_ENV
    assert EnvConfig(model="full").model_spec() == FULL_REFERENCE
    assert EnvConfig(model="full", integration="fast").model_spec() == FULL_FAST
    assert EnvConfig(model="averaged", transitions=True, observe_fins=True).model_spec() == AVERAGED_PPO
    assert not AVERAGED_PAPER.transitions and AVERAGED_PAPER.forcing == "taylor"
    assert AVERAGED_PAPER.yaw_damping == "none"


def test_build_gives_the_models_with_the_specs_options():
    model = AVERAGED_PPO.build(3)
    assert isinstance(model, AveragedModel) and model.n == 3
    assert model.transitions and not model.ripple_offsets and model.dt_max == 0.25
    fast = FULL_FAST.build(2)
    assert isinstance(fast, FullModel) and fast.min_substeps == 8 and fast.dt_max == 0.05
    paper = AVERAGED_PAPER.build(1)
    assert paper.scaling.oscillation_table is None  # eq. (20)'s damping: the section is dropped


def test_a_k_file_identified_for_other_params_is_refused_unless_told(tmp_path):
    path = _k_file(tmp_path, ROBOT)
    spec = AVERAGED_ENV.replace(scaling=str(path))
    with pytest.raises(ValueError, match=r"fin_span: identified 0.07, given 0.061"):
        spec.build(1)  # Table 1
    assert spec.build(1, ROBOT).scaling.identified_params["fin_span"] == 0.07
    spec.replace(check_params=False).build(1)
    with pytest.raises(ValueError, match="fin_span"):
        AVERAGED.build(1, ROBOT)  # the shipped K, another robot


def test_fin_map_and_nmpc_plan_with_the_envs_k_and_check_it(tmp_path):
    from pectoral_gym.agents.controllers.fin_map import FinMap, planning_spec

    path = _k_file(tmp_path, ROBOT)
    config = EnvConfig(model="averaged", params=ROBOT, scaling=str(path))
    assert planning_spec(config) == config.model_spec()
    assert FinMap(config).scaling.identified_params["fin_span"] == 0.07
    with pytest.raises(ValueError, match="fin_span"):
        FinMap(EnvConfig(model="full", params=ROBOT))  # plans on the shipped K, identified for Table 1
    FinMap(EnvConfig(model="full", params=ROBOT, check_scaling_params=False))


def test_the_yaw_damping_is_the_specs_choice_not_the_files(tmp_path):
    shipped = _k_file(tmp_path, FishParams())
    assert EnvConfig(model="averaged", scaling=str(shipped)).model_spec().yaw_damping == "sinusoid"
    assert AVERAGED.replace(scaling=str(shipped)).build(1).scaling.has_oscillation
    plain = AVERAGED.replace(scaling=str(shipped), yaw_damping="none").build(1).scaling
    assert not plain.has_oscillation and plain.has_spline  # the section dropped, K kept
    no_section = tmp_path / "no_oscillation.json"
    plain.save(no_section)
    with pytest.raises(ValueError, match="no yaw_oscillation section"):
        AVERAGED.replace(scaling=str(no_section)).build(1)
    with pytest.raises(ValueError, match="use yaw_damping='none'"):
        AveragedSpec(scaling="none")
    assert env_spec("averaged", scaling="none").yaw_damping == "none"


def test_the_removed_waveform_damping_is_refused_naming_its_tag(tmp_path):
    with pytest.raises(ValueError, match="experiment/waveform"):
        AveragedSpec(yaw_damping="waveform")
    data = ScalingFunctions.load().to_dict()
    data["yaw_waveform"] = {"degree": 3, "harmonics": 1, "cos": [[0.0]], "sin": [[0.0]]}
    path = tmp_path / "waveform.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="experiment/waveform"):
        ScalingFunctions.load(path)


@pytest.mark.parametrize("kwargs,match", [
    ({"model": "full", "scaling": "none"}, "averaged model only"),
    ({"model": "averaged", "integration": "fast"}, "full model only"),
])
def test_option_applicability_is_checked_by_the_spec(kwargs, match):
    with pytest.raises(ValueError, match=match):
        EnvConfig(**kwargs)


def test_the_yaw_damping_is_no_env_option():
    # retired from the envs (docs/model.md 3.6): the env's spec names the richest damping its file holds
    with pytest.raises(TypeError, match="yaw_damping"):
        EnvConfig(model="averaged", yaw_damping="sinusoid")
    with pytest.raises(ValueError, match="unknown model options"):
        env_spec("averaged", yaw_damping="none")
    with pytest.raises(ValueError, match="yaw_damping must be one of"):
        AveragedSpec(yaw_damping="cosine")


def test_bad_spec_dicts_are_refused():
    with pytest.raises(ValueError, match="model = one of"):
        spec_from_dict({"integration": "fast"})
    with pytest.raises(ValueError, match="unknown full model options"):
        spec_from_dict({"model": "full", "transitions": True})
    with pytest.raises(ValueError, match="unknown model preset"):
        spec_from_dict("averaged-fast")


def test_run_folders_record_the_spec_and_old_ones_derive_it():
    from pectoral_gym.agents.training.config import run_model_spec

    old = {"env_id": "PectoralFish-Averaged-v0", "env_kwargs": {"task": "goal", "transitions": True}}
    assert run_model_spec(old) == AVERAGED_PPO
    assert run_model_spec({**old, "model_spec": FULL_FAST.to_dict()}) == FULL_FAST
    assert run_model_spec({"env_id": "PectoralFish-Full-v0", "env_kwargs": {"integration": "fast"}}) == FULL_FAST


def _episode(env_id: str, kwargs: dict, vector: bool) -> list[np.ndarray]:
    if vector:
        env = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", **kwargs)
    else:
        env = gym.make(env_id, **kwargs)
    env.action_space.seed(1)
    out = [env.reset(seed=4)[0]]
    for _ in range(12):
        obs, reward, *_ = env.step(env.action_space.sample())
        out += [obs, np.asarray(reward)]
    env.close()
    return out


@pytest.mark.parametrize("vector", [False, True])
@pytest.mark.parametrize("env_id,kwargs,old", [
    ("PectoralFish-Averaged-v0", {}, lambda n, p: AveragedModel(n, p, transitions=False, ripple_offsets=False)),
    ("PectoralFish-Averaged-v0", {"transitions": True},
     lambda n, p: AveragedModel(n, p, transitions=True, ripple_offsets=False)),
    ("PectoralFish-Full-v0", {"integration": "fast"}, lambda n, p: FullModel(n, p, integration="fast")),
])
def test_registered_envs_are_byte_identical_to_the_constructors_they_replaced(monkeypatch, vector, env_id, kwargs,
                                                                               old):
    """The env's model from its spec steps exactly as the model the env built inline before (e912fb1)."""
    new = _episode(env_id, kwargs, vector)
    spec_class = AveragedSpec if "Averaged" in env_id else FullSpec
    monkeypatch.setattr(spec_class, "build", lambda self, n=1, params=None, k=None: old(n, params))
    before = _episode(env_id, kwargs, vector)
    assert all(a.tobytes() == b.tobytes() for a, b in zip(new, before, strict=True))
