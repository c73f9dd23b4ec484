"""The PC's view of the radio's timing: round-trip estimate (retry timeout) and a lower bound of the robot's clock.

:class:`RttEstimator` is Jacobson/Karels (RFC 6298): ``SRTT``, ``RTTVAR``, retry timeout
``SRTT + max(G, 4 RTTVAR)`` within bounds; the caller applies Karn's rule (no sample from a message that was re-sent).

:class:`RobotClock` turns the robot's STATUS uptimes into a *lower bound* of the robot's clock at any PC
time, so a SET_FINS can carry a deadline on the robot's clock that no copy, however late, can overrun
(``docs/protocol.md``, "Deadline"): a STATUS's ``uptime`` was read before the STATUS left the robot, so
when it arrives at PC time ``t_rx`` the robot's clock reads at least ``uptime``, and ``t - t_rx`` later at
least ``uptime + (t - t_rx) * speed * (1 - tolerance)``, with ``tolerance`` the largest relative rate error
of the robot's oscillator against the PC's clock. The best bound is the largest over recent samples.
:meth:`RobotClock.pc_time` maps the other way, for the robot's reports (LATCH): the PC time at which the
robot's clock read a given uptime, the middle of the narrowest interval the samples leave for it (NTP's
midpoint: exact when the radio's two directions are equally slow).
"""

from __future__ import annotations

import math
from collections import deque

__all__ = ["RttEstimator", "RobotClock", "CLOCK_TOLERANCE", "RENEWAL_INTERVAL", "renewal_lease"]

# Largest relative rate error of the robot's clock against the PC's: a dsPIC on its internal FRC oscillator
# is specified to +-2 % over temperature (a crystal: +-50 ppm). Costs at most 2 % of (lease + sample age) of
# run time, ~20 ms at the default 0.8 s lease.
CLOCK_TOLERANCE = 0.02


# Renewals of a step's command while step() runs, when the deadline would halt the fins before the step's lease
# ends (docs/protocol.md, "Renewal"): at most one per this [s], as often as the keep-alive's copies.
RENEWAL_INTERVAL = 0.1
# What the robot's deadline may fall short of ``horizon - round trip`` after the call besides the return latency:
# the rate tolerance over the horizon and the sample's age (2 % of ~1.5 s), the firmware's 10 ms tick, the ms floor.
_DEADLINE_SHORTFALL = 0.05


def renewal_lease(now: float, sent: float, lease_end: float, horizon: float, rtt: float | None,
                  interval: float = RENEWAL_INTERVAL) -> float | None:
    """The lease [s] of the step's command sent anew at ``now`` to outlast its deadline, or ``None`` if none is due.

    A command's deadline (``horizon`` after its ``set_fins()`` on a lower bound of the robot's clock) halts the
    fins as early as ``horizon - rtt`` after the call: the bound runs behind the robot's clock by the return
    latency, at most the round trip. When that comes before the step's lease ends (``lease_end``), the same
    fins are sent again by a new ``set_fins()``, with the deadline counted from now and the lease that is left
    (``lease_end - now``, rounded down to the wire's ms): the lease ends where the step's did, and no copy of
    any call runs more than ``horizon`` after it. Only while ``step()`` runs: a PC that stops calling it still
    stops the fins by the step's lease.

    Args:
        now: The time [s] (experiment time, as the other times).
        sent: When the step's command, or its last renewal, was sent [s].
        lease_end: When the step's lease ends [s] (its ``set_fins()`` time plus the lease).
        horizon: The deadline's horizon [s] (``RadioLink.deadline_horizon``).
        rtt: The measured round trip [s] (``None``: not measured, no deadline is sent either).
        interval: Least time between renewals [s].
    """
    if rtt is None or now - sent < interval:
        return None
    if sent + horizon - rtt - _DEADLINE_SHORTFALL >= lease_end:
        return None  # the deadline does not halt the fins before the lease would
    lease = math.floor((lease_end - now) * 1000.0) / 1000.0
    return lease if lease >= interval else None


class RttEstimator:
    """Smoothed round trip and retry timeout (RFC 6298: alpha 1/8, beta 1/4, K = 4, granularity ``low``).

    Args:
        initial: Retry timeout before the first sample [s].
        low: Smallest retry timeout [s].
        high: Largest retry timeout [s].
    """

    def __init__(self, initial: float, low: float, high: float):
        if not 0 < low <= high or not math.isfinite(high) or not initial > 0:
            raise ValueError(f"RttEstimator: need 0 < low <= high < inf and initial > 0, got {low}, {high}, {initial}")
        self.initial, self.low, self.high = float(initial), float(low), float(high)
        self.srtt: float | None = None
        self.rttvar = 0.0
        self.samples = 0

    def update(self, rtt: float) -> None:
        """Add one round-trip sample [s] (of a message sent once only)."""
        if not (math.isfinite(rtt) and rtt >= 0):
            return
        if self.srtt is None:
            self.srtt, self.rttvar = rtt, rtt / 2
        else:
            self.rttvar = 0.75 * self.rttvar + 0.25 * abs(self.srtt - rtt)
            self.srtt = 0.875 * self.srtt + 0.125 * rtt
        self.samples += 1

    def timeout(self) -> float:
        """Current retry timeout [s]: ``SRTT + 4 RTTVAR`` within ``[low, high]`` (``initial`` before any sample)."""
        # RFC 6298's SRTT + max(G, K RTTVAR), with ``low`` as the granularity G: a steady link (RTTVAR -> 0)
        # must not time out half of its answers.
        value = self.initial if self.srtt is None else self.srtt + max(self.low, 4.0 * self.rttvar)
        return min(max(value, self.low), self.high)


