"""Altitude for the flyer's controllers: take off to a cruise altitude, then hold it.

The simulated flyer starts landed (altitude 0, or resting on a low obstacle) and takes
``linear.z`` as its climb rate. Low obstacles (OccupancyGrid 50) stand ``0.3 m`` tall in the
simulator: a flyer below that hits them, and its lidar sees them. The built-in controllers
keep it simple and safe: they climb in place to ``cruise_altitude`` and start moving sideways
only once above ``takeoff_altitude`` (over the low obstacles with a margin), where the map's
low obstacles are free space for their planners and out of the scan plane. The altitude comes
from odometry (``pose.pose.position.z``; :attr:`RobotState.z`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TypeVar

from sessgan_controllers.errors import InvalidConfigError
from sessgan_core.validation import require_positive

Decision = TypeVar('Decision')


@dataclass(frozen=True)
class AltitudeHold:
    """A proportional altitude hold with a take-off gate. Metres, seconds."""

    cruise_altitude: float = 0.95
    """Altitude held while flying: the simulator's flight level of other flyers (its
    ``traffic_altitude``), where their scan plane (1.0 m) sees them."""
    takeoff_altitude: float = 0.45
    """No sideways motion below this altitude: above the 0.3 m low obstacles with a margin."""
    climb_gain: float = 1.0
    """Climb rate in m/s per m of altitude error (1/s): with the simulated flyer's 0.3 s
    response lag, nearly critically damped (2.0 overshot the cruise altitude by 6 cm)."""
    max_climb_rate: float = 1.0
    """m/s, up or down."""

    def validate(self) -> None:
        """Raise InvalidConfigError naming the first unusable value."""
        for name in ('cruise_altitude', 'takeoff_altitude', 'climb_gain', 'max_climb_rate'):
            require_positive(name, getattr(self, name), InvalidConfigError)
        if self.takeoff_altitude > self.cruise_altitude:
            raise InvalidConfigError(
                f'takeoff_altitude ({self.takeoff_altitude}) must not exceed cruise_altitude '
                f'({self.cruise_altitude})')

    def climb_rate(self, altitude: float) -> float:
        """Climb rate (m/s) towards the cruise altitude from ``altitude`` (m)."""
        rate = self.climb_gain * (self.cruise_altitude - altitude)
        return max(-self.max_climb_rate, min(self.max_climb_rate, rate))

    def airborne(self, altitude: float) -> bool:
        """Whether the flyer at ``altitude`` (m) is high enough to move sideways."""
        return altitude >= self.takeoff_altitude


def with_climb(decision: Decision, climb: float) -> Decision:
    """A controller's planar ``decision`` (a dataclass with a VelocityCommand ``command``)
    with ``climb`` (m/s) as its command's climb rate."""
    command = dataclasses.replace(decision.command, vz=climb)  # type: ignore[attr-defined]
    return dataclasses.replace(decision, command=command)  # type: ignore[type-var]
