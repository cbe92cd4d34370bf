"""Evidence from the project's own measurements: each criteria item → GSN solutions.

Nothing is measured here and no model is loaded: the figures are read from the model
registry's sidecars (``NAME.json``, ``NAME.oracle.json``) and the results files of
``benchmarks/`` (``robustify.json``, ``oracle.json``, ``case-studies.json`` …), and every
file a figure rests on is hashed. Where a file records the sha256 of what it measured (a
model sidecar its weights', an oracle sidecar its model's, ``oracle_ramps.json`` its
oracle's), a different sha256 today makes the figure stale at once.
"""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from anunnaki.assurance._case import Artefact, Evidence
from anunnaki.assurance._criteria import DEFAULT_STAGE, EvidenceSpec
from anunnaki.assurance._relax_text import Acceptance, check_value
from anunnaki.errors import ModelFileError
from anunnaki.lec import ModelRegistry, sha256_file

__all__ = ["Sources", "collect", "relative", "run_tests"]


def relative(root: Path, path: Path) -> str:
    """``path`` relative to ``root`` where it lies inside it, else absolute (POSIX form)."""
    p = path.resolve()
    return p.relative_to(root).as_posix() if p.is_relative_to(root) else p.as_posix()


@dataclass
class Sources:
    """What a case's evidence is read from, and the hashes taken so far.

    Attributes:
        root: The project root; paths in the case are relative to it.
        files: The launch's own files by role (``launch``, ``goal_model``, ``binding``,
            ``tactics``, ``registry``, ``scenario``).
        registry: The launch's model registry, when it names one.
        criteria_source: The criteria file, for error messages.
        test_results: Node id → ``pass``/``fail`` of the tests run (``--run-tests``).

    """

    root: Path
    files: dict[str, Path]
    registry: ModelRegistry | None = None
    criteria_source: str | None = None
    test_results: dict[str, str] = field(default_factory=dict)
    _hashes: dict[Path, str] = field(default_factory=dict)
    _json: dict[Path, Any] = field(default_factory=dict)

    def rel(self, path: Path) -> str:
        """``path`` relative to the root when inside it."""
        return relative(self.root, path)

    def sha(self, path: Path) -> str:
        """The file's sha256, hashed once per build."""
        p = path.resolve()
        if p not in self._hashes:
            self._hashes[p] = sha256_file(p)
        return self._hashes[p]

    def artefact(self, role: str, path: Path, measured: str | None = None) -> Artefact:
        """An artefact record for ``path`` (which must exist)."""
        return Artefact(role, self.rel(path), self.sha(path), measured)

    def read_json(self, path: Path, element: str) -> Any:
        """A results or sidecar file's JSON, read once."""
        p = path.resolve()
        if p not in self._json:
            try:
                self._json[p] = json.loads(p.read_text(encoding="utf-8"))
            except FileNotFoundError:
                raise ModelFileError(
                    f"{self.rel(p)} does not exist",
                    path=self.criteria_source,
                    element=element,
                    hint="run the benchmark that writes it, or fix the path (relative to --root)",
                ) from None
            except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
                raise ModelFileError(
                    f"cannot read {self.rel(p)}: {exc}", path=self.criteria_source, element=element
                ) from None
        return self._json[p]

    def resolve(self, name: str, element: str) -> tuple[str, Path]:
        """A ``rests_on`` name → (role, file)."""
        if name in self.files:
            return name, self.files[name]
        kind, _, ident = name.partition(":")
        if kind in ("model", "oracle") and ident:
            spec = self._model(ident, element)
            if kind == "model":
                return name, spec.file
            if spec.oracle is None:
                raise ModelFileError(
                    f"model {ident!r} has no oracle", path=self.criteria_source, element=element
                )
            return name, spec.oracle.file
        path = self.root / name
        if not path.is_file():
            known = ", ".join([*self.files, "model:ID", "oracle:ID"])
            raise ModelFileError(
                f"rests_on names {name!r}: not an artefact of the launch nor a file",
                path=self.criteria_source,
                element=element,
                hint=f"use one of {known}, or a file path relative to the project root",
            )
        return "file", path

    def _model(self, ident: str, element: str) -> Any:
        if self.registry is None:
            raise ModelFileError(
                f"{ident!r}: the launch names no model registry",
                path=self.criteria_source,
                element=element,
            )
        try:
            return self.registry.get(ident)
        except LookupError:
            raise ModelFileError(
                f"the launch's registry has no model {ident!r}",
                path=self.criteria_source,
                element=element,
                hint=f"its models: {', '.join(self.registry.ids())}",
            ) from None

    def models(self, wanted: list[str] | None, element: str) -> list[Any]:
        """The registry's models, or those named (each must exist)."""
        if self.registry is None:
            raise ModelFileError(
                "this kind of evidence reads the launch's model registry, and it names none",
                path=self.criteria_source,
                element=element,
            )
        if wanted is None:
            return list(self.registry.models)
        return [self._model(i, element) for i in wanted]


