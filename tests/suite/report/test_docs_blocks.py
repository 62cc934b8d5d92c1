"""Generated figures in README.md and docs/ match the committed files they come from."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from scenes.errors import SuiteError
from suite.report import docs_blocks

ROOT = Path(__file__).resolve().parents[3]


def test_no_committed_page_differs_from_its_data():
    changed = docs_blocks.render(ROOT, write=False)
    assert changed == [], f"run `python -m suite docs`: {changed}"


def test_a_changed_figure_is_found_and_rewritten(tmp_path):
    for page in {page for page, _ in docs_blocks.BLOCKS.values()}:
        (tmp_path / page).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(ROOT / page, tmp_path / page)
    for sub in ("results/reference", "planners/configs", "results/perception", "results/peers", "results/peers-equal"):
        shutil.copytree(ROOT / sub, tmp_path / sub, ignore=shutil.ignore_patterns("*.jsonl", "*.html", "arena", "families"))
    readme = tmp_path / "README.md"
    text = readme.read_text(encoding="utf-8")
    block = docs_blocks.blocks_of(text)["answer-table"]
    readme.write_text(text.replace(block, block.replace("|---|", "|---|\n| a row nobody wrote |", 1)), encoding="utf-8")
    assert docs_blocks.render(tmp_path, write=False) == ["README.md: answer-table"]
    assert docs_blocks.render(tmp_path, write=True) == ["README.md: answer-table"]
    assert docs_blocks.render(tmp_path, write=False) == []
    assert "a row nobody wrote" not in readme.read_text(encoding="utf-8")


def test_a_page_without_its_markers_is_a_one_line_error(tmp_path):
    (tmp_path / "README.md").write_text("# no markers\n", encoding="utf-8")
    with pytest.raises(SuiteError, match="README.md has no generated block 'answer-table'"):
        docs_blocks.render(tmp_path, write=False)
