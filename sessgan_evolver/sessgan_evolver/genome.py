"""The genome: the evolvable tensors of one generator pyramid.

A generator pyramid's ``state_dict()`` holds three kinds of entries:

* learned weights: convolution ``weight``/``bias`` and BatchNorm ``weight``/``bias``;
* BatchNorm statistics: ``running_mean`` and ``running_var`` (float buffers);
* bookkeeping that evolution must not touch: BatchNorm ``num_batches_tracked`` (an integer
  counter) and the pyramid's fixed noise buffers (noise amplitudes, reconstruction noise),
  which were calibrated during training and define what a seed means.

The rule (``is_evolvable_entry``): an entry is evolvable when it is a floating-point tensor
AND the last component of its dotted name is one of ``EVOLVABLE_LEAF_NAMES``
(``weight``, ``bias``, ``running_mean``, ``running_var``). Noise buffers have other leaf
names, counters are integers, so both stay fixed. A caller with a different model passes
its own ``KeyPredicate``.

A ``Genome`` holds only the evolvable tensors, in state-dict order; ``to_state_dict``
merges it back into the pre-trained state dict (the template) to load a generator.
"""

from __future__ import annotations

import hashlib
import io
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass

import torch

from sessgan_evolver.errors import GenomeError

KeyPredicate = Callable[[str, torch.Tensor], bool]
"""Decides from a state-dict entry's name and tensor whether evolution may change it."""

EVOLVABLE_LEAF_NAMES = frozenset({'weight', 'bias', 'running_mean', 'running_var'})
"""Last dotted-name components of the entries the default rule evolves."""

POSITIVE_LEAF_NAMES = frozenset({'running_var'})
"""Entries that must stay strictly positive after any change (BatchNorm variances)."""

GENOME_FORMAT = 'sessgan_evolver.genome/1'
"""Tag stored with serialized genomes; bytes without it are rejected."""


def is_evolvable_entry(name: str, tensor: torch.Tensor) -> bool:
    """The default rule: float tensors whose leaf name is in ``EVOLVABLE_LEAF_NAMES``."""
    return tensor.is_floating_point() and name.rsplit('.', 1)[-1] in EVOLVABLE_LEAF_NAMES


def must_stay_positive(name: str) -> bool:
    """Whether the entry ``name`` is a variance that must stay > 0 (see ``clamp_positive``)."""
    return name.rsplit('.', 1)[-1] in POSITIVE_LEAF_NAMES


