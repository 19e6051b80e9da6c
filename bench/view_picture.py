"""The README's picture of glsynth view (docs/view.png): the demo preset's environment 0 in
headless Chromium, the labels pass over colour at a sampled camera (--camera, stepped to
with key N) that shows columns and the town behind them.

Needs Debian's chromium and chromium-driver and the selenium package (the browser tests'
own); the page is 1020x432 CSS pixels.

    .venv/bin/python bench/view_picture.py [--out docs/view.png]
"""

import argparse
import re
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

from glsynth.core.fileio import atomic_write_bytes

ROOT = Path(__file__).resolve().parents[1]
WAIT_S = 300


def _still(driver, pass_name: str, after: int) -> int:
    """Waits for a still frame of ``pass_name`` newer than frame ``after``; its number."""
    from selenium.webdriver.support.ui import WebDriverWait

    def ready(d):
        c = d.find_element("id", "frame")
        seq = int(c.get_attribute("data-seq") or 0)
        return seq if (seq > after and c.get_attribute("data-still") == "true"
                       and c.get_attribute("data-pass") == pass_name) else False
    return WebDriverWait(driver, WAIT_S, poll_frequency=0.2).until(ready)


def _seq(driver) -> int:
    return int(driver.find_element("id", "frame").get_attribute("data-seq") or 0)


def _browser(profile: Path):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = "/usr/bin/chromium"
    for arg in ("--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                f"--user-data-dir={profile}"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)
    # The page's own size, whatever the headless window's frame takes.
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
        "width": 1020, "height": 432, "deviceScaleFactor": 1, "mobile": False})
    return driver


def _labels_at_camera(driver, camera: int) -> None:
    """The labels pass at sampled camera ``camera`` (the page opens at camera 0; key N steps
    to the next). Radio buttons are clicked by script, so the side panel does not scroll."""
    _still(driver, "color", 0)
    for _ in range(camera):
        seq = _seq(driver)
        driver.find_element("id", "frame").send_keys("n")
        _still(driver, "color", seq)
    seq = _seq(driver)
    labels = driver.find_element("css selector", "input[name=pass][value=labels]")
    driver.execute_script("arguments[0].click(); window.scrollTo(0, 0);", labels)
    _still(driver, "labels", seq)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "view.png"))
    parser.add_argument("--camera", type=int, default=3,
                        help="sampled camera (3: columns, a block, trees and sky)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        server = subprocess.Popen(
            [sys.executable, "-m", "glsynth", "view", "--preset", "demo", "--seed", "0",
             "--env", "0", "--port", "0", "--out", str(Path(tmp) / "views")],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            url = re.search(r"(http://\S+/)", server.stdout.readline())
            if url is None:
                raise SystemExit("glsynth view did not start")
            driver = _browser(Path(tmp) / "profile")
            try:
                driver.get(url.group(1))
                _labels_at_camera(driver, args.camera)
                atomic_write_bytes(Path(args.out), driver.get_screenshot_as_png())
            finally:
                driver.quit()
        finally:
            server.send_signal(signal.SIGINT)
            server.wait(60)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
