"""Every registered id behaves as recorded: seeded episodes and resolved settings equal a golden file, exactly.

The golden file (``tests/data/config_fingerprint.npz``) was written by ``python tests/config_fingerprint.py``
with the code before the configuration moved to one table; the ids' behaviour must not move with how their
settings are organised. Regenerate it only for a deliberate change of an id (which then needs a new version).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from config_fingerprint import GOLDEN, fingerprint

from pectoral_gym.registration import ENV_IDS


@pytest.fixture(scope="module")
def current():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # Gymnasium's notice on older versions
        return fingerprint()


def test_every_registered_id_is_recorded():
    golden = np.load(GOLDEN)
    recorded = {name.split("/")[0] for name in golden.files}
    assert recorded == set(ENV_IDS)


@pytest.mark.parametrize("env_id", sorted(ENV_IDS))
def test_seeded_episodes_and_settings_unchanged(current, env_id):
    golden = np.load(GOLDEN)
    names = sorted(name for name in golden.files if name.startswith(env_id + "/"))
    assert names == sorted(name for name in current if name.startswith(env_id + "/"))
    for name in names:
        expected, got = golden[name], current[name]
        assert expected.dtype == got.dtype and expected.shape == got.shape, name
        # Byte-identical: the same arithmetic on the same settings (NaN where an info key is absent).
        assert expected.tobytes() == got.tobytes(), f"{name} differs from the recorded run"


def test_the_recorded_ids_tell_their_settings_apart():
    """The comparison can fail: ids one setting apart record different episodes (ripple offsets, v1 -> v2)."""
    golden = np.load(GOLDEN)
    assert golden["PectoralFish-Averaged-v1/obs"].tobytes() != golden["PectoralFish-Averaged-v2/obs"].tobytes()
    assert golden["PectoralFish-Averaged-v0/obs"].tobytes() != golden["PectoralFish-Averaged-v1/obs"].tobytes()
    # Full-v2 is Full-v1 (the registry's table says so): the same episodes.
    assert golden["PectoralFish-Full-v1/obs"].tobytes() == golden["PectoralFish-Full-v2/obs"].tobytes()