class RobotClock:
    """A lower bound of the robot's clock (uptime of its current boot) at PC times.

    Args:
        tolerance: Largest relative rate error of the robot's clock against the PC's.
        window: Samples older than this [PC s] are dropped (the newest is always kept).
        size: Most samples kept.
    """

    def __init__(self, tolerance: float = CLOCK_TOLERANCE, window: float = 5.0, size: int = 64):
        if not 0 <= tolerance < 1:
            raise ValueError(f"RobotClock: tolerance must be in [0, 1), got {tolerance!r}")
        self.tolerance, self.window = float(tolerance), float(window)
        self.boot: int | None = None
        # (PC time of arrival [s], uptime [robot s], PC time the answered message left [s] or -inf if not known)
        self._samples: deque[tuple[float, float, float]] = deque(maxlen=size)

    def clear(self) -> None:
        """Forget every sample (the robot rebooted)."""
        self.boot = None
        self._samples.clear()

    def add(self, boot: int, uptime_ms: int, t_rx: float, t_sent: float | None = None) -> None:
        """A STATUS of boot ``boot`` reporting ``uptime_ms`` arrived at PC time ``t_rx`` [s].

        Args:
            boot: The robot's boot id.
            uptime_ms: The robot's clock when it sent the STATUS [ms].
            t_rx: PC time the STATUS arrived [s].
            t_sent: PC time the message this STATUS answers was sent [s] (its only copy), if known: the robot
                read ``uptime_ms`` after that message reached it, which bounds the clock from the other side.
        """
        if boot != self.boot:
            self.clear()
            self.boot = boot
        self._samples.append((float(t_rx), uptime_ms / 1000.0, -math.inf if t_sent is None else float(t_sent)))
        while len(self._samples) > 1 and t_rx - self._samples[0][0] > self.window:
            self._samples.popleft()

    @property
    def synced(self) -> bool:
        """Whether there is at least one sample."""
        return bool(self._samples)

    def lower_bound(self, t: float, speed: float = 1.0) -> float | None:
        """Robot seconds the robot's clock reads at least at PC time ``t`` (``None`` without samples).

        Args:
            t: PC time [s], not before the samples.
            speed: Nominal robot seconds per PC second (an accelerated emulator's ``speed``).
        """
        rate = speed * (1.0 - self.tolerance)
        return max((u + max(t - t_rx, 0.0) * rate for t_rx, u, _ in self._samples), default=None)

    def pc_time(self, boot: int, uptime_ms: int, speed: float = 1.0, span: float = 1.0) -> float | None:
        """The PC time [s] at which the robot's clock (boot ``boot``) read ``uptime_ms``; ``None`` if not known.

        Every STATUS puts the robot's clock offset (PC time minus robot time) at most ``t_rx - uptime / speed``
        (its uptime was read before it left); one that answers a message sent once at ``t_sent`` puts it at
        least ``t_sent - uptime / speed`` (read after that message arrived). Over the samples within ``span``
        robot seconds of ``uptime_ms`` the tightest of each bound leave an interval; its middle is the estimate
        (NTP's midpoint), off by at most half the width of that interval plus the clock's rate error over
        ``span`` (``tolerance * span`` at worst), and exact when the radio's two directions are equally slow.
        Without an answered sample it is the upper bound: late by the fastest return latency (100 ms behind a
        radio 100 ms slow each way, which put a live replay of the fins a tenth of a second behind the robot's).
        Not a bound in either direction: for logs and replays, never for safety.

        Args:
            boot: The boot id the uptime is of (``None`` is returned for another boot than the samples').
            uptime_ms: The robot's clock [ms].
            speed: Nominal robot seconds per PC second (an accelerated emulator's ``speed``).
            span: Samples whose uptime is this close [robot s] count (all samples if none is).
        """
        if boot != self.boot or not self._samples:
            return None
        u = uptime_ms / 1000.0
        near = [sample for sample in self._samples if abs(sample[1] - u) <= span] or list(self._samples)
        high = min(t_rx - v / speed for t_rx, v, _ in near)
        low = max(t_sent - v / speed for _, v, t_sent in near)
        return u / speed + (high if low == -math.inf else 0.5 * (low + high))

    def deadline_ms(self, t: float, speed: float = 1.0) -> int:
        """The SET_FINS ``deadline`` for a command that must stop by PC time ``t``: u32 ms, 0 if not synced."""
        bound = self.lower_bound(t, speed)
        if bound is None:
            return 0
        return max(1, int(math.floor(bound * 1000.0))) & 0xFFFFFFFF or 1
