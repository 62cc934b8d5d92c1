"""report.html in a real browser (headless Chromium over the DevTools protocol): it renders with no
console error, filtering to one family shows only that family's rows, a drill-down opens and draws.

Needs Debian's `chromium` (`apt-get install chromium`); run with `python -m pytest -m browser`.
"""

from __future__ import annotations

import json

import pytest
from chromium_cdp import Chromium, find_chromium
from synthetic_runs import write_dataset_run

from suite.report.html import write_html

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    binary = find_chromium()
    if binary is None:
        pytest.skip("no Chromium on PATH: install Debian's chromium package (apt-get install chromium)")
    pytest.importorskip("tornado.websocket", reason="the DevTools client needs tornado (the test extra brings it)")
    run_dir, ds = write_dataset_run(tmp_path_factory.mktemp("run"), "recycle-v2.1:quick")
    report = write_html(run_dir)
    with Chromium(binary, width=1400, height=1000) as browser:
        browser.open(report.resolve().as_uri())
        yield browser, ds, tmp_path_factory.mktemp("shots")


def _shown_families(browser) -> list[str]:
    return browser.evaluate("[...document.querySelectorAll('#problem-table tbody tr')]"
                            ".filter(r => !r.hidden).map(r => r.dataset.family)")


def test_renders_without_console_errors(page):
    browser, ds, shots = page
    assert browser.errors() == []
    assert len(_shown_families(browser)) == len(ds.ids)
    assert browser.evaluate("document.getElementById('f-count').textContent") == \
        f"showing {len(ds.ids)} of {len(ds.ids)} problems"
    assert browser.screenshot(shots / "headline.png").stat().st_size > 20_000


def test_filtering_to_one_family_shows_only_its_rows(page):
    browser, ds, _ = page
    families = sorted({p.scene.variant for p in ds.problems})
    assert len(families) > 1
    for family in families[:2]:
        browser.evaluate(f"(() => {{ const s = document.getElementById('f-family'); s.value = {json.dumps(family)};"
                         "s.dispatchEvent(new Event('input')); })()")
        shown = _shown_families(browser)
        assert shown and set(shown) == {family}
        assert len(shown) == sum(p.scene.variant == family for p in ds.problems)
    # planner and status: "stuck" timed out everywhere, "ref" never failed
    browser.evaluate("(() => { const p = document.getElementById('f-planner'), s = document.getElementById('f-status');"
                     "p.value = 'ref'; s.value = '*failed'; s.dispatchEvent(new Event('input')); })()")
    assert _shown_families(browser) == []
    browser.evaluate("(() => { const p = document.getElementById('f-planner'); p.value = 'stuck';"
                     "p.dispatchEvent(new Event('input')); })()")
    assert set(_shown_families(browser)) == {families[1]}
    browser.evaluate("document.getElementById('f-reset').click()")
    assert len(_shown_families(browser)) == len(ds.ids)
    assert browser.errors() == []


def test_sorting_by_a_column(page):
    browser, _, _ = page
    browser.evaluate("document.querySelector('#problem-table thead th').click()")
    ids = browser.evaluate("[...document.querySelectorAll('#problem-table tbody tr')].map(r => r.dataset.pid)")
    assert ids == sorted(ids)
    browser.evaluate("document.querySelector('#problem-table thead th').click()")
    ids = browser.evaluate("[...document.querySelectorAll('#problem-table tbody tr')].map(r => r.dataset.pid)")
    assert ids == sorted(ids, reverse=True)


def test_a_drilldown_opens_and_draws(page):
    browser, ds, shots = page
    browser.evaluate("(() => { const s = document.getElementById('f-family'); s.value = 'window';"
                     "s.dispatchEvent(new Event('input')); })()")
    anchor = browser.evaluate("[...document.querySelectorAll('#problem-table tbody tr')].find(r => !r.hidden)"
                              ".dataset.anchor")
    assert browser.evaluate(f"document.getElementById('{anchor}').hidden") is True
    browser.evaluate(f"document.querySelector('tr[data-anchor=\"{anchor}\"] td:nth-child(2)').click()")
    browser.wait_for_event("Page.navigatedWithinDocument")
    state = browser.evaluate(f"""(() => {{ const d = document.getElementById('{anchor}');
        return {{hidden: d.hidden, hash: location.hash, views: d.querySelectorAll('.views svg').length,
                 polygons: d.querySelectorAll('.views svg polygon').length,
                 paths: d.querySelectorAll('.views svg polyline.path:not(.ref)').length,
                 joints: d.querySelectorAll('.joints svg').length,
                 open: document.querySelectorAll('section.drill:not([hidden])').length}}; }})()""")
    assert state == {"hidden": False, "hash": "#" + anchor, "views": 2, "polygons": state["polygons"],
                     "paths": 2, "joints": 7, "open": 1}  # "ref"'s path in each view; "stuck" has none
    assert state["polygons"] > 6  # plate, bin walls, window frame, cans
    assert browser.screenshot(shots / "drilldown.png", selector=f"#{anchor}").stat().st_size > 20_000
    # "next" stays within the filtered rows
    browser.evaluate(f"document.querySelector('#{anchor} button[data-nav=\"1\"]').click()")
    shown = browser.evaluate("[...document.querySelectorAll('section.drill:not([hidden])')].map(d => d.id)")
    assert len(shown) == 1 and shown[0] != anchor
    family = browser.evaluate(f"document.querySelector('tr[data-anchor=\"{shown[0]}\"]').dataset.family")
    assert family == "window"
    assert browser.errors() == []
