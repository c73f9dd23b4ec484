"""Whether the camera shows *our* fish, live: the poses it reports against what our fins can and must do.

Pixel tests (:class:`pectoral_gym.hardware.vision.framecheck.FrameCheck`) can always be outrun: a source that
replays more frames than they remember, or a frozen image under fresh sensor noise. Physics cannot. The PC
knows every command it sent, hence what the fins did, and the fish must follow them. :class:`LivenessWatch`
checks three consequences on the sightings (each a stop with a reason saying what was seen):

* **jump**: two consecutive sightings further apart than the fastest the fish can move
  (:class:`pectoral_gym.hardware.safety.geofence.SpeedBound`) plus the pose noise allowance: a replayed ring of
  frames going round, a cut to another recording;
* **too fast**: the camera's fish moving (least-squares speed less two standard errors) faster than the physical
  bound allows ours: fins still and the fish coasted to rest, while the camera shows a fish that swims;
* **motion**: the fins are replayed from the commands sent, so their phase at any past instant is known.
  *Frozen*: the averaged model (:class:`pectoral_gym.model.models.AveragedModel`) and the blade-element model
  (:class:`pectoral_gym.model.models.FullModel`) driven by them, started from the pose and mean velocity of the
  window before the last ``window`` s, both predict at least ``min_motion`` (displacement plus half a body length
  times the heading change, less three standard errors) and the camera shows less than ``ratio`` of the smaller
  prediction, over ``window`` or ``long_window``, however the pixels are dressed up. (Each model misses where the
  other does not: the averaged one lone transitional half-strokes, the blade-element one a slow fish whose
  stroke surges a mean velocity does not hold; the blade-element one runs only when the averaged one would stop.)
  *Innovation*: the blade-element model (:class:`pectoral_gym.model.models.FullModel`) driven by them, started
  in the state whose path fits the poses of the window before, misses the end position by more than
  ``innovation`` plus three standard errors of the measurement, twice in a row: a recording, another fish.

The robot takes a command somewhere between its send and the STATUS that acknowledges it (the radio's forward
delay): the fins are replayed three times (:class:`~pectoral_gym.hardware.safety.shadow_fins.ShadowFins`), taking
every command at its send, half way and at its acknowledgement, and each window is judged against the prediction
most favourable to liveness (the smaller predicted motion, the smaller miss). The robot's reports of its latches
(:meth:`LivenessWatch.latch`) go into all three: each then runs the half-strokes the robot says it ran, when it ran
them, and infers only what lies between reports (a report lost, a robot that sends none).

``docs/guide/safety.md``, "Liveness from physics", gives the figures behind the bounds.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Callable

import numpy as np

from pectoral_gym.hardware.safety.geofence import SpeedBound
from pectoral_gym.hardware.safety.liveness_predictions import Predictions, batches, fit_line, line_state
from pectoral_gym.hardware.safety.shadow_fins import ShadowFins
from pectoral_gym.model.finrules import FirmwareConfig
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.servo import ServoLimits

__all__ = ["LivenessWatch"]

_NOISE_SIGMAS = 9.0  # a jump allowance of 9 pose-noise sigmas: P(|2-D noise step| > 9 sigma) = exp(-81/4) ~ 2e-9
_END_SPAN = 0.1  # poses this long at the window's end are averaged for its pose [s]


class LivenessWatch:
    """Checks the camera's poses against the fins' commands (module docstring); :meth:`sighting` gives the reason.

    The fins are replayed from the commands sent from the arm on, so their phase at any past instant is
    known; a prediction starts a fish model from the fins' phase of the window's start and the fish's
    measured pose and velocity there.

    Args:
        params: The fish's parameters (the model's and the speed bound's).
        bound: The physical speed bound, fed every command sent (the supervisor's).
        pose_noise: Standard deviation of a tracked position [m] (the jump allowance is 9 of them).
        window: Span of the motion and innovation checks [s].
        long_window: A second, longer span of the motion check [s]: fins that beat gently move the fish slowly,
            and a longer span makes their motion large enough to judge.
        ratio: The camera must show at least this share of the predicted motion.
        min_motion: Predicted motions below this are not judged [m].
        innovation: The model's own error allowed between the predicted and the measured end position [m]; three
            standard errors of the measurement (from the poses' scatter) are added.

    Attributes:
        last_prediction: ``(M_pred, M_meas, innovation)`` of the last motion check [m] (``nan`` when none ran).
        predictions: The recent checks, ``(t, M_pred, M_meas, innovation, allowed)`` (the newest 4096, for studies).
    """

    def __init__(self, params: FishParams, bound: SpeedBound, pose_noise: float, window: float = 0.8,
                 long_window: float = 2.4, ratio: float = 0.1, min_motion: float = 0.03, innovation: float = 0.04,
                 limits: ServoLimits | None = None):
        self.params, self.bound, self.pose_noise = params, bound, float(pose_noise)
        self.window, self.ratio, self.min_motion = float(window), float(ratio), float(min_motion)
        self.innovation, self.long_window = float(innovation), float(long_window)
        self._strikes = 0
        config = FirmwareConfig(limits=limits or ServoLimits())
        # The robot takes a command between its send and the STATUS that acknowledges it: the fins replayed with
        # each command at the send, half way and at the acknowledgement (the forward delay, if the return one
        # equals it) sample what the robot's fins did.
        self._early = ShadowFins(params, config, 0.0)
        self._later = [ShadowFins(params, config, 0.5), ShadowFins(params, config, 1.0)]
        self._predictions = Predictions(params, 1 + len(self._later))
        self._last_beats: np.ndarray | None = None
        self._first_command = math.inf  # send time of the first command since the reset [s]
        self._poses: collections.deque[tuple[float, float, float, float]] = collections.deque(maxlen=256)
        self._warm_up()
        self.last_prediction = (math.nan, math.nan, math.nan)
        self.predictions: collections.deque[tuple[float, float, float, float]] = collections.deque(maxlen=4096)
        self._next_check = -math.inf

    def _warm_up(self) -> None:
        """Compile or load the models' kernels now, as they will be called, not inside a supervisor poll."""
        self.reset(0.0)
        self.command(0.0, np.array([[math.pi / 2, 0.5, 1.0, 1.0]] * 2))
        self._advance_shadows(0.4)
        self._predictions.warm_up(self._early.snapshots)
        self.reset()

    def reset(self, t: float = math.nan) -> None:
        """Start over at ``t`` [s] with the fins still (an arm after a confirmed stop); forget poses and commands."""
        for shadow in (self._early, *self._later):
            shadow.reset(t)
        self._last_beats = None
        self._first_command = math.inf
        self._poses.clear()
        self._next_check = -math.inf
        self._strikes = 0
        # the replays' views for a sighting, commands and reports, and whether each delayed one differs from the
        # first from an instant on: {index: (since, differs)}
        self._views: tuple[tuple[float, int, int], list, dict] = ((math.nan, -1, -1), [], {})
        # ShadowFins.differs's memos, one per delayed replay and window (each window compares its own span)
        self._differs_memos: dict[tuple[int, bool], dict] = {(k, w): {} for k in range(len(self._later))
                                                              for w in (True, False)}
        self._commands = 0  # commands taken in since the reset
        self._reports = 0  # latch reports taken in since the reset
        self._since = t  # reports of latches before this are not of these fins
        self._newest = -math.inf  # the newest sighting's capture time [s]

    def command(self, t: float, beats: np.ndarray, acknowledged: Callable[[], float | None] | None = None) -> None:
        """A command ``(2, 4)`` sent at ``t`` [s].

        ``acknowledged`` gives the arrival time [s] of the first STATUS acknowledging it (or a later message),
        ``None`` until there is one: the robot took the command between ``t`` and then. Without it the command
        is taken as started at ``t``.
        """
        if self._last_beats is not None and np.array_equal(self._last_beats, beats):
            return  # a lease renewal of the same command: the fins go on as they were
        if not math.isfinite(self._early.t):
            self.reset(t)
        self._last_beats = np.array(beats, dtype=float).reshape(2, 4)
        self._commands += 1
        self._first_command = min(self._first_command, float(t))
        for shadow in (self._early, *self._later):
            shadow.queue.append((float(t), self._last_beats, acknowledged))

    def latch(self, t: float, fin: int, beat: np.ndarray, turn: float, power: bool) -> bool:
        """The robot reported that fin ``fin`` latched ``beat`` ``(4,)`` at angle ``turn`` [rad] at ``t`` [s].

        Every replay starts that half-stroke at ``t`` (:meth:`ShadowFins.latch`, rewinding if it is past ``t``):
        what the robot says its fins did is their truth, whatever the camera shows. Ignored before the first
        command since the reset and for a latch before the reset (another episode's fins). Returns whether it was
        taken.
        """
        if not (math.isfinite(self._since) and t >= self._since and t >= self._first_command):
            return False
        for shadow in (self._early, *self._later):
            shadow.latch(t, fin, beat, turn, power)
        self._reports += 1
        return True

    def _advance_shadows(self, to: float) -> None:
        for shadow in (self._early, *self._later):
            shadow.advance(to)

    def sighting(self, t: float, x: float, y: float, psi: float) -> str:
        """A tracked pose captured at ``t`` [s]; returns why the camera is not live, or ``""``."""
        reason = ""
        if self._poses:
            t0, x0, y0, psi0 = self._poses[-1]
            psi = psi0 + math.remainder(psi - psi0, math.tau)  # unwrapped against the last sighting
            dt = t - t0
            if dt > 0:
                step = math.hypot(x - x0, y - y0)
                allowed = self.bound.peak(t0, t) * dt + _NOISE_SIGMAS * self.pose_noise
                if step > allowed:
                    reason = (f"camera not live: the fish jumped {step * 1000:.0f} mm in {dt:.3f} s, more than our "
                              f"fish can move ({allowed * 1000:.0f} mm with the pose noise)")
        self._poses.append((float(t), float(x), float(y), float(psi)))
        self._newest = max(self._newest, float(t))
        if math.isfinite(self._early.t):
            self._advance_shadows(t)
        if not reason and t >= self._next_check:
            self._next_check = t + 0.1  # the model check at 10 per second is plenty for a window of 0.8 s
            reason = self._too_fast(t) or self._motion(t, self.window, True) or \
                self._motion(t, self.long_window, False)
        return reason

    # ------------------------------------------------------------ the checks
    def _recent(self, t0: float, t1: float) -> np.ndarray:
        return np.array([p for p in self._poses if t0 <= p[0] <= t1]).reshape(-1, 4)

    def _too_fast(self, t: float) -> str:
        poses = self._recent(t - 0.5, t)
        if len(poses) < 6 or np.ptp(poses[:, 0]) < 0.3:
            return ""
        _, rates = fit_line(poses, t)
        centred = poses[:, 0] - poses[:, 0].mean()
        error = 2.0 * max(self.pose_noise, 1e-4) / math.sqrt(float(centred @ centred))
        speed = math.hypot(rates[0], rates[1]) - math.sqrt(2.0) * error
        allowed = self.bound.peak(t - 0.5, t)
        if speed > allowed:
            return (f"camera not live: it shows a fish moving at {speed:.2f} m/s, and ours cannot exceed "
                    f"{allowed:.2f} m/s with the fins it was sent")
        return ""

    def _motion(self, t1: float, window: float, innovation_check: bool) -> str:
        """The fish models' motion over the last ``window`` against the camera's; the innovation too if asked.

        The motion: each model starts at the centre ``t_c`` of the window before (``[t1 - 2 window,
        t1 - window]``) from the least-squares line through its poses (there the line's position and slope are the
        pose and mean velocity with the smallest errors, ``sigma / sqrt(n)`` and ``sigma / sqrt(sum (t - t_c)^2)``,
        uncorrelated), compared inside the last window, between the mean poses of its first and last 0.1 s. The
        end position: the blade-element model from the state whose path through the replayed fins fits the
        window before (:meth:`~pectoral_gym.hardware.safety.liveness_predictions.Predictions.fitted`), its
        standard error taken as the line's (a pose and a velocity fitted to the same poses, the path's shape given).
        """
        before = self._recent(t1 - 2.0 * window, t1 - window)
        middle = self._recent(t1 - window - 0.5 * _END_SPAN, t1 - window + 0.5 * _END_SPAN)
        end = self._recent(t1 - _END_SPAN, t1)
        if len(before) < 6 or np.ptp(before[:, 0]) < 0.6 * window or len(middle) < 2 or len(end) < 2:
            return ""
        t_c, t_s = float(before[:, 0].mean()), float(before[0, 0])
        snapshots = self._early.snapshots
        known = snapshots and snapshots[0][0] <= t_c and self._first_command <= t_c
        if not (known and self.bound.run_until >= t1):
            return ""  # the fins did not run the whole span on commands we know
        fitted = snapshots[0][0] <= t_s and self._first_command <= t_s  # known from the window's start too
        t_m, t_e = float(middle[:, 0].mean()), float(end[:, 0].mean())
        meas_m, meas_e = middle[:, 1:4].mean(axis=0), end[:, 1:4].mean(axis=0)
        reach = 0.5 * self.params.body_length
        m_meas = _moved(np.array([meas_m, meas_e]), reach)
        # The prediction most favourable to liveness, of the fins taking each command at its send, half way and at
        # its acknowledgement: the smaller predicted motion, the smaller miss. The motion: from the line's pose and
        # mean velocity at t_c (a start fitted through the fins would let a frozen window before explain itself by
        # a fish that swims backwards against its thrust), by the averaged model and, where that one would call
        # the camera frozen, by the blade-element model too: the smaller (each model misses where the other does
        # not: the averaged one lone transitional half-strokes, the blade-element one a slow fish whose stroke
        # surges the line's mean velocity does not hold). The end position: the blade-element model from the
        # state fitted through each replay's fins, whose path also had to match the window before (a frozen one
        # included).
        line_c = fit_line(before, t_c)  # the start's line, and the scatter about it below
        start_c = line_state(before, t_c, line_c)
        m_pred = innovation = math.inf
        key = (self._newest, self._commands, self._reports)
        if self._views[0] != key:  # the replays' views, once per sighting, commands and reports for both windows
            self._views = (key, [s.view(self._newest) for s in (self._early, *self._later)], {})
        early = self._views[1][0]
        since = t_s if fitted else t_c
        views = [early] + [v for k, v in enumerate(self._views[1][1:])
                           if self._differs(k, early, v, since, innovation_check)]
        motions, misses = [math.inf] * len(views), [math.inf] * len(views)
        for indices, stacked in batches(views, since, t_e):  # the views with snapshots at the same instants
            pred = self._predictions.motion(stacked, len(indices), start_c, t_c, (t_m, t_e))
            ends = self._predictions.fitted(stacked, len(indices), before, reach, (t_e,))[0] \
                if fitted and innovation_check else None
            for row, view in enumerate(indices):
                motions[view] = _moved(pred[:, row], reach)
                if ends is not None:
                    misses[view] = math.hypot(*(meas_e[:2] - ends[row, :2]))
        for motion, miss in zip(motions, misses, strict=True):  # in the views' order, as min() meets them
            m_pred = min(m_pred, motion)
            innovation = min(innovation, miss)
        if not fitted:
            innovation = math.nan  # not judged (the fins are not known from the window's start)
        scatter, sxx = self._scatter(before, t_c, line_c)
        # Standard errors [m]: of the predicted motion inside the window (the start's slope error over it), and of
        # the end position (the start's position and slope, and the end's mean).
        motion_error = scatter * (t_e - t_m) / math.sqrt(sxx)
        end_error = scatter * math.sqrt(1.0 / len(before) + (t_e - t_c) ** 2 / sxx + 1.0 / len(end))
        allowed = self.innovation + 3.0 * end_error

        def frozen(motion: float) -> bool:
            return motion - 3.0 * motion_error >= self.min_motion and m_meas < self.ratio * motion

        if frozen(m_pred):  # the blade-element model too (rarely run: on a live camera the averaged one seldom stops)
            for indices, stacked in batches(views, since, t_e):
                pred = self._predictions.motion(stacked, len(indices), start_c, t_c, (t_m, t_e), blade_element=True)
                m_pred = min(m_pred, *(_moved(pred[:, row], reach) for row in range(len(indices))))
        if innovation_check and fitted:
            self.last_prediction = (m_pred, m_meas, innovation)
            self.predictions.append((t1, m_pred, m_meas, innovation, allowed))
        if frozen(m_pred):
            return (f"camera frozen: the fish has moved {m_meas * 1000:.0f} mm in {window:.1f} s while its "
                    f"fins beat for {m_pred * 1000:.0f} mm (the averaged and the blade-element model, the smaller; "
                    f"at least {self.ratio * m_pred * 1000:.0f} mm expected)")
        if not innovation_check:
            return ""
        if math.isnan(innovation):
            return ""
        self._strikes = self._strikes + 1 if innovation > allowed else 0
        if self._strikes >= 2:  # twice in a row (0.1 s apart): one odd window is not enough
            return (f"camera not live: the fish it shows ended {innovation * 1000:.0f} mm from where the fins sent "
                    f"over the last {t_e - t_c:.1f} s put ours (the blade-element model; at most "
                    f"{allowed * 1000:.0f} mm allowed)")
        return ""

    def _differs(self, k: int, early: list, view: list, since: float, innovation_check: bool) -> bool:
        """Whether delayed view ``k`` differs from ``early`` from ``since`` [s] on (:meth:`ShadowFins.differs`).

        The same views for the other window: a verdict on a span holds for a span inside it when it is "the same",
        and for a span round it when it is "differs"; a span round a span found the same is compared before it only.
        """
        verdicts, memo = self._views[2], self._differs_memos[k, innovation_check]
        known = verdicts.get(k)
        if known is not None and since >= known[0] and not known[1]:
            return False  # the same over a span holding this one
        if known is not None and since <= known[0]:
            if known[1]:
                return True  # differs inside this span
            differs = ShadowFins.differs(early, view, since, memo, until=known[0])  # the same from known[0] on
        else:
            differs = ShadowFins.differs(early, view, since, memo)
        if known is None or since <= known[0]:
            verdicts[k] = (since, differs)
        return differs

    def _scatter(self, poses: np.ndarray, t_c: float, line: tuple[np.ndarray, np.ndarray]) -> tuple[float, float]:
        """The positions' scatter about their line [m] (at least the assumed pose noise) and ``sum (t - t_c)^2``.

        ``line``: ``fit_line(poses, t_c)``.
        """
        pose_c, rates_c = line
        residual = poses[:, 1:3] - (pose_c[:2] + np.outer(poses[:, 0] - t_c, rates_c[:2]))
        scatter = math.sqrt(float((residual ** 2).sum()) / max(2 * (len(poses) - 2), 1))
        centred = poses[:, 0] - t_c
        return max(scatter, 1e-4), float(centred @ centred)


def _moved(path: np.ndarray, reach: float) -> float:
    """The motion between the two poses ``(2, 3)`` of ``path``: displacement plus ``reach`` times the turn [m]."""
    return math.hypot(*(path[1, :2] - path[0, :2])) + reach * abs(path[1, 2] - path[0, 2])
