"""Settings shared by every test of the workspace (per-package and cross-package).

Property tests (hypothesis) run without a per-example deadline, because CI machines are
noisy and speed is measured by the benchmark scripts, never by tests; and derandomized, so
a run is reproducible (the examples come from a fixed seed).
"""

from hypothesis import settings

settings.register_profile('vd', deadline=None, derandomize=True, print_blob=True)
settings.load_profile('vd')
