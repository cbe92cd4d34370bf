"""The robust-training recipe in the loop: worst-of-k, the consistency loss, the weight average."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
import pytest
import torch
from torch import nn

from anunnaki.datasets import Dataset
from anunnaki.lec import CenterNetDetector, DetectorError, TrainConfig, TrainState, train_detector
from anunnaki.lec._centernet import centernet_loss
from anunnaki.lec._recipe import (
    CandidatePerturb,
    WeightAverage,
    candidate_losses,
    consistency_loss,
)
from anunnaki.lec._train import _batch_tensors, _fitted, _Loop

SIZE = (64, 64)


def tiny_data(n: int = 8, seed: int = 0) -> Dataset:
    """Red pedestrians on grey, one a frame (as test_lec_train's)."""
    rng = np.random.default_rng(seed)
    images, boxes, labels = [], [], []
    for _ in range(n):
        image = np.full((64, 64, 3), 90, np.uint8)
        x, y = (int(v) for v in rng.integers(4, 40, 2))
        image[y : y + 16, x : x + 12] = (220, 40, 40)
        images.append(image)
        boxes.append([[x, y, x + 12, y + 16]])
        labels.append([0])
    return Dataset.from_arrays(images, boxes, labels, ("pedestrian", "deer"))


class Shades:
    """k candidates: the image darkened by k different gains (a :class:`CandidatePerturb`)."""

    def __init__(self, k: int = 3, select: Literal["hardest", "random"] = "hardest") -> None:
        self.k, self.select = k, select
        self.calls = 0

    def candidates(self, image: Any, rng: np.random.Generator) -> list[Any]:
        self.calls += 1
        if rng.random() < 0.25:
            return [image]
        gains = rng.uniform(0.05, 1.0, self.k)
        return [(image * g).astype(np.uint8) for g in gains]

    def __call__(self, image: Any, rng: np.random.Generator) -> Any:
        return self.candidates(image, rng)[0]


def _loop(cfg: TrainConfig, data: Dataset) -> _Loop:
    det = CenterNetDetector.create(data.classes, input_size=SIZE, width=8, seed=0)
    rngs = {k: np.random.default_rng(i) for i, k in enumerate(("order", "aug", "perturb"))}
    return _Loop(cfg, det, _fitted(data, SIZE, cfg), SIZE, rngs=rngs, num_classes=2)


def _own_losses(net: nn.Module, images: list[Any], sample: Any) -> list[float]:
    """Each candidate's loss computed alone, the plain way (eval mode, one image a pass)."""
    net.eval()
    out = []
    with torch.no_grad():
        for image in images:
            x, heat_t, box_t, weight = _batch_tensors([(image, *sample[1:])], SIZE, 2, 4)
            out.append(float(centernet_loss(net(x), heat_t, box_t, weight)[0]))
    net.train()
    return out


def test_shades_is_a_candidate_perturb() -> None:
    assert isinstance(Shades(), CandidatePerturb)
    assert not isinstance(lambda image, rng: image, CandidatePerturb)


def test_worst_of_k_keeps_the_candidate_with_the_highest_loss() -> None:
    data = tiny_data(4)
    loop = _loop(TrainConfig(width=8, batch_size=4, perturb=Shades(4)), data)
    net = loop.det.network
    sample = loop.data[0]
    image = sample[0]
    candidates = [
        image,
        (image * 0.1).astype(np.uint8),
        255 - image,
        (image * 0.6).astype(np.uint8),
    ]
    losses = _own_losses(net, candidates, sample)
    hardest = int(np.argmax(losses))
    assert len(set(np.round(losses, 6))) == 4  # the losses are distinct: the pick is decided
    drawn = (hardest + 1) % 4  # the random draw points elsewhere
    before = {k: v.clone() for k, v in net.state_dict().items()}
    offered = [(c, None) for c in candidates]  # the loop's candidates: (image, no mask)
    chosen = loop._choose([(sample, offered, drawn), (loop.data[1], [(loop.data[1][0], None)], 0)])
    assert chosen[0][0] is candidates[hardest]
    assert chosen[1][0] is loop.data[1][0]  # a single candidate is kept as it is
    assert np.array_equal(chosen[0][1], sample[1])  # with the image's own targets
    assert loop.counts["select_forwards"] == 4 and loop.counts["candidates"] == 4
    # scoring leaves the network as it was: no BatchNorm statistics moved, training mode
    for k, v in net.state_dict().items():
        assert torch.equal(v, before[k]), k
    assert net.training
    # the same draw under "random": the drawn one, and no forward pass
    rand = _loop(TrainConfig(width=8, batch_size=4, perturb=Shades(4, "random")), data)
    chosen = rand._choose([(sample, offered, drawn)])
    assert chosen[0][0] is candidates[drawn]
    assert rand.counts["select_forwards"] == 0 and rand.counts["candidates"] == 4


def test_candidate_losses_do_not_depend_on_the_other_candidates() -> None:
    data = tiny_data(6)
    loop = _loop(TrainConfig(width=8), data)
    x, heat_t, box_t, weight = _batch_tensors(loop.data, SIZE, 2, 4)
    all_at_once = candidate_losses(loop.det.network, x, heat_t, box_t, weight, batch_size=6)
    in_pairs = candidate_losses(loop.det.network, x, heat_t, box_t, weight, batch_size=2)
    torch.testing.assert_close(all_at_once, in_pairs)
    own = [_own_losses(loop.det.network, [s[0]], s)[0] for s in loop.data]
    assert all_at_once.tolist() == pytest.approx(own, rel=1e-5)


def test_worst_of_k_and_its_random_control_train_on_the_same_draws() -> None:
    data = tiny_data(8)
    runs = {}
    for select in ("hardest", "random"):
        shades = Shades(3, select)  # type: ignore[arg-type]
        cfg = TrainConfig(epochs=1, batch_size=4, width=8, seed=2, perturb=shades)
        runs[select] = train_detector(data, data, config=cfg)
    hard, rand = runs["hardest"], runs["random"]
    # the same candidates rendered (the same stream draws), forward passes only to select
    assert hard.counts["candidates"] == rand.counts["candidates"] > 0
    assert hard.counts["select_forwards"] == hard.counts["candidates"]
    assert rand.counts["select_forwards"] == 0
    assert hard.counts["train_forwards"] == rand.counts["train_forwards"] == 8
    training = hard.detector.training
    assert training["steps"] == 2 and training["select_forwards"] == hard.counts["candidates"]


def test_consistency_is_zero_for_identical_views_and_the_clean_view_gets_no_gradient() -> None:
    gen = torch.Generator().manual_seed(0)
    clean = torch.randn(2, 3, 8, 8, generator=gen, requires_grad=True)
    same = clean.detach().clone().requires_grad_(True)
    assert float(consistency_loss(same, clean).detach()) == 0.0
    other = torch.randn(2, 3, 8, 8, generator=gen, requires_grad=True)
    loss = consistency_loss(other, clean)
    assert float(loss.detach()) > 0.0
    loss.backward()  # type: ignore[no-untyped-call]
    assert clean.grad is None  # detached: nothing flows into the clean view
    assert other.grad is not None and float(other.grad.abs().sum()) > 0
    # symmetric in value, and bounded by ln 2 per cell
    value = float(loss.detach())
    assert float(consistency_loss(clean, other).detach()) == pytest.approx(value, rel=1e-5)
    assert value <= np.log(2) * 3 * 8 * 8
    with pytest.raises(DetectorError, match="differ"):
        consistency_loss(other, clean[:1])


def test_training_with_consistency_counts_the_clean_views() -> None:
    data = tiny_data(8)
    shades = Shades(1)
    cfg = TrainConfig(epochs=1, batch_size=4, width=8, seed=1, perturb=shades, consistency=1.0)
    result = train_detector(data, data, config=cfg)
    assert 0 < result.counts["consistency_forwards"] <= 8
    assert result.history[0]["consistency"] > 0
    assert result.detector.training["consistency"] == 1.0
    off = train_detector(data, data, config=TrainConfig(epochs=1, batch_size=4, width=8, seed=1))
    assert off.counts["consistency_forwards"] == 0 and "consistency" not in off.history[0]
    with pytest.raises(DetectorError, match="consistency"):
        TrainConfig(consistency=-1.0)


def test_the_weight_average_is_the_hand_computed_one() -> None:
    net = nn.Sequential(nn.Linear(2, 1, bias=False), nn.BatchNorm1d(1))
    lin = net[0]
    assert isinstance(lin, nn.Linear)
    with torch.no_grad():
        lin.weight.copy_(torch.tensor([[1.0, 2.0]]))
    ema = WeightAverage(net, decay=0.2)
    w = [torch.tensor([[1.0, 2.0]]), torch.tensor([[3.0, 0.0]]), torch.tensor([[-1.0, 4.0]])]
    expected = w[0].clone()
    for n, target in enumerate(w[1:], start=1):
        with torch.no_grad():
            lin.weight.copy_(target)
        net(torch.ones(4, 2) * n)  # moves BatchNorm's statistics and its batch counter
        ema.update(net)
        d = min(0.2, (1 + n) / (10 + n))  # 2/11 first, then the ceiling 0.2
        expected = d * expected + (1 - d) * target
    assert ema.rate(1) == pytest.approx(2 / 11) and ema.rate(2) == 0.2
    torch.testing.assert_close(ema.state["0.weight"], expected)
    assert int(ema.state["1.num_batches_tracked"]) == 2  # integers are copied
    with pytest.raises(DetectorError, match="decay"):
        WeightAverage(net, decay=1.0)


def test_resume_with_ema_worst_of_k_and_consistency_ends_as_an_uninterrupted_run(
    tmp_path: Any,
) -> None:
    data = tiny_data(8)

    def config() -> TrainConfig:
        return TrainConfig(
            epochs=3, batch_size=4, width=8, seed=5, perturb=Shades(2), consistency=0.5, ema=0.9
        )

    def save(state: TrainState) -> None:  # the state holds the live tensors: save it now
        state.save(tmp_path / f"epoch-{state.epoch}.pt")

    straight = train_detector(data, data, config=config(), checkpoint=save)
    states = [TrainState.load(tmp_path / f"epoch-{e}.pt") for e in (1, 2, 3)]
    assert states[0].ema is not None and states[0].ema["updates"] == 2
    resumed = train_detector(data, data, config=config(), resume=states[0])
    a = straight.detector.network.state_dict()
    b = resumed.detector.network.state_dict()
    for k in a:
        assert torch.equal(a[k], b[k]), k
    assert straight.counts == resumed.counts
    assert straight.threshold == resumed.threshold
    # the saved weights are the average, and the threshold was chosen with them
    last = states[-1]
    assert last.ema is not None
    for k, v in last.ema["state"].items():
        assert torch.equal(a[k], v), k
    assert not all(torch.equal(last.network[k], a[k]) for k in a)
    assert straight.detector.training["ema"] == 0.9
    with pytest.raises(DetectorError, match="ema"):
        train_detector(
            data, data, config=TrainConfig(epochs=3, batch_size=4, width=8, seed=5),
            resume=states[0],
        )  # fmt: skip


def test_a_checkpoint_without_the_new_fields_still_loads(tmp_path: Any) -> None:
    """Checkpoints written before the weight average and the counts resume as before."""
    data = tiny_data(4)
    states: list[TrainState] = []
    cfg = TrainConfig(epochs=2, batch_size=4, width=8)
    train_detector(data, data, config=cfg, checkpoint=states.append)
    old = {k: v for k, v in states[0].__dict__.items() if k not in ("ema", "counts")}
    torch.save(old, tmp_path / "old.pt")
    back = TrainState.load(tmp_path / "old.pt")
    assert back.ema is None and back.counts == {}
    assert train_detector(data, data, config=cfg, resume=back).detector.training["steps"] == 2
