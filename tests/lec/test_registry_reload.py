"""Models registered while the model manager runs (issue 23, item 3): ``/lm_manager/reload``.

A model is added to the registry file of a running :class:`LecNode` (in-process bus), the
operator asks for a reload, and a swap to the new model succeeds; every kind of bad registry
(malformed, hostile, a wrong sha256, a file that is not a model of the right shape, one that
drops the model in use) and every request without the operator token is refused with the
error, and the old registry keeps working. The models are tiny CenterNets (width 8, 64 × 64),
made in a second; a new model is a copy of one under a new id.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from lec_helpers import Collector

from anunnaki import topics
from anunnaki.bus import Bus, ServiceError, open_bus
from anunnaki.errors import ModelFileError
from anunnaki.lec import LecNode, load_registry
from anunnaki.messages import Detections, Image
from anunnaki.tokens import OPERATOR_TOKEN_ENV

CAMERA = "/uav/camera/image"
TOKEN = "reload-test-Token-0123456789abcdefXYZ"


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def make_model(folder: Path, model_id: str, domain: str, seed: int, width: int = 8) -> Path:
    from anunnaki.lec._centernet import CenterNetDetector
    from anunnaki.lec._detector import save_detector

    det = CenterNetDetector.create(
        ("person", "car"), input_size=(64, 64), width=width, seed=seed, model_id=model_id,
        domain=domain,
    )  # fmt: skip
    det.metrics = {"test": {"f1": 0.9}}
    path = folder / f"{model_id}.safetensors"
    save_detector(det, path)
    return path


@pytest.fixture(scope="module")
def made(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The models every test copies: two of width 8, one of width 4 (another shape)."""
    folder = tmp_path_factory.mktemp("made")
    make_model(folder, "uav-default", "default", seed=0)
    make_model(folder, "uav-fog", "fog", seed=1)
    make_model(folder, "narrow", "default", seed=2, width=4)
    return folder


def copy_model(made: Path, folder: Path, source: str, name: str) -> Path:
    """Copy model ``source`` to ``folder`` as ``name`` (the sidecar names its weights file)."""
    weights = folder / f"{name}.safetensors"
    shutil.copy(made / f"{source}.safetensors", weights)
    card = json.loads((made / f"{source}.json").read_text())
    card.update(weights=weights.name, model_id=name)
    (folder / f"{name}.json").write_text(json.dumps(card))
    return weights


def entry(folder: Path, name: str, model_id: str | None = None, domain: str | None = None) -> str:
    file = folder / f"{name}.safetensors"
    text = f"  - file: {name}.safetensors\n    sha256: {sha(file)}\n"
    if model_id is not None:
        text += f"    id: {model_id}\n    domain: {domain}\n"
    return text


HEAD = "anunnaki: models/1\nlec: detector\nmodels:\n"


@pytest.fixture
def folder(made: Path, tmp_path: Path) -> Path:
    """A registry folder: ``registry.yaml`` with uav-default and uav-fog, and a third model
    (``uav-rain``, a copy of uav-fog) already copied there but not registered yet."""
    root = tmp_path / "models"
    root.mkdir()
    copy_model(made, root, "uav-default", "uav-default")
    copy_model(made, root, "uav-fog", "uav-fog")
    copy_model(made, root, "uav-fog", "uav-rain")
    (root / "registry.yaml").write_text(HEAD + entry(root, "uav-default") + entry(root, "uav-fog"))
    return root


@pytest.fixture
def bus() -> Iterator[Bus]:
    with open_bus("inproc") as b:
        yield b


@pytest.fixture
def node(bus: Bus, folder: Path) -> Iterator[LecNode]:
    with LecNode(
        bus,
        load_registry(folder / "registry.yaml"),
        camera=CAMERA,
        active_period=None,
        operator_token=TOKEN,
    ) as n:
        yield n


def register_rain(folder: Path) -> Path:
    """Append uav-rain (domain rain) to the registry file, as an operator would."""
    registry = folder / "registry.yaml"
    with registry.open("a") as f:
        f.write(entry(folder, "uav-rain", "uav-rain", "rain"))
    return registry


def reload(bus: Bus, **fields: Any) -> dict[str, Any]:
    reply = bus.request(topics.RELOAD_MODELS, {"token": TOKEN, "caller": "test", **fields})
    return dict(reply.to_body()["body"])


def swap(bus: Bus, **fields: Any) -> dict[str, Any]:
    reply = bus.request(topics.SWAP, {"lec": "detector", **fields})
    return dict(reply.to_body()["body"])


_PNG = cv2.imencode(".png", np.full((64, 64, 3), 128, np.uint8))[1].tobytes()


