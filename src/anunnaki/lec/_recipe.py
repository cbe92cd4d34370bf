"""The robust-training recipe's parts that need the network: worst-of-k, consistency, EMA.

The training loop (:func:`anunnaki.lec.train_detector`) calls them; each is here so that it
can be read, and tested, on its own:

- :class:`CandidatePerturb`: a ``TrainConfig.perturb`` that offers *k* candidate images per
  training image. The loop renders them (from the perturbation stream) and keeps one: the
  candidate with the highest detector loss on the image's own targets under the network
  being trained (:func:`candidate_losses`, worst-of-k), or one at random (the control arm
  with the same rendering cost and no selection);
- :func:`consistency_loss`: the distance between the heat maps of a perturbed view and of
  the clean view of the same image, the clean view's output detached (AugMix's consistency
  term, for a CenterNet heat map);
- :class:`WeightAverage`: an exponential moving average of the weights, the model that is
  saved and whose threshold is chosen on val.

Why the candidates are scored in eval mode: in training mode BatchNorm would normalise each
candidate by the statistics of the others (a candidate's loss would depend on what it was
scored with) and the scoring passes would move the running statistics; in eval mode each
candidate gets the loss the network, as it stands, gives that image alone, and the scoring
leaves the network exactly as it was.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
import torch
from torch import Tensor, nn

from anunnaki.lec._centernet import centernet_loss
from anunnaki.lec._detector import DetectorError

__all__ = ["CandidatePerturb", "WeightAverage", "candidate_losses", "consistency_loss", "pick"]

Image = npt.NDArray[np.uint8]

#: Probabilities are kept in ``[EPS, 1 - EPS]`` (as the focal loss keeps them).
EPS = 1e-4


@runtime_checkable
class CandidatePerturb(Protocol):
    """A ``TrainConfig.perturb`` that offers several candidates per image (worst-of-k).

    The training loop calls :meth:`candidates` instead of the hook itself, with the
    perturbation stream, after the image's zoom, flip and recolouring. One candidate (the
    clean image, when the source leaves it clean) is used as it is. Of several, the loop
    draws one index uniformly from the same stream (always, so that arms differing only in
    ``select`` stay paired) and keeps:

    - ``select == "hardest"``: the candidate with the highest loss under the network being
      trained (:func:`candidate_losses`; one no-grad forward pass per candidate, counted);
    - ``select == "random"``: the drawn one (no forward pass).

    """

    select: Literal["hardest", "random"]

    def candidates(self, image: Image, rng: np.random.Generator) -> list[Any]:
        """The candidate images for *image* (at least one), drawing only from *rng*.

        Each an image, or ``(image, mask)`` with the perturbation's occlusion mask (as
        :data:`anunnaki.lec.Perturb` may return): the boxes it hides become ignore boxes.
        """
        ...


def candidate_losses(
    network: nn.Module,
    x: Tensor,
    heat_t: Tensor,
    box_t: Tensor,
    weight: Tensor,
    *,
    batch_size: int = 32,
) -> Tensor:
    """Each image's own detector loss under *network*, with no gradient, in eval mode.

    Args:
        network: A :class:`~anunnaki.lec.CenterNet` (or any module with its outputs).
        x: ``[N, 3, H, W]`` images (the training batch's encoding).
        heat_t: ``[N, C, h, w]`` heat-map targets of each image.
        box_t: ``[N, 4, h, w]`` box targets.
        weight: ``[N, 1, h, w]`` box-regression weights.
        batch_size: Images per forward pass (memory only; the losses do not depend on it).

    Returns:
        ``[N]`` losses: :func:`~anunnaki.lec._centernet.centernet_loss` of each image alone
        (its focal loss normalised by its own objects). The network's mode is restored.

    """
    was_training = network.training
    network.eval()
    out = []
    try:
        with torch.no_grad():
            for start in range(0, len(x), batch_size):
                end = min(len(x), start + batch_size)
                heat, box = network(x[start:end])
                for i in range(end - start):
                    j = start + i
                    loss, _ = centernet_loss(
                        (heat[i : i + 1], box[i : i + 1]),
                        heat_t[j : j + 1],
                        box_t[j : j + 1],
                        weight[j : j + 1],
                    )
                    out.append(loss)
    finally:
        network.train(was_training)
    return torch.stack(out) if out else torch.zeros(0)


def consistency_loss(perturbed: Tensor, clean: Tensor) -> Tensor:
    """Jensen-Shannon divergence between the heat maps of two views, the clean one detached.

    A CenterNet heat map is an independent Bernoulli probability per cell and class
    (``sigmoid`` of the logits), so the distance is the Bernoulli JSD per cell,
    ``JSD(p, q) = ½ KL(p ‖ m) + ½ KL(q ‖ m)`` with ``m = (p + q) / 2`` (AugMix's term, per
    cell; bounded by ``ln 2``), summed over cells and classes and divided by the number of
    images: ``λ = 1`` weighs one image's whole heat map like one object of the focal loss.
    It is zero exactly when the two maps are equal, and only *perturbed* gets a gradient.

    Args:
        perturbed: ``[N, C, h, w]`` heat-map logits of the perturbed views.
        clean: ``[N, C, h, w]`` heat-map logits of the clean views (detached here).

    Returns:
        A scalar tensor.

    Raises:
        DetectorError: The two shapes differ.

    """
    if perturbed.shape != clean.shape:
        raise DetectorError(
            f"consistency: the perturbed views' heat maps {tuple(perturbed.shape)} and the "
            f"clean views' {tuple(clean.shape)} differ; give one clean view per perturbed one"
        )
    if perturbed.numel() == 0:
        return perturbed.sum() * 0.0
    p = torch.sigmoid(perturbed).clamp(EPS, 1 - EPS)
    q = torch.sigmoid(clean.detach()).clamp(EPS, 1 - EPS)
    m = (p + q) / 2

    def kl(a: Tensor) -> Tensor:
        return a * torch.log(a / m) + (1 - a) * torch.log((1 - a) / (1 - m))

    jsd = 0.5 * (kl(p) + kl(q))
    return jsd.sum() / len(perturbed)


class WeightAverage:
    """An exponential moving average (EMA) of a network's weights, for the saved model.

    After every optimiser step, each floating-point entry of the network's ``state_dict``
    (weights and BatchNorm running statistics) moves toward the network's:
    ``avg ← d · avg + (1 − d) · w`` with ``d = min(decay, (1 + n) / (10 + n))`` at the
    *n*-th update (TensorFlow's ``ExponentialMovingAverage`` with ``num_updates``: early on
    the average follows the weights, so that a short fine-tune is not dominated by its
    starting point). Integer entries (BatchNorm's batch counter) are copied.

    Args:
        network: The network whose weights are averaged; the average starts at them.
        decay: ``d``'s ceiling in ``(0, 1)``; 0.99 averages over about the last 100 steps.

    """

    def __init__(self, network: nn.Module, decay: float) -> None:
        if not 0.0 < decay < 1.0:
            raise DetectorError(f"the EMA decay must be in (0, 1), got {decay}")
        self.decay = float(decay)
        self.updates = 0
        self.state: dict[str, Tensor] = {
            k: v.detach().clone() for k, v in network.state_dict().items()
        }

    def rate(self, n: int) -> float:
        """The decay used at the *n*-th update."""
        return min(self.decay, (1 + n) / (10 + n))

    def update(self, network: nn.Module) -> None:
        """Move the average toward *network*'s current weights (after an optimiser step)."""
        self.updates += 1
        d = self.rate(self.updates)
        with torch.no_grad():
            for key, value in network.state_dict().items():
                avg = self.state[key]
                if avg.dtype.is_floating_point:
                    avg.mul_(d).add_(value.detach(), alpha=1.0 - d)
                else:
                    avg.copy_(value)

    def as_dict(self) -> dict[str, Any]:
        """What a checkpoint keeps (:class:`~anunnaki.lec.TrainState`'s ``ema``)."""
        return {"decay": self.decay, "updates": self.updates, "state": dict(self.state)}

    def restore(self, saved: dict[str, Any]) -> None:
        """Continue from :meth:`as_dict`'s output.

        Raises:
            DetectorError: It is of another decay or another network.

        """
        state = saved.get("state")
        if float(saved.get("decay", -1.0)) != self.decay or not isinstance(state, dict) or (
            set(state) != set(self.state)
        ):  # fmt: skip
            raise DetectorError(
                f"the checkpoint's weight average (decay {saved.get('decay')}) is not this "
                f"training's (decay {self.decay}); delete the checkpoint to start over"
            )
        self.updates = int(saved.get("updates", 0))
        self.state = {k: v.detach().clone() for k, v in state.items()}


def pick(losses: Sequence[float] | Tensor, drawn: int, select: Literal["hardest", "random"]) -> int:
    """The kept candidate: the first with the highest loss, or the drawn one."""
    if select == "random":
        return drawn
    values = [float(v) for v in losses]
    return int(np.argmax(values))
