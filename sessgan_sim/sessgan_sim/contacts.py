"""Who caused a contact: the classifier of one robot under test's contacts (see
sessgan_sim.metrics for the kinds and which of them are faults)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable

from sessgan_sim.agents import DummyAgents
from sessgan_sim.metrics import (
    CONTACT_DEBOUNCE,
    FASTER_PARTNER,
    STANDING_SPEED,
    ContactKind,
    MetricsRecorder,
)

RobotLookup = Callable[[int], 'tuple[int, tuple[float, float]] | None']
"""A pybullet body id -> (index, position) of the robot under test with that body, else None."""


class ContactClassifier:
    """Records one robot's contacts in its MetricsRecorder, each attributed to the robot or to
    whoever drove into it.

    The robot drove into a partner (an agent, another robot under test) if it moved toward it
    faster than a standing robot would just before or during the contact step; into an agent
    only if the agent did not close in more than ``FASTER_PARTNER`` times as fast (a blind
    agent ramming a robot that brakes, creeps or passes across its way drove into it). While
    an agent or another robot drives into it (and CONTACT_DEBOUNCE after), whatever else the
    robot touches is that partner's doing too: it was shoved.
    """

    def __init__(self, recorder: MetricsRecorder, agents: DummyAgents,
                 robot_at: RobotLookup) -> None:
        self.recorder = recorder
        self.agents = agents
        self.robot_at = robot_at
        self.pushed_by: tuple[str, int] | None = None
        """('agent', i) or ('robot', j) that last drove into the robot, until pushed_until."""
        self.pushed_until = -math.inf

    def record(self, partners: Iterable[int], time: float, x: float, y: float,
               velocities: tuple[tuple[float, float], ...]) -> None:
        """Record one physics step's contacts with the bodies ``partners`` at sim ``time``
        (s), the robot at (``x``, ``y``) m moving at each of ``velocities`` (m/s, map frame)
        around the step."""
        recorder = self.recorder
        agents = self.agents
        touches_static = False
        for body in partners:
            agent = agents.index_of(body)
            found = self.robot_at(body) if agent is None else None
            if agent is None and found is None:
                touches_static = True
                continue
            if agent is not None:
                partner_x, partner_y = agents.positions[agent, 0], agents.positions[agent, 1]
            else:
                assert found is not None
                partner_x, partner_y = found[1]
            dx, dy = partner_x - x, partner_y - y
            distance = math.hypot(dx, dy) or 1e-9
            approach = max((vx * dx + vy * dy) / distance for vx, vy in velocities)
            pushed = self.pushed_by is not None and time <= self.pushed_until
            if agent is not None:
                agent_vx, agent_vy = agents.velocities[agent]
                agent_approach = -(agent_vx * dx + agent_vy * dy) / distance
                if approach > STANDING_SPEED and not pushed \
                        and FASTER_PARTNER * approach >= agent_approach:
                    kind = ContactKind.ROBOT_INTO_AGENT
                else:
                    kind = ContactKind.AGENT_INTO_ROBOT
                    self.pushed_by, self.pushed_until = ('agent', agent), time + CONTACT_DEBOUNCE
                recorder.record_contact(time, agent, kind, x, y)
                continue
            assert found is not None
            other = found[0]
            if approach > STANDING_SPEED and not pushed:
                kind = ContactKind.ROBOT_INTO_ROBOT
            else:
                kind = ContactKind.ROBOT_HIT_BY_ROBOT
                self.pushed_by, self.pushed_until = ('robot', other), time + CONTACT_DEBOUNCE
            recorder.record_contact(time, -1, kind, x, y, other_robot=other)
        if touches_static:
            # Shoved into a wall by an agent or a robot: its doing (the event names it).
            if self.pushed_by is not None and time <= self.pushed_until:
                if self.pushed_by[0] == 'agent':
                    recorder.record_contact(time, -1, ContactKind.AGENT_INTO_ROBOT, x, y)
                else:
                    recorder.record_contact(time, -1, ContactKind.ROBOT_HIT_BY_ROBOT, x, y)
            else:
                recorder.record_contact(time, -1, ContactKind.STATIC, x, y)
