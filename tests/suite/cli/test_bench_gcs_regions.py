"""`bench gcs-regions`: its world selection and its summary (the builds themselves are measured,
not tested: `tests/planners/gcs/test_gcs.py` tests the strategies)."""

from suite.bench.gcs_regions import parse_kinds, pick_worlds, summarize
from suite.problems.dataset import load_dataset


def test_kinds_per_family_and_world_selection():
    assert parse_kinds("window=transit,return;shelf=") == {"window": {"transit", "return"}, "shelf": set()}
    assert parse_kinds("") == {}
    ds = load_dataset("recycle-v3:tune")
    worlds = pick_worlds(ds, families={"window", "shelf"}, kinds=parse_kinds("window=transit,return"),
                         per_family=3)
    fams = [w[0][1] for w in worlds]
    assert fams.count("window") == 3 and fams.count("shelf") == 3
    for w in worlds:
        assert len({p.world_key() for *_, p in w}) == 1  # one world per job
        if w[0][1] == "window":
            assert any(kind in ("transit", "return") for _, _, kind, _ in w)


def test_summary_counts_window_transits_and_returns_apart():
    def trial(kind, valid, connected=True, s=0.5):
        return {"kind": kind, "valid": valid, "connected": connected, "planning_s": s, "gcs_first_solve_s": 0.1}

    rows = [
        {"family": "window", "strategies": {"chain": {"offline_s": 30.0, "regions": 8, "coverage_task": 0.7,
                                                      "coverage_uniform": 0.05,
                                                      "trials": [trial("transit", True), trial("lift", False, False)]}}},
        {"family": "shelf", "strategies": {"chain": {"offline_s": 50.0, "regions": 6, "coverage_task": 0.8,
                                                     "coverage_uniform": 0.08, "trials": [trial("approach", True)]}}},
    ]
    s = summarize(rows, ["chain"])["chain"]
    assert s["worlds"] == 2 and s["valid"] == 2 and s["connected"] == 2 and s["problems"] == 3
    assert s["window_transit_return"] == "1/1"
    assert s["offline_s_median"] == 40.0 and s["offline_s_p90"] == 50.0
    assert s["planning_s_median"] == 0.5
