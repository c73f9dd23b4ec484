"""A prototype of a cheaper single-env reset (not in the package), against the package's own, in one process.

``python docs/validation/speed/reset_prototype.py [ENV_ID]`` (default ``PectoralFish-Averaged-v2``) times
``env.reset()`` (best of 7 x 20000), then replaces two methods for the rest of the process and times it again:

* ``FishModel.reset`` with fins given as ``FinBeat`` (or ``None``) for every fish: both fins' patterns written
  into one new array (the package broadcasts and copies each, then stacks them) and the fins set by a compiled
  loop (``strokes.init_fins`` makes seven numpy assignments); any other call goes to the package's method;
* ``TaskState.observe_reset``: the rest pattern's row built once, the reset observation's kernel called through
  its compiled entry point (numba's dispatcher types its seven arguments at every call).

Before each timing it steps seeded episodes of random actions and prints a digest of every observation,
reward and ``info`` value: the two digests are the same when the prototype gives the same bits.
"""

from __future__ import annotations

import hashlib
import sys
import timeit

import gymnasium as gym
import numba
import numpy as np

import pectoral_gym  # noqa: F401 - registers the fish ids
from pectoral_gym.envs.tasks import kernels as tk
from pectoral_gym.envs.tasks import table
from pectoral_gym.model import models
from pectoral_gym.model.jit import entry_point
from pectoral_gym.model.params import FinBeat
from pectoral_gym.model.strokes import ANGLE_FROM, ANGLE_TO, BEAT_AMPLITUDE, BEAT_BIAS, BIAS
from pectoral_gym.versions import LATEST


@numba.njit
def _init_fins(fins, pending, beats):
    """``strokes.init_fins`` for every fish, as one loop."""
    for i in range(fins.shape[0]):
        for f in range(2):
            fins[i, f, :] = 0.0
            fins[i, f, ANGLE_TO] = beats[i, f, BEAT_BIAS] - beats[i, f, BEAT_AMPLITUDE]
            fins[i, f, ANGLE_FROM] = fins[i, f, ANGLE_TO]
            for k in range(4):
                fins[i, f, BIAS + k] = beats[i, f, k]
                pending[i, f, k] = beats[i, f, k]


_package_reset = models.FishModel.reset
_rest = models.REST.as_array()


def _model_reset(self, state=None, right=None, left=None, index=None):
    if index is not None or not (isinstance(right, FinBeat | None) and isinstance(left, FinBeat | None)):
        return _package_reset(self, state, right, left, index)
    beats = np.empty((self.n, 2, 4))
    beats[:, 0] = _rest if right is None else right.as_array()
    beats[:, 1] = _rest if left is None else left.as_array()
    self.state[:] = 0.0 if state is None else state
    self.integral[:] = 0.0
    _init_fins(self.fins, self.pending, beats)
    self.forcing_cache[:] = 0.0
    self.time = 0.0
    return None


def _observe_reset(self, index, state):
    self.beats[index] = _rest
    call = self.__dict__.get("_reset_entry")
    if call is None:
        call = self._reset_entry = entry_point(tk.observe_reset, (index, state, self.ep, self.fish, self.obs,
                                                                  self.out, self.action_code))
    call(index, state, self.ep, self.fish, self.obs, self.out, self.action_code)


def digest(env_id: str) -> str:
    """SHA-256 (16 hex digits) of 2000 seeded random steps' observations, rewards, flags and info values."""
    env = gym.make(env_id)
    env.action_space.seed(1)
    obs, info = env.reset(seed=3)
    h = hashlib.sha256(obs.tobytes())
    for _ in range(2000):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        h.update(obs.tobytes() + repr((reward, terminated, truncated, list(info.items()))).encode())
        if terminated or truncated:
            obs, info = env.reset()
            h.update(obs.tobytes() + repr(list(info.items())).encode())
    return h.hexdigest()[:16]


def reset_time(env_id: str) -> float:
    """Best time of one ``env.reset()`` [us]."""
    env = gym.make(env_id)
    env.reset(seed=0)
    env.reset()  # compiles the prototype's kernel, or binds its entry point
    return min(timeit.repeat(env.reset, number=20_000, repeat=7)) / 20_000 * 1e6


def main() -> None:
    """Print the package's and the prototype's digest and reset time."""
    env_id = sys.argv[1] if len(sys.argv) > 1 else LATEST["averaged"]
    print(f"package:   digest {digest(env_id)}, reset {reset_time(env_id):.2f} us")
    models.FishModel.reset = _model_reset
    table.TaskState.observe_reset = _observe_reset
    print(f"prototype: digest {digest(env_id)}, reset {reset_time(env_id):.2f} us")


if __name__ == "__main__":
    main()
