"""Settings shared by every test of the workspace (per-package and cross-package).

Property tests (hypothesis) run without a per-example deadline, because CI machines are
noisy and speed is measured by the benchmark scripts, never by tests; and derandomized, so
a run is reproducible (the examples come from a fixed seed).
"""

from hypothesis import settings

settings.register_profile('vd', deadline=None, derandomize=True, print_blob=True)
settings.load_profile('vd')


# --- long end-to-end runs ------------------------------------------------------------------
# `make test` leaves the tests marked `slow` (whole drives through the simulator, graphs of
# nodes over the middleware) out, so that it takes minutes; CI runs every test (CI set, or
# VD_TEST_ALL=1: `make test-all`, which .ci/run uses).
import os  # noqa: E402

import pytest  # noqa: E402


def _run_all() -> bool:
    def truthy(name: str) -> bool:
        return os.environ.get(name, '').strip().lower() not in ('', '0', 'false', 'no')

    return truthy('VD_TEST_ALL') or truthy('CI')


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if _run_all():
        return
    skip = pytest.mark.skip(reason='long end-to-end run: CI runs it (here: make test-all)')
    for item in items:
        if 'slow' in item.keywords:
            item.add_marker(skip)
