"""Who drove into whom: the contact classifier's attribution of robot-agent contacts."""

import numpy as np
import pytest

from sessgan_sim.contacts import ContactClassifier
from sessgan_sim.metrics import ContactKind, MetricsRecorder

pytestmark = pytest.mark.unit

AGENT_BODY = 7


class OneAgent:
    """What the classifier reads of DummyAgents: one agent at (1, 0) moving at ``velocity``."""

    def __init__(self, velocity: tuple[float, float]) -> None:
        self.positions = np.array([[1.0, 0.0]])
        self.velocities = np.array([velocity])

    def index_of(self, body: int) -> int | None:
        return 0 if body == AGENT_BODY else None


def contact_kind(robot_velocity: tuple[float, float], agent_velocity: tuple[float, float]
                 ) -> ContactKind:
    """The kind of a contact of a robot at the origin with the agent at (1, 0)."""
    recorder = MetricsRecorder(10.0)
    classifier = ContactClassifier(recorder, OneAgent(agent_velocity), lambda body: None)
    classifier.record([AGENT_BODY], 1.0, 0.0, 0.0, (robot_velocity, robot_velocity))
    (event,) = recorder.contacts
    return event.kind


@pytest.mark.parametrize('robot,agent,kind', [
    ((0.3, 0.0), (0.0, 0.0), ContactKind.ROBOT_INTO_AGENT),     # into a standing agent
    ((0.3, 0.0), (-0.5, 0.0), ContactKind.ROBOT_INTO_AGENT),    # head-on, at speed
    ((0.3, 0.0), (0.0, 0.5), ContactKind.ROBOT_INTO_AGENT),     # into a crossing agent
    ((0.0, 0.0), (-0.5, 0.0), ContactKind.AGENT_INTO_ROBOT),    # rammed, standing
    ((0.2, 0.0), (0.5, 0.0), ContactKind.ROBOT_INTO_AGENT),     # caught up with it
    # Braking or creeping (0.06-0.09 m/s toward it) and rammed at 0.3-0.5 m/s: the agent's
    # doing, though the robot still moved toward it faster than a standing robot.
    ((0.06, 0.0), (-0.5, 0.0), ContactKind.AGENT_INTO_ROBOT),
    ((0.09, 0.0), (-0.3, 0.0), ContactKind.AGENT_INTO_ROBOT),
    ((0.2, 0.0), (-0.4, 0.0), ContactKind.ROBOT_INTO_AGENT),    # a third of the closing speed
    ((0.04, 0.0), (0.0, 0.0), ContactKind.AGENT_INTO_ROBOT),    # standing still (0.05 m/s)
])
def test_a_robot_drove_into_an_agent_only_with_a_fair_share_of_the_closing_speed(
        robot, agent, kind):
    assert contact_kind(robot, agent) == kind
