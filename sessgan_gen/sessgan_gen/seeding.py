"""Seeding: every random choice of training and sampling flows from one seed set here."""

from __future__ import annotations

import os
import random

import numpy as np
import torch

SEED_MODULUS = 2**63 - 1
"""Seeds are reduced into this range so any Python int is accepted by torch.Generator."""


def seed_everything(seed: int, deterministic: bool = True) -> None:
    """Seed Python's ``random``, NumPy and torch (CPU and CUDA) from ``seed``.

    With ``deterministic``, torch is asked for deterministic algorithms (warning,
    not failing, where an operation has none), so a training run repeats bit for
    bit on the same device and thread count.
    """
    seed = int(seed) % SEED_MODULUS
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    if deterministic:
        # cuBLAS is deterministic only with a fixed workspace; read when CUDA starts.
        os.environ.setdefault('CUBLAS_WORKSPACE_CONFIG', ':4096:8')
        torch.use_deterministic_algorithms(True, warn_only=True)
        torch.backends.cudnn.benchmark = False


def derive_seeds(base_seed: int, count: int, stream: int = 0) -> list[int]:
    """``count`` well-spread 63-bit seeds derived from ``base_seed`` (and a ``stream`` number
    to get independent lists); the same arguments always give the same list."""
    sequence = np.random.SeedSequence([int(base_seed) % SEED_MODULUS, int(stream)])
    return [int(value) % SEED_MODULUS for value in sequence.generate_state(count, np.uint64)]
