"""Whether the compiled kernels are in Numba's on-disk cache (so a first use can say so).

The kernels are compiled with ``cache=True``: the first process compiles them (about 20 s on
the 2-core machine CI uses) and writes them next to the sources (or into
``NUMBA_CACHE_DIR``); every later process loads them. A missing or older index file of the
closed loop's entry point means a cold cache.
"""

from __future__ import annotations

import os


def kernels_cached() -> bool:
    """True when the closed loop's compiled code is cached and newer than its source."""
    from .world import run_loop

    try:
        index = run_loop._cache._cache_file._index_path  # numba's cache layout
        source = run_loop.py_func.__code__.co_filename
        return os.path.getmtime(index) >= os.path.getmtime(source)
    except (AttributeError, OSError):
        return False
