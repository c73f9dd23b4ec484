"""Where one single-env step of a fish env goes: the compiled model, each layer of Python around it, the resets.

``python docs/validation/speed/single_step.py [ENV_ID] [--steps N] [--repeats N]`` (default
``PectoralFish-Averaged-v2``, 20000 steps, best of 5) steps ``gym.make(ENV_ID)`` with random actions
pre-generated from the seeded action space, new every step, and records where its episodes end. It then runs
the same actions through ever fewer layers of the env, resetting (``env.reset()``, the wrapped env's) where the
full run did, so every layer walks the same seeded trajectory and does the same resets:

* ``wrapped``: ``env.step`` through Gymnasium's wrappers (``TimeLimit``, ``OrderEnforcing``, ``PassiveEnvChecker``);
* ``env``: ``env.unwrapped.step``;
* ``info``: the ``core`` layer, then the step's ``info`` dict built as the env builds it;
* ``core``: the action written into the core's buffer, then the core's step of it as the env calls it
  (``EnvCore.buffer_step``: the fused step's binding check, its compiled call, the model's clock);
* ``compiled``: the action written into the buffer, then the fused step's compiled entry point alone (the
  step and the observation's fin block, one argument);
* ``copy``: the action written into the buffer only;
* ``resets``: nothing but the loop and the resets;
* ``loop``: the loop alone.

The differences of neighbouring layers are what each layer adds per step; the passes go round robin over the
layers (a burst of load hits them alike), best pass kept. CartPole-v1 runs the same loop through ``gym.make``
in the same process, for the ratio. Last, one reset alone, the fish's and CartPole's (``env.reset()`` through
the wrappers, best of ``--repeats`` runs of 2000). The layers below ``env`` read private attributes of the env
core (this is a measurement, not an interface).
"""

from __future__ import annotations

import argparse
import time
import timeit

import gymnasium as gym
import numpy as np

import pectoral_gym  # noqa: F401 - registers the fish ids
from pectoral_gym.envs.core import task_info
from pectoral_gym.envs.layout import O_COST
from pectoral_gym.versions import LATEST


def main() -> None:
    """Measure the layers and print the table (markdown)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("env_id", nargs="?", default=LATEST["averaged"])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    def record(env_id: str):
        """The env, its pre-generated actions and where its episodes end (numba's compilation or cache load)."""
        env = gym.make(env_id)
        env.action_space.seed(0)
        actions = [env.action_space.sample() for _ in range(args.steps)]
        ends = []
        env.reset(seed=0)
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            ends.append(terminated or truncated)
            if ends[-1]:
                env.reset()
        return env, actions, ends

    env, actions, ends = record(args.env_id)
    cartpole, cart_actions, cart_ends = record("CartPole-v1")
    unwrapped = env.unwrapped
    core = unwrapped.core
    buffer_step, row, out = core.buffer_step(), core.action_buffer[0], core.out[0]
    task, cost = unwrapped.config.task_id, unwrapped.config.stop_band
    fused = core._step
    bound = fused._bound  # the compiled entry point and the arrays (with the settings) it was bound with
    own, arrays = bound.own, bound.arrays

    def wrapped(action):
        env.step(action)

    def env_only(action):
        unwrapped.step(action)

    def core_info(action):
        row[...] = action
        buffer_step()
        info = task_info(out, task)
        if cost:
            info["cost"] = out[O_COST]

    def core_step(action):
        row[...] = action
        buffer_step()

    def compiled(action):
        row[...] = action
        own(arrays)

    def copy(action):
        row[...] = action

    def nothing(action):
        pass

    def cart_step(action):
        cartpole.step(action)

    def run(step, on=env, steps=actions, at=ends) -> float:
        """Seconds per step of ``step`` over the actions, ``on.reset()`` where the recorded episodes end."""
        on.reset(seed=0)
        start = time.perf_counter()
        for action, end in zip(steps, at, strict=True):
            step(action)
            if end:
                on.reset()
        return (time.perf_counter() - start) / len(steps)

    def empty_loop() -> float:
        start = time.perf_counter()
        for action, _end in zip(actions, ends, strict=True):
            nothing(action)
        return (time.perf_counter() - start) / len(actions)

    layers = {"wrapped": wrapped, "env": env_only, "info": core_info, "core": core_step, "compiled": compiled,
              "copy": copy, "resets": nothing}
    best = dict.fromkeys([*layers, "loop", "CartPole-v1"], np.inf)
    for _ in range(args.repeats):
        for name, step in layers.items():
            best[name] = min(best[name], run(step))
        best["loop"] = min(best["loop"], empty_loop())
        best["CartPole-v1"] = min(best["CartPole-v1"], run(cart_step, cartpole, cart_actions, cart_ends))
    us = {k: v * 1e6 for k, v in best.items()}
    rows = [
        ("the compiled step (fused call and fin block, its argument's unboxing included)",
         us["compiled"] - us["copy"]),
        ("the action written into the core's float64 buffer", us["copy"] - us["resets"]),
        ("the core's step in Python (the fused step's binding check and the model's clock)",
         us["core"] - us["compiled"]),
        ("the info dict (a new one, numpy scalars)", us["info"] - us["core"]),
        ("the rest of the env's step (observation copy, reward and flags, attribute lookups)", us["env"] - us["info"]),
        ("Gymnasium's wrappers", us["wrapped"] - us["env"]),
        (f"resets, per step ({len(ends) / max(sum(ends), 1):.1f} steps per episode)", us["resets"] - us["loop"]),
        ("the loop (the zip, a Python call per step)", us["loop"]),
    ]
    total = us["wrapped"]
    print(f"| per step of {args.env_id} | us | share |\n|---|---|---|")
    for label, value in rows:
        print(f"| {label} | {value:.2f} | {value / total:.0%} |")
    print(f"| total, `gym.make` | {total:.2f} | 100% |")
    cart_episode = len(cart_ends) / max(sum(cart_ends), 1)
    print(f"| CartPole-v1, `gym.make`, the same loop ({cart_episode:.1f} steps per episode) | "
          f"{us['CartPole-v1']:.2f} | "
          f"{us['CartPole-v1'] / total:.0%} (rate ratio {us['CartPole-v1'] / total:.3f}x) |")
    env.reset(seed=0)
    reset = min(timeit.repeat(env.reset, number=2000, repeat=args.repeats)) / 2000 * 1e6
    cart_reset = min(timeit.repeat(cartpole.reset, number=2000, repeat=args.repeats)) / 2000 * 1e6
    print(f"\none reset, `env.reset()` through `gym.make`: {reset:.1f} us (CartPole-v1: {cart_reset:.1f} us)")
    env.close()
    cartpole.close()


if __name__ == "__main__":
    main()
