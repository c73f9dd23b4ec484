"""Loading a Stable-Baselines3 model to act only: SB3's own load, without building its policy's optimizer.

:func:`pectoral_gym.agents.training.policy.load_policy` loads every policy through :func:`load_for_acting`.
"""

from __future__ import annotations

import io
import json
import zipfile
from typing import Any

__all__ = ["load_for_acting"]


class _ActingOnly:
    """Stands in for a loaded policy's optimizer: it keeps the saved state and cannot step.

    A controller only acts. Building a torch optimizer imports ``torch._dynamo`` (most of a second of CPU, in every
    process that loads a policy), and its state is of no use to acting; the saved state is kept, so that the model
    saves again as it was loaded.
    """

    def __init__(self, params: Any, **settings: Any):
        self.param_groups = [{"params": list(params), **settings}]
        self._state: dict[str, Any] = {}

    def load_state_dict(self, state: dict[str, Any], strict: bool = True) -> None:
        self._state = state

    def state_dict(self) -> dict[str, Any]:
        return self._state

    def zero_grad(self, *args: Any, **kwargs: Any) -> None:
        raise RuntimeError("this model was loaded to act only (pectoral_gym's load_policy): load it with its "
                           "algorithm's load() to train it")

    step = zero_grad


def load_for_acting(algo_class: Any, raw: bytes, device: str) -> Any:
    """``algo_class.load`` of the SB3 zip ``raw`` with its policy's optimizer left out (:class:`_ActingOnly`).

    Everything else is SB3's own loading and checks (parameters matched exactly); the model's ``policy_kwargs``
    and its policy's ``optimizer_class`` are the saved ones again afterwards. A zip whose ``policy_kwargs`` cannot
    be read is loaded as it is.
    """
    import inspect

    import torch as th
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.save_util import json_to_data

    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as archive:
            saved = json.loads(archive.read("data").decode()).get("policy_kwargs", {})
        kwargs = json_to_data(json.dumps({"policy_kwargs": saved}))["policy_kwargs"]
    except (KeyError, ValueError, TypeError, AttributeError, zipfile.BadZipFile):
        kwargs = None
    if not isinstance(kwargs, dict):
        return algo_class.load(io.BytesIO(raw), device=device)
    model = algo_class.load(io.BytesIO(raw), device=device,
                            custom_objects={"policy_kwargs": {**kwargs, "optimizer_class": _ActingOnly}})
    model.policy_kwargs = kwargs
    policy = getattr(model, "policy", None)
    if policy is not None and hasattr(policy, "optimizer_class"):  # what policy.save() records
        default = inspect.signature(type(policy)).parameters.get("optimizer_class")
        policy.optimizer_class = kwargs.get("optimizer_class", None if default is None else default.default)
        if kwargs.get("optimizer_kwargs") is None and isinstance(policy, ActorCriticPolicy) \
                and policy.optimizer_class is th.optim.Adam:
            policy.optimizer_kwargs = {"eps": 1e-5}  # ActorCriticPolicy's own default for Adam
    return model
