"""fmu_models/export/c/numpy_random.c reproduces numpy.random.default_rng(seed) bit for bit."""
from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

C_DIR = Path(__file__).resolve().parents[2] / "fmu_models" / "export" / "c"
N_DRAWS = 1000

FIXED_SEEDS = [0, 1, 2, 3, 42, 2**32 - 1, 2**32, 2**63, 2**64 - 1]
_seed_rng = np.random.default_rng(20240611)
RANDOM_SEEDS = [int(s) for s in _seed_rng.integers(0, 2**64, size=100, dtype=np.uint64, endpoint=False)] + [
    int(s) for s in _seed_rng.integers(0, 2**32, size=100, dtype=np.uint64)
]
ALL_SEEDS = FIXED_SEEDS + RANDOM_SEEDS


class NpPcg64(ctypes.Structure):
    _fields_ = [
        ("state_hi", ctypes.c_uint64),
        ("state_lo", ctypes.c_uint64),
        ("inc_hi", ctypes.c_uint64),
        ("inc_lo", ctypes.c_uint64),
    ]


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.skip("gcc not available")
    out = tmp_path_factory.mktemp("numpy_random") / "libnumpy_random.so"
    cmd = [gcc, "-shared", "-fPIC", "-O2", "-std=c99", "-Wall", "-Wextra", "-Werror",
           "-I", str(C_DIR), str(C_DIR / "numpy_random.c"), "-o", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == "", proc.stderr  # no warnings at all
    so = ctypes.CDLL(str(out))
    so.np_default_rng.argtypes = [ctypes.POINTER(NpPcg64), ctypes.c_uint64]
    so.np_default_rng.restype = None
    so.np_next_uint64.argtypes = [ctypes.POINTER(NpPcg64)]
    so.np_next_uint64.restype = ctypes.c_uint64
    so.np_random.argtypes = [ctypes.POINTER(NpPcg64)]
    so.np_random.restype = ctypes.c_double
    return so


def _seeded(lib, seed: int) -> NpPcg64:
    rng = NpPcg64()
    lib.np_default_rng(ctypes.byref(rng), seed)
    return rng


def _draw(lib, rng: NpPcg64, n: int) -> np.ndarray:
    ref = ctypes.byref(rng)
    f = lib.np_random
    return np.array([f(ref) for _ in range(n)], dtype=np.float64)


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.array_equal(a.view(np.uint64), b.view(np.uint64)))


def test_seeding_matches_numpy_state(lib):
    """The struct after np_default_rng is numpy's PCG64 state/inc, word for word."""
    for seed in ALL_SEEDS:
        rng = _seeded(lib, seed)
        st = np.random.default_rng(seed).bit_generator.state["state"]
        assert (rng.state_hi << 64 | rng.state_lo) == st["state"], seed
        assert (rng.inc_hi << 64 | rng.inc_lo) == st["inc"], seed


def test_random_matches_numpy_bit_for_bit(lib):
    for seed in ALL_SEEDS:
        got = _draw(lib, _seeded(lib, seed), N_DRAWS)
        expected = np.random.default_rng(seed).random(N_DRAWS)
        assert _same_bits(got, expected), f"seed {seed}: first mismatch at {np.flatnonzero(got != expected)[:1]}"
        assert np.all((got >= 0.0) & (got < 1.0))


def test_next_uint64_matches_random_raw(lib):
    for seed in FIXED_SEEDS + RANDOM_SEEDS[:20]:
        rng = _seeded(lib, seed)
        got = [lib.np_next_uint64(ctypes.byref(rng)) for _ in range(50)]
        expected = np.random.default_rng(seed).bit_generator.random_raw(50)
        assert got == [int(v) for v in expected], seed


def test_uint64_and_random_share_one_stream(lib):
    """Interleaving raw and double draws consumes one uint64 each, as numpy does."""
    seed = 123456789
    rng = _seeded(lib, seed)
    ref = np.random.default_rng(seed)
    for i in range(100):
        if i % 3:
            assert lib.np_random(ctypes.byref(rng)) == ref.random()
        else:
            assert lib.np_next_uint64(ctypes.byref(rng)) == int(ref.bit_generator.random_raw())


def test_state_is_plain_data(lib):
    """Copying the struct mid-stream (memmove, as an FMU state save would) and continuing
    from the copy gives the same continuation as the original and as numpy."""
    seed = 2**40 + 7
    rng = _seeded(lib, seed)
    head = _draw(lib, rng, 300)

    saved = NpPcg64()
    ctypes.memmove(ctypes.byref(saved), ctypes.byref(rng), ctypes.sizeof(NpPcg64))
    assert ctypes.sizeof(NpPcg64) == 32
    snapshot = bytes(saved)

    tail_original = _draw(lib, rng, 700)
    tail_copy = _draw(lib, saved, 700)
    assert _same_bits(tail_original, tail_copy)
    assert _same_bits(np.concatenate([head, tail_copy]), np.random.default_rng(seed).random(1000))

    # restoring the saved bytes into the advanced original rewinds it
    restored = NpPcg64.from_buffer_copy(snapshot)
    ctypes.memmove(ctypes.byref(rng), ctypes.byref(restored), ctypes.sizeof(NpPcg64))
    assert _same_bits(_draw(lib, rng, 700), tail_copy)
