"""glsynth view in a real browser: Debian's chromium through chromium-driver and selenium,
headless. Each test skips, saying why, where Chromium is not installed (scripts/install.sh
installs it unless GLSYNTH_NO_CHROMIUM is set).

Tolerances: stills travel as PNG and are drawn 1:1 without smoothing or colour conversion, so
the canvas must equal `glsynth render`'s image.png exactly (0 grey levels)."""

import base64
import json
import shutil

import cv2
import numpy as np
import pytest

from glsynth.core.labels import Component
from glsynth.core.palette import COMPONENT_RGB

pytestmark = pytest.mark.slow
CHROMIUM, DRIVER = shutil.which("chromium"), shutil.which("chromedriver")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--window-size=1400,900"]
WAIT_S = 120


def chromium(profile) -> object:
    """A headless Chromium with a fresh profile, or a skip naming what is missing."""
    if CHROMIUM is None or DRIVER is None:
        pytest.skip("browser test skipped: Debian's chromium and chromium-driver are not "
                    "installed (scripts/install.sh installs them)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in [*CHROMIUM_ARGS, f"--user-data-dir={profile}"]:
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    driver.set_script_timeout(30)
    return driver


def canvas_pixels(driver) -> np.ndarray:
    data = driver.execute_script("return document.getElementById('frame').toDataURL()")
    png = base64.b64decode(data.split(",", 1)[1])
    return cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)[..., ::-1]


def wait_still(driver, pass_name: str, after: int = 0) -> int:
    """Waits for a still frame of ``pass_name`` newer than frame ``after``; its number."""
    from selenium.webdriver.support.ui import WebDriverWait

    def ready(d):
        c = d.find_element("id", "frame")
        seq = int(c.get_attribute("data-seq") or 0)
        return seq if (seq > after and c.get_attribute("data-still") == "true"
                       and c.get_attribute("data-pass") == pass_name) else False
    return WebDriverWait(driver, WAIT_S, poll_frequency=0.2).until(ready)


def show_pass(driver, name: str) -> None:
    """Shows pass ``name`` and waits for its still frame (at once where it is shown: choosing
    the chosen pass again draws nothing new)."""
    frame = driver.find_element("id", "frame")
    if frame.get_attribute("data-pass") == name and frame.get_attribute("data-still") == "true":
        return
    seq = int(frame.get_attribute("data-seq") or 0)
    driver.find_element("css selector", f"input[name=pass][value={name}]").click()
    wait_still(driver, name, seq)


def copied_camera(driver) -> dict:
    driver.find_element("id", "copy").click()
    return json.loads(driver.find_element("id", "camera-json").get_attribute("value"))


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    """The viewer in Chromium at a sampled camera that shows a column, and `glsynth render`
    of the camera the page copies."""
    from viewhelpers import ViewServer, render_camera_json

    tmp = tmp_path_factory.mktemp("browser")
    driver = chromium(tmp / "profile")
    server = None
    try:
        server = ViewServer(tmp / "views")
        driver.get(server.url)
        wait_still(driver, "color")
        show_pass(driver, "component")
        for _ in range(12):  # step through the sampled cameras (key N) to one with a column
            if (canvas_pixels(driver) == COMPONENT_RGB[Component.COLUMN]).all(-1).sum() > 400:
                break
            seq = int(driver.find_element("id", "frame").get_attribute("data-seq"))
            driver.find_element("id", "frame").send_keys("n")
            wait_still(driver, "component", seq)
        # The live frames are the render before the camera model (docs/design.md).
        rendered = render_camera_json(copied_camera(driver), tmp / "render", photo=False)
        yield driver, server, rendered
    finally:
        driver.quit()
        if server is not None:
            server.stop()


def read_png(path) -> np.ndarray:
    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED)


def test_the_page_shows_a_frame_equal_to_renders_colour(page):
    driver, _, rendered = page
    show_pass(driver, "color")
    expected = read_png(rendered / "image.png")[..., ::-1]
    assert np.array_equal(canvas_pixels(driver), expected)


def test_the_component_pass_shows_the_palette_colours_of_renders_labels(page):
    driver, _, rendered = page
    show_pass(driver, "component")
    assert np.array_equal(canvas_pixels(driver), COMPONENT_RGB[read_png(rendered /
                                                                        "component.png")])


def test_clicking_a_column_reports_column_and_its_depth(page):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.support.ui import WebDriverWait

    driver, _, rendered = page
    component, depth = read_png(rendered / "component.png"), np.load(rendered / "depth.npy")
    inner = cv2.erode((component == Component.COLUMN).astype(np.uint8), np.ones((7, 7)))
    rows, cols = np.nonzero(inner)
    row, col = int(np.median(rows)), int(cols[np.argmin(np.abs(rows - np.median(rows)))])
    canvas = driver.find_element("id", "frame")
    size = driver.execute_script("const r = arguments[0].getBoundingClientRect(); "
                                 "return [r.width, r.height];", canvas)
    scale = size[0] / component.shape[1]
    ActionChains(driver).move_to_element_with_offset(
        canvas, round((col + 0.5) * scale - size[0] / 2),
        round((row + 0.5) * scale - size[1] / 2)).click().perform()
    box = driver.find_element("id", "inspect")
    WebDriverWait(driver, WAIT_S).until(lambda d: box.get_attribute("data-clicked"))
    # CSS pixels are whole numbers: the click lands on the pixel asked for or a neighbour.
    WebDriverWait(driver, WAIT_S).until(
        lambda d: abs(int(box.get_attribute("data-col")) - col) <= 1
        and abs(int(box.get_attribute("data-row")) - row) <= 1, message=box.text)
    at = int(box.get_attribute("data-row")), int(box.get_attribute("data-col"))
    assert box.get_attribute("data-component") == "column", box.text
    assert abs(float(box.get_attribute("data-depth")) - float(depth[at])) < 0.01
    assert box.get_attribute("data-part").startswith("column")


def test_dragging_moves_the_camera_and_a_new_frame_arrives(page):
    from selenium.webdriver.common.action_chains import ActionChains

    driver, _, _ = page
    show_pass(driver, "color")
    before, seq = copied_camera(driver), int(driver.find_element("id", "frame")
                                             .get_attribute("data-seq"))
    ActionChains(driver).drag_and_drop_by_offset(driver.find_element("id", "frame"), 150,
                                                 40).perform()
    assert wait_still(driver, "color", seq) > seq
    after = copied_camera(driver)
    assert not np.allclose(before["pose"], after["pose"])


def test_a_config_with_a_bad_value_shows_the_error_and_keeps_the_scene(page, tmp_path):
    from selenium.webdriver.support.ui import WebDriverWait

    driver, _, _ = page
    bad = tmp_path / "bad.toml"
    bad.write_text("[render]\nmsaa = -2\n")
    seq = int(driver.find_element("id", "frame").get_attribute("data-seq"))
    driver.find_element("id", "config-file").send_keys(str(bad))
    error = driver.find_element("id", "error")
    WebDriverWait(driver, WAIT_S).until(lambda d: error.is_displayed() and "msaa" in error.text)
    assert "\n" not in error.text.strip()
    # The scene stays: the same environment, and moving the camera still renders.
    assert driver.find_element("id", "env").get_attribute("value") == "0"
    driver.find_element("id", "frame").send_keys("+")
    assert wait_still(driver, "color", seq) > seq