def test_a_model_registered_while_running_becomes_swappable(
    bus: Bus, node: LecNode, folder: Path
) -> None:
    detections = Collector(bus, node.detections_topic)
    active = Collector(bus, topics.ACTIVE_MODEL)
    with pytest.raises(ServiceError, match="no model for domain 'rain'"):
        swap(bus, domain="rain")  # not registered yet
    registry = register_rain(folder)
    announced = len(active.items)
    body = reload(bus)
    assert body == {
        "lec": "detector",
        "registry": str(registry),
        "active": "uav-default",
        "models": ["uav-default", "uav-fog", "uav-rain"],
        "added": ["uav-rain"],
        "changed": [],
        "removed": [],
        "caller": "test",
    }
    active.wait(announced + 1)  # the reload is announced
    assert node.active.id == "uav-default"  # the model in use was never dropped
    assert node.registry.get("uav-rain").domain == "rain"
    swapped = swap(bus, domain="rain")
    assert (swapped["model"], swapped["previous"], swapped["changed"]) == (
        "uav-rain",
        "uav-default",
        True,
    )
    bus.publish(CAMERA, Image(encoding="png", width=64, height=64, data=_PNG, seq=7))
    (got,) = detections.wait(1)
    assert isinstance(got, Detections) and (got.model_id, got.domain) == ("uav-rain", "rain")
    stats = node.stats()
    assert (stats.reloads, stats.reloads_refused, stats.swaps) == (1, 0, 1)


def test_a_reload_from_another_file_in_the_folder_and_from_python(
    node: LecNode, folder: Path
) -> None:
    other = folder / "next.yaml"
    other.write_text(
        HEAD + entry(folder, "uav-default") + entry(folder, "uav-rain", "uav-rain", "rain")
    )
    result = node.reload(other, caller="ops")
    assert result.ok and result.registry == str(other)
    assert (result.added, result.removed) == (("uav-rain",), ("uav-fog",))
    assert node.registry.source == str(other)
    assert node.swap(domain="rain").ok
    assert not node.swap(domain="fog").ok  # removed by the reload
    # Without a path, the file in force now is read again.
    assert node.reload().registry == str(other)


def test_a_changed_entry_drops_its_cached_model(node: LecNode, folder: Path, made: Path) -> None:
    assert node.swap(domain="fog").ok and node.swap(domain="default").ok  # fog now cached
    cached = node._cache["uav-fog"]
    copy_model(made, folder, "uav-default", "uav-fog2")  # a retrained fog model, say
    (folder / "registry.yaml").write_text(
        HEAD + entry(folder, "uav-default") + entry(folder, "uav-fog2", "uav-fog", "fog")
    )
    result = node.reload()
    assert result.ok and result.changed == ("uav-fog",)
    assert "uav-fog" not in node._cache
    assert node.swap(domain="fog").ok
    assert node._active.detector is not cached
    assert node.active.file == folder / "uav-fog2.safetensors"


def test_the_model_in_use_may_change_its_metrics_but_not_its_file(
    node: LecNode, folder: Path
) -> None:
    text = HEAD + entry(folder, "uav-default") + "    metrics: {f1: 0.5}\n"
    (folder / "registry.yaml").write_text(text + entry(folder, "uav-fog"))
    assert node.reload().changed == ("uav-default",)
    assert node.active.clean_f1 == 0.5 and node.registry.clean_f1("uav-default") == 0.5


# -- refused: the old registry keeps working ----------------------------------------------------


def _malformed(folder: Path, made: Path) -> str:
    return HEAD + entry(folder, "uav-default") + "  - file: uav-fog: safetensors\n"


def _unknown_field(folder: Path, made: Path) -> str:
    return HEAD + entry(folder, "uav-default") + entry(folder, "uav-fog") + "    weights: x\n"


def _yaml_bomb(folder: Path, made: Path) -> str:
    bomb = 'a: &a ["x","x","x","x","x","x","x","x","x"]\nb: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]\n'
    return bomb + HEAD + entry(folder, "uav-default")


def _outside(folder: Path, made: Path) -> Path:
    """A model next to the registry's folder, not in it."""
    outside = folder.parent / "outside"
    outside.mkdir(exist_ok=True)
    return copy_model(made, outside, "uav-fog", "evil")


def _escapes(folder: Path, made: Path) -> str:
    file = _outside(folder, made)
    rel = os.path.relpath(file, folder)
    return HEAD + entry(folder, "uav-default") + f"  - file: {rel}\n    sha256: {sha(file)}\n"


def _symlink_out(folder: Path, made: Path) -> str:
    file = _outside(folder, made)
    for suffix in (".safetensors", ".json"):
        (folder / f"link{suffix}").symlink_to(file.with_suffix(suffix))
    return HEAD + entry(folder, "uav-default") + entry(folder, "link", "evil", "rain")


