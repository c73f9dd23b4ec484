"""The env versions' table: one frozen configuration per id, the latest ids, the env classes' default version."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import pytest

import pectoral_gym  # noqa: F401  (registers the ids)
from pectoral_gym.envs import EnvConfig, PectoralFishEnv, PectoralFishVectorEnv
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.spec import AVERAGED, AVERAGED_PAPER, PRESETS, AveragedSpec
from pectoral_gym.registration import ENV_SETTINGS
from pectoral_gym.versions import (
    ENV_VERSIONS,
    LATEST,
    LATEST_AVERAGED,
    LATEST_FULL,
    ROBOT,
    SIMULATION,
    EnvVersion,
)


def test_every_registered_id_is_one_frozen_entry_of_the_table():
    assert set(ENV_SETTINGS) == set(ENV_VERSIONS) == {env_id for env_id in gym.registry
                                                      if env_id.startswith("PectoralFish-")}
    for env_id, version in ENV_VERSIONS.items():
        with pytest.raises(dataclasses.FrozenInstanceError):
            version.robot = SIMULATION  # type: ignore[misc]
        config = gym.make(env_id).unwrapped.config
        assert config.model_spec() == version.model
        assert config.robot_readiness() == version.robot
    with pytest.raises(TypeError):
        ENV_VERSIONS["PectoralFish-Averaged-v9"] = ENV_VERSIONS[LATEST_AVERAGED]  # type: ignore[index]


def test_full_v2_is_declared_full_v1():
    assert ENV_VERSIONS["PectoralFish-Full-v2"].same_as == "PectoralFish-Full-v1"
    assert ENV_SETTINGS["PectoralFish-Full-v2"] == ENV_SETTINGS["PectoralFish-Full-v1"]
    assert all(version.same_as is None for env_id, version in ENV_VERSIONS.items() if env_id != "PectoralFish-Full-v2")


def test_latest_ids_are_the_highest_version_of_each_model():
    for model, env_id in LATEST.items():
        versions = [int(i.rsplit("-v", 1)[1]) for i in ENV_VERSIONS if i.startswith(f"PectoralFish-{model.title()}-")]
        assert env_id == f"PectoralFish-{model.title()}-v{max(versions)}"
    assert (LATEST_FULL, LATEST_AVERAGED) == (LATEST["full"], LATEST["averaged"])


def test_the_averaged_model_is_configured_once():
    """AveragedModel's defaults, AveragedSpec()'s and the latest averaged id's model are one configuration."""
    model, built = AveragedModel(1), AveragedSpec().build(1)
    for name in ("transitions", "ripple_offsets", "dt_max", "mode"):
        assert getattr(model, name) == getattr(built, name), name
    assert ENV_VERSIONS[LATEST_AVERAGED].model == AVERAGED == AveragedSpec() == PRESETS["averaged"]


def test_env_classes_without_a_version_are_the_latest_ids():
    for model, env_id in LATEST.items():
        registered = gym.make(env_id).unwrapped.config
        assert PectoralFishEnv(model=model).config == registered
        assert PectoralFishVectorEnv(2, model=model).config == registered
    assert PectoralFishEnv().config == gym.make(LATEST_FULL).unwrapped.config
    # Arguments go on top of the version's settings; EnvConfig itself keeps the v0 ids' defaults.
    assert PectoralFishEnv(model="averaged", observe_fins=False).config.observe_fins is False
    assert EnvConfig(model="averaged") == gym.make("PectoralFish-Averaged-v0").unwrapped.config
    assert EnvConfig().robot_readiness() == SIMULATION
    with pytest.raises(ValueError, match="model must be one of"):
        PectoralFishEnv(model="blade")


def test_each_version_is_the_spec_its_env_options_resolve_to():
    from pectoral_gym.model.spec import env_options, env_spec

    for version in ENV_VERSIONS.values():
        assert env_spec(version.model.model, **env_options(version.model)) == version.model


def test_a_version_takes_only_a_model_an_env_runs():
    with pytest.raises(ValueError, match="not a model an env runs"):
        EnvVersion(AVERAGED_PAPER, ROBOT)  # the Taylor forcing is no env option


def test_the_tools_default_to_the_latest_ids():
    """Every tool that trains or evaluates defaults to LATEST; the studies pinned to v0 say so by name."""
    from pectoral_gym.agents.controllers import band_study
    from pectoral_gym.agents.studies import benchmark_settings, seeds, solve_probe, stack_gap, sweep
    from pectoral_gym.agents.training import demo, evaluate, train
    from pectoral_gym.tools import bench
    from pectoral_gym.versions import SIMULATION_IDS

    assert train.build_parser().get_default("env") == sweep.build_parser().get_default("env") == LATEST_AVERAGED
    assert evaluate.build_parser().get_default("env") == LATEST_FULL
    assert seeds.build_parser().get_default("train_env") == demo.TRAIN_ENV == seeds.TRAIN_ENV == LATEST_AVERAGED
    assert demo.EVAL_ENVS == (LATEST_AVERAGED, LATEST_FULL)
    assert (benchmark_settings.AVERAGED_ID, benchmark_settings.FULL_ID) == (LATEST_AVERAGED, LATEST_FULL)
    assert benchmark_settings.env_id("full") == LATEST_FULL
    assert benchmark_settings.VERSIONS[0] == LATEST_FULL.rsplit("-", 1)[1]
    assert solve_probe.FULL_ID == stack_gap.DEFAULT_ENV == LATEST_FULL
    assert set(seeds.TRAIN_ENVS) == set(ENV_VERSIONS)
    assert band_study.build_parser().get_default("env") == SIMULATION_IDS["full"]
    assert (bench.AVERAGED_ID, bench.FULL_ID) == (SIMULATION_IDS["averaged"], SIMULATION_IDS["full"])
