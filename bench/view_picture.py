"""The README's picture of glsynth view (docs/view.png): the demo preset's environment 0 in
headless Chromium, the labels pass over colour at the first sampled camera (key N steps)
that shows a column and the town behind it.

Needs Debian's chromium and chromium-driver and the selenium package (the browser tests'
own); a window of 1020x432 CSS pixels.

    .venv/bin/python bench/view_picture.py [--out docs/view.png]
"""

import argparse
import re
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

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
    for arg in ("--headless", "--no-sandbox", "--disable-gpu", "--window-size=1020,432",
                "--hide-scrollbars", f"--user-data-dir={profile}"):
        options.add_argument(arg)
    return webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=options)


def _labels_at_a_column(driver) -> None:
    """The labels pass at the first camera whose component pass shows a column and, at its
    top, some sky or town (non-bridge)."""
    import base64

    import cv2

    from glsynth.core.labels import Component
    from glsynth.core.palette import COMPONENT_RGB

    _still(driver, "color", 0)
    driver.find_element("css selector", "input[name=pass][value=component]").click()
    _still(driver, "component", 0)
    for _ in range(12):
        data = driver.execute_script("return document.getElementById('frame').toDataURL()")
        png = np.frombuffer(base64.b64decode(data.split(",", 1)[1]), np.uint8)
        rgb = cv2.imdecode(png, cv2.IMREAD_COLOR)[..., ::-1]
        column = (rgb == COMPONENT_RGB[Component.COLUMN]).all(-1).mean()
        town = (rgb == COMPONENT_RGB[Component.NONBRIDGE]).all(-1).mean()
        if column > 0.05 and town > 0.2:
            break
        seq = _seq(driver)
        driver.find_element("id", "frame").send_keys("n")
        _still(driver, "component", seq)
    seq = _seq(driver)
    driver.find_element("css selector", "input[name=pass][value=labels]").click()
    _still(driver, "labels", seq)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "view.png"))
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        server = subprocess.Popen(
            [sys.executable, "-m", "glsynth.cli", "view", "--preset", "demo", "--seed", "0",
             "--env", "0", "--port", "0", "--out", str(Path(tmp) / "views")],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            url = re.search(r"(http://\S+/)", server.stdout.readline())
            if url is None:
                raise SystemExit("glsynth view did not start")
            driver = _browser(Path(tmp) / "profile")
            try:
                driver.get(url.group(1))
                _labels_at_a_column(driver)
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
