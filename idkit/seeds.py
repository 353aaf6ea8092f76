"""Seeds: any integer in ``[0, 2**64)``, one random stream per seed.

Every seeded random draw in idkit (noise, swarms, multi-starts, random states for base
parameters, excitation search) comes from a generator made here. The whole seed goes into numpy's
``SeedSequence``, which hashes it into as many state words as a generator needs, so two seeds
give unrelated streams — also seeds that differ only in high bits. Handing the seed to torch
directly does not: the CPU generator (a Mersenne Twister) keeps only the low 32 bits of
``manual_seed``'s argument (measured: seeds ``0``, ``2**32`` and ``2**63`` drew the same numbers),
and ``2**64`` overflowed. So:

* a CPU ``torch.Generator`` gets its whole 624-word Mersenne-Twister state from the sequence
  (:func:`torch_generator`; its ``initial_seed()`` is the seed);
* any other device's generator (CUDA's Philox takes a 64-bit key) is seeded with 64 bits of it.

Refused in one line: a bool, a float, a string, a negative integer or one ``>= 2**64``.
``Seed`` is the annotation for a seed option, so a config's ``seed=2**64`` is refused with the
other options, before anything runs.
"""

from __future__ import annotations

import functools
import numbers
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np

if TYPE_CHECKING:
    import torch

#: Seeds are the integers ``0 <= seed < SEED_BOUND``.
SEED_BOUND = 2**64
#: Words of torch's CPU Mersenne-Twister state, and where they start in ``Generator.get_state()``
#: (``uint64 seed; int left; int seeded; uint64 next; uint64 state[624]; ...``, 5056 bytes).
_MT_WORDS, _MT_OFFSET, _CPU_STATE_BYTES = 624, 24, 5056


def check_seed(seed: Any, name: str = "seed") -> int:
    """``seed`` as a Python ``int`` if it is an integer in ``[0, 2**64)``, else ``ValueError``.

    Numpy integers are accepted; ``True``/``False`` and whole floats are not (a seed is no number
    to round).
    """
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, numbers.Integral):
        raise ValueError(f"{name} must be an integer in [0, 2**64), got {seed!r} ({type(seed).__name__})")
    if not 0 <= int(seed) < SEED_BOUND:
        raise ValueError(f"{name} must be an integer in [0, 2**64), got {int(seed)}")
    return int(seed)


def trial_seed(seed: int, trial: int) -> int:
    """The seed of trial ``trial`` of a study seeded ``seed``: ``seed + trial`` modulo ``2**64``."""
    return (check_seed(seed) + trial) % SEED_BOUND


def seed_sequence(seed: int) -> np.random.SeedSequence:
    """numpy's ``SeedSequence`` of the whole seed (checked)."""
    return np.random.SeedSequence(check_seed(seed))


def torch_generator(seed: int, device: Any = "cpu") -> torch.Generator:
    """A fresh ``torch.Generator`` on ``device`` whose whole state comes from ``seed``.

    Same seed and device → the same numbers; different seeds → independent streams.
    """
    import torch

    device = torch.device(device)
    sequence = seed_sequence(seed)
    generator = torch.Generator(device=device)
    if device.type != "cpu":
        return generator.manual_seed(int(sequence.generate_state(1, np.uint64)[0]))
    state = _seeded_cpu_state().copy()
    state[:8] = np.array([check_seed(seed)], dtype=np.uint64).view(np.uint8)
    words = sequence.generate_state(_MT_WORDS, np.uint32).astype(np.uint64)
    state[_MT_OFFSET : _MT_OFFSET + 8 * _MT_WORDS] = words.view(np.uint8)
    generator.set_state(torch.from_numpy(state))
    return generator


@functools.cache
def _seeded_cpu_state() -> np.ndarray:
    """A freshly seeded CPU state (next draw twists the words) after checking its layout."""
    import torch

    probe = 0x0123_4567_89AB_CDEF
    state = torch.Generator().manual_seed(probe).get_state().numpy().copy()
    header = (
        state[:8].view(np.uint64)[0],
        state[8:16].view(np.int32).tolist(),
        state[16:24].view(np.uint64)[0],
    )
    first = state[_MT_OFFSET : _MT_OFFSET + 8].view(np.uint64)[0]
    if state.size != _CPU_STATE_BYTES or header != (probe, [1, 1], 0) or first != probe & 0xFFFF_FFFF:
        raise RuntimeError(
            f"torch {torch.__version__}: unknown CPU generator state layout; idkit.seeds needs updating"
        )
    return state


class _SeedRule:
    """pydantic hook of :data:`Seed` (pydantic imported lazily): :func:`check_seed`, after turning
    a string of digits into its integer, as a command line passes ``seed='7'``. A float is refused,
    not rounded: ``1e19`` is not exactly an integer a user typed."""

    def __get_pydantic_core_schema__(self, source: Any, handler: Any) -> Any:
        from pydantic_core import PydanticCustomError, core_schema

        def validate(value: Any) -> int:
            digits = isinstance(value, str) and value.strip().isdigit() and value.strip().isascii()
            try:
                return check_seed(int(value) if digits else value)
            except ValueError:
                kind = " (a bool is not one)" if isinstance(value, (bool, np.bool_)) else ""
                raise PydanticCustomError("seed", f"seeds are the integers 0 to 2**64 - 1{kind}") from None

        return core_schema.no_info_plain_validator_function(validate)


#: Annotation of a seed option or setting: ``seed: Seed = 0`` (checked by ``idkit.options``).
Seed = Annotated[int, _SeedRule()]
