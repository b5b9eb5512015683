"""The demo's HTML report in a real browser: headless Chromium renders it, takes a screenshot, and the
test checks that every figure loaded, nothing is wider than the window, and the browser logged no error.

Chromium and its driver come from the distribution's packages (`chromium`, `chromium-driver`); `.ci/run`
installs them when missing. Without them the test is skipped on a developer's machine, but it FAILS when
`RIMLESS_REQUIRE_BROWSER=1` (set by `.ci/run`) or `CI` is set: CI must never pass without looking.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

WIDTHS_PX = (1280, 1024)  # a desktop window and a laptop's
CHECK_JS = """
const w = window.innerWidth;
const imgs = Array.from(document.images).map(i => ({src: i.getAttribute('src'), complete: i.complete,
    natural: i.naturalWidth, shown: i.getBoundingClientRect().width,
    parent: i.parentElement.getBoundingClientRect().width}));
const wide = [];
for (const el of document.body.querySelectorAll('*')) {
  const r = el.getBoundingClientRect();
  if (r.width > 0 && (r.right > w + 1 || r.left < -1)) {
    wide.push(el.tagName.toLowerCase() + (el.id ? '#' + el.id : '') + ' right=' + Math.round(r.right));
  }
}
return {innerWidth: w, scrollWidth: document.documentElement.scrollWidth, imgs: imgs, wide: wide.slice(0, 10),
        height: document.documentElement.scrollHeight, title: document.title};
"""


def _browser() -> tuple[str, str] | None:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    return (chromium, driver) if chromium and driver else None


def _required() -> bool:
    return os.environ.get("RIMLESS_REQUIRE_BROWSER") == "1" or bool(os.environ.get("CI"))


@pytest.fixture(scope="module")
def browser_paths() -> tuple[str, str]:
    found = _browser()
    if found is None:
        message = (
            "headless Chromium and chromedriver are not installed (Debian packages chromium and "
            "chromium-driver; `.ci/run` installs them)"
        )
        if _required():
            pytest.fail(
                f"{message}, and this run requires them (RIMLESS_REQUIRE_BROWSER=1 or CI set): "
                "the HTML report would go unchecked"
            )
        pytest.skip(message)
    pytest.importorskip("selenium", reason="selenium is in the test extra: pip install -e '.[pc,test]'")
    return found


@pytest.fixture(scope="module")
def demo_report(demo_run) -> Path:
    assert demo_run.returncode == 0, demo_run.stderr[-3000:]
    html = demo_run.out / "report.html"
    assert html.is_file(), f"the demo wrote no {html}"
    return html


def _driver(chromium: str, chromedriver: str, width: int):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = chromium
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--hide-scrollbars",
        f"--window-size={width},900",
    ):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(executable_path=chromedriver), options=opts)


@pytest.mark.xdist_group("demo")  # one worker reads the demo; the other never waits on its lock
@pytest.mark.slow
@pytest.mark.parametrize("width", WIDTHS_PX)
def test_demo_report_renders_in_chromium(browser_paths, demo_report: Path, width: int, tmp_path: Path) -> None:
    import base64

    chromium, chromedriver = browser_paths
    driver = _driver(chromium, chromedriver, width)
    try:
        driver.set_page_load_timeout(60)
        driver.get(demo_report.as_uri())
        driver.execute_async_script(
            "const done = arguments[arguments.length - 1];"
            "if (document.readyState === 'complete') done(); else window.addEventListener('load', () => done());"
        )
        page = driver.execute_script(CHECK_JS)
        # the whole page, not only the first screen
        shot = driver.execute_cdp_cmd("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True})
        png = tmp_path / f"report-{width}px.png"
        png.write_bytes(base64.b64decode(shot["data"]))
        logs = [entry for entry in driver.get_log("browser") if entry.get("level") == "SEVERE"]
    finally:
        driver.quit()

    print(f"screenshot: {png} ({page['innerWidth']} x {page['height']} px)")
    assert page["title"], "the report has no title"
    assert len(page["imgs"]) >= 2, f"expected the CoM-height and step-period figures, found {page['imgs']}"
    broken = [i["src"] for i in page["imgs"] if not (i["complete"] and i["natural"] > 0)]
    assert not broken, f"figures that did not load: {broken}"
    tiny = [i["src"] for i in page["imgs"] if i["shown"] < min(i["natural"], 0.5 * page["innerWidth"])]
    assert not tiny, f"figures shown smaller than half the window: {tiny}"
    assert page["scrollWidth"] <= page["innerWidth"], (
        f"the page scrolls sideways at {width} px: {page['scrollWidth']} px wide; widest elements: {page['wide']}"
    )
    assert not page["wide"], f"elements reach past the window at {width} px: {page['wide']}"
    assert not logs, f"the browser logged errors: {logs}"

    # the screenshot is a real picture of the page: a PNG of the full height with more than one colour
    from matplotlib.image import imread

    pixels = imread(png)
    assert pixels.shape[1] >= width * 0.9 and pixels.shape[0] >= 900
    assert float(pixels[..., :3].std()) > 0.01, "the screenshot is blank"
