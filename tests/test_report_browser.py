"""The compare report as a browser sees it: tables are HTML (the per-image one sortable),
and every image of the page loads. Opens the page in headless Chromium (skipped where
Debian's ``chromium`` is not installed; scripts/setup.sh installs it when root)."""
import html.parser
import os
import shutil
import subprocess

import pytest

from relight.cli import main
from relight.predictions import write_predictions
from relight.verify.report import markdown_html

N_IMAGES = 3
BROWSER_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--virtual-time-budget=10000"]


class _Tags(html.parser.HTMLParser):
    """Start tags with their attributes, and the text of elements by id."""

    def __init__(self):
        super().__init__()
        self.tags, self.text, self._open = [], {}, None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append((tag, attrs))
        if "id" in attrs:
            self._open = attrs["id"]
            self.text.setdefault(self._open, "")

    def handle_data(self, data):
        if self._open:
            self.text[self._open] += data

    def handle_endtag(self, tag):
        self._open = None


def _parse(text):
    p = _Tags()
    p.feed(text)
    return p


@pytest.fixture(scope="module")
def report(tmp_path_factory, mi):
    from relight.dataset import read_manifest
    from relight.generator.run import generate
    from relight.generator.sampling import GeneratorConfig
    root = tmp_path_factory.mktemp("report_browser")
    generate(root / "ds", count=N_IMAGES, seed=5, cfg=GeneratorConfig(res=32, spp=4), progress=False)
    recs = read_manifest(root / "ds")
    # pans moved by 10, 20, 30 deg: known per-image direction errors to sort by
    entries = [{"id": r["id"], "pan_deg": (r["pan_rel_deg"] + 10.0 * (k + 1)) % 360.0,
                "tilt_deg": r["light"]["tilt_deg"], "rgb": r["light"]["rgb"]}
               for k, r in enumerate(recs)]
    write_predictions(root / "p.json", entries, dataset=str(root / "ds"))
    assert main(["compare", str(root / "p.json"), "--out", str(root / "report"), "--quiet"]) == 0
    return root / "report", recs


def test_markdown_tables_become_html():
    md = ("**Table 1. Overall (degrees)**\n\n| Stat | n | Pan |\n|---|---|---:|\n"
          "| Mean | 3 | 1.50 |\n\n- a: `x` bad\n")
    out = markdown_html(md)
    assert "<p><b>Table 1. Overall (degrees)</b></p>" in out
    assert "<th style='text-align:left'>Stat</th>" in out and "<th style='text-align:right'>Pan</th>" in out
    assert "<td style='text-align:right'>1.50</td>" in out and "---" not in out
    assert "<li>a: <code>x</code> bad</li>" in out


def test_report_page_structure(report):
    out, recs = report
    page = (out / "index.html").read_text()
    assert "<pre>" not in page and "|---" not in page          # no raw markdown left
    p = _parse(page)
    tables = [a for t, a in p.tags if t == "table"]
    assert {"class": "sortable", "id": "per-image"} in tables
    assert sum(a.get("class") == "stats" for a in tables) >= 4   # Tables 1-3 and image errors
    srcs = [a["src"] for t, a in p.tags if t == "img"]
    assert srcs == ["figure3.png"] + [f"panels/{r['id']}.png" for r in recs]
    for src in srcs:
        assert (out / src).is_file(), src
    assert "<script>" in page


def _chromium():
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("headless Chromium is not installed (scripts/setup.sh installs it as root)")


def _dump_dom(url, tmp_path, extra=()):
    browser = _chromium()
    run = subprocess.run([browser, *BROWSER_FLAGS, f"--user-data-dir={tmp_path / 'profile'}",
                          *extra, "--dump-dom", url], capture_output=True, text=True, timeout=180)
    assert run.returncode == 0, run.stderr[-2000:]
    return run.stdout


def test_every_image_loads_in_chromium(report, tmp_path):
    out, recs = report
    dom = _parse(_dump_dom((out / "index.html").as_uri(), tmp_path))
    check = [a for t, a in dom.tags if a.get("id") == "image-check"]
    assert check, "the page's image check did not run"
    total = N_IMAGES + 1                                         # Figure 3 and one panel each
    assert check[0].get("data-total") == str(total)
    assert check[0].get("data-loaded") == str(total), dom.text.get("image-check")


def test_a_missing_image_is_caught(report, tmp_path):
    # the check can fail: remove one panel from a copy of the report
    out, recs = report
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    os.remove(copy / "panels" / f"{recs[0]['id']}.png")
    dom = _parse(_dump_dom((copy / "index.html").as_uri(), tmp_path))
    check = [a for t, a in dom.tags if a.get("id") == "image-check"][0]
    assert check.get("data-loaded") == str(N_IMAGES) and check.get("data-total") == str(N_IMAGES + 1)


def test_per_image_table_sorts_in_chromium(report, tmp_path):
    # click the pan-error header once (ascending: the pan shifts 10, 20, 30 in manifest
    # order) and again (descending: reversed). A page script clicks and reports.
    out, recs = report
    page = (out / "index.html").read_text()
    probe = ("<script>window.addEventListener('load', function () {"
             "function ids() { return Array.from(document.querySelectorAll('#per-image tbody tr'))"
             ".map(function (r) { return r.cells[0].textContent; }).join(','); }"
             "var th = document.querySelectorAll('#per-image th')[3]; th.click(); var up = ids();"
             "th.click(); var down = ids();"
             "document.body.insertAdjacentHTML('beforeend', \"<p id='up'>\" + up + \"</p><p id='down'>\" + down + '</p>');"
             "});</script></body>")
    (out.parent / "sort_probe.html").write_text(page.replace("</body>", probe).replace(
        "src='", "src='report/").replace("href='", "href='report/"))
    dom = _parse(_dump_dom((out.parent / "sort_probe.html").as_uri(), tmp_path))
    assert "pan_error_deg" in page
    order = [r["id"] for r in recs]
    assert dom.text.get("up", "").split(",") == order
    assert dom.text.get("down", "").split(",") == order[::-1]
