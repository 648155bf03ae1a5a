"""Robot models under test: a registry of planar robots with real dynamics.

Every robot takes a body-frame velocity command like geometry_msgs/Twist
(:class:`BodyCommand`: linear.x, linear.y, angular.z) and turns it into
motion through its own dynamics:

* ``diff_drive``: a differential-drive cylinder. linear.x is the forward speed,
  angular.z the yaw rate, each under speed and acceleration limits; linear.y is
  ignored (it cannot move sideways).
* ``tricycle``: the differential drive's body, speeds and accelerations on a steered
  drive wheel (a tugger or forklift AGV whose steering stops short of 90 degrees): its
  yaw rate is at most ``|forward speed| / min_turn_radius``, so it cannot turn in place
  and needs room to turn.
* ``car``: a kinematic bicycle (rear-axle reference) with a steering angle
  limit, a steering rate limit, separate acceleration and braking limits and a
  high top speed. angular.z is turned into a steering angle through the bicycle
  model, ``delta = atan(wheelbase * wz / vx)`` at the *commanded* speed (the
  Twist-to-Ackermann convention); at standstill a non-zero wz asks for full
  lock. The tyres' grip caps the lateral acceleration: beyond it the car
  understeers (its yaw rate saturates at grip / speed), so a sharp turn taken
  too fast runs wide into the barrier. linear.y is ignored.
* ``flyer``: a holonomic flyer with altitude. linear.x and linear.y are body-frame
  velocities, linear.z the climb rate (m/s, up positive), angular.z the yaw rate; the
  velocity follows the command through a first-order lag (its response time) under
  acceleration limits, a top speed and a top climb rate. Its **altitude** is the height of
  the body's underside above the ground, between 0 (on the ground) and ``max_altitude``
  (walls are taller, see :class:`sessgan_sim.world.WorldStyle`). It starts landed at the
  start pose: on the ground, or resting on top of a low obstacle that lies under its
  footprint. At any altitude it may move sideways (at 0 it skims the ground); a low
  obstacle it flies into below the obstacle's height is a contact like a wall.

How the dynamics are integrated: each physics step the model advances its state
(speed, steering, ...) toward the command and sets the body's velocity; pybullet
then resolves contacts, so a wall stops or deflects the robot. After the step
the model reads the body's real velocity back, so a robot pressed against a
wall does not keep a speed it does not have. Gravity is off: ground robots ride at a
fixed height and the flyer at its model's altitude (the model sets the vertical
velocity too); contact-induced tilt and height drift are removed after each step.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import pybullet as p

from sessgan_core.environment import Pose2D
from sessgan_core.quaternion import quaternion_from_yaw, yaw_from_quaternion
from sessgan_core.scenarios import FREE, LOW_OBSTACLE
from sessgan_core.validation import require_positive
from sessgan_sim.errors import InvalidConfigError, UnknownRobotError
from sessgan_sim.world import ROBOT_MASK, CollisionGroup

DRIFT_TOLERANCE = 1e-4
"""Height (m) or quaternion tilt component above which a body is put back upright."""

TILT_INERTIA_FACTOR = 1000.0
"""Roll and pitch inertia multiplier: contacts must not tip a planar robot over."""


class BodyCommand(NamedTuple):
    """A body-frame velocity command, as geometry_msgs/Twist carries it, that the simulated
    body executes (a controller's answer is sessgan_controllers' VelocityCommand)."""

    vx: float = 0.0
    """linear.x in m/s (forward)."""
    vy: float = 0.0
    """linear.y in m/s (left); only the flyer uses it."""
    wz: float = 0.0
    """angular.z in rad/s (counter-clockwise)."""
    vz: float = 0.0
    """linear.z in m/s (up); only the flyer uses it."""


STOP = BodyCommand()


class BodyState(NamedTuple):
    """Pose in the map frame and twist in the body frame of the simulated body (what a
    controller sees of it is sessgan_controllers' RobotState)."""

    x: float
    y: float
    yaw: float
    vx: float
    vy: float
    wz: float
    z: float = 0.0
    """Altitude in m: the body's underside above the ground (0 for ground robots)."""
    vz: float = 0.0
    """Climb rate in m/s."""


def _clip(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


def _check_positive(owner: str, params: Any, names: tuple[str, ...]) -> None:
    for name in names:
        require_positive(f'{owner}: {name}', getattr(params, name), InvalidConfigError)


class Robot(abc.ABC):
    """A planar robot body in a pybullet world, driven by velocity commands.

    Subclasses set ``name``, ``params_type`` and the model hooks; the base class owns
    the pybullet body and the per-step read-back.
    """

    name: ClassVar[str]
    params_type: ClassVar[type]
    flies: ClassVar[bool] = False
    passable_values: ClassVar[tuple[int, ...]] = (FREE,)
    """OccupancyGrid values the robot's centre may stand on."""

    def __init__(self, params: Any = None) -> None:
        self.params = params if params is not None else self.params_type()
        if not isinstance(self.params, self.params_type):
            raise InvalidConfigError(f'robot {self.name!r} takes {self.params_type.__name__}, '
                                     f'got {type(self.params).__name__}')
        self.validate()
        self.client = -1
        self.body_id = -1
        self._x = self._y = self._yaw = 0.0
        self._cos_yaw, self._sin_yaw = 1.0, 0.0
        self._vx = self._vy = self._wz = 0.0
        self._altitude = self._climb_rate = 0.0

    @classmethod
    def with_overrides(cls, overrides: Mapping[str, float] | None = None) -> Robot:
        """A robot whose default parameters are replaced by ``overrides``."""
        known = {item.name for item in dataclasses.fields(cls.params_type)}
        unknown = sorted(set(overrides or {}) - known)
        if unknown:
            raise InvalidConfigError(f'robot {cls.name!r} has no parameter(s) {unknown}; '
                                     f'known: {sorted(known)}')
        return cls(dataclasses.replace(cls.params_type(), **dict(overrides or {})))

    # --- geometry, supplied by each model -------------------------------------------------

    @property
    @abc.abstractmethod
    def footprint_radius(self) -> float:
        """Radius (m) of the smallest circle around the centre holding the footprint."""

    @property
    @abc.abstractmethod
    def ride_height(self) -> float:
        """Height (m) of the body's centre above the ground."""

    @property
    @abc.abstractmethod
    def sensor_height(self) -> float:
        """Height (m) of the lidar's scan plane above the robot's underside at altitude 0 (the
        ground for ground robots): ``base_scan`` above ``base_footprint``."""

    @property
    def traffic_height(self) -> float:
        """Height (m) of the centre of the moving agents sharing the robot's space: its own
        ride height for ground robots."""
        return self.ride_height

    @property
    def altitude(self) -> float:
        """Height (m) of the body's underside above the ground after the last step: 0 for
        ground robots; ``base_footprint``'s z in the odom frame."""
        return self._altitude

    @property
    def vertical_extent(self) -> tuple[float, float]:
        """Heights (m) of the body's underside and top above the ground now."""
        half = float(self.params.height) / 2  # every model's params have a body height
        centre = self.ride_height + self._altitude
        return centre - half, centre + half

    @property
    def scan_height(self) -> float:
        """Height (m) of the scan plane above the ground now."""
        return self._altitude + self.sensor_height

    def start_altitude(self, support_height: float) -> float:
        """Altitude (m) to spawn at when the tallest obstacle under the start footprint is
        ``support_height`` m tall: 0 for ground robots (they never stand on obstacles)."""
        return 0.0

    @abc.abstractmethod
    def validate(self) -> None:
        """Raise InvalidConfigError naming the first unusable parameter."""

    @abc.abstractmethod
    def _create_shape(self, client: int) -> int:
        """Create the body's collision shape in ``client``; return its id."""

    @property
    @abc.abstractmethod
    def mass(self) -> float:
        """Mass in kg."""

    @property
    @abc.abstractmethod
    def top_speed(self) -> float:
        """Fastest forward speed in m/s."""

    # --- dynamics, supplied by each model -------------------------------------------------

    @abc.abstractmethod
    def _reset_model(self) -> None:
        """Zero the model's internal state (speeds, steering)."""

    @abc.abstractmethod
    def _advance(self, command: BodyCommand, dt: float) -> tuple[float, float, float]:
        """Advance the model by ``dt`` seconds toward ``command``; return the body-frame
        velocity (vx, vy, wz) of the body's centre to impose for this step."""

    @abc.abstractmethod
    def _observe(self, vx: float, vy: float, wz: float) -> None:
        """Take the body's real body-frame velocity after a step back into the model."""

    def _advance_altitude(self, command: BodyCommand, dt: float) -> float:
        """Advance the altitude model by ``dt`` seconds toward ``command``; return the
        vertical velocity (m/s) to impose for this step. Ground robots do not climb."""
        return 0.0

    # --- the body ------------------------------------------------------------------------

    def spawn(self, client: int, pose: Pose2D, altitude: float = 0.0) -> int:
        """Create the robot's body in ``client`` at ``pose`` and ``altitude`` m (the flyer's;
        ground robots stay on the ground), at rest; return the body id."""
        self._altitude = float(altitude) if self.flies else 0.0
        self._climb_rate = 0.0
        shape = self._create_shape(client)
        orientation = p.getQuaternionFromEuler([0.0, 0.0, pose.yaw])
        body = p.createMultiBody(self.mass, shape,
                                 basePosition=[pose.x, pose.y,
                                               self.ride_height + self._altitude],
                                 baseOrientation=orientation, physicsClientId=client)
        inertia = p.getDynamicsInfo(body, -1, physicsClientId=client)[2]
        p.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0, restitution=0.0,
                         lateralFriction=0.5,
                         localInertiaDiagonal=[inertia[0] * TILT_INERTIA_FACTOR,
                                               inertia[1] * TILT_INERTIA_FACTOR, inertia[2]],
                         physicsClientId=client)
        p.setCollisionFilterGroupMask(body, -1, int(CollisionGroup.ROBOT), ROBOT_MASK,
                                      physicsClientId=client)
        self.client = client
        self.body_id = body
        self._x, self._y, self._yaw = float(pose.x), float(pose.y), float(pose.yaw)
        self._cos_yaw, self._sin_yaw = math.cos(self._yaw), math.sin(self._yaw)
        self._vx = self._vy = self._wz = 0.0
        self._reset_model()
        return body

    def apply(self, command: BodyCommand, dt: float) -> None:
        """Advance the model by one physics step of ``dt`` s and set the body's velocity."""
        vx, vy, wz = self._advance(command, dt)
        vz = self._advance_altitude(command, dt) if self.flies else 0.0
        cos_yaw, sin_yaw = self._cos_yaw, self._sin_yaw
        p.resetBaseVelocity(self.body_id,
                            [cos_yaw * vx - sin_yaw * vy, sin_yaw * vx + cos_yaw * vy, vz],
                            [0.0, 0.0, wz], physicsClientId=self.client)

    def sync(self) -> None:
        """Read the body's pose and velocity after a physics step into the robot state."""
        client = self.client
        position, (qx, qy, qz, qw) = p.getBasePositionAndOrientation(self.body_id,
                                                                     physicsClientId=client)
        linear, angular = p.getBaseVelocity(self.body_id, physicsClientId=client)
        x, y, z = position
        yaw = yaw_from_quaternion(qx, qy, qz, qw)
        if self.flies:
            self._observe_altitude(z - self.ride_height, linear[2])
        height = self.ride_height + self._altitude
        if (abs(z - height) > DRIFT_TOLERANCE or abs(qx) > DRIFT_TOLERANCE
                or abs(qy) > DRIFT_TOLERANCE):
            p.resetBasePositionAndOrientation(
                self.body_id, [x, y, height],
                quaternion_from_yaw(yaw), physicsClientId=client)
        cos_yaw, sin_yaw = math.cos(yaw), math.sin(yaw)
        self._x, self._y, self._yaw = x, y, yaw
        self._cos_yaw, self._sin_yaw = cos_yaw, sin_yaw
        self._vx = cos_yaw * linear[0] + sin_yaw * linear[1]
        self._vy = -sin_yaw * linear[0] + cos_yaw * linear[1]
        self._wz = angular[2]
        self._observe(self._vx, self._vy, self._wz)

    def _observe_altitude(self, altitude: float, climb_rate: float) -> None:
        """Take the body's altitude and vertical velocity after a step (fliers only)."""

    @property
    def state(self) -> BodyState:
        """Pose (map frame), body-frame twist, altitude and climb rate after the last step."""
        return BodyState(self._x, self._y, self._yaw, self._vx, self._vy, self._wz,
                          self._altitude, self._climb_rate)

    @property
    def position(self) -> tuple[float, float]:
        return self._x, self._y


ROBOTS: dict[str, type[Robot]] = {}
"""The robot registry: name -> Robot subclass."""


def register_robot(cls: type[Robot]) -> type[Robot]:
    """Class decorator adding a Robot subclass to the registry under ``cls.name``."""
    ROBOTS[cls.name] = cls
    return cls


def robot_names() -> list[str]:
    """Names of the registered robots, sorted."""
    return sorted(ROBOTS)


def get_robot_class(name: str) -> type[Robot]:
    """Look a robot model up by name; the error lists the known names."""
    try:
        return ROBOTS[name]
    except KeyError as err:
        raise UnknownRobotError(
            f'unknown robot {name!r}; known robots: {", ".join(robot_names())}') from err


def create_robot(name: str, overrides: Mapping[str, float] | None = None) -> Robot:
    """A robot of model ``name`` with default parameters replaced by ``overrides``."""
    return get_robot_class(name).with_overrides(overrides)


# --- differential drive ---------------------------------------------------------------------


@dataclass(frozen=True)
class DiffDriveParams:
    """A factory robot (TurtleBot-like footprint, AMR-like speeds)."""

    radius: float = 0.2
    height: float = 0.3
    mass: float = 10.0
    ground_clearance: float = 0.01
    sensor_height: float = 0.2
    max_linear_speed: float = 1.0
    """m/s forward."""
    max_reverse_speed: float = 0.3
    """m/s backward."""
    max_angular_speed: float = 2.0
    """rad/s."""
    max_linear_acceleration: float = 1.0
    """m/s^2, speeding up and slowing down."""
    max_angular_acceleration: float = 4.0
    """rad/s^2."""


@register_robot
class DiffDriveRobot(Robot):
    """Differential drive: forward speed and yaw rate, no sideways motion."""

    name = 'diff_drive'
    params_type = DiffDriveParams
    params: DiffDriveParams

    def validate(self) -> None:
        _check_positive(self.name, self.params, (
            'radius', 'height', 'mass', 'sensor_height', 'max_linear_speed',
            'max_reverse_speed', 'max_angular_speed', 'max_linear_acceleration',
            'max_angular_acceleration'))

    @property
    def footprint_radius(self) -> float:
        return self.params.radius

    @property
    def ride_height(self) -> float:
        return self.params.ground_clearance + self.params.height / 2

    @property
    def sensor_height(self) -> float:
        return self.params.sensor_height

    @property
    def mass(self) -> float:
        return self.params.mass

    @property
    def top_speed(self) -> float:
        return self.params.max_linear_speed

    def _create_shape(self, client: int) -> int:
        return p.createCollisionShape(p.GEOM_CYLINDER, radius=self.params.radius,
                                      height=self.params.height, physicsClientId=client)

    def _reset_model(self) -> None:
        self._speed = 0.0
        self._turn_rate = 0.0

    def _advance(self, command: BodyCommand, dt: float) -> tuple[float, float, float]:
        params = self.params
        target_speed = _clip(command.vx, -params.max_reverse_speed, params.max_linear_speed)
        target_rate = _clip(command.wz, -params.max_angular_speed, params.max_angular_speed)
        step = params.max_linear_acceleration * dt
        self._speed += _clip(target_speed - self._speed, -step, step)
        step = params.max_angular_acceleration * dt
        self._turn_rate += _clip(target_rate - self._turn_rate, -step, step)
        return self._speed, 0.0, self._turn_rate

    def _observe(self, vx: float, vy: float, wz: float) -> None:
        # Wheels do not slide sideways: only the forward part of a deflection survives.
        self._speed = vx
        self._turn_rate = wz


@dataclass(frozen=True)
class TricycleParams(DiffDriveParams):
    """The factory robot on a steered drive wheel instead of two driven wheels."""

    min_turn_radius: float = 0.5
    """m, tightest turn of the robot's centre (at any speed): no turning in place."""


@register_robot
class TricycleRobot(DiffDriveRobot):
    """Differential-drive body and limits, but turning only while moving: the yaw rate is
    capped at the current forward speed / ``min_turn_radius``."""

    name = 'tricycle'
    params_type = TricycleParams
    params: TricycleParams

    def validate(self) -> None:
        super().validate()
        _check_positive('tricycle', self.params, ('min_turn_radius',))

    def _advance(self, command: BodyCommand, dt: float) -> tuple[float, float, float]:
        speed, _, turn_rate = super()._advance(command, dt)
        limit = abs(speed) / self.params.min_turn_radius
        self._turn_rate = _clip(turn_rate, -limit, limit)
        return speed, 0.0, self._turn_rate


# --- car (bicycle model) --------------------------------------------------------------------


@dataclass(frozen=True)
class CarParams:
    """A small race car (footprint inside the race track's 0.6 m radius)."""

    length: float = 1.0
    width: float = 0.5
    height: float = 0.35
    mass: float = 40.0
    ground_clearance: float = 0.05
    sensor_height: float = 0.2
    wheelbase: float = 0.7
    """m between the axles; the body's centre is halfway between them."""
    max_steering_angle: float = 0.5
    """rad (about 29 degrees)."""
    max_steering_rate: float = 1.5
    """rad/s."""
    max_speed: float = 12.0
    """m/s forward."""
    max_reverse_speed: float = 3.0
    """m/s backward."""
    max_acceleration: float = 4.0
    """m/s^2 when speeding up."""
    max_braking: float = 8.0
    """m/s^2 when slowing down."""
    max_lateral_acceleration: float = 8.0
    """m/s^2 the tyres can hold in a turn (about 0.8 g); beyond it the car understeers."""


@register_robot
class CarRobot(Robot):
    """Kinematic bicycle with steering and grip limits."""

    name = 'car'
    params_type = CarParams
    params: CarParams

    def validate(self) -> None:
        _check_positive('car', self.params, (
            'length', 'width', 'height', 'mass', 'sensor_height', 'wheelbase',
            'max_steering_angle', 'max_steering_rate', 'max_speed', 'max_reverse_speed',
            'max_acceleration', 'max_braking', 'max_lateral_acceleration'))
        if self.params.max_steering_angle >= math.pi / 2:
            raise InvalidConfigError(f'car: max_steering_angle must be < pi/2 rad, got '
                                     f'{self.params.max_steering_angle}')

    @property
    def footprint_radius(self) -> float:
        return math.hypot(self.params.length / 2, self.params.width / 2)

    @property
    def ride_height(self) -> float:
        return self.params.ground_clearance + self.params.height / 2

    @property
    def sensor_height(self) -> float:
        return self.params.sensor_height

    @property
    def mass(self) -> float:
        return self.params.mass

    @property
    def top_speed(self) -> float:
        return self.params.max_speed

    @property
    def steering_angle(self) -> float:
        """Current steering angle in rad (positive = left)."""
        return self._steering

    def _create_shape(self, client: int) -> int:
        params = self.params
        return p.createCollisionShape(
            p.GEOM_BOX, halfExtents=[params.length / 2, params.width / 2, params.height / 2],
            physicsClientId=client)

    def _reset_model(self) -> None:
        self._speed = 0.0
        self._steering = 0.0

    def target_steering(self, command: BodyCommand) -> float:
        """Steering angle (rad) that turns at ``command.wz`` when driving at ``command.vx``."""
        params = self.params
        speed = command.vx
        angle = math.atan2(params.wheelbase * command.wz, abs(speed))
        if speed < 0:
            angle = -angle
        return _clip(angle, -params.max_steering_angle, params.max_steering_angle)

    def _advance(self, command: BodyCommand, dt: float) -> tuple[float, float, float]:
        params = self.params
        step = params.max_steering_rate * dt
        self._steering += _clip(self.target_steering(command) - self._steering, -step, step)
        target = _clip(command.vx, -params.max_reverse_speed, params.max_speed)
        speed = self._speed
        braking = (speed > 0 and target < speed) or (speed < 0 and target > speed)
        step = (params.max_braking if braking else params.max_acceleration) * dt
        new_speed = speed + _clip(target - speed, -step, step)
        if braking and speed * new_speed < 0:
            new_speed = 0.0  # brakes stop the car; reversing is a new acceleration
        self._speed = new_speed
        yaw_rate = new_speed * math.tan(self._steering) / params.wheelbase
        if new_speed != 0.0:
            grip_limit = params.max_lateral_acceleration / abs(new_speed)
            yaw_rate = _clip(yaw_rate, -grip_limit, grip_limit)
        # The centre lies half a wheelbase ahead of the rear axle: it swings sideways.
        return new_speed, yaw_rate * params.wheelbase / 2, yaw_rate

    def _observe(self, vx: float, vy: float, wz: float) -> None:
        self._speed = vx


# --- flyer ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class FlyerParams:
    """A small quadrotor with altitude control."""

    radius: float = 0.2
    height: float = 0.1
    mass: float = 1.5
    max_altitude: float = 1.5
    """m, highest altitude (the body's underside above the ground); walls must be taller than
    ``max_altitude + height`` (the episode checks it against the world's wall height)."""
    traffic_altitude: float = 0.95
    """m, the altitude the other flyers (dummy agents) fly at: their centres at
    ``traffic_altitude + height / 2`` (1.0 m), the scan plane of a flyer cruising there."""
    max_speed: float = 2.0
    """m/s, horizontal."""
    max_acceleration: float = 3.0
    """m/s^2, horizontal."""
    max_climb_rate: float = 1.0
    """m/s, up or down: linear.z is clipped to it."""
    max_vertical_acceleration: float = 2.0
    """m/s^2."""
    response_time: float = 0.3
    """s, time constant of the first-order lag from commanded to actual velocity."""
    max_yaw_rate: float = 2.0
    """rad/s."""
    max_yaw_acceleration: float = 6.0
    """rad/s^2."""


START_SUPPORT_GAP = 0.005
"""m between a flyer that starts on top of a low obstacle and the obstacle: resting on it,
not touching it (a touch would count as a collision)."""


@register_robot
class FlyerRobot(Robot):
    """Holonomic flyer with inertia and altitude (see the module docstring)."""

    name = 'flyer'
    params_type = FlyerParams
    params: FlyerParams
    flies = True
    passable_values = (FREE, LOW_OBSTACLE)

    def validate(self) -> None:
        _check_positive('flyer', self.params, (
            'radius', 'height', 'mass', 'max_altitude', 'traffic_altitude', 'max_speed',
            'max_acceleration', 'max_climb_rate', 'max_vertical_acceleration',
            'response_time', 'max_yaw_rate', 'max_yaw_acceleration'))
        if self.params.traffic_altitude > self.params.max_altitude:
            raise InvalidConfigError(
                f'flyer: traffic_altitude ({self.params.traffic_altitude}) must not exceed '
                f'max_altitude ({self.params.max_altitude})')

    @property
    def footprint_radius(self) -> float:
        return self.params.radius

    @property
    def ride_height(self) -> float:
        return self.params.height / 2

    @property
    def sensor_height(self) -> float:
        return self.params.height / 2

    @property
    def traffic_height(self) -> float:
        return self.params.traffic_altitude + self.params.height / 2

    @property
    def top(self) -> float:
        """Height (m) of the body's top at its highest altitude."""
        return self.params.max_altitude + self.params.height

    @property
    def mass(self) -> float:
        return self.params.mass

    @property
    def top_speed(self) -> float:
        return self.params.max_speed

    def start_altitude(self, support_height: float) -> float:
        """Landed: on the ground, or on top of the tallest obstacle under the footprint."""
        if support_height <= 0.0:
            return 0.0
        return min(support_height + START_SUPPORT_GAP, self.params.max_altitude)

    def _create_shape(self, client: int) -> int:
        return p.createCollisionShape(p.GEOM_CYLINDER, radius=self.params.radius,
                                      height=self.params.height, physicsClientId=client)

    def _reset_model(self) -> None:
        self._world_vx = 0.0
        self._world_vy = 0.0
        self._turn_rate = 0.0

    def _advance(self, command: BodyCommand, dt: float) -> tuple[float, float, float]:
        params = self.params
        cos_yaw, sin_yaw = self._cos_yaw, self._sin_yaw
        target_x = cos_yaw * command.vx - sin_yaw * command.vy
        target_y = sin_yaw * command.vx + cos_yaw * command.vy
        speed = math.hypot(target_x, target_y)
        if speed > params.max_speed:
            target_x *= params.max_speed / speed
            target_y *= params.max_speed / speed
        gain = min(1.0, dt / params.response_time)
        change_x = (target_x - self._world_vx) * gain
        change_y = (target_y - self._world_vy) * gain
        change = math.hypot(change_x, change_y)
        limit = params.max_acceleration * dt
        if change > limit:
            change_x *= limit / change
            change_y *= limit / change
        self._world_vx += change_x
        self._world_vy += change_y
        target_rate = _clip(command.wz, -params.max_yaw_rate, params.max_yaw_rate)
        limit = params.max_yaw_acceleration * dt
        self._turn_rate += _clip((target_rate - self._turn_rate) * gain, -limit, limit)
        return (cos_yaw * self._world_vx + sin_yaw * self._world_vy,
                -sin_yaw * self._world_vx + cos_yaw * self._world_vy, self._turn_rate)

    def _advance_altitude(self, command: BodyCommand, dt: float) -> float:
        params = self.params
        target = _clip(command.vz, -params.max_climb_rate, params.max_climb_rate)
        gain = min(1.0, dt / params.response_time)
        limit = params.max_vertical_acceleration * dt
        rate = self._climb_rate + _clip((target - self._climb_rate) * gain, -limit, limit)
        # The ground and the ceiling (max_altitude) stop it within this step.
        rate = _clip(rate, -self._altitude / dt, (params.max_altitude - self._altitude) / dt)
        self._climb_rate = rate
        return rate

    def _observe(self, vx: float, vy: float, wz: float) -> None:
        cos_yaw, sin_yaw = self._cos_yaw, self._sin_yaw
        self._world_vx = cos_yaw * vx - sin_yaw * vy
        self._world_vy = sin_yaw * vx + cos_yaw * vy
        self._turn_rate = wz

    def _observe_altitude(self, altitude: float, climb_rate: float) -> None:
        # The body's altitude after the step (a low obstacle's top stops a descent onto it),
        # within the model's bounds.
        self._altitude = _clip(altitude, 0.0, self.params.max_altitude)
        self._climb_rate = climb_rate
