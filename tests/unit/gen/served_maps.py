"""Token maps of the shipped generators as the sampler serves them, for the placement tests
(missions, fleets) that draw their own start, goal and more on them."""

from collections.abc import Iterable, Mapping

from sessgan_core.scenarios import get_scenario
from sessgan_core.token_map import occupancy_to_tokens
from sessgan_gen.environment_sampler import EnvironmentSampler


def served_token_maps(seeds: Mapping[str, Iterable[int]]) -> dict[str, list]:
    """{scenario: [(seed, token map), ...]} for each scenario's ``seeds``."""
    sampler = EnvironmentSampler()
    return {scenario: [(environment.seed, occupancy_to_tokens(environment.occupancy,
                                                              get_scenario(scenario)))
                       for environment in sampler.sample(list(scenario_seeds),
                                                         scenario=scenario)]
            for scenario, scenario_seeds in seeds.items()}
