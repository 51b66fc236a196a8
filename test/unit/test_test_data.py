"""helpers.shared_data / find_bag: missing test data skips a test, except under CI (CI=true)."""
from __future__ import annotations

from helpers import find_bag, SHARED_DATA, shared_data
import pytest


def test_missing_data_skips_locally(monkeypatch):
    monkeypatch.delenv('CI', raising=False)
    with pytest.raises(pytest.skip.Exception, match='shared data not found'):
        shared_data('no_such_folder')
    with pytest.raises(pytest.skip.Exception, match='no_such_bag'):
        find_bag('no_such_bag')


def test_missing_data_is_an_error_under_ci(monkeypatch):
    monkeypatch.setenv('CI', 'true')
    with pytest.raises(pytest.fail.Exception, match='CI=true'):
        shared_data('no_such_folder')
    with pytest.raises(pytest.fail.Exception, match='CI=true'):
        find_bag('no_such_bag')


def test_present_data_is_returned():
    assert shared_data() == SHARED_DATA
    assert shared_data('maps', 'depot.yaml').is_file()
    assert find_bag('intel_queries').is_dir()
