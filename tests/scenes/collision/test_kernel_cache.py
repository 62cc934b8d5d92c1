"""numba's disk cache of the compiled kernels cannot go stale (`scenes.collision.kernel_data`): it is keyed
on the kernel modules' sources, found by module name, and on the field layout.

The subprocess test copies the kernel modules out of the tree: a copy at another path loads the
cache (the key follows the modules, not the files), a copy whose field layout was reordered
recompiles, and both give the same rows; the same change with its key faked back to the first
loads the first layout's code and maps other rows (the control: the test sees a stale cache)."""

from __future__ import annotations

import ast
import importlib.util
import json
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenes.collision import kernel_data as D

#: Run in a copy of the kernel modules: compile (or load) `fk_rows` on a packed world with
#: distinct Mc, Ms and M1, and print where it is cached, whether it loaded, and the rows it maps.
_PROBE = """
import json, numpy as np
import scenes.collision.kernel_state as K, scenes.collision.kernel_data as D
rng = np.random.default_rng(4)
fields = {k: np.zeros(0) for k in (*D.FLOAT_FIELDS, *D.INT_FIELDS, "tab_cells")}
fields.update(Mc=rng.normal(size=112), Ms=rng.normal(size=112), M1=rng.normal(size=112), rows0=rng.normal(size=28),
              rows=np.zeros(21), scratch=np.zeros(D.SCRATCH), link_end=np.array([7, 7, 6, 5, 4, 3, 2, 1]),
              is_frame=np.zeros(7))
F, I, C = D.pack(fields, (7, 7, 0, 0, 0, 0, 1, 0))
K.fk_rows(np.linspace(-1.0, 1.0, 7), F, I)
st = K.fk_rows.stats
print(json.dumps({"file": K.__file__, "key": D.KEY, "path": str(D.CACHE_PATH), "cache_path": st.cache_path,
                  "hits": sum(st.cache_hits.values()), "misses": sum(st.cache_misses.values()),
                  "f_mc": D.F_MC, "rows": D.float_field(F, I, "rows").tolist()}))
"""


#: The kernels' package, and its depth below the import root.
_PACKAGE = D.__package__.split(".")


def _copy_kernels(root: Path) -> Path:
    """The kernels' package (`scenes.collision`, each level's `__init__`) with only its kernel
    modules, under `root` (found by module name); returns the package's directory."""
    pkg = root.joinpath(*_PACKAGE)
    pkg.mkdir(parents=True)
    for k in range(1, len(_PACKAGE) + 1):
        shutil.copy(importlib.util.find_spec(".".join(_PACKAGE[:k])).origin, root.joinpath(*_PACKAGE[:k], "__init__.py"))
    for m in D.KERNEL_MODULES:
        shutil.copy(importlib.util.find_spec(f"{D.__package__}.{m}").origin, pkg / f"{m}.py")
    return pkg


def _probe(pkg: Path, cache: Path) -> dict:
    root = pkg.parents[len(_PACKAGE) - 1]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CACHE_LOCATOR_CLASSES")}
    env["NUMBA_CACHE_DIR"] = str(cache)
    r = subprocess.run([sys.executable, "-c", _PROBE], cwd=root, env=env, capture_output=True, text=True,
                       timeout=300)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert Path(out["file"]).resolve().parent == pkg.resolve()  # the copy, not the tree
    return out


def test_a_moved_copy_loads_and_a_changed_layout_recompiles(tmp_path):
    cache = tmp_path / "cache"  # cold: nothing there yet
    first = _copy_kernels(tmp_path / "first")
    moved = _copy_kernels(tmp_path / "elsewhere" / "moved")
    changed = _copy_kernels(tmp_path / "changed")
    src = (changed / "kernel_data.py").read_text()
    # the same fields, Mc and Ms swapped: every kernel must now read Ms at 0 and Mc at 1
    old_list, new_list = 'FLOAT_FIELDS = ("Mc", "Ms",', 'FLOAT_FIELDS = ("Ms", "Mc",'
    old_idx, new_idx = "(F_MC, F_MS,", "(F_MS, F_MC,"
    assert src.count(old_list) == 1 and src.count(old_idx) == 1
    (changed / "kernel_data.py").write_text(src.replace(old_list, new_list).replace(old_idx, new_idx))
    # the kernel modules' own files are untouched: numba's own check (their stamps) would load them
    assert all((changed / f"{m}.py").read_bytes() == (first / f"{m}.py").read_bytes()
               for m in ("kernel_state", "kernel_motion", "kernel_codes"))

    a = _probe(first, cache)
    assert (a["misses"], a["hits"]) == (1, 0)  # compiled
    assert a["cache_path"] == a["path"] == str(D.keyed_path(cache, a["key"]))
    assert a["key"] == D.KEY  # the copy's sources and layout are the tree's
    assert any(Path(a["path"]).glob("kernel_state.fk_rows-*.nbi"))  # numba's index: written
    assert any(np.abs(a["rows"]) > 1e-3)

    b = _probe(moved, cache)
    assert b["key"] == a["key"] and b["path"] == a["path"]  # other files, same modules: same key
    assert (b["misses"], b["hits"]) == (0, 1)  # loaded
    assert b["rows"] == a["rows"]

    c = _probe(changed, cache)
    assert c["f_mc"] == 1 and a["f_mc"] == 0
    assert c["key"] != a["key"] and c["path"] != a["path"]
    assert (c["misses"], c["hits"]) == (1, 0)  # recompiled, not loaded
    assert c["rows"] == a["rows"]  # the layout moved, the rows did not

    again = _probe(first, cache)
    assert (again["misses"], again["hits"]) == (0, 1)  # the first key's cache is still there

    # the control: the same change with the key faked back to the first one loads the first
    # layout's code, which reads Ms as Mc (the stale cache the key prevents)
    stale = _copy_kernels(tmp_path / "stale")
    faked = (changed / "kernel_data.py").read_text()
    line = "KEY = cache_key(kernel_sources(), layout())"
    assert faked.count(line) == 1
    (stale / "kernel_data.py").write_text(faked.replace(line, f"KEY = {a['key']!r}"))
    s = _probe(stale, cache)
    assert (s["misses"], s["hits"]) == (0, 1) and s["f_mc"] == 1
    assert s["rows"] != a["rows"]


