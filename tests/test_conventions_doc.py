"""docs/conventions.md is the repository's copy of the shared conventions contract:
every section heading and every code block of the contract appears in it unchanged."""
import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "conventions.md")
SHARED = os.path.join(os.path.dirname(ROOT), "shared", "conventions.md")


def _headings(text):
    return [ln.strip() for ln in text.splitlines() if re.match(r"#{1,6} ", ln)]


def _code_blocks(text):
    return re.findall(r"^```[^\n]*\n.*?^```", text, flags=re.S | re.M)


def test_doc_has_project_additions():
    with open(DOC, encoding="utf-8") as f:
        doc = f.read()
    for needle in ("render.sampler", "colour_prior", "cone90_deg", "to_light_camera",
                   "Camera frame", "relight.predictions/v1"):
        assert needle in doc, needle


def test_doc_matches_shared_contract():
    if not os.path.isfile(SHARED):
        pytest.skip("the shared contract is not next to this checkout")
    with open(SHARED, encoding="utf-8") as f:
        shared = f.read()
    with open(DOC, encoding="utf-8") as f:
        doc = f.read()
    assert _headings(shared) and _code_blocks(shared)   # the parsers see something
    doc_headings = set(_headings(doc))
    missing = [h for h in _headings(shared) if h not in doc_headings]
    assert not missing, f"headings of the contract missing from docs/conventions.md: {missing}"
    for block in _code_blocks(shared):
        assert block in doc, f"code block of the contract missing or changed:\n{block}"