@dataclass(eq=False)
class Genome:
    """The evolvable tensors of one generator, name -> tensor, in state-dict order.

    Tensors are detached, contiguous and on the CPU. A genome is treated as a value:
    operators return new genomes and never modify their inputs.
    """

    tensors: dict[str, torch.Tensor]

    def __post_init__(self) -> None:
        for name, tensor in self.tensors.items():
            if not isinstance(tensor, torch.Tensor):
                raise GenomeError(f'genome entry {name!r} is a {type(tensor).__name__}, '
                                  f'not a tensor')
            if not tensor.is_floating_point():
                raise GenomeError(f'genome entry {name!r} has dtype {tensor.dtype}; '
                                  f'only floating-point tensors evolve')

    # -- mapping-like access ------------------------------------------------------------

    def __getitem__(self, name: str) -> torch.Tensor:
        return self.tensors[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.tensors)

    def __len__(self) -> int:
        return len(self.tensors)

    def names(self) -> list[str]:
        """Entry names in state-dict order."""
        return list(self.tensors)

    def items(self) -> Iterator[tuple[str, torch.Tensor]]:
        return iter(self.tensors.items())

    @property
    def num_values(self) -> int:
        """Total number of scalar values (the search space's dimension)."""
        return sum(int(t.numel()) for t in self.tensors.values())

    # -- values ---------------------------------------------------------------------------

    def clone(self) -> Genome:
        """A deep copy (tensors are copied)."""
        return Genome({name: t.clone() for name, t in self.tensors.items()})

    def equals(self, other: Genome) -> bool:
        """Same names in the same order, same dtypes and shapes, bitwise-equal values."""
        if self.names() != other.names():
            return False
        return all(a.dtype == b.dtype and a.shape == b.shape and torch.equal(a, b)
                   for a, b in zip(self.tensors.values(), other.tensors.values()))

    def digest(self) -> str:
        """SHA-256 hex digest of names, dtypes, shapes and raw bytes: equal digests,
        equal genomes (used to log and compare populations cheaply)."""
        hasher = hashlib.sha256()
        for name, tensor in self.tensors.items():
            hasher.update(f'{name}|{tensor.dtype}|{tuple(tensor.shape)}|'.encode())
            hasher.update(_tensor_bytes(tensor))
        return hasher.hexdigest()

    def check_compatible(self, other: Genome) -> None:
        """Raise GenomeError unless ``other`` has the same entries, shapes and dtypes."""
        if self.names() != other.names():
            missing = sorted(set(self.names()) ^ set(other.names()))
            raise GenomeError(f'genomes have different entries (differing: {missing[:5]}'
                              f'{"..." if len(missing) > 5 else ""}; or a different order)')
        for name, a in self.tensors.items():
            b = other.tensors[name]
            if a.shape != b.shape or a.dtype != b.dtype:
                raise GenomeError(f'genome entry {name!r}: {tuple(a.shape)} {a.dtype} vs '
                                  f'{tuple(b.shape)} {b.dtype}')

    # -- state dicts ----------------------------------------------------------------------

    @classmethod
    def from_state_dict(cls, state_dict: Mapping[str, torch.Tensor],
                        is_evolvable: KeyPredicate = is_evolvable_entry) -> Genome:
        """Copy the evolvable entries of a generator's state dict (in its order)."""
        tensors = {name: tensor.detach().to('cpu').clone().contiguous()
                   for name, tensor in state_dict.items()
                   if isinstance(tensor, torch.Tensor) and is_evolvable(name, tensor)}
        if not tensors:
            raise GenomeError('the state dict has no evolvable entries '
                              f'(its entries: {list(state_dict)[:8]})')
        return cls(tensors)

    def to_state_dict(self, template: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """A full state dict: ``template`` (the pre-trained one) with this genome's tensors
        substituted. Shapes and dtypes must match the template's entries."""
        merged = dict(template)
        for name, tensor in self.tensors.items():
            if name not in template:
                raise GenomeError(f'genome entry {name!r} is not in the template state dict')
            reference = template[name]
            if reference.shape != tensor.shape or reference.dtype != tensor.dtype:
                raise GenomeError(
                    f'genome entry {name!r} is {tuple(tensor.shape)} {tensor.dtype}; the '
                    f'template has {tuple(reference.shape)} {reference.dtype}')
            merged[name] = tensor.clone()
        return merged

    # -- bytes ----------------------------------------------------------------------------

    def to_plain(self) -> dict[str, torch.Tensor]:
        """A plain ``dict`` of tensor copies (what checkpoints and ``to_bytes`` store)."""
        return {name: t.clone() for name, t in self.tensors.items()}

    @classmethod
    def from_plain(cls, tensors: Mapping[str, torch.Tensor]) -> Genome:
        """Inverse of ``to_plain``."""
        if not isinstance(tensors, Mapping):
            raise GenomeError(f'a genome must be a mapping of tensors, got '
                              f'{type(tensors).__name__}')
        return cls({str(name): t.detach().to('cpu').clone().contiguous()
                    for name, t in tensors.items()})

    def to_bytes(self) -> bytes:
        """Serialize with ``torch.save`` (no numpy objects inside, so ``weights_only``
        loading works); suitable for checkpoints and for a ROS ``uint8[]`` field."""
        buffer = io.BytesIO()
        torch.save({'format': GENOME_FORMAT, 'tensors': self.to_plain()}, buffer)
        return buffer.getvalue()

    @classmethod
    def from_bytes(cls, data: bytes | bytearray | memoryview) -> Genome:
        """Inverse of ``to_bytes``; GenomeError for bytes that are not a genome."""
        try:
            payload = torch.load(io.BytesIO(bytes(data)), map_location='cpu',
                                 weights_only=True)
        except Exception as err:  # torch raises many types for corrupt input
            raise GenomeError(f'cannot read genome bytes ({len(data)} bytes): {err}') from err
        if not isinstance(payload, dict) or payload.get('format') != GENOME_FORMAT:
            raise GenomeError(f'bytes are not a serialized genome (expected format '
                              f'{GENOME_FORMAT!r})')
        return cls.from_plain(payload['tensors'])


def clamp_positive(genome: Genome, minimum: float) -> Genome:
    """Return ``genome`` with every variance entry (``must_stay_positive``) clamped to at
    least ``minimum`` (> 0); other entries are shared, not copied."""
    if not minimum > 0:
        raise GenomeError(f'the variance floor must be > 0, got {minimum}')
    return Genome({name: (t.clamp(min=minimum) if must_stay_positive(name) else t)
                   for name, t in genome.items()})


def _tensor_bytes(tensor: torch.Tensor) -> bytes:
    """Raw bytes of a CPU tensor (viewed as uint8 first, so bfloat16 works too)."""
    flat = tensor.detach().to('cpu').contiguous().reshape(-1)
    return flat.view(torch.uint8).numpy().tobytes() if flat.numel() else b''
