"""Whether a worker the campaign discovered may run its episodes: the same software version,
and a simulator that hosts the robot the campaign's scenario (or controller) drives.

A worker says what it is through its ``bags`` service (sessgan_interfaces/WorkerBags: its
version and settings as JSON). Episodes of another version may be simulated or recorded
differently, and a simulator started with ``-p robot:=car`` runs every goal with that robot
(a worker set up for another scenario), so either would mix other results into the run.
"""

from __future__ import annotations

import json


def worker_difference(name: str, version: str, settings_json: str, expected_version: str,
                      expected_robot: str, scenario: str) -> str | None:
    """Why worker ``name`` is refused (naming the difference), or None if it matches."""
    if version != expected_version:
        return (f'worker {name} runs sessgan {version or "(unknown)"}, this campaign '
                f'{expected_version}: install the same version on every host')
    try:
        settings = json.loads(settings_json)
    except ValueError as err:
        return f'worker {name} describes its settings with malformed JSON ({err})'
    robot = str(settings.get('robot') or '') if isinstance(settings, dict) else ''
    if robot and robot != expected_robot:
        return (f'worker {name} hosts robot {robot!r} (its simulator parameter robot), the '
                f"campaign's scenario {scenario} needs {expected_robot!r}: a worker set up "
                'for another scenario')
    return None
