"""One-hot token maps and token-aware downsampling (TOAD-GAN's special downsampling).

Plain bilinear downsampling of a one-hot map blurs thin structures (a one-cell
wall, a narrow track) into a mixture that the argmax then drops. TOAD-GAN keeps
them: after the bilinear step, the highest token of the scenario's hierarchy
that is present in a cell wins it, and a sharp softmax turns the cell back into
an almost one-hot vector, so real maps at every scale look like generator output.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
import torch.nn.functional as F

SOFTMAX_SHARPNESS = 30.0
"""Temperature of the softmax applied after the hierarchy step (TOAD-GAN uses 30)."""

PRESENCE_THRESHOLD = 0.5
"""Bilinear weight from which a token counts as present in a downsampled cell: it must
cover at least half of the cell. TOAD-GAN counts any weight > 0, which suits sparse
special tokens but turns a dense factory into solid wall at the coarsest scale (98 %
W at 8x8, no layout left); at half, a one-cell straight wall or track still covers
half of every 2x2 block it crosses and survives each halving, while open areas follow
the majority."""


def one_hot(cells: np.ndarray | torch.Tensor, num_tokens: int) -> torch.Tensor:
    """Return the one-hot float tensor (1, num_tokens, height, width) of a token-id map."""
    ids = torch.as_tensor(np.asarray(cells), dtype=torch.long)
    if ids.ndim != 2:
        raise ValueError(f'a token map must be 2-D (height, width), got shape {tuple(ids.shape)}')
    if ids.numel() and (int(ids.min()) < 0 or int(ids.max()) >= num_tokens):
        raise ValueError(
            f'token ids must lie in 0..{num_tokens - 1}, got {int(ids.min())}..{int(ids.max())}')
    return F.one_hot(ids, num_tokens).permute(2, 0, 1).unsqueeze(0).float()


def token_aware_downsample(
    image: torch.Tensor,
    size: tuple[int, int],
    hierarchy: Sequence[int],
    sharpness: float = SOFTMAX_SHARPNESS,
) -> torch.Tensor:
    """Downsample a one-hot map (batch, tokens, h, w) to ``size`` = (height, width).

    Bilinear (antialiased when shrinking by more than 2, so every fine cell under
    a coarse cell contributes), then in each cell only the highest token of
    ``hierarchy`` (ids from lowest to highest priority) that is present (weight at
    least PRESENCE_THRESHOLD) keeps its weight, then a softmax with ``sharpness``
    makes the cell nearly one-hot again.
    """
    num_tokens = image.shape[1]
    if sorted(hierarchy) != list(range(num_tokens)):
        raise ValueError(
            f'hierarchy {tuple(hierarchy)} must list each of {num_tokens} tokens once')
    if tuple(size) == tuple(image.shape[-2:]):
        return image.clone()
    # Up to a factor 2, plain bilinear already averages every fine cell of a block.
    antialias = size[0] * 2 < image.shape[-2] or size[1] * 2 < image.shape[-1]
    blurred = F.interpolate(image, size=tuple(size), mode='bilinear', align_corners=False,
                            antialias=antialias)
    rank = torch.empty(num_tokens, dtype=torch.long)
    rank[torch.as_tensor(list(hierarchy))] = torch.arange(num_tokens)
    rank = rank.view(1, num_tokens, 1, 1).to(image.device)
    present = blurred >= PRESENCE_THRESHOLD - 1e-6  # 0.5 exactly on a 2x2 block edge
    # Highest rank present per cell; cells with nothing present keep every token.
    best_rank = torch.where(present, rank, torch.full_like(rank, -1)).amax(dim=1, keepdim=True)
    kept = torch.where(rank == best_rank, blurred, torch.zeros_like(blurred))
    kept = torch.where(best_rank < 0, blurred, kept)
    return torch.softmax(sharpness * kept, dim=1)


def downsample_pyramid(
    image: torch.Tensor,
    shapes: Sequence[tuple[int, int]],
    hierarchy: Sequence[int],
) -> list[torch.Tensor]:
    """Return ``image`` at every shape of ``shapes`` (coarsest first).

    Each scale is made from the next finer one (finest first), so a coarse cell
    inherits every token present in its block; a shape equal to the image's own
    keeps the exact one-hot map.
    """
    scaled = []
    current = image
    for shape in reversed(list(shapes)):
        current = token_aware_downsample(current, (int(shape[0]), int(shape[1])), hierarchy)
        scaled.append(current)
    return scaled[::-1]
