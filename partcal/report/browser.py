"""Open a report in headless Chromium: what a person would see, checked by a program.

Uses Playwright with the system's Chromium (Debian package ``chromium``);
nothing is downloaded. The page is opened from a file URL with the network
features of the browser switched off, so any request the page makes shows up
as a failure.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import PartcalError

ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", "--no-first-run", "--disable-quic"]


@dataclass
class PageCheck:
    console_errors: list[str] = field(default_factory=list)
    failed_requests: list[str] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)
    image_widths: list[int] = field(default_factory=list)
    cells: dict[str, dict[str, str]] = field(default_factory=dict)     # model -> {data-key: data-value}
    dialogs: list[str] = field(default_factory=list)                    # alert() & co: must never happen
    wider_than_page: list[str] = field(default_factory=list)            # tables (id or class) cut at the page's width
    screenshot: Path | None = None


def check_screenshot_tools() -> None:
    """``run --screenshot`` needs Chromium and Playwright: refuse (before any fit) when either is missing."""
    chromium_path()
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        raise PartcalError("--screenshot needs the Python package 'playwright' (pip install 'partcal[browser]'; it "
                           "uses the system's chromium)") from None


def chromium_path() -> str:
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if not path:
        raise PartcalError("no chromium found: install the Debian package 'chromium' for screenshots")
    return path


def open_report(html: Path, screenshot: Path | None = None, width: int = 1280) -> PageCheck:
    """Load ``html`` in headless Chromium, ``width`` pixels wide; collect errors, requests, images, table cells
    and the tables wider than the page's text column (a screenshot cuts them)."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        raise PartcalError("screenshots need the 'playwright' package (pip install playwright)") from None
    check = PageCheck()
    with tempfile.TemporaryDirectory(prefix="partcal-chromium-") as profile, sync_playwright() as pw:
        browser = pw.chromium.launch_persistent_context(profile, executable_path=chromium_path(), args=ARGS,
                                                        headless=True, viewport={"width": width, "height": 900})
        try:
            page = browser.new_page()
            page.on("console", lambda m: check.console_errors.append(m.text) if m.type == "error" else None)
            page.on("pageerror", lambda e: check.console_errors.append(str(e)))
            page.on("request", lambda r: check.requests.append(r.url))
            page.on("requestfailed", lambda r: check.failed_requests.append(r.url))
            page.on("dialog", lambda d: (check.dialogs.append(d.message), d.dismiss()))
            page.goto(Path(html).resolve().as_uri(), wait_until="load")
            check.image_widths = page.evaluate("Array.from(document.images).map(i => i.complete ? i.naturalWidth : 0)")
            check.cells = page.evaluate("""() => {
                const out = {};
                document.querySelectorAll('#comparison-table tbody tr').forEach(tr => {
                    const row = {};
                    tr.querySelectorAll('td[data-key]').forEach(td => { row[td.dataset.key] = td.dataset.value; });
                    out[tr.dataset.model] = row;
                });
                return out;
            }""")
            check.wider_than_page = page.evaluate("""() => {
                const main = document.querySelector('main'), style = getComputedStyle(main);
                const column = main.clientWidth - parseFloat(style.paddingLeft) - parseFloat(style.paddingRight);
                return Array.from(document.querySelectorAll('table'))
                    .filter(t => t.getBoundingClientRect().width > column)
                    .map(t => t.id || t.className || 'table');
            }""")
            if screenshot is not None:
                page.screenshot(path=str(screenshot), full_page=True)
                check.screenshot = screenshot
        finally:
            browser.close()
    return check
