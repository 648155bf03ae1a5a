"""sessgan_gen generator node: publishes generated environments and samples them on request.

Publishes (relative names, so namespaces work):
* ``environments`` (sessgan_interfaces/Environment): every sampled environment, with start/goal;
* ``environment`` (nav_msgs/OccupancyGrid, reliable, transient local, depth 1): the latest map,
  for RViz, Nav2 map consumers and the simulator's free mode.
Serves ``generate_environments`` (sessgan_interfaces/GenerateEnvironments).

With ``mission_stations`` > 0 every environment is a pick-up -> place mission: that many
stations drawn from the map seed before home, every leg certified (sessgan_core.missions).
With ``robots`` > 1 every environment is a fleet episode: robots r1, r2, ... with their own
start, goal and certified route beside the environment's own (sessgan_core.fleet).
"""

from __future__ import annotations

import rclpy
from nav_msgs.msg import OccupancyGrid
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from sessgan_core.environment import MAX_ROBOTS
from sessgan_core.errors import SessganCoreError
from sessgan_core.fleet import FleetSpec
from sessgan_core.missions import DEFAULT_DWELL_TIME, MAX_MISSION_STATIONS, MissionSpec
from sessgan_core.node_help import exit_if_help
from sessgan_core.ros_conversion import environment_to_msg
from sessgan_core.ros_spin import exit_process, run_node
from sessgan_gen.checkpoint import incomplete_warning
from sessgan_gen.environment_sampler import DEFAULT_MAX_CELLS_PER_REQUEST, EnvironmentSampler
from sessgan_gen.errors import SessganGenError
from sessgan_interfaces.msg import Environment as EnvironmentMsg
from sessgan_interfaces.srv import GenerateEnvironments

MAP_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class GeneratorNode(Node):

    def __init__(self) -> None:
        super().__init__('sessgan_gen')
        self.declare_parameter('scenario', 'factory')
        self.declare_parameter('checkpoint', '')  # empty: the scenario's shipped checkpoint
        self.declare_parameter('width', 0)        # cells; 0: the checkpoint's map size
        self.declare_parameter('height', 0)
        self.declare_parameter('seed', 0)         # first seed; each publication uses the next
        self.declare_parameter('rate', 0.0)       # Hz; 0 publishes one environment at start
        self.declare_parameter('device', 'cpu')
        # Most cells (seeds x height x width) one generate_environments request may ask for.
        self.declare_parameter('max_cells_per_request', DEFAULT_MAX_CELLS_PER_REQUEST)
        self.declare_parameter('mission_stations', 0, ParameterDescriptor(
            description=f'Mission stations (pick-up, place, ...) drawn before home on every map, '
                        f'0..{MAX_MISSION_STATIONS}; 0: plain start -> goal episodes'))
        self.declare_parameter('station_dwell_time', DEFAULT_DWELL_TIME, ParameterDescriptor(
            description='Sim seconds the robot stands still at each station (loading)'))
        self.mission = MissionSpec(
            self.get_parameter('mission_stations').value,
            self.get_parameter('station_dwell_time').value).validate()
        self.declare_parameter('robots', 1, ParameterDescriptor(
            description=f'Robots under test on every map (a fleet episode), 1..{MAX_ROBOTS}; '
                        f'1: one robot'))
        self.fleet = FleetSpec(self.get_parameter('robots').value).validate(
            self.mission.stations)
        self.sampler = EnvironmentSampler(
            device=self.get_parameter('device').value,
            max_cells_per_request=int(self.get_parameter('max_cells_per_request').value))
        checkpoint = self.get_parameter('checkpoint').value
        if checkpoint:  # an unreadable checkpoint ends the node at once, with the reason
            _, metadata = self.sampler.load(checkpoint, self.get_parameter('scenario').value)
            if warning := incomplete_warning(metadata, f'checkpoint {checkpoint}'):
                self.get_logger().warning(warning)
        self.next_seed = int(self.get_parameter('seed').value)
        self.environment_publisher = self.create_publisher(EnvironmentMsg, 'environments', 10)
        self.map_publisher = self.create_publisher(OccupancyGrid, 'environment', MAP_QOS)
        self.service = self.create_service(
            GenerateEnvironments, 'generate_environments', self.on_generate)
        rate = float(self.get_parameter('rate').value)
        self.timer = self.create_timer(1.0 / rate if rate > 0 else 0.1, self.publish_next)
        self.publish_once = rate <= 0

    def publish_next(self) -> None:
        if self.publish_once:
            self.timer.cancel()
        scenario = self.get_parameter('scenario').value
        size = (self.get_parameter('height').value, self.get_parameter('width').value)
        try:
            environment = self.sampler.sample(
                [self.next_seed], self.get_parameter('checkpoint').value, scenario, size,
                mission=self.mission, fleet=self.fleet)[0]
        except (SessganCoreError, SessganGenError, ValueError) as err:
            self.get_logger().error(f'cannot generate an environment: {err}')
            self.timer.cancel()
            return
        self.next_seed += 1
        msg = environment_to_msg(environment, stamp=self.get_clock().now().to_msg())
        self.environment_publisher.publish(msg)
        self.map_publisher.publish(msg.map)
        self.get_logger().info(
            f'published environment {environment.id} ({environment.width}x{environment.height} '
            f'cells, feasible={environment.feasible})')

    def on_generate(self, request, response):
        checkpoint = bytes(request.weights) or request.checkpoint or \
            self.get_parameter('checkpoint').value
        scenario = request.scenario or self.get_parameter('scenario').value
        try:
            environments = self.sampler.sample(
                list(request.seeds), checkpoint, scenario, (request.height, request.width),
                generation=request.generation, member=request.member, mission=self.mission,
                fleet=self.fleet)
        except (SessganCoreError, SessganGenError, ValueError, RuntimeError) as err:
            response.success = False
            response.message = str(err)
            self.get_logger().warning(f'generate_environments refused: {err}')
            return response
        stamp = self.get_clock().now().to_msg()
        response.environments = [environment_to_msg(env, stamp) for env in environments]
        response.success = True
        return response


def main(args=None) -> None:
    """Spin the generator until a signal (which ends it at once and cleanly, also while it
    samples: sessgan_core.ros_spin); an unusable scenario, checkpoint or parameter ends the
    process with a one-line error and exit status 1."""
    exit_if_help('sessgan_gen generator', __doc__ or '', GeneratorNode, args)
    try:
        status = run_node(GeneratorNode, args=args)
    except (SessganCoreError, SessganGenError, ValueError, ParameterException) as err:
        rclpy.logging.get_logger('sessgan_gen').fatal(f'cannot start the generator: {err}')
        status = 1
    exit_process(status)
