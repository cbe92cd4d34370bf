"""benchmarks/switching.py: one model for all domains vs switching, end to end, and its report.

The figures are not judged here (a tiny run measures nothing): that every arm saw the same
frames, the switching rule is the tactics', the all-domain model had one domain model's
budget and trained on every domain's selection, a second run continues from the work folder
to the same figures, other settings are refused, and docs/switching.md is exactly what
``--report`` makes of the committed JSON.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest
from bench_helpers import ROOT, script_module

SCRIPT = ROOT / "benchmarks" / "switching.py"


@pytest.fixture(scope="module")
def bench() -> ModuleType:
    return script_module("switching.py", "switching_benchmark")


def test_docs_switching_md_is_what_the_report_makes_of_the_committed_json(bench: Any) -> None:
    doc = json.loads((ROOT / "benchmarks" / "results" / "switching.json").read_text("utf-8"))
    page = (ROOT / "docs" / "switching.md").read_text("utf-8")
    assert bench.render_report(doc) == page, (
        "docs/switching.md is out of date: run .venv/bin/python benchmarks/switching.py --report"
    )
    assert (ROOT / "docs" / "images" / "switching-stream.png").is_file()
    assert "switching.md" in (ROOT / "docs" / "robustify.md").read_text("utf-8")
    assert not doc["quick"] and len(doc["settings"]["stream_seeds"]) >= 3
    assert set(doc["budget"]["all_domains_steps"]) == set(doc["budget"]["shipped_steps"].values())


class Scripted:
    """An oracle that reports, per frame, what a list says (for the active model)."""

    def __init__(self, reports: list[tuple[int, str]]) -> None:
        self.reports = reports
        self.asked: list[str] = []

    def assess(self, image: Any, *, seq: int, model_id: str) -> Any:
        from anunnaki.messages import Assessment

        self.asked.append(model_id)
        cat, context = self.reports[seq]
        return Assessment(
            category=cat, confidence=0.9, context={"phenomenon": context}, model_id=model_id,
            assessor="scripted", frame_seq=seq,
        )  # fmt: skip


def _stream(n: int) -> dict[str, Any]:
    return {"images": [np.zeros((4, 4, 3), np.uint8)] * n, "condition": ["clean"] * n}


def test_the_switched_models_are_the_registrys(bench: Any) -> None:
    """Each domain's model is the one the shipped registry swaps in for it (fog: rover-fog-enki)."""
    from anunnaki.lec import load_registry

    registry = load_registry(bench.MODELS / "rover.yaml")
    for domain, (model_id, _) in bench.DOMAINS.items():
        assert registry.for_domain(domain).id == model_id, domain


def test_the_switching_rule_is_the_tactics(bench: Any) -> None:
    s = bench.Settings(rate=10, hold=(("hsl", 3), ("raindrop", 3), ("fog", 1)), cooldown_s=1.0,
                       back_after_s=0.5)  # fmt: skip
    reports = (
        [(0, "clear")] * 2
        + [(1, "fog")]  # fog: at once
        + [(0, "fog")] * 3  # the fog model's oracle: fine, fog still there
        + [(0, "clear")] * 5  # clear for 0.5 s: back to default
        + [(1, "hsl")] * 2  # hsl: not yet (G20 holds 3 frames)
        + [(0, "clear")]
        + [(1, "hsl")] * 3  # now
        + [(1, "clear")]  # the hsl model degraded in clear weather: default at once
        + [(1, "raindrop+raindrop+raindrop")] * 3  # the composition names the raindrop domain
        + [(1, "brightness")] * 3  # no model for it: stay
    )
    oracle = Scripted(reports)
    out = bench.switch_by_oracle(_stream(len(reports)), s, oracle)
    got = [(w["frame"], w["to"], w["tactic"]) for w in out["swaps"]]
    assert got == [
        (2, "fog", "swap-to-fog"),
        (10, "default", "back-to-default"),
        (16, "hsl", "swap-to-hsl"),
        (17, "default", "default-in-clear-weather"),
        (18, "raindrop", "swap-to-raindrop"),  # G20 counts the alarm since frame 13
    ]
    # a swap is in force from the next frame, and the active model's oracle is asked
    assert out["active"][2] == "default" and out["active"][3] == "fog"
    assert oracle.asked[3] == "rover-fog-enki" and oracle.asked[19] == "rover-raindrop"
    assert out["active"][-1] == "raindrop"


