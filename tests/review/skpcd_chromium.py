"""Headless Chromium driven by Selenium (Debian's ``chromium`` and
``chromedriver``), for the review page's tests and its benchmark
(benchmarks/bench_review.py).

:func:`start_chromium` raises :class:`BrowserUnavailable` with the reason
when no browser can be started.
"""

import shutil
import tempfile

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


class BrowserUnavailable(RuntimeError):
    """No browser could be started; the message says why."""


def start_chromium(download_dir):
    """A Selenium driver of headless Chromium that saves downloads into
    ``download_dir``, with a new profile; returns ``(driver, profile_dir)``
    (remove the profile after ``driver.quit()``)."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        raise BrowserUnavailable(
            "selenium is not installed: pip install 'skpcd[test]'"
        ) from None
    binary = shutil.which("chromium") or shutil.which("chromium-browser")
    driver_path = shutil.which("chromedriver")
    if binary is None or driver_path is None:
        raise BrowserUnavailable(NO_BROWSER)
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
        raise BrowserUnavailable(
            f"chromium did not start ({type(exc).__name__}: {exc})"
        ) from exc
    driver.set_script_timeout(20)
    return driver, profile