def _fmt(x: float | None, digits: int = 3) -> str:
    return "—" if x is None else f"{x:.{digits}f}"


def _acceptance(
    spec: EvidenceSpec, relax: Acceptance | None, unit: str, element: str, src: Sources
) -> Acceptance:
    if spec.relax:
        if relax is None:
            raise ModelFileError(
                "'relax: true' but the goal has no RELAX operator to take a criterion from",
                path=src.criteria_source,
                element=element,
                hint="give 'at_least', 'at_most' or 'equals' instead",
            )
        return relax
    u = f" {unit}" if unit else ""
    if spec.at_least is not None:
        return Acceptance(f"≥ {spec.at_least:g}{u}", spec.at_least, None)
    if spec.at_most is not None:
        return Acceptance(f"≤ {spec.at_most:g}{u}", None, spec.at_most)
    assert spec.equals is not None
    return Acceptance(f"= {spec.equals:g}{u}", spec.equals, spec.equals)


class _Figure(NamedTuple):
    """What one evidence record says, before its criterion is checked."""

    figure: str
    value: float | None
    command: str
    artefacts: list[Artefact]
    model: str | None = None
    conditions: list[str] | None = None


def _make(spec: EvidenceSpec, acc: Acceptance, fig: _Figure) -> Evidence:
    figure, value, command, artefacts, model, conditions = fig
    result = "not run" if value is None else "pass" if check_value(value, acc) else "fail"
    ev = Evidence(
        kind=spec.kind,
        stage=spec.stage or DEFAULT_STAGE[spec.kind],
        figure=figure,
        value=value,
        criterion=acc.text,
        result=result,  # type: ignore[arg-type]
        command=spec.command or command,
        artefacts=artefacts,
        model=model,
        conditions=spec.conditions or conditions,
    )
    changed = [
        f"{a.path} is {a.sha256[:12]}… but the figure was measured on {a.measured_sha256[:12]}…"
        for a in artefacts
        if a.measured_sha256 and a.measured_sha256 != a.sha256
    ]
    if changed:
        ev.stale = "; ".join(changed)
    return ev


def _detector(spec: EvidenceSpec, acc: Acceptance, src: Sources, element: str) -> list[Evidence]:
    out = []
    registry = src.files["registry"]
    for m in src.models(spec.models, element):
        sidecar = m.file.with_suffix(".json")
        card = src.read_json(sidecar, element) if sidecar.is_file() else {}
        test = (m.metrics or {}).get("test") or {}
        f1 = test.get("f1")
        n = (card.get("training") or {}).get("test_images")
        counts = ""
        if {"tp", "fp", "fn"} <= set(test):
            counts = f"; {test['tp']} TP, {test['fp']} FP, {test['fn']} FN"
        over = f" over {n} held-out test images" if n else ""
        figure = (
            f"{m.id}: held-out F1 {_fmt(f1)} (P {_fmt(test.get('precision'))}, "
            f"R {_fmt(test.get('recall'))}{counts}){over}, clean frames"
            if f1 is not None
            else f"{m.id}: no held-out F1 recorded in its sidecar"
        )
        arts = [src.artefact(f"model:{m.id}", m.file, card.get("sha256"))]
        if sidecar.is_file():
            arts.append(src.artefact(f"sidecar:{m.id}", sidecar))
        arts.append(src.artefact("registry", registry))
        data = spec.data or f"data/{m.id.split('-')[0]}"
        command = (
            f"anunnaki evaluate-detector {src.rel(registry)} --model {m.id} "
            f"--data {data} --split test"
        )
        out.append(_make(spec, acc, _Figure(figure, f1, command, arts, m.id, ["clear"])))
    return out


