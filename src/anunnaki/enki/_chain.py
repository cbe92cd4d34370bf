"""``robustify``: the whole chain for one domain, stage by stage, resumable (docs/robustify.md).

search (or a given archive) → select → fine-tune → measure → assess the new model → its
oracle → register (optional). Every stage records its result in the work folder
(:class:`~anunnaki.enki._work.WorkFolder`); a rerun continues where the last one stopped.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from anunnaki._names import NameRuleError, check_domain, check_name, inside
from anunnaki.datasets import Dataset, load_split
from anunnaki.enki._errors import EnkiError
from anunnaki.enki._finetune import Budget, finetune
from anunnaki.enki._select import LEARNABLE_F1, Selection, SelectionRule, select_contexts
from anunnaki.enki._sources import CONTEXT_SOURCES, SourceSpec, make_source
from anunnaki.enki._work import WorkFolder, write_json
from anunnaki.enlil import Archive, read_archive
from anunnaki.errors import AnunnakiError
from anunnaki.lec import ResolvedModel, resolve_model, sha256_file

__all__ = ["RobustifyConfig", "archive_sha256", "new_model_id", "robustify"]

#: ``progress(stage, done, total)``: a stage's advance (``total`` 0 while unknown).
Progress = Callable[[str, int, int], None]

#: The fields of :class:`RobustifyConfig` that make the training recipe (with the budget's EMA).
RECIPE = ("source", "k", "select", "share", "jitter", "consistency")

#: What a fine-tune spends beside its optimiser steps (images through the network, and the
#: worst-of-k candidates rendered): recorded with the steps (docs/robustify.md, "Budget").
FORWARDS = ("train_forwards", "select_forwards", "consistency_forwards", "candidates")


@dataclass(frozen=True)
class RobustifyConfig:
    """The chain's options (``anunnaki robustify``'s, one for one).

    Attributes:
        phenomenon: The domain's phenomenon (or composition, ``rain+brightness``).
        domain: The new model's domain (the registry's and the model manager's name).
        archive: Reuse this Enlil archive of the model and phenomenon instead of searching.
        model_id: The new model's id (default: :func:`new_model_id`).
        budget: Evaluations of each search (the model's, then the new model's).
        search: The search strategy (``enlil``, ``random``, ``sobol``).
        batch_images: Images of the fixed val batch every context is measured on.
        search_round: Contexts per search round.
        workers: Local processes of the searches (does not change any result).
        thresholds: Relative F1 drops of categories 1 and 2.
        rule: The selection rule (:class:`SelectionRule`).
        clean: Share of training frames left clean.
        finetune: Epochs, batch size, learning rate and threads of the fine-tune.
        seed: The one seed: searches, fine-tune, measurement and oracle all use it.
        measure_contexts: Archive contexts the new and the input model are measured on.
        oracle: Overrides of the oracle's training settings (``frames``, ``val_frames``,
            ``epochs``, ``threads``); the rest are ``anunnaki oracle train``'s defaults.
        oracle_architecture: The oracle's network; ``None``: the measured choice
            (:func:`anunnaki.enlil.oracle_architecture` of the phenomenon and the new
            model's id), as ``scripts/train-oracles.sh`` chooses it.
        source: The fine-tune's context source by name (:data:`CONTEXT_SOURCES`:
            ``archive``, the selected contexts, as before; ``archive_mix``; ``uniform``;
            ``corruption_mix``).
        k: Candidates per perturbed frame; above 1 the source is wrapped in worst-of-k
            (:class:`~anunnaki.enki.WorstOfK`).
        select: Worst-of-k's choice: ``hardest`` (the highest loss under the network being
            trained) or ``random`` (the control with the same rendering).
        share: ``archive_mix``: share of perturbed frames from the selected contexts.
        jitter: ``archive_mix``: standard deviation of their jitter (normalised units).
        consistency: λ of the consistency loss (0: off).
        second_opinion: A second model (file or registry id) for the learnability cap: its
            F1 is measured on the archive's contexts where the input model scores below
            the floor (``rule.learnable``), on the search's val batch, and a context is left
            out only if both score below it (:func:`select_contexts`' ``others``). ``None``:
            one model, nothing left out.

    The recipe's options (``source`` … ``consistency``, and ``finetune.ema``) are recorded
    in the work folder only where they differ from the defaults, so that a folder made
    before they existed continues as it was.

    The oracle's options (``oracle``, ``oracle_architecture``) are the oracle stage's own:
    when they change, a rerun into the same work folder trains the oracle again and reuses
    the rest.

    """

    phenomenon: str
    domain: str
    archive: str | None = None
    model_id: str | None = None
    budget: int = 400
    search: str = "enlil"
    batch_images: int = 32
    search_round: int = 16
    workers: int = 2
    thresholds: tuple[float, float] = (0.05, 0.10)
    rule: SelectionRule = field(default_factory=SelectionRule)
    clean: float = 0.3
    finetune: Budget = field(default_factory=Budget)
    seed: int = 0
    measure_contexts: int = 32
    oracle: dict[str, int] = field(default_factory=dict)
    oracle_architecture: str | None = None
    source: str = "archive"
    k: int = 1
    select: Literal["hardest", "random"] = "hardest"
    share: float = 0.5
    jitter: float = 0.1
    consistency: float = 0.0
    second_opinion: str | None = None

    def __post_init__(self) -> None:
        """Refuse a domain or an id that is no name (they become file names: docs/robustify.md).

        And an unknown source (listing the valid ones) or recipe options out of range.
        """
        try:
            check_domain(self.domain, what="--domain")
            if self.model_id is not None:
                check_name(self.model_id, what="--id")
        except NameRuleError as exc:
            raise EnkiError(str(exc)) from None
        try:
            CONTEXT_SOURCES.factory(self.source)
        except AnunnakiError as exc:
            raise EnkiError(f"--source {self.source}: {exc}") from None
        if self.k < 1 or self.select not in ("hardest", "random"):
            raise EnkiError(
                f"--k is the number of candidates per frame (1: no worst-of-k), --select "
                f"hardest or random; got --k {self.k}, --select {self.select}"
            )
        if not 0 <= self.share <= 1 or self.jitter < 0 or self.consistency < 0:
            raise EnkiError(
                f"--share must be in [0, 1], --jitter and --consistency >= 0; got "
                f"{self.share}, {self.jitter}, {self.consistency}"
            )

    def recipe(self) -> dict[str, Any]:
        """The training recipe: source, worst-of-k, mix, consistency and EMA."""
        return {key: getattr(self, key) for key in RECIPE} | {"ema": self.finetune.ema}

    def options(self) -> dict[str, Any]:
        """The options that decide the results, JSON-safe.

        All but ``workers`` and the oracle stage's own (:meth:`oracle_options`); the
        recipe's only as ``recipe`` and only when it is not the default one.
        """
        data = asdict(self)
        for key in ("workers", "oracle", "oracle_architecture", *RECIPE):
            del data[key]
        del data["finetune"]["ema"]
        if self.recipe() != RobustifyConfig.default_recipe():
            data["recipe"] = self.recipe()
        if data["rule"]["learnable"] == LEARNABLE_F1:  # as recorded before the cap existed
            del data["rule"]["learnable"]
        if data["second_opinion"] is None:  # folders made before it continue as they were
            del data["second_opinion"]
        return data

    @staticmethod
    def default_recipe() -> dict[str, Any]:
        """The recipe a config gets when none of its options are given."""
        return {key: RobustifyConfig.__dataclass_fields__[key].default for key in RECIPE} | {
            "ema": Budget().ema
        }

    def oracle_options(self, model_id: str | None = None) -> dict[str, Any]:
        """The oracle stage's options: the overrides and the network.

        The network: ``oracle_architecture``, else the rule's for the phenomenon and the new
        model's id *model_id* (:func:`anunnaki.enlil.oracle_architecture`).
        """
        from anunnaki.enlil import oracle_architecture

        arch = self.oracle_architecture or oracle_architecture([self.phenomenon], model_id=model_id)
        return {**self.oracle, "architecture": arch}


def new_model_id(model_id: str, domain: str) -> str:
    """``rover-default`` → ``rover-DOMAIN``; any other id gets ``-DOMAIN`` appended.

    Raises:
        EnkiError: The result is no name (:data:`anunnaki._names.NAME_RULE`): it would be
            a file name.

    """
    base = model_id.removesuffix("-default")
    try:
        return check_name(
            f"{base}-{domain}",
            what=f"the new model's id (from model {model_id!r} and domain {domain!r})",
            fix="give the new model an id that follows it with --id NAME",
        )
    except NameRuleError as exc:
        raise EnkiError(str(exc)) from None


def archive_sha256(path: str | Path) -> str:
    """sha256 of an archive: of the file, or over a folder's parts (names and contents)."""
    root = Path(path)
    if root.is_file():
        return sha256_file(root)
    h = hashlib.sha256()
    for part in sorted(root.glob("part-*.parquet")):
        h.update(part.name.encode())
        h.update(bytes.fromhex(sha256_file(part)))
    return h.hexdigest()


def _check_phenomenon(name: str) -> None:
    from anunnaki.phenomena import PHENOMENA

    try:
        PHENOMENA.create(name)
    except AnunnakiError as exc:
        raise EnkiError(f"--phenomenon {name}: {exc}") from None


def _oracle_options(config: RobustifyConfig, model_id: str) -> dict[str, Any]:
    """The oracle stage's options, with its network checked against the registered ones."""
    from anunnaki.enlil import ORACLE_ARCHITECTURES

    try:
        options = config.oracle_options(model_id)
    except AnunnakiError as exc:
        raise EnkiError(f"--phenomenon {config.phenomenon}: {exc}") from None
    names = ORACLE_ARCHITECTURES.names()
    if options["architecture"] not in names:
        raise EnkiError(
            f"--oracle-architecture {options['architecture']!r}: no such oracle architecture; "
            f"the registered ones are {', '.join(names)}"
        )
    return options


def _splits(data: str | Path) -> tuple[Dataset, Dataset, Dataset | None]:
    """The train, val and (optional) test splits, with errors naming the folder."""
    root = Path(data)
    if not root.is_dir():
        raise EnkiError(
            f"--data {data}: no dataset folder there; make one with anunnaki make-dataset "
            f"rover --out {data} (train, val and test splits)"
        )
    out: list[Dataset | None] = []
    for split in ("train", "val", "test"):
        try:
            out.append(load_split(root, split, cache=True))
        except AnunnakiError as exc:
            if split == "test":
                out.append(None)
                continue
            raise EnkiError(
                f"--data {data}: no readable {split} split ({exc}); robustify trains on train "
                "and picks the threshold on val: give a folder made by anunnaki make-dataset"
            ) from None
    train, val, test = out
    assert train is not None and val is not None
    return train, val, test


class _Chain:
    """The stages of one robustify run (see the module docstring)."""

    def __init__(
        self,
        model: ResolvedModel,
        data: Path,
        work: WorkFolder,
        cfg: RobustifyConfig,
        *,
        splits: tuple[Dataset, Dataset, Dataset | None],
        model_in_id: str | None,
        new_id: str,
        progress: Progress | None,
    ) -> None:
        self.model, self.model_in_id, self.data, self.work = model, model_in_id, data, work
        self.cfg, self.new_id, self.splits = cfg, new_id, splits
        self._progress = progress
        self.reused: list[str] = []
        self.rerun: list[str] = []

    def progress(self, stage: str, done: int, total: int) -> None:
        if self._progress is not None:
            self._progress(stage, done, total)

    def stage(
        self,
        name: str,
        run: Callable[[], dict[str, Any]],
        options: dict[str, Any] | None = None,
    ) -> dict[str, Any]:
        """The stage's recorded result, or run it and record it.

        *options*: the stage's own options, recorded with its result; a result recorded
        with other ones is run again.
        """
        old = self.work.stage(name)
        if old is not None and options is not None:
            before = old.get("options") or self._legacy_options(name, old)
            if before != options:
                changed = sorted(k for k in set(before) | set(options)
                                 if before.get(k) != options.get(k))  # fmt: skip
                self.progress(f"{name}: {', '.join(changed)} changed, run again", 0, 0)
                self.rerun.append(name)
                old = None
        if old is not None:
            self.reused.append(name)
            self.progress(f"{name} (done before)", 1, 1)
            return old
        result = run()
        return self.work.done(name, result if options is None else result | {"options": options})

    def _legacy_options(self, name: str, old: dict[str, Any]) -> dict[str, Any]:
        """The options of a stage recorded before stages recorded them.

        The oracle's: the folder's ``oracle`` overrides and the network its file names.
        """
        from anunnaki.enlil import load_oracle

        if name != "oracle":
            return {}
        arch = load_oracle(old["file"]).card.architecture
        return {**self.work.recorded.get("oracle", {}), "architecture": arch}

    # -- stages ------------------------------------------------------------------------------

    def _job(self, model: str, model_id: str | None) -> Any:
        from anunnaki.enlil import Job

        return Job(
            model=model,
            data=str(self.data),
            phenomenon=self.cfg.phenomenon,
            split="val",
            batch_images=self.cfg.batch_images,
            seed=self.cfg.seed,
            thresholds=self.cfg.thresholds,
            model_id=model_id,
        )

    def _search(self, model: str, model_id: str | None, out: Path, label: str) -> Archive:
        from anunnaki.enlil import run_search

        outcome = run_search(
            self._job(model, model_id),
            out,
            search=self.cfg.search,
            budget=self.cfg.budget,
            seed=self.cfg.seed,
            batch=self.cfg.search_round,
            workers=self.cfg.workers,
            progress=lambda done, total: self.progress(label, done, total),
        )
        return outcome.archive

    def search(self) -> dict[str, Any]:
        if self.cfg.archive is not None:
            path = Path(self.cfg.archive)
            archive = self._given_archive(path)
        else:
            path = self.work.path / "search"
            self.progress(f"search {self.model.model_id}", 0, self.cfg.budget)
            archive = self._search(
                str(self.model.source), self.model_in_id, path, f"search {self.model.model_id}"
            )
        return _archive_record(archive, path, reused=self.cfg.archive is not None)

    def _given_archive(self, path: Path) -> Archive:
        archive = read_archive(path)
        meta, cfg = archive.meta, self.cfg
        fix = "or leave --archive out and robustify runs the search itself"
        if meta.phenomenon != cfg.phenomenon:
            raise EnkiError(
                f"--archive {path}: it is a search of {meta.phenomenon}, not of --phenomenon "
                f"{cfg.phenomenon}; give an archive of {cfg.phenomenon} ({fix})"
            )
        if meta.sha256 != self.model.sha256:
            raise EnkiError(
                f"--archive {path}: it assesses model {meta.model_id!r} (sha256 "
                f"{meta.sha256[:12] or 'unknown'}…), not {self.model.source} "
                f"({self.model.model_id!r}, sha256 {self.model.sha256[:12]}…); give the "
                f"archive of a search against this model ({fix})"
            )
        if tuple(meta.thresholds) != tuple(cfg.thresholds):
            raise EnkiError(
                f"--archive {path}: its categories use thresholds {list(meta.thresholds)}, "
                f"this run {list(cfg.thresholds)}; give --thresholds {meta.thresholds[0]} "
                f"{meta.thresholds[1]} ({fix})"
            )
        return archive

    def select(self, archive_path: str) -> dict[str, Any]:
        archive = read_archive(archive_path)
        others, second = self._second_opinion(archive)
        selection = select_contexts(archive, self.cfg.rule, others=others)
        return selection.as_dict() | {"counts": selection.counts()} | second

    def _second_opinion(self, archive: Archive) -> tuple[list[Any], dict[str, Any]]:
        """The second model's F1 where the input model is below the floor (``nan`` elsewhere).

        Only those rows can be left out by the cap, so only they are measured: on the
        search's val batch, with its seed, as the archive's own F1 was.
        """
        cfg = self.cfg
        if cfg.second_opinion is None or cfg.rule.learnable == 0.0:
            return [], {}
        from anunnaki.enlil import executor_map
        from anunnaki.lec import resolve_model

        other = resolve_model(cfg.second_opinion)
        low = np.flatnonzero(np.asarray(archive.f1, np.float64) < cfg.rule.learnable)
        f1 = np.full(len(archive), np.nan)
        job = self._job(str(other.file), None)  # the file resolved
        label, done = f"learnability: {other.model_id}", [0]
        self.progress(label, 0, len(low))

        def tick(i: int, result: Any) -> None:
            done[0] += 1
            self.progress(label, done[0], len(low))

        with executor_map(cfg.workers, on_result=tick) as run:
            results = run([(job, archive.params[row].tolist()) for row in low])
        for row, result in zip(low, results, strict=True):
            f1[row] = result.f1
        record = {"model_id": other.model_id, "sha256": other.sha256, "measured": len(low)}
        return [f1], {"second_opinion": record}

    def finetune(self, search: dict[str, Any], selection: Selection) -> dict[str, Any]:
        from anunnaki.lec import save_detector

        train, val, test = self.splits
        cfg = self.cfg
        spec = SourceSpec(cfg.phenomenon, selection.params, clean=cfg.clean, share=cfg.share,
                          jitter=cfg.jitter)  # fmt: skip
        source = make_source(cfg.source, spec, k=cfg.k, select=cfg.select)
        epochs = cfg.finetune.epochs
        self.progress("fine-tune", 0, cfg.finetune.steps(len(train)))
        last = {"text": ""}

        def on_epoch(info: dict[str, float]) -> None:
            last["text"] = f" (epoch {int(info['epoch'])}: loss {info['loss']:.3f}, " + (
                f"val F1 {info['val_f1']:.3f})"
            )

        result = finetune(
            self.model.file, train, val, source, budget=cfg.finetune, seed=cfg.seed, test=test,
            model_id=self.new_id, domain=cfg.domain, checkpoints=self.work.path / "finetune",
            on_step=lambda step, total, info: self.progress(
                f"fine-tune, epoch {int(info['epoch'])}/{epochs}{last['text']}", step, total
            ),
            on_epoch=on_epoch, consistency=cfg.consistency,
        )  # fmt: skip
        det = result.detector
        counts = {k: int(det.training[k]) for k in FORWARDS}
        det.training["enki"] = {
            "domain": cfg.domain,
            "phenomenon": cfg.phenomenon,
            "from": {"model_id": self.model.model_id, "sha256": self.model.sha256},
            "archive": {"path": search["path"], "sha256": search["sha256"]},
            "selection": {"rule": asdict(cfg.rule), "counts": selection.counts()},
            "seeds": {"search": cfg.seed, "finetune": cfg.seed, "measure": cfg.seed,
                      "assess": cfg.seed, "oracle": cfg.seed},
            "budget": {**asdict(cfg.finetune), "steps": det.training["steps"],
                       "images": len(train), **counts},
            "recipe": cfg.recipe(),
        }  # fmt: skip
        file = inside(self.work.path, self.work.path / f"{self.new_id}.safetensors",
                      what="the new model")  # fmt: skip
        sha = save_detector(det, file)
        return {
            "file": str(file),
            "sha256": sha,
            "threshold": result.threshold,
            "epochs": epochs,
            "steps": det.training["steps"],
            "images": len(train),
            **counts,
            "source": source.describe(),
            "seconds": round(result.seconds, 1),
            "history": result.history,
            "val": result.val.as_dict(),
            "test": None if result.test is None else result.test.as_dict(),
        }

    def measure(self, search: dict[str, Any], selection: Selection, file: str) -> dict[str, Any]:
        from anunnaki.lec import evaluate_detector, load_detector, read_card, update_metrics

        _, val, test = self.splits
        split, data = ("test", test) if test is not None else ("val", val)
        models = {"input": self.model.load(), "new": load_detector(file)}
        clean = {k: float(evaluate_detector(m, data).f1) for k, m in models.items()}
        archive = read_archive(search["path"])
        rows = _measure_rows(len(archive), selection.rows, self.cfg.measure_contexts, self.cfg.seed)
        on = {k: self._on_contexts(m, archive, rows, k) for k, m in models.items()}
        metrics = {
            "clean": {"split": split, **clean},
            "archive_contexts": {
                "contexts": len(rows),
                "used_in_training": int(np.isin(rows, selection.rows).sum()),
                **on,
            },
        }
        update_metrics(file, read_card(file).metrics | {"enki": metrics})
        return metrics

    def _on_contexts(
        self, det: Any, archive: Archive, rows: np.ndarray, who: str
    ) -> dict[str, Any]:
        from anunnaki.enlil import evaluate_context, fixed_batch
        from anunnaki.lec import evaluate_detector

        meta = archive.meta
        batch = fixed_batch(self.data, meta.split, meta.batch_images, meta.seed)
        clean = float(evaluate_detector(det, batch).f1)
        f1s, cats = [], [0, 0, 0]
        for i, row in enumerate(rows):
            r = evaluate_context(
                det, batch, meta.phenomenon, archive.params[row],
                clean_f1=clean, thresholds=meta.thresholds, seed=meta.seed,
            )  # fmt: skip
            f1s.append(r.f1)
            cats[r.category] += 1
            self.progress(f"measure {who} on archive contexts", i + 1, len(rows))
        return {"f1": float(np.mean(f1s)) if f1s else None, "categories": cats}

    def assess(self, file: str) -> dict[str, Any]:
        path = self.work.path / "assess"
        label = f"assess {self.new_id}"
        self.progress(label, 0, self.cfg.budget)
        archive = self._search(file, None, path, label)
        return _archive_record(archive, path, reused=False)

    def oracle(
        self, finetuned: dict[str, Any], assess: dict[str, Any], options: dict[str, Any]
    ) -> dict[str, Any]:
        from anunnaki.enlil import OracleTrainConfig, contexts_from_archive, train_oracle

        train, val, _ = self.splits
        how = "--oracle-architecture" if self.cfg.oracle_architecture else "measured choice"
        config = OracleTrainConfig(
            seed=self.cfg.seed, **options, extra={"architecture_from": how}
        )  # the sidecar's training.config says how the network was chosen
        oracle = train_oracle(
            train, val, [contexts_from_archive(assess["path"])], model_id=self.new_id,
            model_sha256=finetuned["sha256"], thresholds=self.cfg.thresholds, config=config,
            progress=lambda stage, done, total: self.progress(f"oracle: {stage}", done, total),
        )  # fmt: skip
        file = inside(self.work.path, self.work.path / f"{self.new_id}.oracle.safetensors",
                      what="the new model's oracle")  # fmt: skip
        sha = oracle.save(file)
        return {"file": str(file), "sha256": sha, "architecture": oracle.card.architecture,
                "val": oracle.card.metrics.get("val", {})}  # fmt: skip


def _archive_record(archive: Archive, path: Path, *, reused: bool) -> dict[str, Any]:
    return {
        "path": str(path),
        "sha256": archive_sha256(path),
        "reused": reused,
        "evaluations": len(archive),
        "counts": [int((archive.categories == c).sum()) for c in range(3)],
        "clean_f1": archive.meta.clean_f1,
        "model_id": archive.meta.model_id,
    }


def _measure_rows(n: int, used: np.ndarray, k: int, seed: int) -> np.ndarray:
    """Up to *k* archive rows: those not used in training first, then used ones (seeded)."""
    rng = np.random.default_rng(seed)
    unused = np.setdiff1d(np.arange(n), used)
    if len(unused) >= k:
        return np.sort(rng.choice(unused, size=k, replace=False))
    trained = np.intersect1d(np.arange(n), used)
    more = rng.choice(trained, size=min(k - len(unused), len(trained)), replace=False)
    return np.sort(np.concatenate([unused, more]).astype(np.int64))


def robustify(
    model: str | Path,
    data: str | Path,
    out: str | Path,
    config: RobustifyConfig,
    *,
    model_in_id: str | None = None,
    register: str | Path | None = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Run (or continue) the chain; return its summary (also written to ``OUT/summary.json``).

    Args:
        model: The input model: a model file, or a registry (with *model_in_id*). Only read.
        data: A dataset folder with train, val and (for the reported figures) test splits.
        out: The work folder (see docs/robustify.md).
        config: The options.
        model_in_id: With a registry as *model*: which of its models.
        register: A model registry (``models/1`` YAML) to add the new model and its oracle to.
        progress: ``progress(stage, done, total)`` as stages advance.

    Raises:
        EnkiError: Bad input (phenomenon, archive, data, work folder, a domain or a new id
            that is no name: docs/model-manager.md#names), naming it and the fix.

    """
    _check_phenomenon(config.phenomenon)
    resolved = resolve_model(model, model_in_id)
    new_id = config.model_id or new_model_id(resolved.model_id, config.domain)  # a name
    splits = _splits(data)  # a missing split fails before any work
    oracle_options = _oracle_options(config, new_id)  # a bad network too
    options = config.options() | {
        "model": resolved.model_id,
        "model_sha256": resolved.sha256,
        "data": str(Path(data).resolve()),
        "model_id": new_id,
    }
    work = WorkFolder(out, options, scoped=("oracle",))  # older folders recorded it here
    if register is not None:  # a registry that would refuse the model fails before any work
        _check_register(work, Path(register), new_id=new_id, domain=config.domain)
    chain = _Chain(
        resolved, Path(data), work, config, splits=splits, model_in_id=model_in_id,
        new_id=new_id, progress=progress,
    )  # fmt: skip
    search = chain.stage("search", chain.search)
    picked = chain.stage("select", lambda: chain.select(search["path"]))
    selection = Selection.from_dict(picked)
    tuned = chain.stage("finetune", lambda: chain.finetune(search, selection))
    metrics = chain.stage("measure", lambda: chain.measure(search, selection, tuned["file"]))
    assess = chain.stage("assess", lambda: chain.assess(tuned["file"]))
    oracle = chain.stage("oracle", lambda: chain.oracle(tuned, assess, oracle_options),
                         options=oracle_options)  # fmt: skip
    if "oracle" in chain.rerun:  # a registration of the earlier oracle is stale
        work.forget("register-")
    summary: dict[str, Any] = {
        "input": {"model_id": resolved.model_id, "file": str(resolved.file),
                  "sha256": resolved.sha256},
        "model": {"model_id": new_id, "domain": config.domain, "file": tuned["file"],
                  "sha256": tuned["sha256"], "threshold": tuned["threshold"]},
        "phenomenon": config.phenomenon,
        "archive": search,
        "selection": {"counts": picked["counts"], "rule": asdict(config.rule)},
        "finetune": {k: tuned[k] for k in ("epochs", "steps", "images", "seconds")}
        | {k: tuned.get(k, 0) for k in FORWARDS}
        | {"recipe": config.recipe()},
        "metrics": metrics,
        "assessment": assess,
        "oracle": oracle,
        "seed": config.seed,
        "work": str(work.path),
        "reused_stages": chain.reused,
        "rerun_stages": chain.rerun,
    }  # fmt: skip
    if register is not None:
        summary["registered"] = _register(
            work, Path(register), tuned=tuned, oracle=oracle, new_id=new_id, config=config
        )
    write_json(work.path / "summary.json", summary)
    return summary


def _register_key(registry: Path) -> str:
    """The work folder's stage name of a registration into *registry*."""
    return "register-" + hashlib.sha256(str(registry.resolve()).encode()).hexdigest()[:12]


def _check_register(work: WorkFolder, registry: Path, *, new_id: str, domain: str) -> None:
    """Refuse ``--register`` up front when the registry has the id or a model of the domain.

    A registration this work folder made already is left to the register stage (it reuses it).
    """
    from anunnaki.lec import check_registrable

    if not registry.is_file() or work.stage(_register_key(registry)) is not None:
        return  # a missing registry is register_model's to refuse, with its own message
    try:
        check_registrable(registry, new_id, domain)
    except AnunnakiError as exc:
        raise EnkiError(
            f"--register {exc} (or leave --register out and register the model later: "
            "anunnaki.lec.register_model)"
        ) from None


def _register(
    work: WorkFolder,
    registry: Path,
    *,
    tuned: dict[str, Any],
    oracle: dict[str, Any],
    new_id: str,
    config: RobustifyConfig,
) -> dict[str, Any]:
    """Add the model and its oracle to *registry* (once per registry: a rerun reuses it)."""
    from anunnaki.lec import register_model

    key = _register_key(registry)
    done = work.stage(key)
    if done is not None:
        return done
    m = read_metrics(tuned["file"])
    description = (
        f"Enki: fine-tuned for {config.phenomenon} on contexts of its search; "
        f"clean F1 {m.get('input', 0):.3f} -> {m.get('new', 0):.3f}"
    )
    spec = register_model(
        registry, tuned["file"], oracle=oracle["file"], model_id=new_id,
        domain=config.domain, description=description,
    )  # fmt: skip
    return work.done(key, {"registry": str(registry), "model_id": spec.id,
                           "file": str(spec.file), "domain": spec.domain})  # fmt: skip


def read_metrics(file: str) -> dict[str, float]:
    """The clean F1s robustify wrote into a model's sidecar (``metrics.enki.clean``)."""
    from anunnaki.lec import read_card

    clean = read_card(file).metrics.get("enki", {}).get("clean", {})
    return {k: float(v) for k, v in clean.items() if k != "split"}
