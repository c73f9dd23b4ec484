"""Train the demo's PPO recipe on an averaged id and evaluate the policy on ``PectoralFish-Full-v2`` (the transfer).

``python docs/validation/speed/fast_step_training.py OUT_DIR STEP SEED [EPISODES]`` (default 300 episodes):
the recipe of ``agents/hyperparams/ppo.yml``'s ``PectoralFish-Averaged-v2`` entry (the demo's: 1.6 M steps,
32 envs, its evaluation on the full model selecting ``best_model.zip``) trained with ``SEED`` on
``PectoralFish-Averaged-v2`` with the averaged model's ``STEP``, ``fast`` (the env option ``fast_step=True``) or
``default`` (the recipe as it is), then
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

out, step, seed = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
if step not in ("fast", "default"):
    raise SystemExit(f"STEP must be fast or default, got {step!r}")
episodes = int(sys.argv[4]) if len(sys.argv) > 4 else 300
env_id = "PectoralFish-Averaged-v2"
config = resolve_config("ppo", env_id, seed, task="goal",  # the recipe's entry
                        env_kwargs={"fast_step": True} if step == "fast" else None)
run_dir = out / f"{step}_seed{seed}"
train(config, run_dir, progress=False, command=" ".join(["python", *sys.argv]))
training = json.loads((run_dir / "training.json").read_text())
policy = load_policy(run_dir)
result = evaluate(policy, "PectoralFish-Full-v2", n_episodes=episodes, seed=10_000, env_kwargs={"task": "goal"})
summary = {"env_id": env_id, "step": step, "seed": seed, "train_time_s": training["train_time_s"],
           "train_steps_per_s": training["steps_per_s"], "full_v2": result.to_dict(per_episode=False)}
(run_dir / "transfer.json").write_text(json.dumps(summary, indent=1))
print(json.dumps(summary), flush=True)
