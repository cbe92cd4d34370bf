"""Phenomena: parameterised, deterministic image perturbations, each a plugin.

A phenomenon (fog, a raindrop on the lens, poor lighting, ...) turns a camera frame and a
small vector of named, bounded parameters into a perturbed frame. Enlil and Enki search over
those parameters (the paper's "contexts", §3.2, §4.1.2, §4.2.1); scenario files ramp them
with a scalar strength; oracles report them. Images are ``(height, width, 3)`` ``uint8`` RGB
arrays; anything else is rejected with a :class:`PhenomenonError` that says how to convert.

Using one::

    from anunnaki.phenomena import PHENOMENA, synthetic_scene

    fog = PHENOMENA.create("fog")               # or pass a Phenomenon instance anywhere
    frame = synthetic_scene(128, 128)
    foggy = fog.apply(frame, {"density": 4, "intensity": 0.3}, seed=7)

The contract (:class:`Phenomenon`), shared by every built-in and plugin:

* ``name`` and ``params`` (a tuple of :class:`ParamSpec`: name, bounds, unit, description,
  identity value, optional default, integer flag);
* ``bounds()`` → ``[(low, high), ...]``, ``to_vector(params)`` → ``np.ndarray``,
  ``from_vector(vector)`` → ``dict`` — the fixed-length view pyribs archives need;
* ``validate(params)`` fills optional parameters, rounds integer ones and rejects unknown,
  missing, non-finite and out-of-bounds values, naming the parameter, value, bounds and unit;
* ``identity_params()`` (zero strength: the image is returned unchanged, byte for byte) and
  ``strength_params(s)`` for ``s`` in ``[0, 1]``;
* ``apply(image, params, seed)`` is deterministic: the same image, parameters and seed give
  the same bytes; the only randomness is ``numpy.random.default_rng(seed)``. The input is
  never modified. ``stochastic`` says whether the seed matters at all.

Built-ins (``PHENOMENA.names()``): ``brightness``, ``fog``, ``hsl``, ``motion_blur``,
``noise``, ``rain``, ``raindrop``, ``snow``. ``compose("fog", "raindrop")`` (or the name
``"fog+raindrop"``) chains phenomena into one :class:`Composition` whose parameters are
prefixed with the step label (``fog.density``, ``raindrop.x``; repeats become ``raindrop_2``)
and whose steps get seeds spawned from the one seed.

``occlusion(shape, params, seed)`` → a ``(H, W)`` ``float32`` :data:`Mask` in ``[0, 1]``,
how much of each pixel ``apply`` replaced with the same parameters and seed, or ``None`` (the
default: the phenomenon hides nothing). A raindrop reports one; a composition combines its
steps'. A labelled box whose mean mask is at least :data:`HIDDEN` (0.5) is *hidden*: training
and evaluation make it an ignore box (``anunnaki.lec.hide_boxes``).

``CameraEncoding(90)`` (``CameraEncoding.parse("jpeg:90")``) is what a camera that sends JPEG
does to a frame after the phenomena: ``apply(image)`` encodes and decodes it. Assessments and
oracles for such a camera measure and learn through it (``anunnaki assess --encoding
jpeg:90``; docs/enlil.md).

``with reuse_fog_noise(store):`` keeps a fog's noise layers for the seeds it sees, for work
that applies many contexts to the same images with the same seeds (Enlil's search).

Plugins: subclass :class:`Phenomenon`, then either register it in the slot
(``@PHENOMENA.register``, a :class:`~anunnaki.plugins.Registry` like every slot) or declare
an entry point in the ``anunnaki.phenomena`` group of your package (see
``docs/phenomena.md``). Importing this package needs only numpy; OpenCV and albumentations
(the ``vision`` extra) are imported when a phenomenon that needs them is first applied, and a
missing one raises :class:`~anunnaki.errors.MissingExtraError` naming ``anunnaki[phenomena]``.
"""

from anunnaki.phenomena._base import HIDDEN, Image, Mask, ParamSpec, Phenomenon, PhenomenonError
from anunnaki.phenomena._color import HSL, Brightness
from anunnaki.phenomena._composition import Composition, CompositionStep
from anunnaki.phenomena._encoding import CameraEncoding
from anunnaki.phenomena._fog import Fog, reuse_fog_noise
from anunnaki.phenomena._raindrop import Raindrop
from anunnaki.phenomena._registry import PHENOMENA, StepLike, compose
from anunnaki.phenomena._scene import synthetic_scene
from anunnaki.phenomena._sensor import MotionBlur, Noise, motion_kernel
from anunnaki.phenomena._weather import Rain, Snow

__all__ = [
    "HIDDEN",
    "HSL",
    "PHENOMENA",
    "Brightness",
    "CameraEncoding",
    "Composition",
    "CompositionStep",
    "Fog",
    "Image",
    "Mask",
    "MotionBlur",
    "Noise",
    "ParamSpec",
    "Phenomenon",
    "PhenomenonError",
    "Rain",
    "Raindrop",
    "Snow",
    "StepLike",
    "compose",
    "motion_kernel",
    "reuse_fog_noise",
    "synthetic_scene",
]
