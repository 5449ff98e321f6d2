"""Checkpointable random numbers: xoshiro256** with its state in a uint64[4] array.

The state is an ordinary array, so it is saved with every checkpoint and a resumed run
draws exactly the numbers an uninterrupted run would.
``seed_state`` expands a 64-bit seed with splitmix64, as the generator's authors advise.
The ``*_reference`` functions are plain-Python twins that tests compare against.
"""

from __future__ import annotations

import numpy as np

from .._jit import jit

__all__ = ["seed_state", "next_u64", "next_double", "next_below", "fill_uniform"]

_MASK = (1 << 64) - 1
_U7 = np.uint64(7)
_U11 = np.uint64(11)
_U17 = np.uint64(17)
_U45 = np.uint64(45)
_U5 = np.uint64(5)
_U9 = np.uint64(9)
_TWO_M53 = 1.0 / 9007199254740992.0


def seed_state(seed: int, stream: int = 0) -> np.ndarray:
    """Generator state (uint64[4]) from a seed and an optional stream number (splitmix64)."""
    x = (int(seed) * 0x9E3779B97F4A7C15 + int(stream) * 0xD1B54A32D192ED03) & _MASK
    out = []
    for _ in range(4):
        x = (x + 0x9E3779B97F4A7C15) & _MASK
        z = x
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
        out.append(z ^ (z >> 31))
    if not any(out):  # the all-zero state is the generator's one fixed point
        out[0] = 1
    return np.array(out, dtype=np.uint64)


@jit
def _rotl(x, k):
    return (x << k) | (x >> (np.uint64(64) - k))


@jit
def next_u64(state):
    """Next 64-bit output; advances ``state`` in place."""
    s0 = state[0]
    s1 = state[1]
    s2 = state[2]
    s3 = state[3]
    result = _rotl(s1 * _U5, _U7) * _U9
    t = s1 << _U17
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = _rotl(s3, _U45)
    state[0] = s0
    state[1] = s1
    state[2] = s2
    state[3] = s3
    return result


@jit
def next_double(state):
    """Uniform float64 in [0, 1) from the top 53 bits."""
    return np.float64(next_u64(state) >> _U11) * _TWO_M53


@jit
def next_below(state, n):
    """Integer in [0, n) (n >= 1); the bias of the float method is below 2^-53 * n."""
    k = np.int64(next_double(state) * n)
    return k if k < n else n - 1


@jit
def fill_uniform(state, out):
    """Fill ``out`` (float64, any shape, C order) with uniforms in [0, 1)."""
    flat = out.reshape(-1)
    for i in range(flat.size):
        flat[i] = next_double(state)


def next_u64_reference(state: list[int]) -> int:
    """Plain-Python twin of :func:`next_u64` on a list of four Python ints."""
    s0, s1, s2, s3 = state
    rotl = lambda x, k: ((x << k) | (x >> (64 - k))) & _MASK  # noqa: E731
    result = (rotl((s1 * 5) & _MASK, 7) * 9) & _MASK
    t = (s1 << 17) & _MASK
    s2 ^= s0
    s3 ^= s1
    s1 ^= s2
    s0 ^= s3
    s2 ^= t
    s3 = rotl(s3, 45)
    state[:] = [s0, s1, s2, s3]
    return result
