"""The report in headless Chromium: no console messages or script errors, every
image decodes (naturalWidth > 0), and the sortable table and the compare slider
work. report.js writes its self-check into <body data-images-ok data-errors>;
``--dump-dom`` reads it back after the load event. Screenshots go to the
test's tmp folder (their paths are printed).

Needs the Debian package ``chromium`` (``apt-get install -y chromium``).
"""

import html.parser
import re
import shutil
import subprocess

import numpy as np
import pytest
from PIL import Image



pytestmark = pytest.mark.browser

CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)),
                None)
if CHROMIUM is None:
    pytest.skip("headless Chromium is not installed (apt-get install -y chromium)", allow_module_level=True)

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--no-default-browser-check",
         "--disable-extensions", "--hide-scrollbars", "--enable-logging=stderr", "--v=0",
         "--virtual-time-budget=10000"]

# Injected into a copy of a scene page: sorts the first metrics table by relmse
# twice (ascending, then descending), moves the compare slider and clicks the
# compare view, and records what happened on <body data-selftest-*>.
SELFTEST = """
<script>
window.addEventListener("load", function () {
  var d = document.body.dataset;
  function col(table, idx) {
    return Array.prototype.map.call(table.tBodies[0].rows, function (r) { return r.cells[idx].dataset.sort; });
  }
  var table = document.querySelector("table.metrics");
  var heads = Array.prototype.slice.call(table.tHead.rows[0].cells);
  var idx = heads.findIndex(function (th) { return th.textContent.trim() === "relmse"; });
  heads[idx].click();
  d.selftestAsc = col(table, idx).join(",");
  heads[idx].click();
  d.selftestDesc = col(table, idx).join(",");
  d.selftestAria = heads[idx].getAttribute("aria-sort");
  var fig = document.querySelector(".compare").parentNode;
  var slider = fig.querySelector(".slider"), overlay = fig.querySelector(".overlay");
  slider.value = "25";
  slider.dispatchEvent(new Event("input"));
  d.selftestClip = overlay.style.clipPath;
  fig.querySelector(".compare").click();
  d.selftestClick = overlay.style.clipPath + "|" + slider.value;
});
</script>
"""


class _Body(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.attrs, self.errors_text, self._in_errors = None, "", False

    def handle_starttag(self, tag, attrs):
        if tag == "body" and self.attrs is None:
            self.attrs = dict(attrs)
        self._in_errors = tag == "pre" and dict(attrs).get("id") == "report-errors"

    def handle_data(self, data):
        if self._in_errors:
            self.errors_text += data


def chromium(page, profile, *extra):
    """Run headless Chromium on ``page``; returns (stdout, console lines from stderr)."""
    cmd = [CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *extra, page.resolve().as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, f"chromium exited with {proc.returncode}: {proc.stderr[-2000:]}"
    console = [ln for ln in proc.stderr.splitlines() if ":CONSOLE" in ln]
    return proc.stdout, console


def load(page, profile):
    dom, console = chromium(page, profile, "--dump-dom")
    body = _Body()
    body.feed(dom)
    assert body.attrs is not None, f"no <body> in the DOM of {page}"
    return body, console


def screenshot(page, profile, out, size=(1400, 2400)):
    chromium(page, profile, f"--window-size={size[0]},{size[1]}", f"--screenshot={out}")
    assert out.is_file(), f"no screenshot written for {page}"
    img = np.asarray(Image.open(out).convert("L"), dtype=np.float32)
    assert img.std() > 5, f"{out} looks blank"
    print(f"screenshot: {out}")
    return out


@pytest.fixture(scope="module")
def site(synthetic_site):
    """The session's synthetic site (conftest), shared with test_report."""
    root, _, _, info = synthetic_site
    return root, info


@pytest.mark.parametrize("which", ["index", "scene"])
def test_page_loads_cleanly(site, tmp_path, which):
    root, info = site
    page = info["index"] if which == "index" else info["scene_pages"]["slab"]
    body, console = load(page, tmp_path / "profile")
    a = body.attrs
    assert a.get("data-checked") == "true", "report.js did not run its load check"
    assert a.get("data-errors") == "0", f"script/resource errors: {body.errors_text.strip()}"
    assert console == [], "console messages:\n" + "\n".join(console)
    assert int(a["data-images-total"]) > (0 if which == "index" else 50)
    assert a.get("data-images-ok") == "true", f"images that did not load: {a.get('data-images-broken')}"
    screenshot(page, tmp_path / "profile", tmp_path / f"{which}.png")


def test_broken_image_is_detected(site, tmp_path):
    """The self-check itself: a page with a missing image must fail it."""
    root, info = site
    page = info["index"]
    bad = page.with_name("_broken.html")
    bad.write_text(page.read_text().replace("</main>", '<img src="nope.png" alt="missing"></main>'))
    try:
        body, _ = load(bad, tmp_path / "profile")
    finally:
        bad.unlink()
    assert body.attrs.get("data-images-ok") == "false"
    assert "nope.png" in body.attrs.get("data-images-broken", "")
    assert body.attrs.get("data-errors") != "0" and "nope.png" in body.errors_text


def test_sorting_and_compare_slider(site, tmp_path):
    root, info = site
    page = info["scene_pages"]["slab"]
    probe = page.with_name("_selftest.html")
    probe.write_text(page.read_text().replace("</body>", SELFTEST + "</body>"))
    try:
        body, console = load(probe, tmp_path / "profile")
    finally:
        probe.unlink()
    a = body.attrs
    assert console == [] and a.get("data-errors") == "0", body.errors_text
    asc = [float(x) for x in a["data-selftest-asc"].split(",")]
    desc = [float(x) for x in a["data-selftest-desc"].split(",")]
    assert len(asc) == 12 and asc == sorted(asc) and desc == sorted(asc, reverse=True)
    assert a["data-selftest-aria"] == "descending"
    assert re.fullmatch(r"inset\(0(px)? 0(px)? 0(px)? 25%\)", a["data-selftest-clip"])
    assert a["data-selftest-click"].endswith("|0")  # a click from a split shows all of SSLPV
