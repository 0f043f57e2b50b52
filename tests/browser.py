"""Open an HTML page in Debian's headless Chromium and report what a reader would meet.

No driver library: the page is copied beside itself with a probe script injected first in its
<head>. The probe records console errors, uncaught exceptions and resources that failed to
load; after the load event (and ``--virtual-time-budget`` for late work) it writes its
findings as JSON into the DOM, which ``chromium --dump-dom`` prints. A window of 1280 x 900
CSS pixels is the size the pages must fit. Screenshots: ``chromium --screenshot``.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

WIDTH, HEIGHT = 1280, 900
MARK = "raysim-browser-probe"
PROBE = """<script>
(function () {
  var found = {console_errors: [], exceptions: [], failed_resources: []};
  var error = console.error;
  console.error = function () {
    found.console_errors.push(Array.prototype.map.call(arguments, String).join(" "));
    return error.apply(console, arguments);
  };
  window.addEventListener("error", function (e) {
    if (e.target && e.target !== window && (e.target.src || e.target.href)) {
      found.failed_resources.push(e.target.src || e.target.href);
    } else {
      found.exceptions.push(String(e.message));
    }
  }, true);
  window.addEventListener("unhandledrejection", function (e) {
    found.exceptions.push("unhandled rejection: " + String(e.reason));
  });
  window.addEventListener("load", function () {
    setTimeout(function () {
      var images = Array.prototype.map.call(document.images, function (img) {
        return {src: (img.currentSrc || img.src).slice(0, 120), complete: img.complete,
                natural_width: img.naturalWidth, natural_height: img.naturalHeight};
      });
      found.images = images;
      found.scroll_width = document.documentElement.scrollWidth;
      found.client_width = document.documentElement.clientWidth;
      found.title = document.title;
      var out = document.createElement("pre");
      out.id = "@MARK@";
      out.textContent = JSON.stringify(found);
      document.body.appendChild(out);
    }, 500);
  });
})();
</script>""".replace("@MARK@", MARK)


def chromium() -> str | None:
    """The Chromium executable, or None where it is not installed."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def _run(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess:
    exe = chromium()
    assert exe is not None
    # --no-sandbox: the tests may run as root (CI containers), where the sandbox refuses
    return subprocess.run([exe, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                           f"--window-size={WIDTH},{HEIGHT}", "--virtual-time-budget=5000", *args],
                          capture_output=True, text=True, timeout=timeout)


@dataclass(frozen=True)
class PageReport:
    """What the probe found on one page."""

    console_errors: list[str]
    exceptions: list[str]
    failed_resources: list[str]
    images: list[dict]
    scroll_width: int
    client_width: int
    title: str


def inspect(page: Path) -> PageReport:
    """Load ``page`` (an HTML file; its folder's relative resources stay reachable) and report."""
    html = page.read_text(encoding="utf-8")
    head = re.search(r"<head[^>]*>", html, flags=re.IGNORECASE)
    assert head is not None, f"{page}: no <head>"
    probe = page.with_name(f".{page.stem}.probe.html")
    probe.write_text(html[:head.end()] + PROBE + html[head.end():], encoding="utf-8")
    try:
        done = _run("--dump-dom", probe.resolve().as_uri())
    finally:
        probe.unlink()
    found = re.search(rf'<pre id="{MARK}">(.*?)</pre>', done.stdout, flags=re.DOTALL)
    assert found is not None, f"the probe did not report on {page}:\n{done.stderr[-2000:]}"
    text = found.group(1).replace("&lt;", "<").replace("&gt;", ">").replace("&quot;", '"')
    return PageReport(**json.loads(text.replace("&amp;", "&")))


def screenshot(page: Path, png: Path, height: int = HEIGHT) -> Path:
    """A PNG of the first ``height`` CSS pixels of ``page`` at the test width."""
    done = _run(f"--screenshot={png.resolve()}", f"--window-size={WIDTH},{height}",
                page.resolve().as_uri())
    assert png.exists() and png.stat().st_size > 0, done.stderr[-2000:]
    return png
