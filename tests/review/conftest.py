"""A headless Chromium shared by the browser tests of a module (Selenium
with Debian's ``chromium`` and ``chromedriver``).

Where no browser can be started the tests are skipped with the reason; in
CI (``CI`` set), where ``.ci/run`` installs the browser, they fail instead.
"""

import os
import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from skpcd_chromium import BrowserUnavailable, start_chromium


def _unavailable(reason):
    if os.environ.get("CI"):
        pytest.fail(f"{reason} (CI must run the browser tests)")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def downloads(tmp_path_factory):
    """The folder Chromium saves downloads into."""
    return tmp_path_factory.mktemp("downloads")


@pytest.fixture(scope="module")
def browser(downloads):
    """One headless Chromium for the module's tests."""
    try:
        driver, profile = start_chromium(downloads)
    except BrowserUnavailable as exc:
        _unavailable(str(exc))
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
