"""Tests of physinfer_flag.cloth_numba: a writable numba cache directory."""

from __future__ import annotations

import numba

from physinfer_flag import cloth_numba


def test_falls_back_to_a_temporary_directory_when_nothing_is_writable(monkeypatch, tmp_path):
    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    monkeypatch.setattr(cloth_numba.tempfile, "gettempdir", lambda: str(tmp_path))
    monkeypatch.setattr(cloth_numba, "_writable", lambda path: str(path).startswith(str(tmp_path)))
    chosen = cloth_numba.ensure_cache_dir()
    assert chosen == str(tmp_path / "physinfer-numba-cache")
    assert numba.config.CACHE_DIR == chosen


def test_keeps_numbas_choice_when_the_package_is_writable(monkeypatch):
    monkeypatch.setattr(numba.config, "CACHE_DIR", "")
    monkeypatch.setattr(cloth_numba, "_writable", lambda path: True)
    assert cloth_numba.ensure_cache_dir() is None
    assert numba.config.CACHE_DIR == ""


def test_an_explicit_cache_dir_wins(monkeypatch, tmp_path):
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path))
    assert cloth_numba.ensure_cache_dir() is None
    assert numba.config.CACHE_DIR == str(tmp_path)
