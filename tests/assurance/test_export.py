"""The drawing and the report: every node drawn and coloured, the report self-contained."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from anunnaki.assurance import Case, build_case, render_html, render_svg

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def uav() -> Case:
    return build_case(ROOT / "examples/uav/sim.yaml", root=ROOT)


def test_the_svg_draws_every_node_once_with_its_status(uav: Case) -> None:
    svg = render_svg(uav)
    tree = ET.fromstring(svg)  # well-formed XML
    ns = "{http://www.w3.org/2000/svg}"
    groups = {g.get("id"): g.get("class", "").split() for g in tree.iter(f"{ns}g")}
    assert set(groups) == {f"gsn-{n.id}" for n in uav}
    for n in uav:
        cls = groups[f"gsn-{n.id}"]
        assert cls[:2] == ["gsn", n.type]
        if n.status:
            assert cls[2] == n.status
    assert "undeveloped" in groups["gsn-G12"]
    # a goal is a rectangle, a strategy a parallelogram, a solution a circle
    g1 = next(g for g in tree.iter(f"{ns}g") if g.get("id") == "gsn-G1")
    assert g1.find(f"{ns}rect") is not None
    sn = next(g for g in tree.iter(f"{ns}g") if g.get("id") == "gsn-Sn-G1-1")
    assert sn.find(f"{ns}circle") is not None


def test_the_report_is_self_contained_and_lists_every_evidence(uav: Case) -> None:
    page = render_html(uav)
    assert "<script" not in page and "<link" not in page
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:|//)""", page)
    assert "<svg" in page and "<style>" in page
    for n in uav.solutions():
        assert n.evidence is not None
        assert f'id="{n.id}"' in page
        for a in n.evidence.artefacts:
            assert a.sha256 in page
    assert "nice -n 10 .venv/bin/python benchmarks/case_studies.py --cases uav" in page
    cov = uav.coverage()
    text = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", "", page))
    assert f"{cov['supported']} of {cov['leaf_goals']} leaf goals supported" in text
