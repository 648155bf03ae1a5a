"""``--help`` for node executables: usage, every declared parameter with its default, exit 0.

One helper for every SESS-GAN node (generator, simulator, controllers): call
:func:`exit_if_help` first thing in ``main``. The parameters are read from the node itself, so
the help can never disagree with the code: the node is built once in a context whose DDS
discovery is off (nothing on the network sees it), its declared parameters, defaults (with
any ``-p`` overrides given) and descriptions are printed, and the process exits.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

HELP_FLAGS = ('-h', '--help')


def wants_help(args: Sequence[str] | None = None) -> bool:
    """True if ``args`` (default: sys.argv) holds -h/--help outside the ``--ros-args`` part."""
    args = list(sys.argv[1:] if args is None else args)
    inside_ros_args = False
    for arg in args:
        if arg == '--ros-args':
            inside_ros_args = True
        elif arg == '--':
            inside_ros_args = False
        elif arg in HELP_FLAGS and not inside_ros_args:
            return True
    return False


def parameter_lines(node: Any) -> list[str]:
    """'name (type) = default' lines, each with its description below, for every parameter
    ``node`` (an rclpy Node) declared."""
    names = sorted(node.list_parameters([], 0).names)
    descriptors = node.describe_parameters(names)
    lines = []
    for name, descriptor in zip(names, descriptors, strict=True):
        parameter = node.get_parameter(name)
        kind = parameter.type_.name.lower().replace('_array', '[]')
        read_only = ', read-only' if descriptor.read_only else ''
        lines.append(f'  {name} ({kind}{read_only}) = {parameter.value!r}')
        if descriptor.description:
            lines.append(f'      {descriptor.description}')
    return lines


def help_text(executable: str, description: str, make_node: Callable[[], Any],
              args: Sequence[str] | None = None) -> str:
    """The help of a node: usage, ``description`` and its parameters (built with
    ``make_node()`` in a throw-away ROS context with discovery off)."""
    import rclpy

    # Read by rcl when the context starts: the node never shows up in any graph.
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'OFF'
    given = list(sys.argv[1:] if args is None else args)
    rclpy.init(args=[sys.argv[0], *(arg for arg in given if arg not in HELP_FLAGS),
                     '--ros-args', '--log-level', 'error'])  # no 'ready' lines in the help
    node = None
    try:
        node = make_node()
        parameters = parameter_lines(node)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    summary = description.strip()
    return '\n'.join([
        f'usage: ros2 run {executable} [--ros-args [-r __ns:=/NAMESPACE] '
        '[-p NAME:=VALUE ...]]', '', summary, '',
        'parameters (name (type) = default; set with -p NAME:=VALUE):', *parameters, ''])


def exit_if_help(executable: str, description: str, make_node: Callable[[], Any],
                 args: Sequence[str] | None = None) -> None:
    """Print :func:`help_text` and exit 0 when ``args`` ask for --help; else return.

    ``executable``: 'package executable' as given to ``ros2 run``; ``description``: what the
    node does (its module docstring); ``make_node``: builds the node in rclpy's default
    context (it runs only for --help).
    """
    if not wants_help(args):
        return
    try:
        text = help_text(executable, description, make_node, args)
    except Exception as err:  # a node that cannot even be built: still say how to run it
        print(f'usage: ros2 run {executable} [--ros-args -p NAME:=VALUE ...]\n\n'
              f'{description.strip()}\n\n(cannot list the parameters: {err})', file=sys.stderr)
        sys.exit(1)
    print(text)
    sys.exit(0)
