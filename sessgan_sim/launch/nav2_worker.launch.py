"""Nav2 (ROS 2 Jazzy) driving the robot of one SESS-GAN simulator worker.

    ros2 launch sessgan_sim nav2_worker.launch.py namespace:=w0 real_time_factor:=1.0

Starts, under ``namespace``: the simulator worker in clocked mode, sending every episode's goal
to Nav2's ``navigate_to_pose`` action and clearing Nav2's costmaps before each episode, and
Nav2's controller, planner, behavior and bt_navigator servers with their lifecycle manager,
configured by ``params_file`` (default: this package's config/nav2_params.yaml). Nav2's nodes
read the absolute /tf, /tf_static and /clock, so they are remapped to the worker's relative
topics. Then run a campaign against it with
``ros2 run sessgan_evolver campaign --scenario factory --external``.

Needs a stock Jazzy install with Nav2 (``ros-jazzy-navigation2``); not run on the project's own
machines, where Nav2 cannot be installed (tests/unit/sim/test_nav2_config.py checks this file
and the params against the simulator's contract without running them).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

LIFECYCLE_NODES = ['controller_server', 'planner_server', 'behavior_server', 'bt_navigator']
"""Nav2's servers, started and activated in this order by the lifecycle manager."""

NAV2_NODES = [
    ('nav2_controller', 'controller_server', 'controller_server'),
    ('nav2_planner', 'planner_server', 'planner_server'),
    ('nav2_behaviors', 'behavior_server', 'behavior_server'),
    ('nav2_bt_navigator', 'bt_navigator', 'bt_navigator'),
]
"""(package, executable, node name) of each server."""

REMAPPINGS = [('/tf', 'tf'), ('/tf_static', 'tf_static'), ('/clock', 'clock')]
"""The worker publishes tf, tf_static and clock under its namespace."""


def generate_launch_description() -> LaunchDescription:
    namespace = LaunchConfiguration('namespace')
    params_file = LaunchConfiguration('params_file')
    real_time_factor = LaunchConfiguration('real_time_factor')
    arguments = [
        DeclareLaunchArgument('namespace', default_value='w0',
                              description='namespace of the simulator worker and of Nav2'),
        DeclareLaunchArgument(
            'params_file',
            default_value=PathJoinSubstitution(
                [FindPackageShare('sessgan_sim'), 'config', 'nav2_params.yaml']),
            description='Nav2 parameters'),
        DeclareLaunchArgument('real_time_factor', default_value='1.0',
                              description='sim seconds per wall second'),
    ]
    simulator = Node(
        package='sessgan_sim', executable='simulator', namespace=namespace, output='screen',
        parameters=[{
            'mode': 'clocked',
            'real_time_factor': ParameterValue(real_time_factor, value_type=float),
            'goal_interface': 'navigate_to_pose',
            'reset_costmaps': True,
            # Nav2 activates its servers after the worker is up; its first command comes
            # once a goal is planned.
            'controller_startup_timeout': 60.0,
            'stack_timeout': 10.0,
            # Nav2's default tree recovers (clear, spin, wait, back up) only once its
            # progress checker (0.5 m in 10 s) has failed: 30 s (the simulator's default,
            # kept here for Nav2's sake) leave it a recovery and 10 s to get going again.
            'stuck_timeout': 30.0,
        }])
    nav2 = [Node(package=package, executable=executable, name=name, namespace=namespace,
                 output='screen', parameters=[params_file], remappings=REMAPPINGS)
            for package, executable, name in NAV2_NODES]
    lifecycle_manager = Node(
        package='nav2_lifecycle_manager', executable='lifecycle_manager',
        name='lifecycle_manager_navigation', namespace=namespace, output='screen',
        parameters=[params_file, {'autostart': True, 'node_names': LIFECYCLE_NODES}],
        remappings=REMAPPINGS)
    return LaunchDescription([*arguments, simulator, *nav2, lifecycle_manager])
