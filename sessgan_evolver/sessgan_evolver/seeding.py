"""Seeds that every member of a generation shares, derived from the campaign seed alone.

Members of one generation are compared on the same maps (common random numbers): the
map seeds and simulation seeds of generation ``g`` depend only on ``(campaign seed, g)``,
never on the algorithm's random state, so a resumed campaign evaluates exactly the same
episodes as an uninterrupted one.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np


class SeedStream(IntEnum):
    """Independent seed streams of a generation."""

    MAPS = 1
    """Seeds the generator samples maps from (one per map index)."""
    SIMULATION = 2
    """Seeds of the simulator (sensor noise, dummy agents), one per map index."""
    FRESH_MAPS = 3
    """Map seeds of a fresh-seed evaluation (sessgan_evolver.fresh_seed)."""
    FRESH_SIMULATION = 4
    """Simulator seeds of a fresh-seed evaluation."""


def shared_seeds(campaign_seed: int, generation: int, count: int,
                 stream: SeedStream = SeedStream.MAPS) -> list[int]:
    """``count`` seeds in [0, 2**32) for generation ``generation`` of a campaign.

    The same arguments always give the same seeds; different generations or streams give
    statistically independent ones (numpy ``SeedSequence`` over the three integers).
    """
    if campaign_seed < 0 or generation < 0 or count < 0:
        raise ValueError(f'campaign seed, generation and count must be >= 0, got '
                         f'{campaign_seed}, {generation}, {count}')
    sequence = np.random.SeedSequence([int(campaign_seed), int(generation), int(stream)])
    return [int(value) for value in sequence.generate_state(count, dtype=np.uint32)]
