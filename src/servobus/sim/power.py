"""A simulated device's power supply as a fault: a brownout (:class:`PowerCuts`).

Users of these motors report that a supply that sags for a few hundred milliseconds (a shared supply
under a current peak, a loose connector) restarts the drive: it is silent while the supply is low,
then comes back in its power-on state, as if it had just been switched on (issue [field] case 2).

A brownout is a fault of the device model, not of the link (servobus.sim.faults is only the link):
:meth:`PowerCuts.brownout` cuts the supply at ``now_s`` for ``duration_s``. While it is cut the device
neither acts on frames nor transmits (its output is off: the shaft coasts, or a power-off brake
holds it); from ``now_s + duration_s`` on it is the device just powered up (its family's
``reboot`` at that exact time). Sans-IO like the devices: the time is passed in, and the power
comes back when the device is next used (a frame, a poll) at or after the return, as ``reboot`` at
the return time would have left it. Deterministic: the same calls give the same device.

A family's device is a PowerCuts (a :class:`~servobus.sim.device.ListeningDevice` with a supply,
so the counters it adds to are its own base's, not a re-declared copy) and supplies
:meth:`PowerCuts._power_cut` (the output off at the cut) and ``reboot(now_s)`` (its power-on
state); a device with a C twin keeps the twin out of the way while the power is cut (its guard
reads :attr:`PowerCuts.power_back_s`).
"""

from __future__ import annotations

import math

from servobus.sim.device import ListeningDevice

__all__ = ["PowerCuts"]


class PowerCuts(ListeningDevice):
    """The brownout knob of a simulated device (see the module docstring).

    Counters (the device's own ``counters``): ``brownouts`` (cuts), ``unpowered`` (frames and polls
    that met a cut supply), and the family's ``reboots`` when the power came back.
    """

    #: when the power comes back (None: it is on)
    power_back_s: float | None = None

    def brownout(self, now_s: float, duration_s: float) -> None:
        """The supply is cut at ``now_s`` for ``duration_s``: silent meanwhile, then powered up afresh.

        A cut while the power is already off ends at the later of the two returns.

        Raises:
            ValueError: ``duration_s`` is not a positive finite number of seconds.
        """
        if not (duration_s > 0 and math.isfinite(duration_s)):
            raise ValueError(f"duration_s={duration_s!r} must be a positive, finite number of seconds")
        back = self.power_back_s
        if back is not None and now_s >= back:  # the previous cut ended already: power it up first
            self.powered(now_s)
            back = None
        if back is None:
            self._power_cut(now_s)
        self.power_back_s = max(now_s + duration_s, back or -math.inf)
        self._counters["brownouts"] += 1
        self._power_changed()

    def powered(self, now_s: float) -> bool:
        """True when the supply is on at ``now_s`` (after a cut that ended by then, the device is
        powered up at its end first); False, and counted ``unpowered``, while it is cut."""
        back = self.power_back_s
        if back is None:
            return True
        if now_s < back:
            self._counters["unpowered"] += 1
            return False
        self.power_back_s = None
        self.reboot(back)
        self._power_changed()
        return True

    # ---- the family's part ----

    def _power_cut(self, now_s: float) -> None:
        """The supply fails at ``now_s``: the output goes off (as the family's power-off leaves it)."""
        raise NotImplementedError

    def reboot(self, now_s: float) -> None:
        """The device powered up at ``now_s`` (the family's power cycle)."""
        raise NotImplementedError

    def _power_changed(self) -> None:
        """The power changed outside the network's calls: a C twin's guard and the network's view
        of the device are brought up to date (nothing by default)."""