def _data(spec: EvidenceSpec, acc: Acceptance, src: Sources, element: str) -> list[Evidence]:
    out = []
    for m in src.models(spec.models, element):
        sidecar = m.file.with_suffix(".json")
        card = src.read_json(sidecar, element) if sidecar.is_file() else {}
        t = card.get("training") or {}
        n = t.get("test_images")
        platform = m.id.split("-")[0]
        parts = [f"{m.id}: trained on {t.get('train_images', '?')} images"]
        if t.get("init"):
            parts.append(f"fine-tuned from {t['init']}")
        if (t.get("source") or {}).get("phenomenon"):
            s = t["source"]
            parts.append(
                f"{s.get('contexts', '?')} Enki contexts of {s['phenomenon']} "
                f"({int(100 * float(s.get('clean', 0)))} % clean)"
            )
        if t.get("augment"):
            parts.append(f"augmented with {', '.join(t['augment'])}")
        parts.append(
            f"chosen on {t.get('val_images', '?')} validation images, measured on {n} "
            f"held-out test images (scene layouts of their own split; seed {t.get('seed', '?')})"
        )
        arts = [src.artefact(f"sidecar:{m.id}", sidecar)] if sidecar.is_file() else []
        test_split = src.root / "data" / platform / "test.json"
        if test_split.is_file():
            arts.append(src.artefact("dataset:test", test_split))
        command = f"anunnaki make-dataset {platform} --out data/{platform}"
        count = None if n is None else float(n)
        # held-out test images are clean frames; an Enki model's training covers its phenomenon
        conditions = ["clear"]
        if (t.get("source") or {}).get("phenomenon"):
            conditions.append(str(t["source"]["phenomenon"]))
        out.append(
            _make(spec, acc, _Figure("; ".join(parts), count, command, arts, m.id, conditions))
        )
    return out


def _stat(d: Any) -> tuple[float | None, float | None, int | None]:
    if isinstance(d, dict):
        return d.get("mean"), d.get("std"), d.get("n")
    return None, None, None


def _robustness(spec: EvidenceSpec, acc: Acceptance, src: Sources, element: str) -> list[Evidence]:
    path = src.root / (spec.file or "benchmarks/results/robustify.json")
    data = src.read_json(path, element)
    wanted = {m.id for m in src.models(spec.models, element)}
    metric = spec.metric
    out = []
    for key, dom in (data.get("domains") or {}).items():
        arms = dom.get("arms") or {}
        shipped = arms.get("shipped") or {}
        mid = shipped.get("model")
        if not isinstance(mid, str) or mid not in wanted:
            continue
        s_mean, _, _ = _stat(shipped.get(metric))
        d_mean, _, _ = _stat((arms.get("default") or {}).get(metric))
        e_mean, e_std, e_n = _stat((arms.get("enki") or {}).get(metric))
        vs = (dom.get("enki_vs_random") or {}).get(metric) or {}
        value = None if s_mean is None or d_mean is None else round(s_mean - d_mean, 4)
        seeds = (data.get("settings") or {}).get("seeds") or []
        figure = (
            f"{mid} on {dom.get('phenomenon')} contexts held out from its training "
            f"({key}): {metric} {_fmt(s_mean)} against {dom.get('model')}'s {_fmt(d_mean)} "
            f"(margin {value:+.3f})"
            if value is not None
            else f"{mid}: no {metric} in {key}"
        )
        if e_mean is not None:
            figure += (
                f"; Enki's recipe at an equal budget over {e_n} seeds {seeds}: "
                f"{_fmt(e_mean)} ± {_fmt(e_std)}"
            )
        if vs:
            figure += (
                f", against random augmentation {vs.get('margin', 0):+.3f} "
                f"(spread {_fmt(vs.get('spread'))}: {vs.get('verdict')})"
            )
        arts = [
            src.artefact("results", path),
            src.artefact(f"model:{mid}", src._model(mid, element).file),
        ]
        command = f"nice -n 10 .venv/bin/python benchmarks/robustify.py --domains {key}"
        out.append(
            _make(
                spec, acc, _Figure(figure, value, command, arts, mid, [str(dom.get("phenomenon"))])
            )
        )
    return out


