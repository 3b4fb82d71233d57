"""Tests that read ../shared/data skip where it is absent, and fail where it is absent under CI."""

from __future__ import annotations

import conftest
import pytest

pytestmark = pytest.mark.unit


def test_absent_shared_data_skips_for_users(monkeypatch, tmp_path):
    monkeypatch.setattr(conftest, "SHARED_DATA", tmp_path / "nowhere")
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="absent"):
        conftest.shared_path("carmen")


def test_absent_shared_data_fails_under_ci(monkeypatch, tmp_path):
    monkeypatch.setattr(conftest, "SHARED_DATA", tmp_path / "nowhere")
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="absent"):
        conftest.shared_path("carmen")


def test_present_shared_data_is_returned(monkeypatch, tmp_path):
    (tmp_path / "carmen").mkdir()
    monkeypatch.setattr(conftest, "SHARED_DATA", tmp_path)
    assert conftest.shared_path("carmen") == tmp_path / "carmen"
