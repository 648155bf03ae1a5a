"""`colcon test` entry point of this package: tests/unit/core, as `./sessgan test` runs it
(tests/repository_tier.py). Skipped where the package is installed without its repository."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'tests'))
tier = pytest.importorskip(
    'repository_tier', reason='the package is installed outside its repository')

test_the_unit_tier_of_this_package_passes = tier.unit_tier_test('core')
