"""Benchmark: one campaign and 1, 2 and 4 worker hosts, each host a network namespace
(tests/multihost/network_namespaces.py), DDS across them as in the multi-host test.

Each worker host runs one simulator + controller pair (the external example controller,
--blind: every valid map ends in a failure, so every episode's bag is collected); the
campaign (sessgan, its generator beside it in the campaign's namespace) runs the same
generations on each set-up. Prints per set-up:
* episodes per minute (the campaign's own count over its wall time, start-up excluded);
* the campaign's overhead per episode from its last log line: waiting for the generator,
  dispatch (goal sent to result received, less the worker's episode wall time) and bag transfer;
* CPU seconds per episode of the campaign process and its generator (their rusage);
* from those, how many worker hosts one campaign process could keep busy, and what limits.

Needs root ('ip netns'); run after `source setup.bash`:
    nice -n 5 python tests/benchmarks/bench_multihost.py [--pairs 1,2,4] [--generations 2]
"""

from __future__ import annotations

import argparse
import os
import random
import re
import resource
import secrets
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from tests.multihost.conftest import EXTERNAL_CONTROLLER, dds_environment  # noqa: E402
from tests.multihost.network_namespaces import (  # noqa: E402
    NamespaceNetwork,
    unavailable_reason,
)

OVERHEAD = re.compile(r'campaign overhead per episode \((\d+) episodes\): generator ([\d.]+) '
                      r'ms, dispatch ([\d.]+) ms, bag transfer ([\d.]+) ms \((\d+) bags '
                      r'copied, [\d.]+ ms each; \d+ written in place by the workers\); '
                      r'campaign process CPU ([\d.]+) ms')
DONE = re.compile(r'done in [\d.]+ min: .* in (\d+) episodes')
FIRST_RESULT = 'generation 0'


