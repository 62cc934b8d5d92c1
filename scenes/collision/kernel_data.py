"""The compiled checks' data and set-up (`scenes.collision.kernel_state`): the world's arrays packed
into three buffers and their layout, the decorator every kernel is compiled with, and numba's disk
cache of the kernels, keyed so that it cannot go stale.

numba freezes the globals a kernel reads (the field indices F_*, I_*, S_*, SCR_* below, the codes
of `scenes.collision.kernel_codes`) into its cached code and invalidates a cached function only
when its own file changes: an edit of the field list here would leave the kernels of
`scenes.collision.kernel_state` and `scenes.collision.kernel_motion` reading the wrong fields. So the cache is keyed on `KEY`, a hash of the kernel modules' sources
(`KERNEL_MODULES`, found by module name through importlib, not by path: the files may move) and of
the field layout (`layout()`): every kernel's cache lives under `collision-kernels-<KEY[:16]>` in the
cache directory, with `KEY` as numba's source stamp. Another key is another directory; the same
sources at another path load the same cache.

The cache is attached to each kernel's dispatcher (a cache locator of its own), not through
NUMBA_CACHE_DIR or `numba.config`: numba re-reads its environment on every compile and applies it
to every cached function of the process, and a key in an inherited variable would nest in worker
processes. The base directory is user-writable (NUMBA_CACHE_DIR, else
~/.cache/can-recycling-suite/numba, else the temporary directory), written atomically by numba,
so that worker processes starting together share it; where none is writable, or a load or a save
fails, the kernels compile in memory, in this process.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import logging
import os
import tempfile
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

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


#: The modules whose kernels the cache holds (by name, within this package). A kernel compiled
#: with `_jit` in any other module is refused at import: its sources would not be in the key.
KERNEL_MODULES = ("kernel_codes", "kernel_data", "kernel_state", "kernel_motion")


def layout() -> dict[str, object]:
    """The field layout the kernels read: the field lists, every F_*, I_*, S_* and SCR_* index,
    N_SIZES, HEADER and SCRATCH, by name."""
    g = globals()
    names = [k for k in g if k.split("_", 1)[0] in ("F", "I", "S", "SCR") and k.isupper() and "_" in k]
    return {k: g[k] for k in sorted([*names, "FLOAT_FIELDS", "INT_FIELDS", "N_SIZES", "HEADER", "SCRATCH"])}


def kernel_sources(modules: tuple[str, ...] = KERNEL_MODULES, package: str = __package__) -> dict[str, str]:
    """Each kernel module's source, found by module name (`importlib.util.find_spec`), not by path.

    Raises:
        RuntimeError: a module is not found or has no source (the key would not cover it).
    """
    out = {}
    for m in modules:
        name = f"{package}.{m}"
        spec = importlib.util.find_spec(name)
        source = spec.loader.get_source(name) if spec is not None and spec.loader is not None else None
        if source is None:
            raise RuntimeError(f"kernel module {name} has no source to key numba's cache on")
        out[m] = source
    return out


def cache_key(sources: dict[str, str], fields: dict[str, object]) -> str:
    """The cache's key: sha256 (hex) of the kernel sources and the field layout, in name order."""
    h = hashlib.sha256()
    for name in sorted(sources):
        h.update(f"module {name} {len(sources[name])}\n".encode())
        h.update(sources[name].encode())
    h.update(repr(sorted(fields.items())).encode())
    return h.hexdigest()


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


def keyed_path(base: Path, key: str) -> Path:
    """The directory of the kernels' cache keyed `key` under `base`."""
    return base / f"collision-kernels-{key[:16]}"


KEY = cache_key(kernel_sources(), layout())
_BASE = cache_dir()
#: Where this process's kernels are cached (None: compiled in memory).
CACHE_PATH = keyed_path(_BASE, KEY) if _BASE is not None else None

import numba  # noqa: E402


@functools.lru_cache(maxsize=None)
def _cache_class(path: str, key: str):
    """A numba `FunctionCache` whose every function lives in `path` with source stamp `key`; None
    if this numba has no such interface (the kernels then compile in memory)."""
    try:
        from numba.core import caching
    except ImportError:
        return None
    try:
        base_locator, base_impl, base_cache = caching._CacheLocator, caching.CompileResultCacheImpl, caching.FunctionCache
    except AttributeError:
        return None

    class KeyedLocator(base_locator):
        """Every kernel in one directory per key; numba's index files are stamped with the key
        (another key: stale, recompiled and overwritten), disambiguated by the first line."""

        def __init__(self, py_func):
            self._lineno = py_func.__code__.co_firstlineno

        def get_cache_path(self):
            return path

        def get_source_stamp(self):
            return key

        def get_disambiguator(self):
            return str(self._lineno)

        @classmethod
        def from_function(cls, py_func, py_file):
            self = cls(py_func)
            try:
                self.ensure_cache_path()
            except OSError:
                return None
            return self

    class KeyedImpl(base_impl):
        _locator_classes = [KeyedLocator]

    class KeyedCache(base_cache):
        _impl_class = KeyedImpl
        locator_class = KeyedLocator

        def load_overload(self, sig, target_context):
            try:
                return super().load_overload(sig, target_context)
            except Exception as e:  # an unreadable or foreign file: compile instead
                log.warning("numba cache %s unreadable (%s: %s): compiling", path, type(e).__name__, e)
                return None

        def save_overload(self, sig, data):
            try:
                super().save_overload(sig, data)
            except OSError as e:  # the directory went away or became read-only: keep it in memory
                log.warning("numba cache %s not writable (%s): compiled in memory", path, e)

    return KeyedCache


def keyed_jit(fn, *, path: Path | None, key: str):
    """`fn` compiled by numba (nopython, nogil, no fastmath, numpy's error model) with its disk
    cache in `path` stamped `key`; in memory if `path` is None or cannot hold it."""
    disp = numba.njit(nogil=True, fastmath=False, error_model="numpy")(fn)
    cls = _cache_class(str(path), key) if path is not None else None
    if cls is not None:
        try:
            cache = cls(fn)
        except (RuntimeError, OSError) as e:  # no locator (unwritable path, or NUMBA_CACHE_LOCATOR_CLASSES)
            log.warning("numba cache %s unusable for %s (%s): compiled in memory", path, fn.__qualname__, e)
        else:
            if isinstance(cache._impl.locator, cls.locator_class):
                disp._cache = cache  # what `enable_caching` (cache=True) does, with our locator
            else:  # NUMBA_CACHE_LOCATOR_CLASSES chose another: it would not know the key
                log.warning("numba cache locator overridden for %s: compiled in memory", fn.__qualname__)
    return disp


def _jit(fn):
    """The kernels' decorator: `keyed_jit` on this process's cache; only for `KERNEL_MODULES`."""
    if fn.__module__ not in {f"{__package__}.{m}" for m in KERNEL_MODULES}:
        raise RuntimeError(f"kernel {fn.__module__}.{fn.__qualname__} is outside KERNEL_MODULES "
                           f"{KERNEL_MODULES}: its source would not key numba's cache")
    return keyed_jit(fn, path=CACHE_PATH, key=KEY)


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