def _wrong_sha(folder: Path, made: Path) -> str:
    wrong = sha(folder / "uav-fog.safetensors")  # a real digest, of another file
    return (
        HEAD
        + entry(folder, "uav-default")
        + entry(folder, "uav-fog")
        + f"  - file: uav-rain.safetensors\n    sha256: {wrong[::-1]}\n    id: uav-rain\n"
        "    domain: rain\n"
    )


def _with_sidecar(folder: Path, made: Path, weights: bytes) -> str:
    """uav-rain's weights replaced by ``weights``, its sidecar's hash made to agree."""
    (folder / "uav-rain.safetensors").write_bytes(weights)
    card = json.loads((folder / "uav-rain.json").read_text())
    card["sha256"] = sha(folder / "uav-rain.safetensors")
    (folder / "uav-rain.json").write_text(json.dumps(card))
    return HEAD + entry(folder, "uav-default") + entry(folder, "uav-rain", "uav-rain", "rain")


def _not_safetensors(folder: Path, made: Path) -> str:
    return _with_sidecar(folder, made, b"\x00not a safetensors file at all" * 10)


def _wrong_shape(folder: Path, made: Path) -> str:
    return _with_sidecar(folder, made, (made / "narrow.safetensors").read_bytes())


def _drops_active(folder: Path, made: Path) -> str:
    return HEAD + entry(folder, "uav-fog", "uav-fog", "default")


def _replaces_active(folder: Path, made: Path) -> str:
    return HEAD + entry(folder, "uav-rain", "uav-default", "default") + entry(folder, "uav-fog")


def _other_lec(folder: Path, made: Path) -> str:
    return (HEAD + entry(folder, "uav-default")).replace("lec: detector", "lec: planner")


def _oracle_sha(folder: Path, made: Path) -> str:
    (folder / "fog.oracle.safetensors").write_bytes(b"an oracle")
    wrong = "ab" * 32
    return (
        HEAD
        + entry(folder, "uav-default")
        + entry(folder, "uav-fog")
        + f"    oracle: {{file: fog.oracle.safetensors, sha256: {wrong}}}\n"
    )


def _no_default(folder: Path, made: Path) -> str:
    return HEAD + entry(folder, "uav-fog")


BAD: dict[str, tuple[Callable[[Path, Path], str], str, str]] = {
    # kind: (the registry text, what the error says, the element it names)
    "malformed": (_malformed, "invalid YAML", ":6:"),
    "unknown-field": (_unknown_field, "weights", "models[1]"),
    "yaml-bomb": (_yaml_bomb, "YAML anchor", ":1:"),
    "path-escape": (_escapes, "outside the registry's folder", "models[1].file"),
    "symlink-out": (_symlink_out, "outside the registry's folder", "models[1].file"),
    "wrong-sha256": (_wrong_sha, "sha256 mismatch", "models[2].sha256"),
    "not-safetensors": (_not_safetensors, "the loader refused", "models[1].file"),
    "wrong-shape": (_wrong_shape, "the loader refused", "models[1].file"),
    "drops-active": (_drops_active, "the model in use, 'uav-default', is not listed", "models"),
    "replaces-active": (_replaces_active, "changes its file", "models[0].file"),
    "other-lec": (_other_lec, "lec 'planner'", "lec"),
    "oracle-sha256": (_oracle_sha, "sha256 mismatch for its oracle", "models[1].oracle"),
    "no-default": (_no_default, "no model for the domain 'default'", "models"),
}


@pytest.mark.parametrize("kind", sorted(BAD))
def test_a_bad_registry_is_refused_and_the_old_one_kept(
    kind: str, bus: Bus, node: LecNode, folder: Path, made: Path
) -> None:
    write, says, element = BAD[kind]
    registry = folder / "registry.yaml"
    before = registry.read_text()
    registry.write_text(write(folder, made))
    with pytest.raises(ServiceError) as info:
        reload(bus)
    error = info.value.error
    assert error.startswith(f"{registry}:"), error  # the file (and the line)
    assert says in error and element in error and "(hint: " in error, error  # and the fix
    assert node.registry.ids() == ["uav-default", "uav-fog"]  # the old registry is kept
    assert node.registry.source == str(registry) and node.active.id == "uav-default"
    assert swap(bus, domain="fog")["model"] == "uav-fog"  # and keeps working
    assert node.stats().reloads_refused == 1
    copy_model(made, folder, "uav-fog", "uav-rain")  # the operator fixes what was wrong
    registry.write_text(before + entry(folder, "uav-rain", "uav-rain", "rain"))
    assert reload(bus)["added"] == ["uav-rain"]  # a fixed file is taken


