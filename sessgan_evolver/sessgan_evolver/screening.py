"""Cheap signals about a candidate test, learnt and remembered during one search.

What the ``screened`` search (sessgan_evolver.screened_search) spends before an episode of
the robot under test, never a rollout of it:

* :func:`route_features`: the certified route of a map and an environment seed
  (``place_start_goal``, the certificate every test gets) described along the route:
  length, bottleneck, the clearance profile, tight passages, turns, detour;
* :class:`OnlineLogistic`: a surrogate of P(valid failure | features), an L2-regularised
  logistic regression refitted on the run's own episodes (a few Newton steps; hundreds of
  rows);
* :func:`closest_encounter`: how near the episode's dummy agents (their patrols for a
  simulator seed, sessgan_sim.episode.PatrolPlanner) come to the robot driving
  :func:`reactive_path` at its speed: a third of Nearness-Diagram's factory failures are
  drives into an agent, and they happen where the two meet;
* :class:`FaultArchive`: the fault keys seen so far (sessgan_evolver.faults), so a
  candidate whose route passes a known fault place with the same surrounding map is known
  to risk finding that fault again.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from sessgan_core.environment import Environment, Pose2D
from sessgan_core.grid_search import descend, distance_field
from sessgan_core.route_certificate import (
    Placement,
    certify,
    map_clearance,
    min_route_steps,
    place_start_goal,
    required_clearances,
)
from sessgan_core.scenarios import Scenario
from sessgan_evolver.errors import SearchMethodError
from sessgan_evolver.faults import FaultKey, FaultRule, place_context
from sessgan_sim.agents import PatrolPath

Pose = tuple[float, float, float]
"""(x, y, yaw): metres and radians, map frame."""

FEATURE_NAMES = (
    'route_length', 'bottleneck_clearance', 'mean_clearance', 'tight_share',
    'tight_passages', 'turns', 'turning_angle', 'sharpest_turn', 'detour_ratio',
    'start_clearance', 'goal_clearance',
)
"""The columns of :func:`route_features`, in order."""

TIGHT_MARGIN = 0.25
"""m above the route's required clearance below which the route counts as tight."""


@dataclass(frozen=True)
class CertifiedCandidate:
    """A map with its placement for one environment seed (what an episode would get)."""

    occupancy: np.ndarray
    placement: Placement

    @property
    def feasible(self) -> bool:
        return self.placement.certificate is not None


def certify_candidate(occupancy: np.ndarray, spec: Scenario, seed: int) -> CertifiedCandidate:
    """The plain episode's start, goal and route for ``seed`` (make_environment's own)."""
    placement = place_start_goal(occupancy, spec.cell_size, (0.0, 0.0), spec, seed)
    return CertifiedCandidate(np.asarray(occupancy), placement)


def certify_route(occupancy: np.ndarray, spec: Scenario, start: Pose, goal: Pose
                  ) -> CertifiedCandidate:
    """A map with a given start and goal (another map's, say), certified by the rules every
    test's placement follows: both with the start's clearance, a route with the route's
    clearance and at least ``min_route_steps`` long. Infeasible when any rule fails."""
    grid = map_clearance(occupancy, spec.cell_size, (0.0, 0.0), spec)
    place_need, route_need = required_clearances(spec)
    cells = [grid.cell_of(pose[0], pose[1]) for pose in (start, goal)]
    height, width = grid.clearance.shape
    inside = all(0 <= row < height and 0 <= col < width for row, col in cells)
    certificate = None
    if inside and all(grid.clearance[cell] >= place_need - 1e-9 for cell in cells):
        certificate = certify(grid, cells[0], cells[1], route_need)
        if certificate is not None and len(certificate.path) - 1 < min_route_steps(
                np.asarray(occupancy).shape, grid.subdivision):
            certificate = None
    if certificate is None:
        placement = Placement(None, None, None, 0.0, 0.0, 'moved start or goal not certified')
    else:
        placement = Placement(tuple(start), tuple(goal), certificate,  # type: ignore[arg-type]
                              float(grid.clearance[cells[0]]), float(grid.clearance[cells[1]]),
                              '')
    return CertifiedCandidate(np.asarray(occupancy), placement)