def test_a_swap_tactic_waits_out_its_cooldown(bench: Any) -> None:
    s = bench.Settings(rate=10, hold=(("hsl", 1), ("raindrop", 1), ("fog", 1)), cooldown_s=1.0,
                       back_after_s=0.2)  # fmt: skip
    reports = [(1, "fog"), (1, "clear"), (1, "fog"), *[(1, "fog")] * 8, (1, "fog")]
    out = bench.switch_by_oracle(_stream(len(reports)), s, Scripted(reports))
    fog = [w["frame"] for w in out["swaps"] if w["to"] == "fog"]
    assert fog == [0, 10]  # fired at 0, then not before 10 frames (1 s) had passed


def test_paired_differences_and_run_length_codes(bench: Any) -> None:
    runs = {
        "a": [{"stream_seed": i, "f1": {"overall": v}} for i, v in enumerate([0.8, 0.7, 0.9])],
        "b": [{"stream_seed": i, "f1": {"overall": v}} for i, v in enumerate([0.7, 0.6, 0.8])],
        "c": [{"stream_seed": i, "f1": {"overall": v}} for i, v in enumerate([0.9, 0.5, 0.9])],
    }
    win = bench.paired(runs, "a", "b", "overall")
    assert win["n"] == 3 and win["mean"] == pytest.approx(0.1) and win["verdict"] == "win"
    assert bench.paired(runs, "a", "c", "overall")["verdict"] == "tie"  # +0.2, -0.1, 0: spread
    assert bench.paired(runs, "b", "a", "overall")["verdict"] == "loss"
    codes = bench.runs_of(["x", "x", "y", "x"])
    assert codes == [["x", 0, 2], ["y", 2, 1], ["x", 3, 1]]
    assert bench.expand(codes) == ["x", "x", "y", "x"]


def test_scores_pool_counts_per_phase_and_count_wrong_models(bench: Any) -> None:
    stream = {"condition": ["clean", "clean", "fog", "fog", "hsl"]}
    counts = np.array([[1, 0, 0], [1, 1, 0], [0, 0, 2], [1, 0, 1], [0, 0, 0]])
    active = ["default", "fog", "default", "fog", "fog"]
    r = bench.score(counts, stream, active)
    assert r["f1"]["clean"] == round(2 * 2 / (2 * 2 + 1), 5)
    assert r["f1"]["fog"] == round(2 / (2 + 3), 5)
    assert r["f1"]["hsl"] is None and r["f1"]["raindrop"] is None
    assert r["wrong_frames"] == 3
    assert r["wrong_detail"] == {"adverse_in_default": 1, "clean_in_domain_model": 1,
                                 "adverse_in_other_domain_model": 1}  # fmt: skip
    assert bench.score(counts, stream, None)["wrong_frames"] is None
    # a phase with false positives and nothing to find has no F1 (not 0): issue 34, item 5
    only_fp = bench.score(np.array([[0, 2, 0]]), {"condition": ["hsl"]}, None)
    assert only_fp["f1"]["hsl"] is None
    truth = bench.switch_by_truth({"condition": ["clean", "fog", "fog", "clean"]})
    assert truth["active"] == ["default", "fog", "fog", "default"] and len(truth["swaps"]) == 2


