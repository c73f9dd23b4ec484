"""The demo policy on ``PectoralFish-Averaged-v2`` with the averaged model's ``fast_step`` off and on.

``python docs/validation/speed/fast_step_policy.py RUN_DIR [EPISODES]`` (default 500): the policy of a training
run (``load_policy``), evaluated as the demo evaluates it (``agents.training.evaluate``, goal task, episode
``k`` seeded ``10000 + k``) on the averaged env, whose model's ``fast_step`` is set after the env is built
(as ``gym.make("PectoralFish-Averaged-v2", fast_step=True)`` builds it), and on ``PectoralFish-Full-v2`` (the
transfer, which the option does not touch).
Prints success rates with their 95 % bootstrap intervals and the mean time to goal.
"""

import sys

from pectoral_gym.agents.training import evaluate as evaluation
from pectoral_gym.agents.training.policy import load_policy

run_dir = sys.argv[1]
episodes = int(sys.argv[2]) if len(sys.argv) > 2 else 500
make_vector_env = evaluation.make_vector_env


def with_fast_step(fast: bool):
    """A ``make_vector_env`` whose envs' model runs with ``fast_step = fast``."""
    def make(env_id, num_envs, env_kwargs=None):
        env = make_vector_env(env_id, num_envs, env_kwargs)
        if env.core.model.averaged:
            env.core.model.fast_step = fast
        return env
    return make


policy = load_policy(run_dir)
for env_id, fast in (("PectoralFish-Averaged-v2", False), ("PectoralFish-Averaged-v2", True),
                     ("PectoralFish-Full-v2", False)):
    evaluation.make_vector_env = with_fast_step(fast)
    result = evaluation.evaluate(policy, env_id, n_episodes=episodes, seed=10_000, env_kwargs={"task": "goal"})
    summary = result.to_dict(per_episode=False)
    print(f"{env_id} fast_step={fast}: {summary}", flush=True)