def test_a_registry_outside_the_reload_folders_is_refused(
    bus: Bus, node: LecNode, folder: Path, tmp_path: Path, made: Path
) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    copy_model(made, elsewhere, "uav-default", "uav-default")
    (elsewhere / "registry.yaml").write_text(HEAD + entry(elsewhere, "uav-default"))
    with pytest.raises(ServiceError, match="outside the folders a reload may read") as info:
        reload(bus, registry=str(elsewhere / "registry.yaml"))
    assert f"{elsewhere / 'registry.yaml'}:" in info.value.error and "reload_dirs" in str(
        info.value
    )
    os.mkfifo(folder / "pipe.yaml")  # a pipe in the folder is refused, never read (no hang)
    with pytest.raises(ServiceError, match="not a regular file"):
        reload(bus, registry=str(folder / "pipe.yaml"))
    with pytest.raises(ServiceError, match="'registry' must be a path"):
        reload(bus, registry=3)
    assert node.registry.ids() == ["uav-default", "uav-fog"]


def test_reload_dirs_widen_where_a_registry_may_come_from(
    bus: Bus, folder: Path, tmp_path: Path, made: Path
) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    copy_model(made, elsewhere, "uav-default", "uav-default")  # the same bytes, elsewhere
    copy_model(made, elsewhere, "uav-fog", "uav-rain")
    text = HEAD + entry(elsewhere, "uav-default") + entry(elsewhere, "uav-rain", "uav-rain", "rain")
    fog = folder / "uav-fog.safetensors"
    other = elsewhere / "registry.yaml"
    other.write_text(text + f"  - file: {fog}\n    sha256: {sha(fog)}\n")
    registry = load_registry(folder / "registry.yaml")
    with LecNode(
        bus, registry, camera=CAMERA, active_period=None, operator_token=TOKEN,
        reload_dirs=[elsewhere],
    ) as node:  # fmt: skip
        with pytest.raises(ServiceError, match="outside the registry's folder"):
            reload(bus, registry=str(other))  # a registry's models stay in its folder
        other.write_text(text)
        body = reload(bus, registry=str(other))
        assert (body["added"], body["changed"], body["removed"]) == (
            ["uav-rain"],
            ["uav-default"],  # its file moved; the bytes in use are the same: it stays
            ["uav-fog"],
        )
        assert node.active.file == elsewhere / "uav-default.safetensors"
        assert swap(bus, domain="rain")["model"] == "uav-rain"


# -- the operator token ---------------------------------------------------------------------------


@pytest.mark.parametrize("token", [None, "", "another-Token-0123456789abcdefXYZ", 42])
def test_a_reload_without_the_operator_token_is_refused(
    bus: Bus, node: LecNode, folder: Path, token: Any
) -> None:
    register_rain(folder)
    request: dict[str, Any] = {"caller": "intruder"}
    if token is not None:
        request["token"] = token
    with pytest.raises(ServiceError) as info:
        bus.request(topics.RELOAD_MODELS, request)
    assert info.value.error.startswith("unauthorised: reload needs the operator token")
    assert node.registry.ids() == ["uav-default", "uav-fog"]
    assert node.stats().reloads_refused == 1
    assert reload(bus)["added"] == ["uav-rain"]  # the operator's own request is taken


def test_the_token_comes_from_the_environment_else_the_users_file(
    bus: Bus, folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from anunnaki.tokens import client_operator_token

    registry = load_registry(folder / "registry.yaml")
    monkeypatch.delenv(OPERATOR_TOKEN_ENV, raising=False)
    with LecNode(bus, registry, camera=CAMERA, active_period=None) as node:
        user = client_operator_token()  # the user's file, there since the node started
        assert user is not None
        with pytest.raises(ServiceError, match="unauthorised"):
            bus.request(topics.RELOAD_MODELS, {"token": TOKEN})
        bus.request(topics.RELOAD_MODELS, {"token": user})
        assert node.stats().reloads == 1
    monkeypatch.setenv(OPERATOR_TOKEN_ENV, TOKEN)
    with LecNode(bus, registry, camera=CAMERA, active_period=None):
        bus.request(topics.RELOAD_MODELS, {"token": TOKEN})
        with pytest.raises(ServiceError, match="unauthorised"):
            bus.request(topics.RELOAD_MODELS, {"token": user})
    monkeypatch.setenv(OPERATOR_TOKEN_ENV, "weak")  # refused at bring-up, as by Utu
    with pytest.raises(ModelFileError, match=r"too weak.*\(hint: make one with"):
        LecNode(bus, registry, camera=CAMERA, active_period=None)
    with pytest.raises(ModelFileError, match="operator_token: the operator token"):
        LecNode(bus, registry, camera=CAMERA, operator_token="aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa")
