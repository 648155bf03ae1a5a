"""Clocked mode under load: with every core saturated by busy loops, do the reference
navigator's clocked graph tests pass, or end overloaded and run again, never as a fault?
(issue 21)

Starts ``--load`` busy loops, runs the three
``test_reference_navigator_reaches_the_goal_on_its_timer_in_clocked_mode`` graph tests with
pytest (``--repeat`` times) and prints every episode the simulators ran (outcome, pace, command
figures from the simulator's log), each test's result and the load average. Busy loops and
tests inherit this process's niceness (run it under ``nice`` on a shared machine);
``--test-nice N`` runs the tests N steps nicer than the busy loops, a machine whose other work
gets more of the CPU than the stack under test (the scheduler favours processes that sleep,
like a simulator and a controller waiting for each other, over busy loops of equal weight).

Run after `source setup.bash`, with a ROS_DOMAIN_ID of your own:
    nice -n 5 python tests/benchmarks/bench_clocked_under_load.py [--load 2] [--repeat 1]
        [--test-nice 0]
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TESTS = ('tests/graph/test_reference_navigator_graph.py::'
         'test_reference_navigator_reaches_the_goal_on_its_timer_in_clocked_mode')
EPISODE = re.compile(r'\[(?P<node>[\w.]+)\.sessgan_sim\]: episode (?P<id>\S+): (?P<outcome>\w+) '
                     r'after (?P<sim>[\d.]+) sim s in (?P<wall>[\d.]+) wall s \(x(?P<pace>[\d.]+) '
                     r'real time\).*?(?:; commands: (?P<commands>.*))?$')
RESULT = re.compile(r'::(test_\w+\[\w+\]) (PASSED|FAILED|ERROR)')


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--load', type=int, default=2, help='busy-loop processes')
    parser.add_argument('--repeat', type=int, default=1, help='runs of the three tests')
    parser.add_argument('--test-nice', type=int, default=0,
                        help='niceness of the tests above the busy loops (0..19)')
    args = parser.parse_args()

    busy = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
            for _ in range(args.load)]
    results: collections.Counter = collections.Counter()
    outcomes: collections.Counter = collections.Counter()
    loads = []
    start = time.monotonic()
    try:
        time.sleep(2.0)  # let the busy loops take the cores
        for run in range(args.repeat):
            with tempfile.TemporaryDirectory(prefix='sessgan-clocked-load-') as temp:
                completed = subprocess.run(
                    ['nice', '-n', str(args.test_nice), sys.executable, '-m', 'pytest', TESTS,
                     '-v', '-p', 'no:cacheprovider', '--basetemp', temp], cwd=ROOT,
                    capture_output=True, text=True, timeout=1800)
                loads.append(os.getloadavg()[0])
                for log in sorted(Path(temp).rglob('*simulator*.log')):
                    for line in log.read_text(errors='replace').splitlines():
                        match = EPISODE.search(line)
                        if match:
                            outcomes[match['outcome']] += 1
                            print(f'run {run + 1}: {match["id"]}: {match["outcome"]} after '
                                  f'{match["sim"]} sim s in {match["wall"]} wall s '
                                  f'(x{match["pace"]}); {match["commands"] or ""}')
                for test, result in RESULT.findall(completed.stdout):
                    results[result] += 1
                    print(f'run {run + 1}: {test} {result}')
                if completed.returncode not in (0, 1):
                    print(completed.stdout[-3000:], completed.stderr[-3000:])
    finally:
        for process in busy:
            process.kill()
            process.wait()
    load_text = ', '.join(f'{load:.1f}' for load in loads)
    print(f'{args.repeat} x 3 tests with {args.load} busy loops, tests {args.test_nice} nicer '
          f'(load average at the end of each run: {load_text}; {os.cpu_count()} cores) in '
          f'{time.monotonic() - start:.0f} s: tests {dict(results)}, episodes {dict(outcomes)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
