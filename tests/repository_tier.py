"""What every package's ``test/test_repository_tier.py`` runs: its tier of the repository's
unit tests (tests/unit/<tier>, marker unit) with the repository's pytest settings, so
`colcon test` and `./sessgan test` run the same tests; the graph and smoke tiers, ruff and mypy
run with `./sessgan test`."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def unit_tier_test(tier: str) -> Callable[[], None]:
    """The test that runs tests/unit/``tier`` in a pytest of its own and passes when it does."""
    tests = ROOT / 'tests' / 'unit' / tier

    def test_the_unit_tier_of_this_package_passes() -> None:
        assert tests.is_dir(), f'{tests} not found'
        result = subprocess.run([sys.executable, '-m', 'pytest', str(tests), '-m', 'unit',
                                 '-q', '-p', 'no:cacheprovider'], cwd=ROOT,
                                capture_output=True, text=True, timeout=3600)
        assert result.returncode == 0, result.stdout[-6000:] + result.stderr[-2000:]

    return test_the_unit_tier_of_this_package_passes