def _domains(root: Path) -> Path:
    """Tiny chain folders: an archive and a selection per domain."""
    from anunnaki.enki import SelectionRule, select_contexts
    from anunnaki.enlil import ArchiveMeta, ArchiveWriter, read_archive, resolve_phenomenon
    from anunnaki.enlil._context import ContextResult

    rng = np.random.default_rng(0)
    for model_id, phen in (("rover-hsl", "hsl"), ("rover-raindrop", "raindrop+raindrop+raindrop"),
                           ("rover-fog-enki", "fog")):  # fmt: skip
        names = tuple(resolve_phenomenon(phen).param_names)
        meta = ArchiveMeta(
            model_id="rover-default", sha256="", dataset="d", split="val", phenomenon=phen,
            param_names=names, seed=0, thresholds=(0.05, 0.1), budget=12, search="sobol",
            batch_images=4, clean_f1=0.9,
        )  # fmt: skip
        folder = root / model_id
        results = [ContextResult(rng.random(len(names)), 0.5, 0.4, int(i % 3)) for i in range(12)]
        ArchiveWriter(folder / "search", meta).append(0, 0, results)
        sel = select_contexts(read_archive(folder / "search"), SelectionRule(contexts=4))
        (folder / "stages").mkdir()
        (folder / "stages" / "select.json").write_text(json.dumps(sel.as_dict()), "utf-8")
    return root


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(SCRIPT), *args],
        capture_output=True, text=True, timeout=500, cwd=ROOT, check=False,
    )  # fmt: skip


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_quick_run_end_to_end_resumes_and_reports(
    bench: Any, tiny_rover: Path, tmp_path: Path
) -> None:
    pytest.importorskip("torch")
    domains = _domains(tmp_path / "domains")
    work, out = tmp_path / "work", tmp_path / "switching.json"
    argv = ["--quick", "--data", str(tiny_rover), "--domains", str(domains), "--work", str(work),
            "--output", str(out), "--quiet"]  # fmt: skip
    first = _run(*argv)
    assert first.returncode == 0, first.stdout[-2000:] + first.stderr[-4000:]
    doc = json.loads(out.read_text("utf-8"))
    assert doc["quick"] is True and list(doc["summary"]) == list(bench.ARMS)
    seeds = doc["settings"]["stream_seeds"]
    # every arm ran on every stream; the all-domain arm once per fine-tune seed
    for arm in bench.ARMS:
        per = [r["stream_seed"] for r in doc["runs"][arm]]
        assert sorted(set(per)) == sorted(seeds)
    for st in doc["streams"]:
        assert st["plan"][0] == "clean" and sorted(set(st["plan"]) - {"clean"}) == [
            "fog", "hsl", "raindrop"]  # fmt: skip
        assert st["frames"] == sum(st["frames_per_phase"])
        # every adverse phase has a context of its domain's held-out pool
        assert all(
            (c is None) == (p == "clean") for p, c in zip(st["plan"], st["contexts"], strict=True)
        )
    # the budget: one domain model's settings, and the mixed source of the three selections
    (ft,) = doc["finetunes"]
    assert ft["steps"] == doc["budget"]["all_domains_steps"][0] > 0
    assert ft["source"]["kind"] == "mixed"
    assert [x["phenomenon"] for x in ft["source"]["sources"]] == [
        "hsl", "raindrop+raindrop+raindrop", "fog"]  # fmt: skip
    # the arms' runs: default never swaps and is in a wrong model exactly on adverse frames
    for r, st in zip(doc["runs"]["default"], doc["streams"], strict=True):
        adverse = sum(k for p, k in zip(st["plan"], st["frames_per_phase"], strict=True)
                      if p != "clean")  # fmt: skip
        assert r["swaps"] == 0 and r["wrong_frames"] == adverse
    for r in doc["runs"]["switched_truth"]:
        assert r["wrong_frames"] == 0 and r["swaps"] == 6
    for i, r in enumerate(doc["runs"]["switched"]):
        frames = doc["streams"][i]["frames"]
        assert len(bench.expand(r["active"])) == len(bench.expand(r["reports"])) == frames
        assert ("counts" in r) == (i == 0)  # per-frame counts for the plotted stream only
        assert len({w["frame"] for w in r["swap_list"]}) == r["swaps"]
    # the paired differences: one per stream (and fine-tune seed), a verdict each
    p = doc["paired"]["switched-all_domains"]["overall"]
    assert p["n"] == len(doc["streams"]) and p["verdict"] in ("win", "tie", "loss")
    # a second run continues: nothing is trained or rendered again, the figures are the same
    mtime = (work / "all-s0" / "rover-all.safetensors").stat().st_mtime
    again = _run(*argv)
    assert again.returncode == 0, again.stderr[-3000:]
    assert (work / "all-s0" / "rover-all.safetensors").stat().st_mtime == mtime
    assert json.loads(out.read_text("utf-8"))["summary"] == doc["summary"]
    # other settings are refused, naming the setting
    (work / "settings.json").write_text(
        (work / "settings.json").read_text("utf-8").replace('"epochs": 1', '"epochs": 2'), "utf-8"
    )
    refused = _run(*argv)
    assert refused.returncode != 0 and "epochs" in refused.stderr
    # the report: a page and its plot from the JSON alone
    page, images = tmp_path / "switching.md", tmp_path / "images"
    rep = _run("--report", "--output", str(out), "--doc", str(page), "--images", str(images))
    assert rep.returncode == 0, rep.stderr[-3000:]
    text = page.read_text("utf-8")
    assert "quick" in text and "| rover-default alone |" in text
    assert (images / "switching-stream.png").is_file()
