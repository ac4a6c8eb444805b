"""Whole-system reproductions and held-out checks: every test here carries the ``system`` marker.

They run with the rest of the suite (``python -m pytest -q -n 2``); ``-m "not system"`` leaves them out.
"""

from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config, items):
    for item in items:
        if HERE in Path(item.path).resolve().parents:
            item.add_marker(pytest.mark.system)