def _oracle(spec: EvidenceSpec, acc: Acceptance, src: Sources, element: str) -> list[Evidence]:
    out = []
    for m in src.models(spec.models, element):
        if m.oracle is None:
            continue
        sidecar = m.oracle.file.with_suffix(".json")
        card = src.read_json(sidecar, element) if sidecar.is_file() else {}
        val = (card.get("metrics") or {}).get("val") or {}
        phen = [p.get("name") for p in card.get("phenomena") or [] if isinstance(p, dict)]
        acc_v = val.get("accuracy")
        figure = (
            f"{m.id}'s oracle: validation accuracy {_fmt(acc_v)}, macro-F1 "
            f"{_fmt(val.get('macro_f1'))} over {val.get('frames', val.get('n', '?'))} frames "
            f"(categories nominal / degraded / compromised; phenomena {', '.join(map(str, phen))})"
        )
        arts = [
            src.artefact(f"oracle:{m.id}", m.oracle.file, card.get("weights_sha256")),
            src.artefact(f"model:{m.id}", m.file, card.get("model_sha256")),
        ]
        if sidecar.is_file():
            arts.append(src.artefact(f"oracle-sidecar:{m.id}", sidecar))
        command = (
            f"anunnaki oracle evaluate --models {src.rel(src.files['registry'])} --model {m.id} "
            f"--data data/{m.id.split('-')[0]} --phenomenon {phen[0] if phen else 'fog'}"
        )
        conditions = ["clear", *map(str, phen)]
        out.append(_make(spec, acc, _Figure(figure, acc_v, command, arts, m.id, conditions)))
    return out


def _oracle_ceiling(
    spec: EvidenceSpec, acc: Acceptance, src: Sources, element: str
) -> list[Evidence]:
    path = src.root / (spec.file or "benchmarks/results/oracle.json")
    data = src.read_json(path, element)
    models = {m.id: m for m in src.models(spec.models, element)}
    out = []
    for key, entry in (data.get("accuracy") or {}).items():
        mid, _, phen = key.partition("/")
        if mid not in models or not isinstance(entry, dict):
            continue
        aims = entry.get("aims") or {}
        ioc = aims.get("interior_of_ceiling") or {}
        value = ioc.get("value")
        mf1 = (aims.get("macro_f1_interior") or {}).get("value")
        racc = (aims.get("accuracy_random") or {}).get("value")
        figure = (
            f"{mid}'s oracle on {phen} (test split, interior contexts): macro-F1 {_fmt(mf1)} "
            f"against the labels' ceiling {_fmt(ioc.get('ceiling'))} ({_fmt(value)} of it); "
            f"accuracy on random contexts {_fmt(racc)}"
        )
        m = models[mid]
        arts = [src.artefact("results", path)]
        if m.oracle is not None:
            arts.append(src.artefact(f"oracle:{mid}", m.oracle.file))
        platform = mid.split("-")[0]
        command = (
            f"nice -n 10 .venv/bin/python benchmarks/oracle.py --{platform}-data data/{platform}"
        )
        out.append(_make(spec, acc, _Figure(figure, value, command, arts, mid, [phen])))
    return out


def _dig(data: Any, dotted: str) -> Any:
    cur = data
    for part in dotted.split("."):
        if isinstance(cur, dict) and part in cur:
            cur = cur[part]
        elif isinstance(cur, list) and part.isdigit() and int(part) < len(cur):
            cur = cur[int(part)]
        else:
            raise KeyError(part)
    return cur


def _result(spec: EvidenceSpec, acc: Acceptance, src: Sources, element: str) -> list[Evidence]:
    assert spec.file and spec.path and spec.text
    path = src.root / spec.file
    data = src.read_json(path, element)
    try:
        raw = _dig(data, spec.path)
    except KeyError as exc:
        raise ModelFileError(
            f"{spec.file} has no {spec.path!r} (no key {exc.args[0]!r})",
            path=src.criteria_source,
            element=element,
            hint="a dotted key path into the JSON, e.g. cases.rover.summary.utu.collisions.max",
        ) from None
    if isinstance(raw, bool) or not isinstance(raw, int | float):
        raise ModelFileError(
            f"{spec.file}: {spec.path} is {raw!r}, not a number",
            path=src.criteria_source,
            element=element,
        )
    value = float(raw)
    unit = f" {spec.unit}" if spec.unit else ""
    arts = [src.artefact("results", path)]
    measured: tuple[str, str] | None = None
    if spec.measured_sha256:
        try:
            measured = (
                spec.measured_sha256["artefact"],
                str(_dig(data, spec.measured_sha256["path"])),
            )
        except KeyError:
            raise ModelFileError(
                f"{spec.file} has no {spec.measured_sha256['path']!r}",
                path=src.criteria_source,
                element=f"{element}.measured_sha256",
            ) from None
    for name in spec.rests_on:
        role, file = src.resolve(name, element)
        sha = measured[1] if measured and measured[0] == name else None
        arts.append(src.artefact(role, file, sha))
    if measured and measured[0] not in spec.rests_on:
        role, file = src.resolve(measured[0], element)
        arts.append(src.artefact(role, file, measured[1]))
    model = next(
        (n.partition(":")[2] for n in spec.rests_on if n.startswith(("model:", "oracle:"))), None
    )
    command = spec.command or f"(re-run the benchmark that writes {spec.file})"
    return [
        _make(
            spec,
            acc,
            _Figure(
                f"{spec.text}: {value:g}{unit} ({spec.file}: {spec.path})",
                value,
                command,
                arts,
                model,
            ),
        )
    ]


