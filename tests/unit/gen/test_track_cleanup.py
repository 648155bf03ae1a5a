"""Tests of the race track's structural post-process (sessgan_gen.track_cleanup)."""

import dataclasses

import numpy as np
import pytest

from sessgan_core.scenarios import TrackCleanup, get_scenario, register_scenario
from sessgan_core.token_map import load_example_map, tokens_to_occupancy
from sessgan_core.valid_tests import reachable_regions
from sessgan_gen.environment_sampler import EnvironmentSampler
from sessgan_gen.sampling import sample_token_maps
from sessgan_gen.track_cleanup import (
    bridge_gaps,
    clean_generated_maps,
    clean_token_map,
    clean_track,
    fill_islands,
    keep_circuit,
    largest_loop_block,
    largest_piece,
    remove_spurs,
)
from sessgan_gen.track_realism import count_dead_ends, skeleton, track_clearance

pytestmark = pytest.mark.unit


def ring(size=60, inner=12.0, outer=17.0):
    rows, cols = np.mgrid[0:size, 0:size]
    radius = np.hypot(rows - (size - 1) / 2, cols - (size - 1) / 2)
    return (radius >= inner) & (radius < outer)


def test_fill_islands_fills_specks_in_the_road_only():
    track = np.zeros((30, 30), dtype=bool)
    track[5:25, 5:25] = True
    track[10, 10] = False                 # a speck: 1 cell
    track[14:20, 14:20] = False           # a 36-cell hole
    track[0:5, 12] = True                 # road to the edge
    track[0:3, 13] = False                # off-track touching the edge: never filled
    filled = fill_islands(track, 25)
    assert filled[10, 10] and not filled[14:20, 14:20].any()
    assert (filled ^ track).sum() == 1
    assert fill_islands(track, 36)[14:20, 14:20].all()
    assert (fill_islands(track, 0) == track).all()


def test_bridge_gaps_joins_pieces_but_keeps_barriers_inside_a_piece():
    track = np.zeros((20, 40), dtype=bool)
    track[5:10, 2:18] = True
    track[5:10, 19:38] = True             # the same road, broken by a one-cell column
    bridged = bridge_gaps(track)
    assert bridged[5:10, 18].all() and (bridged ^ track).sum() == 5
    assert len(reachable_regions(bridged).sizes) == 1
    # Diagonal contact between two pieces: one cell joins them.
    diagonal = np.zeros((6, 6), dtype=bool)
    diagonal[0:2, 0:2] = True
    diagonal[2:4, 2:4] = True
    assert len(reachable_regions(bridge_gaps(diagonal)).sizes) == 1
    # A U whose arms are one cell apart is one piece: its barrier stays.
    u_shape = np.zeros((12, 12), dtype=bool)
    u_shape[1:11, 1:5] = True
    u_shape[1:11, 6:10] = True
    u_shape[1:3, 5] = True
    assert (bridge_gaps(u_shape) == u_shape).all()


def test_largest_piece_drops_the_rest():
    track = np.zeros((20, 20), dtype=bool)
    track[2:8, 2:8] = True
    track[12:14, 12:14] = True
    assert (largest_piece(track) == (np.arange(20)[:, None] >= 2) & (np.arange(20)[:, None] < 8)
            & (np.arange(20)[None, :] >= 2) & (np.arange(20)[None, :] < 8)).all()
    assert not largest_piece(np.zeros((3, 3), dtype=bool)).any()


def test_remove_spurs_drops_short_spurs_and_keeps_long_dead_ends_whole():
    closed = ring()
    assert (remove_spurs(closed, 20) == closed).all()
    short = ring()
    short[27:32, 46:57] = True            # a stub reaching 10 cells out of the ring
    assert count_dead_ends(short) == 1
    cleaned = remove_spurs(short, 20)
    assert count_dead_ends(cleaned) == 0
    assert cleaned[27:32, 50:57].sum() <= 2            # a corner or two: specks, see below
    assert (cleaned | short == short).all()           # only deletes
    assert (cleaned[closed] == closed[closed]).mean() > 0.97
    long = np.zeros((60, 100), dtype=bool)
    long[:, :60] = ring()
    long[27:32, 46:99] = True             # a dead end 50 cells long
    kept = remove_spurs(long, 20)
    assert kept[27:32, 50:95].all() and count_dead_ends(kept) == 1


def test_the_example_track_is_left_as_it_is():
    spec = get_scenario('racetrack')
    assert spec.track_cleanup is not None
    cells = load_example_map('racetrack').cells
    assert (clean_token_map(cells, spec) == cells).all()


def test_cleanup_of_a_maze_keeps_one_piece_and_no_short_spurs():
    cleanup = TrackCleanup('T', 'O', max_island_cells=25, max_spur_cells=20)
    maze = ring(size=80, inner=20, outer=25)
    maze[10:12, 10:14] = True             # a speck of road far away
    maze[37:43, 60:75] = True             # a short spur
    maze[39, 17] = False                  # a speck of barrier in the road
    maze[55:67, 40] = False               # one-cell breaks across the ring: two pieces
    maze[12:27, 40] = False
    cleaned = clean_track(maze, cleanup)
    assert len(reachable_regions(cleaned).sizes) == 1
    assert not cleaned[10:12, 10:14].any() and not cleaned[37:43, 67:75].any()
    assert count_dead_ends(cleaned) == 0
    assert cleaned[39, 17]
    for rows in (slice(55, 67), slice(12, 27)):       # the breaks are bridged
        assert cleaned[rows, 40].sum() == maze[rows, 39].sum()


