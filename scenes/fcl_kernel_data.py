"""The compiled checks' data and set-up (`scenes.fcl_kernel`): where numba caches the kernels, the
decorator every kernel is compiled with, and the world's arrays packed into three buffers.

The cache is a user-writable directory (NUMBA_CACHE_DIR, else ~/.cache/can-recycling-suite/numba,
else the temporary directory), written atomically by numba, so that worker processes starting
together share it; where none is writable the kernels compile in memory, in every process.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np


def cache_candidates() -> list[Path]:
    """Where the kernels' cache may go, in order: NUMBA_CACHE_DIR if set, the user's cache
    (XDG_CACHE_HOME or ~/.cache) under can-recycling-suite/numba, then the temporary directory."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return [*([Path(env)] if env else []), Path(base) / "can-recycling-suite" / "numba",
            Path(tempfile.gettempdir()) / f"can-recycling-suite-numba-{os.getuid()}"]


def cache_dir(candidates: list[Path] | None = None) -> Path | None:
    """The first writable directory of `candidates` (default `cache_candidates()`), created if
    need be; None if none is writable (the kernels then compile in memory, in every process)."""
    for d in cache_candidates() if candidates is None else candidates:
        try:
            d.mkdir(parents=True, exist_ok=True)
            probe = tempfile.NamedTemporaryFile(dir=d, prefix=".probe", delete=True)
            probe.close()
            return d
        except OSError:
            continue
    return None


_CACHE = cache_dir()
if _CACHE is not None:
    os.environ.setdefault("NUMBA_CACHE_DIR", str(_CACHE))

import numba  # noqa: E402  (after NUMBA_CACHE_DIR is set: numba reads it on import)

if _CACHE is not None and numba.config.CACHE_DIR != str(_CACHE):
    numba.config.CACHE_DIR = str(_CACHE)  # numba was imported before this module

_jit = numba.njit(cache=_CACHE is not None, nogil=True, fastmath=False, error_model="numpy")


#: The world's arrays packed into three buffers (one dispatch argument each: a numba call pays
#: about 60 ns per argument, more than a state's sphere tier with 26 of them).
FLOAT_FIELDS = ("Mc", "Ms", "M1", "rows0", "obs_ctr", "obs_half", "R2", "rho2", "tab_lo", "tab_inv", "tab_n",
                "row_chain", "pair_r", "pair_self", "rows", "d2", "scratch", "lam_pair", "fine_rows0", "fine_out2",
                "fine_in2", "obs_rot", "sph")
INT_FIELDS = ("link_end", "s_row", "ia", "ib", "pp", "tab_j", "tab_k", "pair_b", "pair_counts", "pairs", "is_frame",
              "pp_part", "pp_obs", "part_link", "fine_start", "obs_type")
#: Each field's place, in the order above: the kernels read `_f(F, I, F_ROWS)`, never a bare number.
(F_MC, F_MS, F_M1, F_ROWS0, F_OBS_CTR, F_OBS_HALF, F_R2, F_RHO2, F_TAB_LO, F_TAB_INV, F_TAB_N, F_ROW_CHAIN,
    F_PAIR_R, F_PAIR_SELF, F_ROWS, F_D2, F_SCRATCH, F_LAM_PAIR, F_FINE_ROWS0, F_FINE_OUT2, F_FINE_IN2,
    F_OBS_ROT, F_SPH) = range(len(FLOAT_FIELDS))
(I_LINK_END, I_S_ROW, I_IA, I_IB, I_PP, I_TAB_J, I_TAB_K, I_PAIR_B, I_PAIR_COUNTS, I_PAIRS, I_IS_FRAME,
    I_PP_PART, I_PP_OBS, I_PART_LINK, I_FINE_START, I_OBS_TYPE) = range(len(INT_FIELDS))
#: Header of the int buffer: sizes, then (start, length) of every float field, then of every int field.
N_SIZES = 8
#: The sizes' places: robot rows, world rows, obstacles, sphere pairs, joint tables, scene pairs,
#: a table's width (cells + 1), part-level pairs.
(S_R, S_RT, S_O, S_P, S_T, S_NENV, S_TABW, S_NPP) = range(N_SIZES)
HEADER = N_SIZES + 2 * (len(FLOAT_FIELDS) + len(INT_FIELDS))
#: The scratch field: the joint transforms LT, the chain's W and V, and W_k of every link (kept
#: for the frame rows, which are mapped only when FCL needs them).
SCR_LT, SCR_W, SCR_V, SCR_WALL, SCRATCH = 0, 112, 124, 136, 220


def pack(fields: dict, sizes: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, I, C): every float field, every int field (after the header) and the table cells."""
    fl = [np.ascontiguousarray(fields[k], np.float64).ravel() for k in FLOAT_FIELDS]
    il = [np.ascontiguousarray(fields[k], np.int64).ravel() for k in INT_FIELDS]
    F = np.concatenate(fl) if fl else np.zeros(0)
    head = np.zeros(HEADER, np.int64)
    head[:N_SIZES] = sizes
    at = 0
    for f, a in enumerate(fl):
        head[N_SIZES + 2 * f], head[N_SIZES + 2 * f + 1] = at, len(a)
        at += len(a)
    at = HEADER
    base = N_SIZES + 2 * len(FLOAT_FIELDS)
    for f, a in enumerate(il):
        head[base + 2 * f], head[base + 2 * f + 1] = at, len(a)
        at += len(a)
    I = np.concatenate([head, *il])
    C = np.ascontiguousarray(fields["tab_cells"], np.uint8).ravel()
    return F, I, C


def float_field(F: np.ndarray, I: np.ndarray, name: str) -> np.ndarray:
    """A view of float field `name` in F (for Python: the rows FCL places parts by)."""
    f = FLOAT_FIELDS.index(name)
    a, n = I[N_SIZES + 2 * f], I[N_SIZES + 2 * f + 1]
    return F[a : a + n]


def int_field(I: np.ndarray, name: str) -> np.ndarray:
    f = N_SIZES + 2 * len(FLOAT_FIELDS) + 2 * INT_FIELDS.index(name)
    return I[I[f] : I[f] + I[f + 1]]


@_jit
def _f(F, I, f):
    a = I[N_SIZES + 2 * f]
    return F[a : a + I[N_SIZES + 2 * f + 1]]


@_jit
def _i(I, f):
    k = N_SIZES + 2 * len(FLOAT_FIELDS) + 2 * f
    return I[I[k] : I[k] + I[k + 1]]