def _tests(spec: EvidenceSpec, acc: Acceptance, src: Sources, element: str) -> list[Evidence]:
    arts = []
    seen: set[str] = set()
    for node in spec.tests:
        file = node.split("::")[0]
        path = src.root / file
        if not path.is_file():
            raise ModelFileError(
                f"test file {file} does not exist",
                path=src.criteria_source,
                element=element,
                hint="name tests as pytest does: tests/x/test_y.py::test_z",
            )
        if file not in seen:
            seen.add(file)
            arts.append(src.artefact("tests", path))
    results = [src.test_results.get(t) for t in spec.tests]
    if all(r is not None for r in results):
        passed = sum(r == "pass" for r in results)
        value: float | None = float(passed == len(results))
        figure = f"{passed} of {len(results)} tests pass: " + ", ".join(
            t.split("::")[-1] for t in spec.tests
        )
    else:
        value = None
        figure = f"{len(spec.tests)} tests, not run at build (--run-tests runs them): " + ", ".join(
            t.split("::")[-1] for t in spec.tests
        )
    command = ".venv/bin/python -m pytest -q " + " ".join(shlex.quote(t) for t in spec.tests)
    every = Acceptance("every test passes", 1.0, None)
    return [_make(spec, every, _Figure(figure, value, command, arts))]


_KINDS: dict[str, Callable[[EvidenceSpec, Acceptance, Sources, str], list[Evidence]]] = {
    "detector": _detector,
    "data": _data,
    "robustness": _robustness,
    "oracle": _oracle,
    "oracle_ceiling": _oracle_ceiling,
    "result": _result,
    "tests": _tests,
}

_UNITS = {"detector": "", "data": "images", "robustness": "", "oracle": "", "oracle_ceiling": ""}


def collect(
    spec: EvidenceSpec, relax: Acceptance | None, src: Sources, element: str
) -> list[Evidence]:
    """The evidence one criteria item yields (one record per model where it is per model)."""
    unit = spec.unit or _UNITS.get(spec.kind, "")
    acc = _acceptance(spec, relax, unit, element, src) if spec.kind != "tests" else Acceptance("")
    return _KINDS[spec.kind](spec, acc, src, element)


def run_tests(node_ids: list[str], root: Path) -> dict[str, str]:
    """Run pytest once on ``node_ids`` (from ``root``); node id → ``pass`` or ``fail``."""
    if not node_ids:
        return {}
    with tempfile.TemporaryDirectory(prefix="anunnaki-assurance-") as tmp:
        report = Path(tmp) / "tests.xml"
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"]
        cmd += [f"--junitxml={report}", *node_ids]
        subprocess.run(cmd, cwd=root, capture_output=True, text=True, check=False)
        return _junit(report, node_ids)


def _junit(report: Path, node_ids: list[str]) -> dict[str, str]:
    """Each node id's outcome in pytest's JUnit XML: pass when it ran and nothing failed."""
    import xml.etree.ElementTree as ET

    try:
        tree = ET.parse(report)
    except (OSError, ET.ParseError):
        return {t: "fail" for t in node_ids}
    ran: dict[str, list[bool]] = {t: [] for t in node_ids}
    for case in tree.iter("testcase"):
        name = case.get("name", "")
        classname = case.get("classname", "")
        failed = any(child.tag in ("failure", "error", "skipped") for child in case)
        for t in node_ids:
            file, _, func = t.partition("::")
            module = file.removesuffix(".py").replace("/", ".")
            if classname == module and func in (name, name.split("[")[0]):
                ran[t].append(failed)
    return {t: "pass" if f and not any(f) else "fail" for t, f in ran.items()}