def test_the_sampler_cleans_race_tracks_deterministically():
    sampler = EnvironmentSampler()
    spec = get_scenario('racetrack')
    cleaned = sampler.sample([5, 6], scenario='racetrack')
    again = sampler.sample([5, 6], scenario='racetrack')
    raw = sampler.sample([5, 6], scenario='racetrack', post_process=False)
    for first, second, original in zip(cleaned, again, raw):
        assert (first.occupancy == second.occupancy).all()
        track = first.occupancy == 0
        assert len(reachable_regions(track).sizes) == 1
        assert len(reachable_regions(original.occupancy == 0).sizes) > 10
        # Bridges, filled specks and the circuit's widened pinches aside, the post-process
        # only deletes road (widened pinches: 3.0 % of a served track on average, at most
        # 8.5 %, over seeds 800000-800199).
        added = track & (original.occupancy != 0)
        assert added.sum() < 0.1 * track.sum()
    # Scenarios without a cleanup are sampled as before.
    assert get_scenario('factory').track_cleanup is None
    factory = sampler.sample([5], scenario='factory')[0]
    assert (factory.occupancy == sampler.sample([5], scenario='factory',
                                                post_process=False)[0].occupancy).all()
    assert spec.track_cleanup is not None


def test_a_cleanup_must_name_the_scenario_tokens():
    bad = dataclasses.replace(get_scenario('racetrack'), name='bad-track',
                              track_cleanup=TrackCleanup('X', 'O'))
    with pytest.raises(ValueError, match='track_cleanup tokens'):
        register_scenario(bad)


def test_generated_maps_are_cleaned_as_the_sampler_serves_them():
    sampler = EnvironmentSampler()
    pyramid, _ = sampler.load(scenario='racetrack')
    raw = sample_token_maps(pyramid, [5, 6])
    cleaned = clean_generated_maps(raw, 'racetrack')
    served = sampler.sample([5, 6], scenario='racetrack')
    spec = get_scenario('racetrack')
    for cells, environment in zip(cleaned, served):
        assert (tokens_to_occupancy(cells, spec) == environment.occupancy).all()
    factory = np.zeros((2, 32, 32), dtype=np.int64)
    assert clean_generated_maps(factory, 'factory') is factory


def test_largest_loop_block_is_the_biggest_loop_without_its_tails():
    thin = np.zeros((30, 60), dtype=bool)
    thin[2, 2:20] = thin[20, 2:20] = True          # a 18 x 19 square loop
    thin[2:21, 2] = thin[2:21, 19] = True
    thin[10, 20:30] = True                          # a road to a smaller loop
    thin[6, 30:40] = thin[14, 30:40] = True         # a 9 x 10 loop
    thin[6:15, 30] = thin[6:15, 39] = True
    thin[25, 40:58] = True                          # a separate straight road
    block = largest_loop_block(thin)
    big = np.zeros_like(thin)
    big[2, 2:20] = big[20, 2:20] = big[2:21, 2] = big[2:21, 19] = True
    # The big loop, and at most the first pixel of a road that leaves it (a pixel beside a
    # junction closes a triangle with two of the loop's pixels).
    assert (block | big == block).all() and (block & ~big).sum() <= 1
    tree = np.zeros((10, 10), dtype=bool)
    tree[5, :] = True
    tree[:5, 5] = True
    assert not largest_loop_block(tree).any()


def test_keep_circuit_keeps_the_loop_and_drops_dead_ends_and_side_loops():
    track = np.zeros((60, 140), dtype=bool)
    track[:, :60] = ring()                          # the circuit, centre line about 90 long
    track[27:32, 46:80] = True                      # a road to a smaller loop ...
    small = ring(size=30, inner=5.0, outer=10.0)
    track[15:45, 78:108] = small
    track[27:32, 106:139] = True                    # ... and a dead end beyond it
    track[28:32, 13:17] = False                     # a pinch: the ring is 1 cell wide here
    assert count_dead_ends(track) >= 1
    kept = keep_circuit(track, min_circuit_cells=40, min_width=3.0)
    kept = largest_piece(fill_islands(kept, 25))
    assert not kept[:, 64:].any()                   # side road, small loop and dead end gone
    assert count_dead_ends(kept) == 0
    assert (kept[:, :55] == track[:, :55]).mean() > 0.97  # the loop stays as it was ...
    assert track_clearance(track)[28:32, 13:19].max() == 0.5
    assert (track_clearance(kept)[28:32, 13:19].max(axis=1) >= 1.0).all()  # ... pinch: 3 wide
    assert (kept & ~track).sum() <= 20
    # A circuit shorter than asked for, or none at all: the track is left as it is.
    assert (keep_circuit(track, min_circuit_cells=1000, min_width=3.0) == track).all()
    tree = np.zeros((40, 40), dtype=bool)
    tree[18:23, :] = True
    tree[:20, 18:23] = True
    assert (keep_circuit(tree, 3, 3.0) == tree).all()
    assert largest_loop_block(skeleton(kept)).sum() >= 40
