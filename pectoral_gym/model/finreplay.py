"""The robot's fins replayed on the PC: the stroke phase a fin-observing policy needs, which the robot does not report.

The robot's STATUS message carries no fin angles, but its fins move by known rules
(:mod:`pectoral_gym.model.finrules`: the command as quantised on the wire, clipped to the servo limits, latched at
the next turning point with the rate rule and the transitional stretch, halts). :class:`FinReplay` runs those
rules on the PC, fed the commands the PC sends at the times it sends them, so the robot env
(``pectoral_gym.hardware.env.HardwareFishEnv``) can give the observation's fin block (``observe_fins=True``,
:mod:`pectoral_gym.envs.observation`) and the calibration can replay a run log. The emulator drives its own fins
with the same two functions, :func:`~pectoral_gym.model.finrules.apply_firmware` and
:func:`~pectoral_gym.model.finrules.advance_with_firmware`, under the robot's full state machine.

What the replay cannot see: the radio latency (the robot latches a command a few milliseconds after
the PC sent it) and the firmware's tick (10 ms); a latch may therefore fall one tick apart, and
after a safety stop the fins are taken as halted when the PC learns of it. The fins' angles at
power-up are taken as 90 deg (the firmware's rest). A robot that reports its latches (LATCH messages,
``docs/protocol.md``) removes the first: :meth:`FinReplay.latch` starts the reported half-stroke where and
when the robot says it started (:func:`~pectoral_gym.model.finrules.force_latch`), and the rules infer only what
lies between reports (a lost report, a robot that does not send them). The calibration's replay of a run log uses
it; the live env's fin block does not (it keeps the commands' timing, as the simulated envs a policy trains in:
``docs/hardware.md``).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from pectoral_gym.model import strokes
from pectoral_gym.model.finrules import (
    CHUNK,
    FinState,
    FirmwareConfig,
    apply_firmware,
    force_latch,
    wire_beats,
)
from pectoral_gym.model.models import AveragedModel
from pectoral_gym.model.params import FishParams
from pectoral_gym.model.segment_runs import run_quiet_ticks, run_schedule
from pectoral_gym.model.spec import FULL_REFERENCE

__all__ = ["FinReplay", "warm_up"]


class _ReplayedFirmware(FinState):
    """The firmware as the PC's replay runs it: every command runs until the next one or a stop.

    No lease, watchdog or session: the PC's keep-alives and lease renewals keep the robot running, and when a
    lease or the watchdog stops the robot the PC's supervisor stops the episode, which the replay hears as a stop.
    """

    def __init__(self, config: FirmwareConfig | None = None):
        super().__init__(config)
        self._running = False

    @property
    def running(self) -> bool:
        """Whether the fins are beating (a command arrived since power-up or the last stop)."""
        return self._running

    def tick(self, now: float, fin_angles: np.ndarray | None = None) -> None:
        """The setpoint at ``now`` [s] (no lease or watchdog runs out in the replay)."""
        self.update_setpoint(fin_angles)

    def run(self, beats: np.ndarray, command_id: int) -> None:
        """A new command ``beats`` ``(2, 4)`` (as received) with identity ``command_id``: the fins run it."""
        self.command_id = command_id
        self.accept(beats)
        self._running = True

    def stop(self) -> None:
        """A stop: running fins halt where they are."""
        if self._running:
            self.halt = True
        self._running = False


def _copy_firmware(firmware: _ReplayedFirmware) -> _ReplayedFirmware:
    """A copy of ``firmware`` that shares nothing it changes: what ``copy.deepcopy`` gives, at a fraction of its cost.

    Its arrays are copied (the memo's ``handed`` stays the copy's own ``handed``); the rest are numbers, flags, bytes
    and the settings (frozen), which are replaced, never changed in place.
    """
    clone = copy.copy(firmware)
    for name, value in vars(firmware).items():
        if isinstance(value, np.ndarray):
            setattr(clone, name, value.copy())
    memo = firmware.latch_memo
    if memo is not None and memo[2] is firmware.handed:
        clone.latch_memo = (memo[0], memo[1], clone.handed)
    return clone


class FinReplay:
    """The robot's fins, replayed from the commands the PC sends.

    Times are the PC's experiment clock [robot s] (``HardwareFishEnv.now()``).

    Args:
        params: Model parameters (only the fin kinematics matter).
        firmware: The robot's firmware settings (servo limits).
    """

    def __init__(self, params: FishParams | None = None, firmware: FirmwareConfig | None = None):
        self.firmware_config = firmware
        self.model = FULL_REFERENCE.build(1, params)  # the fins' kinematics: the integration preset does not matter
        self.reset(0.0)

    def reset(self, t: float) -> None:
        """Fins at rest at 90 deg at time ``t`` (power-up, or a new replay)."""
        self.firmware = _ReplayedFirmware(self.firmware_config)
        self.model.reset()
        self.model.time = float(t)
        self._command = 0

    def checkpoint(self) -> tuple[Any, ...]:
        """The replay's whole state (firmware, fins, body, clock, command identity), for :meth:`restore`.

        A look-ahead (a provisional stretch run past what is known) runs from a checkpoint and restores it.
        """
        model = self.model
        return (_copy_firmware(self.firmware), model.fins.copy(), model.pending.copy(), model.state.copy(),
                model.integral.copy(), model.forcing_cache.copy(), model.time, self._command)

    def restore(self, checkpoint: tuple[Any, ...]) -> None:
        """Put the replay back as :meth:`checkpoint` found it (the checkpoint may be restored once)."""
        model = self.model
        self.firmware = checkpoint[0]
        model.fins[:], model.pending[:], model.state[:], model.integral[:], model.forcing_cache[:] = checkpoint[1:6]
        model.time, self._command = checkpoint[6:]

    def command(self, t: float, beats: np.ndarray) -> None:
        """The PC sent a new command ``beats`` ``(2, 4)`` at time ``t``; the robot runs it as quantised on the wire.

        The replay keeps it running until :meth:`stop` or the next command: the PC's keep-alives and
        lease renewals keep the robot running, and when a lease or the watchdog stops the robot the
        PC's supervisor stops the episode, which calls :meth:`stop`.

        Raises:
            ValueError: If a value does not fit the wire format (:func:`~pectoral_gym.model.finrules.fin_words`).
        """
        self.advance(t)
        received = wire_beats(beats)
        self._command = (self._command + 1) & 0xFFFF  # the wire's command identity
        self.firmware.run(received, self._command)

    def stop(self, t: float) -> None:
        """The fins were stopped at time ``t`` (STOP, a safety trip): they halt where they are."""
        self.advance(t)
        self.firmware.stop()
        apply_firmware(self.firmware, self.model)  # the halt, now

    def latch(self, t: float, fin: int, beat: np.ndarray, turn: float, power: bool) -> bool:
        """The robot reported that fin ``fin`` latched ``beat`` at angle ``turn`` at time ``t`` (a LATCH).

        The replay runs to ``t`` and starts that half-stroke (:func:`~pectoral_gym.model.finrules.force_latch`); a
        report that comes after the replay passed ``t`` starts it as far in as the replay is. What the firmware
        commands next is inferred as before. Ignored while the replayed fins are halted (a report from just before
        the robot heard a stop, mapped after it: the fins are still now). Returns whether the report was applied.
        """
        self.advance(t)
        if not self.firmware.running:
            return False
        force_latch(self.model, fin, t, beat, turn, power)
        return True

    def advance(self, t: float) -> None:
        """Run the fins to time ``t`` (earlier times are ignored).

        The ticks of :func:`~pectoral_gym.model.finrules.advance_with_firmware`: each tick the firmware's setpoint,
        its decision handed to the fins (:func:`~pectoral_gym.model.finrules.apply_firmware`), the model advanced
        by :data:`~pectoral_gym.model.finrules.CHUNK`. Where a tick's decision would be skipped at the following
        ticks too (:meth:`_rules_rest`: the command runs, and the fin rules' inputs stay as they are until a turning
        point changes a half-stroke's pattern), those ticks' advances run in one compiled call up to that turning
        point (:func:`~pectoral_gym.model.segment_runs.run_quiet_ticks`), bit for bit the same.
        """
        target, firmware, model = float(t), self.firmware, self.model
        while model.time < target:
            # (the angles are read only by fins not running: the setpoint of halted fins is rest where they are)
            firmware.tick(model.time, None if firmware.running else model.fin_angles()[0][0])
            apply_firmware(firmware, model)
            if self._rules_rest():
                run_quiet_ticks(model, target, CHUNK)
            else:
                model.advance(min(CHUNK, target - model.time))

    def _rules_rest(self) -> bool:
        """Whether the next ticks' rules return at once while the fins' fields ``DURATION``..``RATIO`` keep their bits.

        The rules: :func:`~pectoral_gym.model.finrules.apply_firmware`.
        It does when its memo holds now for a running command: a tick's setpoint is then the command again (the
        same bits: nothing between ticks changes the command, the running state or the halt), and the memo's other
        keys (the limits, the pattern handed and its command) change only where the rules run.
        """
        firmware, memo = self.firmware, self.firmware.latch_memo
        if memo is None or firmware.halt or not firmware.running or firmware.command_id != firmware.handed_id:
            return False
        if memo[1] is not firmware.config.limits or memo[2] is not firmware.handed:
            return False
        return memo[0] == (firmware.setpoint.tobytes(),
                           self.model.fins[0, :, strokes.DURATION:strokes.RATIO + 1].tobytes())

    @property
    def fins(self) -> np.ndarray:
        """``(1, 2, strokes.FIN_FIELDS)`` the replayed half-strokes in progress (:mod:`pectoral_gym.model.strokes`)."""
        return self.model.fins


def warm_up() -> None:
    """Compile (or load) the kernels the fins' replays and the liveness check's paths call, for the types they pass.

    For the kernel bundle's build (:mod:`pectoral_gym.tools.kernel_bundle`), whose env steps do not reach them: a
    replay running a command (the blade-element model's quiet ticks,
    :func:`~pectoral_gym.model.segment_runs.run_quiet_ticks`) and one
    :func:`~pectoral_gym.model.segment_runs.run_schedule` of each model (one fish, one snapshot).
    """
    replay = FinReplay()
    replay.command(0.0, np.array([[0.0, 0.5, 1.0, 0.5], [0.0, 0.5, 1.0, 0.5]]))
    replay.advance(1.5)
    for model in (AveragedModel(n=1), FULL_REFERENCE.build(1, None)):
        run_schedule(model, np.array([0.0]), model.fins[None].copy(), model.pending[None].copy(), 0.0,
                     np.array([0.1, 0.2]))
