"""Shared test configuration for every folder under tests/ (``tests/<stage>/``, ``tests/project/``;
tests/README.md): the ``unit`` / ``integration`` split of the suite.

Markers (registered in pyproject.toml):

- ``integration``: the pipeline end to end (subprocesses, Dask clusters, sweeps into run
  stores, benchmark scripts). Whole modules set it with ``pytestmark``; single tests elsewhere
  with ``@pytest.mark.integration``.
- ``unit``: every other test (one function, kernel or store in this process), set here.
- ``slow``: longer than a minute, left out of the default run.

``python -m pytest -m unit`` runs the unit tests alone. Helper functions live in ``helpers.py``,
which the tests of every folder import as ``from helpers import ...`` (``pythonpath`` in pyproject.toml).
"""

from __future__ import annotations

import pytest


def pytest_collection_modifyitems(items):
    for item in items:
        if item.get_closest_marker("integration") is None:
            item.add_marker(pytest.mark.unit)
