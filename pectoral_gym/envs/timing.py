"""``EnvConfig.timing``: the robot's control-loop timing, as seeded randomisation of the simulated envs' step.

On the robot (``HardwareFishEnv``) a step observes the fish at a tick of the control grid, and the command it
computes from that observation reaches the fins later: after the PC's computing and the radio's one-way delay
(``hardware.radio.channel.RadioChannel``; a lost frame's retry adds more). The ticks themselves come a little
late (the loop sleeps past a deadline), and a late tick does not move the grid: the env's next deadline stays
``control_period`` after the last one (``HardwareFishEnv.step``), so a late observation makes that period longer
and the next one shorter. A simulated env applies its command at once and observes exactly every
``control_period``. With ``timing`` set, each step of env ``i`` instead

* runs the fins on the previous command for ``lag`` seconds, then takes the new one (``command_one``) and runs
  the rest of the period on it: ``lag = level + U(0, latency_jitter)``, the episode's ``level`` drawn from
  ``command_latency`` at the reset;
* lasts ``span = control_period + late_k - late_(k-1)`` seconds, the observation instant ``late_k ~ U(0,
  tick_jitter)`` after its tick (``late = 0`` at the reset).

The reward's energy term and the track task's reference move by the nominal ``control_period``; the observed
mean velocities are over ``span``. Drawn from each env's own generator: the level after everything else the
reset draws, a step's two uniforms before the step (the simulated camera's draws, ``EnvConfig.sensing``, come
after it). Off (``None``), every step is exactly as without this module (``lag = 0``, ``span =
control_period``: the same bits).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from pectoral_gym.option_groups import coerce_group, level_range

__all__ = ["ControlTiming", "LAG", "SPAN", "TimingConfig"]

#: Columns of :attr:`ControlTiming.timing` (the array the compiled step reads): the command's delay into the
#: period and the period's length [s].
LAG, SPAN = 0, 1


@dataclass(frozen=True)
class TimingConfig:
    """The control loop's timing of ``EnvConfig.timing`` (seconds; the module docstring says how it is applied).

    The defaults span the emulated robot's clean radio (no delay, ``pectoral-deploy --emulate``) to the
    degraded one of the robot stack's tolerance targets (100 ms one way, 10 % of frames lost and sent again).

    Attributes:
        command_latency: ``(low, high)`` range of an episode's command delay level [s] (a number ``v`` means
            ``(v, v)``), drawn uniformly at each reset.
        latency_jitter: Each step's command delay is the level plus ``U(0, latency_jitter)`` [s].
        tick_jitter: Each observation comes ``U(0, tick_jitter)`` after its tick of the control grid [s].
    """

    command_latency: tuple[float, float] = (0.0, 0.12)
    latency_jitter: float = 0.03
    tick_jitter: float = 0.01

    def __post_init__(self) -> None:
        object.__setattr__(self, "command_latency", level_range("timing", "command_latency", self.command_latency))
        for name in ("latency_jitter", "tick_jitter"):
            jitter = getattr(self, name)
            if not (isinstance(jitter, (int, float)) and not isinstance(jitter, bool) and math.isfinite(jitter)
                    and jitter >= 0):
                raise ValueError(f"timing[{name!r}] must be a finite number >= 0 [s], got {jitter!r}")
            object.__setattr__(self, name, float(jitter))

    @classmethod
    def coerce(cls, value: Any) -> TimingConfig | None:
        """``EnvConfig.timing`` as given, as a ``TimingConfig`` or ``None`` (off).

        ``None`` or ``False``: off; ``True`` or ``{}``: the defaults; a mapping of fields; a ``TimingConfig``.

        Raises:
            ValueError: For another value, an unknown key, or an invalid setting.
        """
        return coerce_group(cls, "timing", value)

    def longest_lag(self) -> float:
        """The longest command delay a step can draw [s]."""
        return self.command_latency[1] + self.latency_jitter

    def check_period(self, control_period: float) -> None:
        """Raise ``ValueError`` unless every command reaches the fins within its period.

        The shortest period is ``control_period - tick_jitter``; a command delayed longer would be overtaken by
        the next one.
        """
        if self.longest_lag() >= control_period - self.tick_jitter:
            raise ValueError(f"timing: the longest command delay ({self.longest_lag():.4g} s: command_latency high + "
                             f"latency_jitter) must stay below the shortest period ({control_period:.4g} s - "
                             f"tick_jitter {self.tick_jitter:.4g} s)")


class ControlTiming:
    """Each env's command delay and period length per step (``EnvConfig.timing``; the module docstring).

    Args:
        n: Number of envs.
        control_period: The nominal period [s].
        settings: The timing, or ``None`` (off: every step ``lag = 0``, ``span = control_period``).

    Attributes:
        timing: ``(n, 2)`` float64: this step's ``LAG`` and ``SPAN`` per env [s] (read by the compiled step).
        level: ``(n,)`` each env's episode command delay level [s].
        late: ``(n,)`` how late each env's last observation came after its tick [s].
    """

    def __init__(self, n: int, control_period: float, settings: TimingConfig | None):
        self.settings, self.dt = settings, float(control_period)
        if settings is not None:
            settings.check_period(self.dt)
        self.timing = np.zeros((n, 2))
        self.timing[:, SPAN] = self.dt
        self.level, self.late = np.zeros(n), np.zeros(n)
        self._rngs: Sequence[np.random.Generator] = ()

    @property
    def longest_period(self) -> float:
        """The longest period a step can last [s]: ``control_period + tick_jitter``."""
        return self.dt + (0.0 if self.settings is None else self.settings.tick_jitter)

    def reset(self, index: np.ndarray, rngs: Sequence[np.random.Generator]) -> None:
        """Draw the episode levels of the envs in ``index`` (env ``i`` from ``rngs[i]``; one uniform each)."""
        self._rngs = rngs
        if self.settings is None:
            return
        low, high = self.settings.command_latency
        for i in index:
            self.level[i] = low + rngs[i].random() * (high - low)
            self.late[i] = 0.0

    def draw_step(self, skip: np.ndarray | None) -> None:
        """This step's ``LAG`` and ``SPAN`` of every env not in ``skip`` (two uniforms from its generator)."""
        settings = self.settings
        if settings is None:
            return
        for i in range(self.timing.shape[0]) if skip is None else np.flatnonzero(~np.asarray(skip, dtype=bool)):
            u = self._rngs[i].random(2)
            late = u[1] * settings.tick_jitter
            self.timing[i, LAG] = self.level[i] + u[0] * settings.latency_jitter
            self.timing[i, SPAN] = self.dt + late - self.late[i]
            self.late[i] = late