def children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_setup(pairs: int, args: argparse.Namespace, work: Path) -> dict:
    env = {**os.environ, **dds_environment(random.SystemRandom().randrange(100, 200))}
    hosts = ['campaign'] + [f'worker{i}' for i in range(pairs)]
    started: list[subprocess.Popen] = []
    with NamespaceNetwork(secrets.token_hex(3), hosts,
                          random.SystemRandom().randrange(1, 250)) as network:
        try:
            logs = []
            for index in range(pairs):
                host = network.hosts[f'worker{index}']
                namespace = f'/w{index}'
                log = work / f'pairs{pairs}-simulator{index}.log'
                logs.append(log)
                for command, path in (
                        (['ros2', 'run', 'sessgan_sim', 'simulator', '--ros-args', '-r',
                          f'__ns:={namespace}', '-p',
                          f'bags_root:={work / f"worker{pairs}-{index}"}'], log),
                        ([sys.executable, str(EXTERNAL_CONTROLLER), '--blind', '--ros-args',
                          '-r', f'__ns:={namespace}', '-p', 'use_sim_time:=true'],
                         work / f'pairs{pairs}-controller{index}.log')):
                    with open(path, 'wb') as handle:
                        started.append(subprocess.Popen(
                            host.command(command), stdout=handle, stderr=subprocess.STDOUT,
                            env=env, start_new_session=True))
            deadline = time.monotonic() + args.timeout
            while not all('simulator ready' in log.read_text() for log in logs):
                if time.monotonic() > deadline:
                    raise RuntimeError(f'simulators not ready within {args.timeout} s')
                time.sleep(0.2)
            run = f'bench-{pairs}'
            cpu_before = children_cpu()
            began = time.monotonic()
            campaign = subprocess.run(network.hosts['campaign'].command(
                ['ros2', 'run', 'sessgan_evolver', 'campaign', '--external', '--scenario',
                 'factory', '--generations', str(args.generations), '--population',
                 str(args.population), '--maps-per-member', str(args.maps_per_member),
                 '--time-limit', str(args.time_limit), '--seed', '7', '--run', run,
                 '--runs-root', str(work / 'runs'), '--bags-root', str(work / 'bags'),
                 '--worker-bags', 'remove']),
                capture_output=True, text=True, env=env, timeout=args.timeout)
            wall = time.monotonic() - began
            cpu = children_cpu() - cpu_before
        finally:
            for process in started:
                try:
                    os.killpg(process.pid, 9)
                except ProcessLookupError:
                    pass
                process.wait(timeout=10)
    if campaign.returncode != 0:
        raise RuntimeError(f'campaign with {pairs} pairs failed:\n{campaign.stderr[-3000:]}')
    overhead = OVERHEAD.search(campaign.stderr)
    done = DONE.search(campaign.stderr)
    if overhead is None or done is None:
        raise RuntimeError(f'no overhead or done line:\n{campaign.stderr[-3000:]}')
    episodes = int(done.group(1))
    # The campaign's loop time: from its first log line to the end, less start-up (generator
    # and discovery): measured by the campaign's own 'elapsed' of its last generation line.
    elapsed = re.findall(r'elapsed (\d+):(\d+)', campaign.stderr)
    loop = int(elapsed[-1][0]) * 60 + int(elapsed[-1][1]) if elapsed else wall
    return {'pairs': pairs, 'episodes': episodes, 'wall': wall, 'loop': loop,
            'per_minute': 60.0 * episodes / max(loop, 1e-9),
            'generator_ms': float(overhead.group(2)), 'dispatch_ms': float(overhead.group(3)),
            'bag_ms': float(overhead.group(4)), 'bags': int(overhead.group(5)),
            'campaign_cpu_ms': float(overhead.group(6)),
            'cpu_per_episode': cpu / max(1, episodes)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--pairs', default='1,2,4')
    parser.add_argument('--generations', type=int, default=2)
    parser.add_argument('--population', type=int, default=4)
    parser.add_argument('--maps-per-member', type=int, default=2)
    parser.add_argument('--time-limit', type=float, default=15.0)
    parser.add_argument('--timeout', type=float, default=900.0)
    args = parser.parse_args()
    reason = unavailable_reason()
    if reason:
        print(f'bench_multihost: {reason}', file=sys.stderr)
        return 2
    results = []
    with tempfile.TemporaryDirectory(prefix='bench_multihost-') as directory:
        for pairs in [int(value) for value in args.pairs.split(',')]:
            result = run_setup(pairs, args, Path(directory))
            results.append(result)
            print(f'{pairs} worker host(s): {result["episodes"]} episodes in '
                  f'{result["loop"]:.0f} s of campaign loop ({result["wall"]:.0f} s with '
                  f'start-up): {result["per_minute"]:.1f} episodes/min; overhead per episode: '
                  f'generator {result["generator_ms"]:.1f} ms, dispatch '
                  f'{result["dispatch_ms"]:.1f} ms, bag transfer {result["bag_ms"]:.1f} ms '
                  f'({result["bags"]} bags); CPU per episode: campaign loop '
                  f'{result["campaign_cpu_ms"]:.0f} ms, campaign + generator processes with '
                  f'start-up {result["cpu_per_episode"] * 1e3:.0f} ms', flush=True)
    print(f'machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the end '
          '(shared with other work); lockstep episodes, so workers compete for the cores')
    # One campaign process is one thread: it saturates when its busy time per episode (CPU
    # of its loop, plus the generator it waits for, plus bag copies) fills an episode's time.
    last = results[-1]
    busy = (last['campaign_cpu_ms'] + last['generator_ms'] + last['bag_ms']) / 1e3
    for episode_seconds in (10.0, 60.0):
        print(f'model: with {episode_seconds:.0f} s episodes (a clocked Nav2 stack), '
              f'{busy * 1e3:.0f} ms of campaign work per episode (loop CPU '
              f'{last["campaign_cpu_ms"]:.0f} + generator {last["generator_ms"]:.0f} + bags '
              f'{last["bag_ms"]:.0f} ms, at {last["pairs"]} hosts) keeps about '
              f'{episode_seconds / busy:.0f} worker pairs busy')
    return 0


if __name__ == '__main__':
    sys.exit(main())
