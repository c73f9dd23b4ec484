"""Train the demo's PPO recipe on an averaged id and evaluate the policy on ``PectoralFish-Full-v2`` (the transfer).

``python docs/validation/speed/fast_step_training.py OUT_DIR ENV_ID SEED [EPISODES]`` (default 300 episodes):
the recipe of ``agents/hyperparams/ppo.yml``'s ``PectoralFish-Averaged-v2`` entry (the demo's: 1.6 M steps,
32 envs, its evaluation on the full model selecting ``best_model.zip``) trained on ``ENV_ID`` with ``SEED``
(``PectoralFish-Averaged-v3`` is v2's model with its fast step: the same entry, only the id changed), then
evaluated as ``pectoral-demo`` evaluates (``agents.training.evaluate``, goal task, episode ``k`` seeded
``10000 + k``) on ``PectoralFish-Full-v2``. Writes ``OUT_DIR/<env>_seed<SEED>/`` (the run folder) and prints one
JSON line: training time, env steps per second, success rate with its 95 % bootstrap interval, time to goal.
"""

import json
import sys
from pathlib import Path

from pectoral_gym.agents.training.config import resolve_config
from pectoral_gym.agents.training.evaluate import evaluate
from pectoral_gym.agents.training.policy import load_policy
from pectoral_gym.agents.training.train import train

out, env_id, seed = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
episodes = int(sys.argv[4]) if len(sys.argv) > 4 else 300
config = resolve_config("ppo", "PectoralFish-Averaged-v2", seed, task="goal")  # the recipe's entry
config["env_id"] = env_id
run_dir = out / f"{env_id.split('-', 1)[1]}_seed{seed}"
train(config, run_dir, progress=False, command=" ".join(["python", *sys.argv]))
training = json.loads((run_dir / "training.json").read_text())
policy = load_policy(run_dir)
result = evaluate(policy, "PectoralFish-Full-v2", n_episodes=episodes, seed=10_000, env_kwargs={"task": "goal"})
summary = {"env_id": env_id, "seed": seed, "train_time_s": training["train_time_s"],
           "train_steps_per_s": training["steps_per_s"], "full_v2": result.to_dict(per_episode=False)}
(run_dir / "transfer.json").write_text(json.dumps(summary, indent=1))
print(json.dumps(summary), flush=True)