def environment_of(candidate: CertifiedCandidate, spec: Scenario, env_id: str, seed: int
                   ) -> Environment:
    """The plain episode's Environment of a feasible candidate (what make_environment gives
    for a placement drawn from the seed, here for the candidate's own placement)."""
    placement = candidate.placement
    certificate = placement.certificate
    if certificate is None or placement.start is None or placement.goal is None:
        raise SearchMethodError('an infeasible candidate has no environment to run')
    return Environment(
        id=env_id, scenario=spec.name, occupancy=candidate.occupancy,
        resolution=spec.cell_size, start=Pose2D(*placement.start),
        goal=Pose2D(*placement.goal), origin=(0.0, 0.0), seed=seed, feasible=True,
        route_length=certificate.length,
        route_min_clearance=certificate.bottleneck_clearance,
        extra={'start_clearance': placement.start_clearance,
               'goal_clearance': placement.goal_clearance, 'rejection': ''})


def route_features(candidate: CertifiedCandidate, spec: Scenario) -> np.ndarray:
    """FEATURE_NAMES of a feasible candidate's route (metres, radians, counts)."""
    certificate = candidate.placement.certificate
    if certificate is None:
        raise SearchMethodError('an infeasible candidate has no route to describe')
    rows, cols = np.asarray(certificate.path).T
    profile = certificate.grid.clearance[rows, cols]
    tight = profile < required_clearances(spec)[1] + TIGHT_MARGIN
    passages = int(np.count_nonzero(np.diff(tight.astype(np.int8)) == 1) + int(tight[0]))
    points = certificate.points
    turns = np.zeros(0)
    if len(points) > 2:
        headings = np.arctan2(*np.diff(points, axis=0).T[::-1])
        turns = np.abs((np.diff(headings) + math.pi) % (2 * math.pi) - math.pi)
    straight = float(np.hypot(*(points[-1] - points[0]))) if len(points) > 1 else 0.0
    return np.array([
        certificate.length, certificate.bottleneck_clearance, float(profile.mean()),
        float(tight.mean()), passages, len(turns), float(turns.sum()),
        float(turns.max()) if len(turns) else 0.0,
        certificate.length / straight if straight > 0 else 1.0,
        candidate.placement.start_clearance, candidate.placement.goal_clearance,
    ], dtype=np.float64)


def reactive_path(candidate: CertifiedCandidate, spec: Scenario) -> np.ndarray:
    """Points (m) of the shortest way from the certified start to the goal where the robot's
    body fits (clearance >= its radius; the certificate grid's diagonal steps), else the
    certified route: the route keeps a margin that a reactive controller does not, and it
    drives through gaps the route goes around."""
    certificate = candidate.placement.certificate
    if certificate is None:
        raise SearchMethodError('an infeasible candidate has no way to drive')
    grid = certificate.grid
    (start_row, start_col), (goal_row, goal_col) = certificate.path[0], certificate.path[-1]
    steps = distance_field(grid.clearance >= spec.robot_radius, (int(goal_row), int(goal_col)),
                           diagonal=True)
    cells = descend(steps, (int(start_row), int(start_col)))
    if len(cells) < 2:
        return np.asarray(certificate.points, dtype=float)
    return np.array([grid.centre(cell) for cell in cells])


ENCOUNTER_STEP = 0.05
"""m between the points of the robot's way where closest_encounter compares positions."""


def closest_encounter(path: np.ndarray, patrols: Sequence[PatrolPath], robot_speed: float,
                      agent_speed: float) -> float:
    """Least distance (m, centre to centre) between the robot driving ``path`` at
    ``robot_speed`` from time 0 and any agent walking its patrol at ``agent_speed`` at the
    same moment; inf without agents. A forecast, not a simulation: the robot is assumed to
    drive on without waiting."""
    path = np.asarray(path, dtype=float)
    if not patrols or len(path) < 2:
        return math.inf
    if robot_speed <= 0 or agent_speed < 0:
        raise SearchMethodError(f'the robot speed must be positive and the agent speed not '
                                f'negative, got {robot_speed} and {agent_speed}')
    travelled = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
    along = np.append(np.arange(0.0, travelled[-1], ENCOUNTER_STEP), travelled[-1])
    robot = np.stack([np.interp(along, travelled, path[:, 0]),
                      np.interp(along, travelled, path[:, 1])], axis=-1)
    walked = agent_speed * along / robot_speed
    return min(float(np.hypot(*(robot - patrol.positions(walked)).T).min())
               for patrol in patrols)


