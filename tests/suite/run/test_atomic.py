"""Replacing a result file whole: the old file or the new one, never half, and no temporary left."""

from __future__ import annotations

import pytest

from suite.run.atomic import write_text_atomically


def test_the_file_is_replaced_whole_and_nothing_is_left_beside_it(tmp_path):
    path = tmp_path / "execution.json"
    write_text_atomically(path, "old")
    write_text_atomically(path, "new")
    assert path.read_text() == "new" and [p.name for p in tmp_path.iterdir()] == ["execution.json"]


def test_a_failed_write_keeps_the_old_file(tmp_path, monkeypatch):
    import suite.run.atomic as atomic

    path = tmp_path / "manifest.json"
    write_text_atomically(path, "old")

    def no_space(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic.os, "fsync", no_space)
    with pytest.raises(OSError):
        write_text_atomically(path, "new")
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["manifest.json"]
