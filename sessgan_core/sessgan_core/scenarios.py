"""The scenario registry: tokens, encodings, geometry and defaults of each use case.

A scenario ties a token alphabet (what a cell of the example map can be) to the
robot under test and to the physical size of a cell. Everything that differs
between the factory, the race track and the drone area lives here, so the rest
of the code looks a scenario up instead of branching on its name.
"""

from __future__ import annotations

from dataclasses import dataclass

from sessgan_core.errors import UnknownScenarioError

# Common occupancy encoding (nav_msgs/OccupancyGrid values), shared by all scenarios.
FREE = 0
LOW_OBSTACLE = 50
BLOCKED = 100
OCCUPANCY_VALUES = (FREE, LOW_OBSTACLE, BLOCKED)


@dataclass(frozen=True)
class TrackCleanup:
    """A structural post-process of generated maps that keeps their learned geometry
    (sessgan_gen.track_cleanup): it only deletes track pieces and fills small holes, never
    draws new road. Applied by the sampler to every map of a scenario that sets it."""

    track_token: str
    """Token of the track (the cells a robot drives on)."""
    off_track_token: str
    """Token written where track is removed."""
    max_island_cells: int = 0
    """Fill holes of off-track cells (4-connected, not touching the map's edge) of at most this
    many cells with track: specks inside the road. 0: off."""
    bridge_gaps: bool = True
    """Fill one-cell gaps between two different track pieces (an off-track cell with track of
    two different 4-connected pieces on opposite sides, across or diagonally): the
    generator's breaks in a road, never a barrier inside one piece."""
    keep_main_piece: bool = True
    """Remove every track piece (4-connected) but the largest."""
    max_spur_cells: int = 0
    """Remove dead-end spurs whose skeleton ends within this many cells of a junction (longer
    dead ends stay whole). 0: off."""
    keep_circuit: bool = False
    """Keep only the track's largest circuit (sessgan_gen.track_cleanup.keep_circuit): the
    largest biconnected block of the track's skeleton, a network of loops in which every two
    points lie on a common loop, with its road; the rest (dead ends, roads joining circuits)
    is removed. Tracks without a long enough circuit stay as the other steps leave them."""
    min_circuit_sides: float = 1.0
    """Shortest circuit kept, as its centre line's length in the map's shorter sides."""
    min_circuit_width: float = 0.0
    """Cells: where the kept circuit's road is narrower than this (a pinch), it is widened to
    this width around its centre line. 0: off."""


@dataclass(frozen=True)
class Scenario:
    """One use case of the paper.

    Token maps are integer arrays whose values index ``tokens``.
    """

    name: str
    tokens: tuple[str, ...]
    """One character per token, e.g. ('G', 'W'); index = token id."""
    token_names: tuple[str, ...]
    """Human-readable name of each token."""
    occupancy: tuple[int, ...]
    """OccupancyGrid value of each token (FREE, LOW_OBSTACLE or BLOCKED)."""
    hierarchy: tuple[int, ...]
    """Token ids from lowest to highest priority: when downsampling, the highest
    token present in a cell's neighbourhood wins (keeps thin walls and tracks)."""
    traversable: tuple[int, ...]
    """Token ids the robot may occupy (feasibility, start and goal)."""
    default_size: tuple[int, int]
    """(height, width) in cells of the example map and of default samples."""
    cell_size: float
    """Metres per cell."""
    robot: str
    """Default robot model name in sessgan_sim's robot registry."""
    robot_radius: float
    """Radius of the robot's footprint in metres (used to inflate walls)."""
    controller: str
    """Default built-in controller executable in sessgan_controllers."""
    time_limit: float
    """Default episode length limit in sim seconds."""
    proximity_distance: float
    """Clearance in metres below which time counts as proximity time."""
    dummy_agents: int
    """Default number of moving dummy agents."""
    clearance_margin: float = 0.25
    """m beyond the robot's radius that start and goal keep from every obstacle: room to
    turn and to leave (sessgan_core.route_certificate)."""
    route_margin: float = 0.1
    """m beyond the robot's radius that the certified route keeps from every obstacle (Nav2's
    inscribed radius plus an inflation margin); at most ``clearance_margin``."""
    track_cleanup: TrackCleanup | None = None
    """Structural post-process the sampler applies to generated maps (None: none)."""
    goal_track_fraction: float = 0.0
    """The goal lies at least this fraction of the track's length along the route from the
    start, the track's length being the longest certified route between two clear points of
    the start's region (sessgan_core.route_certificate.track_length_steps); 0: off (the
    goal is only at least half the map's shorter side and half the farthest clear point
    away)."""

    @property
    def num_tokens(self) -> int:
        return len(self.tokens)

    def token_id(self, char: str) -> int:
        """Return the id of token character ``char``."""
        try:
            return self.tokens.index(char)
        except ValueError as err:
            raise UnknownScenarioError(
                f'token {char!r} is not one of scenario {self.name!r} tokens {self.tokens}'
            ) from err


