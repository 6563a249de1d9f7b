import time

import numpy as np
from numba import njit

from skpcd.utils._parallel import parallel_rows, parallel_section, thread_profile


@njit(nogil=True, cache=True)
def _fill(lo, hi, out):
    for i in range(lo, hi):
        out[i] = i


def test_thread_profile_adds_up_the_outermost_parallel_sections():
    out = np.zeros(50_000)
    with thread_profile() as sections:
        parallel_rows(_fill, len(out), 2, out)
        with parallel_section("outer"):
            time.sleep(0.02)
            parallel_rows(_fill, len(out), 1, out)  # nested: counted in "outer"
    assert set(sections) == {"_fill", "outer"}
    assert sections["outer"] >= 0.02
    np.testing.assert_array_equal(out, np.arange(len(out)))
    # outside a profile the sections cost nothing and record nothing
    with parallel_section("ignored"):
        pass
    assert "ignored" not in sections
