"""`colcon test` entry point of this package: its tier of the repository's tests.

Runs tests/unit/core (marker unit) with the repository's pytest settings, so `colcon test`
and `./sessgan test` run the same tests; the graph and smoke tiers, ruff and mypy run with
`./sessgan test`. Skipped where the package is installed without its repository.
"""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TESTS = ROOT / 'tests' / 'unit' / 'core'


def test_the_unit_tier_of_this_package_passes():
    if not TESTS.is_dir():
        pytest.skip(f'{TESTS} not found: the package is installed outside its repository')
    result = subprocess.run([sys.executable, '-m', 'pytest', str(TESTS), '-m', 'unit', '-q',
                             '-p', 'no:cacheprovider'], cwd=ROOT, capture_output=True,
                            text=True, timeout=3600)
    assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]