def route_coarse_cells(candidate: CertifiedCandidate, rule: FaultRule) -> set[tuple[int, int]]:
    """Coarse cells (row, col) of the fault rule that the certified route passes."""
    certificate = candidate.placement.certificate
    if certificate is None:
        return set()
    sub = certificate.grid.subdivision * rule.coarse_cells
    return {(int(row) // sub, int(col) // sub) for row, col in certificate.path}


@dataclass
class FaultArchive:
    """Fault places already found: (coarse row, coarse col, context digest) of every key."""

    rule: FaultRule = field(default_factory=FaultRule)
    keys: set[FaultKey] = field(default_factory=set)
    places: set[tuple[int, int, str]] = field(default_factory=set)

    def add(self, key: FaultKey) -> bool:
        """Remember ``key``; True when it is new."""
        if key in self.keys:
            return False
        self.keys.add(key)
        self.places.add((key.row, key.col, key.context))
        return True

    def known_places_on(self, candidate: CertifiedCandidate,
                        cells: Iterable[tuple[int, int]] | None = None) -> int:
        """How many coarse cells along the candidate's route hold a known fault place with
        the same surrounding map (where a failure would be an old fault again)."""
        if not self.places:
            return 0
        cells = route_coarse_cells(candidate, self.rule) if cells is None else cells
        known_cells = {(row, col) for row, col, _ in self.places}
        return sum((row, col, place_context(candidate.occupancy, row, col, self.rule))
                   in self.places for row, col in cells if (row, col) in known_cells)


class OnlineLogistic:
    """P(label 1 | x): L2-regularised logistic regression on standardised features, refitted
    by Newton's method on every row seen (``add`` then ``fit``)."""

    def __init__(self, features: int, l2: float = 1.0, iterations: int = 8) -> None:
        if features < 1:
            raise SearchMethodError(f'a surrogate needs at least one feature, got {features}')
        self.l2, self.iterations = float(l2), int(iterations)
        self.rows: list[np.ndarray] = []
        self.labels: list[float] = []
        self.weights = np.zeros(features + 1)
        self.mean = np.zeros(features)
        self.scale = np.ones(features)

    def add(self, x: np.ndarray, label: bool) -> None:
        self.rows.append(np.asarray(x, dtype=np.float64))
        self.labels.append(float(label))

    @property
    def trained(self) -> bool:
        """Whether both labels have been seen (before that it predicts the base rate)."""
        return 0 < sum(self.labels) < len(self.labels)

    def fit(self) -> None:
        if not self.trained:
            return
        x = np.stack(self.rows)
        y = np.asarray(self.labels)
        self.mean = x.mean(axis=0)
        self.scale = np.where(x.std(axis=0) > 1e-9, x.std(axis=0), 1.0)
        design = np.hstack([np.ones((len(x), 1)), (x - self.mean) / self.scale])
        penalty = self.l2 * np.eye(design.shape[1])
        penalty[0, 0] = 0.0  # the intercept is not shrunk
        weights = np.zeros(design.shape[1])
        weights[0] = math.log(y.mean() / (1 - y.mean()))

        def loss(w: np.ndarray) -> float:
            """Penalised negative log-likelihood (log(1 + e^z) without overflow)."""
            logits = design @ w
            return float(np.sum(np.logaddexp(0.0, logits) - y * logits) + 0.5 * w @ penalty @ w)

        current = loss(weights)
        for _ in range(self.iterations):
            p = 1.0 / (1.0 + np.exp(-np.clip(design @ weights, -30.0, 30.0)))
            gradient = design.T @ (p - y) + penalty @ weights
            hessian = (design * (p * (1 - p))[:, None]).T @ design + penalty
            try:
                step = np.linalg.solve(hessian, gradient)
            except np.linalg.LinAlgError:
                break  # flat in some direction (the intercept unshrunk): keep the last fit
            # Newton's full step, halved while it would raise the loss (a pure Newton step can
            # overshoot on nearly separable labels until every row saturates).
            for _ in range(30):
                trial = loss(weights - step)
                if trial <= current + 1e-9 * max(1.0, abs(current)):
                    break
                step = step / 2
            else:
                break
            weights, current = weights - step, trial
        self.weights = weights

    def predict(self, x: np.ndarray) -> np.ndarray:
        """P(label 1) of each row of ``x`` (n, features); the base rate (0.5 before any
        label) while untrained."""
        x = np.atleast_2d(np.asarray(x, dtype=np.float64))
        if not self.trained:
            rate = float(np.mean(self.labels)) if self.labels else 0.5
            return np.full(len(x), rate)
        logits = self.weights[0] + ((x - self.mean) / self.scale) @ self.weights[1:]
        return 1.0 / (1.0 + np.exp(-np.clip(logits, -30, 30)))
