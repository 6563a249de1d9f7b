"""A headless Chromium shared by the browser tests of a module (Selenium
with Debian's ``chromium`` and ``chromedriver``).

Where no browser can be started the tests are skipped with the reason; in
CI (``CI`` set), where ``.ci/run`` installs the browser, they fail instead.
"""

import os
import shutil
import tempfile

import pytest

NO_BROWSER = "no chromium/chromedriver: apt-get install chromium chromium-driver"

# Flags of a quiet, isolated browser: nothing in the background reaches the
# network, so that what the page requests is all there is.
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--window-size=1200,900",
)


def _unavailable(reason):
    if os.environ.get("CI"):
        pytest.fail(f"{reason} (CI must run the browser tests)")
    pytest.skip(reason)


def start_chromium(download_dir):
    """A Selenium driver of headless Chromium that saves downloads into
    ``download_dir``; returns ``(driver, profile_dir)``."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        _unavailable("selenium is not installed: pip install 'skpcd[test]'")
    binary = shutil.which("chromium") or shutil.which("chromium-browser")
    driver_path = shutil.which("chromedriver")
    if binary is None or driver_path is None:
        _unavailable(NO_BROWSER)
    profile = tempfile.mkdtemp(prefix="skpcd-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={profile}")
    options.add_experimental_option(
        "prefs",
        {
            "download.default_directory": str(download_dir),
            "download.prompt_for_download": False,
        },
    )
    try:
        driver = webdriver.Chrome(service=Service(driver_path), options=options)
    except Exception as exc:  # a driver that does not match the browser, ...
        shutil.rmtree(profile, ignore_errors=True)
        _unavailable(f"chromium did not start ({type(exc).__name__}: {exc})")
    driver.set_script_timeout(20)
    return driver, profile


@pytest.fixture(scope="module")
def downloads(tmp_path_factory):
    """The folder Chromium saves downloads into."""
    return tmp_path_factory.mktemp("downloads")


@pytest.fixture(scope="module")
def browser(downloads):
    """One headless Chromium for the module's tests."""
    driver, profile = start_chromium(downloads)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
