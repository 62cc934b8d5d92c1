"""numba's disk cache of the compiled kernels cannot go stale (`scenes.collision.kernel_data`): it is keyed
on the kernel modules' sources, found by module name, and on the field layout.

The subprocess test copies the kernel modules out of the tree: a copy at another path loads the
cache (the key follows the modules, not the files), a copy whose field layout was reordered
recompiles, and both give the same rows; the same change with its key faked back to the first
loads the first layout's code and maps other rows (the control: the test sees a stale cache).

The cold-cache test runs the tree's kernels (`scenes/collision/`) in worker processes on an empty
cache: they compile into it under the kernel modules' own names, decide states and motions as the
numpy reference does, and a later process loads every kernel without compiling."""

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

#: The repository (the tree's kernels, not a copy).
ROOT = Path(__file__).resolve().parents[3]

#: Run in the tree on a problem's world: decide states and motions with the compiled world, and
#: print them with each kernel's file, cache path, cache misses and hits.
_DECIDE = """
import json, numpy as np
from scenes.collision import compiled, kernel_data, kernel_motion, kernel_state
from suite.problems.dataset import load_dataset
p = load_dataset("recycle-v3:quick").problems[0]
w = compiled.CompiledWorld(p.scene, gripper_opening_m=p.gripper_opening_m, held=p.held,
                           removed_can_ids=p.removed_can_ids)
rng = np.random.default_rng(0)
Q = w.robot.random_configurations(rng, 300)
M = [(Q[i], Q[i] + rng.normal(size=7) * 0.3) for i in range(40)]
kernels = {"kernel_state.state_decide": kernel_state.state_decide, "kernel_state.batch_decide": kernel_state.batch_decide,
           "kernel_motion.motion_check": kernel_motion.motion_check, "kernel_data._f": kernel_data._f}
print(json.dumps({
    "Q": Q.tolist(), "M": [[a.tolist(), b.tolist()] for a, b in M],
    "states": w.states_free(Q).tolist(), "single": [bool(w.is_free(q)) for q in Q],
    "motions": [bool(w.motion_samples_free(a, b, resolution_rad=0.05)) for a, b in M],
    "key": kernel_data.KEY,
    "kernels": {k: {"file": f.py_func.__code__.co_filename, "cache_path": f.stats.cache_path,
                    "misses": sum(f.stats.cache_misses.values()), "hits": sum(f.stats.cache_hits.values())}
                for k, f in kernels.items()}}))
"""


def _decide(cache: Path, n: int) -> list[dict]:
    """`_DECIDE` in n worker processes started together on the cache directory `cache`."""
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_LOCATOR_CLASSES",)}
    env["NUMBA_CACHE_DIR"] = str(cache)
    procs = [subprocess.Popen([sys.executable, "-c", _DECIDE], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(n)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0] * n, [e for _, e in outs]
    return [json.loads(o.strip().splitlines()[-1]) for o, _ in outs]


def test_the_kernels_compile_from_a_cold_cache_and_decide_as_the_reference(tmp_path):
    """Two workers start together on an empty cache (a run on a fresh machine, or after the kernels
    moved): both compile or load the kernels of `scenes/collision/` without error, under the key
    and the modules' own names, and decide every state and motion as the numpy world; a third
    process then loads every kernel and compiles none."""
    from scenes.collision.world import CollisionWorld
    from suite.problems.dataset import load_dataset

    cache = tmp_path / "cache"  # cold: nothing there yet
    cold = _decide(cache, 2)
    warm = _decide(cache, 1)[0]
    keyed = str(D.keyed_path(cache, D.KEY))
    for out in (*cold, warm):
        assert out["key"] == D.KEY
        for name, k in out["kernels"].items():
            assert Path(k["file"]).resolve() == (ROOT / "scenes" / "collision" / f"{name.split('.')[0]}.py").resolve()
            assert k["cache_path"] == keyed, name
    for name in cold[0]["kernels"]:  # compiled by one worker at least; the warm process compiles none
        assert sum(o["kernels"][name]["misses"] for o in cold) >= 1, name
        assert warm["kernels"][name]["misses"] == 0, name
    # the entry points are each loaded or compiled by every worker (`_f` lives inside their code)
    for name in ("kernel_state.state_decide", "kernel_state.batch_decide", "kernel_motion.motion_check"):
        assert all(o["kernels"][name]["misses"] + o["kernels"][name]["hits"] >= 1 for o in cold), name
        assert warm["kernels"][name]["hits"] >= 1, name
    # numba's index files carry the kernel modules' new names, and only theirs
    index = sorted(f.name.split("-")[0] for f in Path(keyed).glob("*.nbi"))
    assert {"kernel_state.state_decide", "kernel_state.batch_decide", "kernel_motion.motion_check",
            "kernel_data._f"} <= set(index)
    assert all(n.split(".")[0] in D.KERNEL_MODULES for n in index), index

    # the same answers in every process, and the numpy reference's
    p = load_dataset("recycle-v3:quick").problems[0]
    ref = CollisionWorld(p.scene, gripper_opening_m=p.gripper_opening_m, held=p.held,
                         removed_can_ids=p.removed_can_ids)
    Q = np.array(warm["Q"])
    states = ref.states_free(Q).tolist()
    motions = [bool(ref.motion_samples_free(np.array(a), np.array(b), resolution_rad=0.05)) for a, b in warm["M"]]
    assert 0 < sum(states) < len(states) and 0 < sum(motions) < len(motions)  # both answers occur
    for out in (*cold, warm):
        assert out["Q"] == warm["Q"] and out["M"] == warm["M"]
        assert out["states"] == states and out["single"] == states
        assert out["motions"] == motions


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
    with pytest.raises(RuntimeError, match=rf"kernel module {D.__package__}\.kernel_gone has no source"):
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
        f = D.keyed_jit(_double, path=blocked / "collision-kernels-x", key="x")
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
    path = tmp_path / "cold" / "collision-kernels-z"
    f = D.keyed_jit(_double, path=path, key="z")
    assert f(1.5) == 3.0 and f.stats.cache_misses and not f.stats.cache_hits
    assert any(path.glob("*.nbi"))
    g = D.keyed_jit(_double, path=path, key="z")  # a fresh dispatcher: what a new process has
    assert g(1.5) == 3.0 and g.stats.cache_hits and not g.stats.cache_misses
    h = D.keyed_jit(_double, path=path, key="z2")  # same directory, another stamp: stale, recompiled
    assert h(1.5) == 3.0 and h.stats.cache_misses and not h.stats.cache_hits