def test_the_key_covers_the_sources_and_the_layout():
    sources = D.kernel_sources()
    assert set(sources) == set(D.KERNEL_MODULES)
    assert D.cache_key(sources, D.layout()) == D.KEY
    lay = D.layout()
    assert lay["F_MC"] == 0 and lay["I_OBS_TYPE"] == len(D.INT_FIELDS) - 1 and lay["SCR_WALL"] == 136
    assert lay["HEADER"] == D.HEADER and lay["S_NPP"] == 7 and lay["FLOAT_FIELDS"] == D.FLOAT_FIELDS
    assert D.cache_key(sources, {**lay, "SCR_WALL": 137}) != D.KEY
    assert D.cache_key({**sources, "kernel_state": sources["kernel_state"] + "\n"}, lay) != D.KEY
    with pytest.raises(RuntimeError, match="kernel module scenes.collision.kernel_gone has no source"):
        D.kernel_sources(("kernel_gone",))


def test_kernels_read_no_module_outside_the_key():
    """A kernel module takes names from the project only from another kernel module (a constant
    imported from elsewhere would be frozen into the cache without being in the key); `_jit`
    refuses a kernel defined outside them."""
    for m in D.KERNEL_MODULES:
        tree = ast.parse(D.kernel_sources()[m])
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "scenes":
                assert node.module in {f"{D.__package__}.{k}" for k in D.KERNEL_MODULES}, (m, node.module)

    def stray(x):
        return x

    with pytest.raises(RuntimeError, match=r"kernel .*stray is outside KERNEL_MODULES"):
        D._jit(stray)


def _double(x):
    return 2.0 * x


def test_an_unwritable_cache_compiles_in_memory(tmp_path, caplog):
    blocked = tmp_path / "file"
    blocked.write_text("")  # a file where the directory should be
    with caplog.at_level(logging.WARNING, logger=D.__name__):
        f = D.keyed_jit(_double, path=blocked / "fcl-kernels-x", key="x")
        assert f(2.0) == 4.0
    assert f.stats.cache_path is None and "compiled in memory" in caplog.text

    # writable when the kernel is defined, gone when it is saved: the save is skipped, not fatal
    later = tmp_path / "later"
    g = D.keyed_jit(_double, path=later, key="y")
    assert g.stats.cache_path == str(later)
    shutil.rmtree(later)
    later.write_text("")
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger=D.__name__):
        assert g(3.0) == 6.0
    assert "not writable" in caplog.text

    # and with no writable directory at all the kernels have no cache path
    assert D.cache_dir([blocked / "numba"]) is None


def test_a_cold_cache_is_created_and_a_warm_one_loads_in_process(tmp_path):
    path = tmp_path / "cold" / "fcl-kernels-z"
    f = D.keyed_jit(_double, path=path, key="z")
    assert f(1.5) == 3.0 and f.stats.cache_misses and not f.stats.cache_hits
    assert any(path.glob("*.nbi"))
    g = D.keyed_jit(_double, path=path, key="z")  # a fresh dispatcher: what a new process has
    assert g(1.5) == 3.0 and g.stats.cache_hits and not g.stats.cache_misses
    h = D.keyed_jit(_double, path=path, key="z2")  # same directory, another stamp: stale, recompiled
    assert h(1.5) == 3.0 and h.stats.cache_misses and not h.stats.cache_hits