SCENARIOS: dict[str, Scenario] = {}


def register_scenario(scenario: Scenario) -> Scenario:
    """Add a scenario to the registry (users may register their own)."""
    if len(scenario.tokens) != len(scenario.occupancy) or len(scenario.tokens) != len(
        scenario.token_names
    ):
        raise ValueError(
            f'scenario {scenario.name!r}: tokens, names and occupancy differ in length')
    if sorted(scenario.hierarchy) != list(range(len(scenario.tokens))):
        raise ValueError(f'scenario {scenario.name!r}: hierarchy must list every token once')
    cleanup = scenario.track_cleanup
    if cleanup is not None and not {cleanup.track_token, cleanup.off_track_token} <= set(
            scenario.tokens):
        raise ValueError(
            f'scenario {scenario.name!r}: track_cleanup tokens {cleanup.track_token!r}, '
            f'{cleanup.off_track_token!r} must be among its tokens {scenario.tokens}')
    if not 0.0 <= scenario.goal_track_fraction <= 1.0:
        raise ValueError(f'scenario {scenario.name!r}: goal_track_fraction '
                         f'({scenario.goal_track_fraction}) must lie in [0, 1]')
    if not 0 <= scenario.route_margin <= scenario.clearance_margin:
        raise ValueError(
            f'scenario {scenario.name!r}: margins must satisfy 0 <= route_margin '
            f'({scenario.route_margin}) <= clearance_margin ({scenario.clearance_margin})')
    SCENARIOS[scenario.name] = scenario
    return scenario


def get_scenario(name: str) -> Scenario:
    """Look a scenario up by name; the error lists the known names."""
    try:
        return SCENARIOS[name]
    except KeyError as err:
        raise UnknownScenarioError(
            f'unknown scenario {name!r}; known scenarios: {", ".join(sorted(SCENARIOS))}'
        ) from err


register_scenario(Scenario(
    name='factory',
    tokens=('G', 'W'),
    token_names=('ground', 'wall'),
    occupancy=(FREE, BLOCKED),
    hierarchy=(0, 1),
    traversable=(0,),
    default_size=(32, 32),
    cell_size=0.5,
    robot='diff_drive',
    robot_radius=0.2,
    controller='nearness_diagram',
    time_limit=60.0,
    proximity_distance=0.25,
    dummy_agents=2,
))

register_scenario(Scenario(
    name='racetrack',
    tokens=('T', 'O'),
    token_names=('track', 'out_of_bounds'),
    occupancy=(FREE, BLOCKED),
    # The track is the thin structure: it must survive downsampling.
    hierarchy=(1, 0),
    traversable=(0,),
    default_size=(128, 128),
    cell_size=1.0,
    robot='car',
    robot_radius=0.6,
    controller='race_controller',
    time_limit=120.0,
    proximity_distance=0.5,
    dummy_agents=0,
    # Relative to the example's track, about 5 m wide: the start lies in the middle band of a
    # track at least 3.2 m wide, and the route keeps a 1.8 m lane.
    clearance_margin=1.0,
    route_margin=0.3,
    # Start and goal at least half the track's length apart (on a closed circuit, where the
    # longest route is half a lap: at least a quarter lap apart, the return the rest of it).
    goal_track_fraction=0.5,
    # The generator draws the example's road but as a maze of ~70 pieces with ~42 dead ends:
    # join one-cell breaks, keep the main piece, drop specks and spurs up to four track
    # widths, then keep the largest circuit (the example is one closed circuit), its pinches
    # widened to 3 m, the narrowest road of the example (README, race-track realism;
    # sessgan_gen.track_cleanup).
    track_cleanup=TrackCleanup(track_token='T', off_track_token='O', max_island_cells=25,
                               bridge_gaps=True, keep_main_piece=True, max_spur_cells=20,
                               keep_circuit=True, min_circuit_sides=1.0,
                               min_circuit_width=3.0),
))

register_scenario(Scenario(
    name='drone',
    tokens=('G', 'W', 'O'),
    token_names=('ground', 'wall', 'low_obstacle'),
    occupancy=(FREE, BLOCKED, LOW_OBSTACLE),
    hierarchy=(0, 2, 1),
    traversable=(0, 2),
    default_size=(32, 32),
    cell_size=0.5,
    robot='flyer',
    robot_radius=0.2,
    controller='velocity_projection',
    time_limit=60.0,
    proximity_distance=0.25,
    dummy_agents=2,
))
