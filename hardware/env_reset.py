"""The start of an episode on the robot: stop the fins, confirm, place the fish, find it, draw the episode, arm.

:class:`EpisodeStart` is :class:`pectoral_gym.hardware.env.HardwareFishEnv`'s ``reset`` and its operator-stop latch
(its "Starting State"); the env's ``step`` runs the episode it starts. It works on the env's robot stack
(:mod:`pectoral_gym.hardware.stack`) and state as the env's constructor sets them up.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pectoral_gym.hardware.realtime import settle_garbage

__all__ = ["EpisodeStart"]


class EpisodeStart:
    """``reset``, :meth:`rearm` and the stop latch's check of :class:`~pectoral_gym.hardware.env.HardwareFishEnv`."""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Stop the fins and wait for the robot to confirm, call the hook, find the fish, draw the episode.

        Returns ``(observation, info)``.

        Raises:
            RuntimeError: The operator's stop is latched (:meth:`stop`; :meth:`rearm` clears it), also when it
                comes during the reset; the robot did not confirm it stopped within ``stop_timeout`` (the
                hook is then not called); no fish was seen within ``reset_timeout``; the env is closed.
            pectoral_gym.hardware.radio.link.DisplacedError: The robot serves another session (``taken_over``,
                ``robot_busy``): nothing is sent, not even the reset's STOP; the run must end.
        """
        super().reset(seed=seed)
        if self._closed:
            raise RuntimeError("the environment is closed")
        self._episode = False
        sup = self.supervisor
        self._check_not_stopped()
        sup.disarm()
        self.stack.confirm_stop(self.stop_timeout)
        self._take_latches()  # the last episode's, before its stop
        self.recorder.record("stop", self.now())
        sup.bound.stopped(self.now())
        settle_garbage()  # the fins are stopped and the rules disarmed: a full collection now, none mid-episode
        resync = getattr(self.link, "resync", None)
        if callable(resync):
            resync()
        if self.reset_hook is not None:
            self.reset_hook(self.np_random)
            sup.bound.reset(self.now())  # the hook leaves the fish at rest, fins still
        self._last_measure, self._observing = -math.inf, False
        # Only frames captured after the hook returned: a camera clock may lead by up to max_frame_lead.
        placed = self.now() + self.safety.max_frame_lead * self.speed
        self.stack.wait_for_fish(placed, self.reset_timeout, self.frame_period / self.speed)
        sup.check_latency()  # measured on the frames of this wait; a latency the tank cannot afford: fins stay stopped
        sup.drain()
        t = self.watch.last_seen
        x, y, psi = sup.pose
        self.observer.reset(x, y, psi, t)
        self._observing = True
        self._last_measure = t
        self.recorder.episode(placed)
        self.recorder.record("pose", t, x, y, psi, sup.confidence)
        self._state = np.array([x, y, psi, 0.0, 0.0, 0.0])
        task = self.task_state
        task.reset_at(0, self.np_random, (x, y, psi))  # draw the target, observe at rest
        self.filter.reset(task.beats[0].copy())  # the rest pattern
        if self.fin_replay is not None:  # stopped above: the fins halt where they are (a hand moves only the fish)
            self.fin_replay.stop(self.now())
            self._observe_fins()
        self._steps = 0
        sup.frames = sup.lost_frames = 0
        self._next_tick = self.now()
        sup.arm(since=placed)
        self._check_not_stopped()  # a stop that came while this reset ran
        self._episode = True
        info = task.info(0)  # zero reward terms, the distance, as the simulated envs
        info.update(pose=[x, y, psi], target=self.target, in_geofence=self.geofence.breached(x, y, psi))
        return task.obs[0].copy(), info

    def _check_not_stopped(self) -> None:
        if self.supervisor.stop_requested:
            raise RuntimeError("the operator's stop is latched (HardwareFishEnv.stop() or a signal): call "
                               "env.rearm() once it is safe, then reset()")

    def rearm(self) -> None:
        """Clear a latched operator stop (:meth:`stop`, a signal): the operator's explicit decision to go on.

        Nothing else clears it. The next :meth:`reset` starts a new episode; the fins stay stopped until then.
        """
        self.supervisor.rearm()
