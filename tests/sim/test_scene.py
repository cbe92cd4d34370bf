"""Scenes and dataset frames: shapes, ground truth from the mask, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from anunnaki.sim import (
    ROVER_CLASSES,
    UAV_CLASSES,
    Frame,
    Placement,
    Scene,
    dataset_frames,
    layout_placements,
)


@pytest.mark.parametrize(("platform", "classes"), [("rover", ROVER_CLASSES), ("uav", UAV_CLASSES)])
def test_frames_have_the_documented_shapes_and_dtypes(platform, classes) -> None:
    frames = list(dataset_frames(platform, layout=1, seed=2, n=6, width=96, height=64))
    assert len(frames) == 6
    assert [f.seq for f in frames] == list(range(6))
    assert sum(len(f.boxes) for f in frames) > 0  # the cameras find objects
    for f in frames:
        assert isinstance(f, Frame)
        assert f.image.shape == (64, 96, 3) and f.image.dtype == np.uint8
        assert f.boxes.dtype == np.float32 and f.boxes.shape == (len(f.labels), 4)
        assert f.labels.dtype == np.int64
        assert np.all((f.labels >= 0) & (f.labels < len(classes)))
        if len(f.boxes):
            x1, y1, x2, y2 = f.boxes.T
            assert np.all(x1 >= 0) and np.all(y1 >= 0)
            assert np.all(x2 <= 96) and np.all(y2 <= 64)
            assert np.all(x2 - x1 >= 4) and np.all(y2 - y1 >= 4)
        assert f.ignore.dtype == np.float32 and f.ignore.shape == (len(f.ignore_labels), 4)
        assert np.all((f.ignore_labels >= 0) & (f.ignore_labels < len(classes)))


def test_boxes_are_tight_around_the_objects_pixels_in_the_mask() -> None:
    rng = np.random.default_rng(5)
    with Scene("rover", 2, width=128, height=96) as scene:
        objects = scene.objects
        checked = 0
        for _ in range(8):
            camera = scene.random_camera(rng)
            frame = scene.render(camera)
            mask = scene.render_mask(camera)
            for box, label in zip(frame.boxes, frame.labels, strict=True):
                matches = []
                for body, (_, body_label) in objects.items():
                    ys, xs = np.nonzero(mask == body)
                    if len(xs) == 0:
                        continue
                    tight = [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]
                    if np.array_equal(np.asarray(tight, dtype=np.float32), box):
                        matches.append(body_label)
                assert label in matches
                checked += 1
        assert checked >= 3


def test_frames_are_deterministic_for_layout_and_seed() -> None:
    a = list(dataset_frames("rover", layout=3, seed=7, n=3))
    b = list(dataset_frames("rover", layout=3, seed=7, n=3))
    for fa, fb in zip(a, b, strict=True):
        assert np.array_equal(fa.image, fb.image)
        assert np.array_equal(fa.boxes, fb.boxes)
        assert np.array_equal(fa.labels, fb.labels)
        assert np.array_equal(fa.ignore, fb.ignore)
    c = list(dataset_frames("rover", layout=3, seed=8, n=3))
    assert not all(np.array_equal(x.image, y.image) for x, y in zip(a, c, strict=True))


def test_different_layouts_are_different_scenes() -> None:
    assert layout_placements("rover", 0) == layout_placements("rover", 0)
    assert layout_placements("rover", 0) != layout_placements("rover", 1)
    assert layout_placements("uav", 0) != layout_placements("uav", 1)
    a = next(iter(dataset_frames("uav", layout=0, seed=0, n=1)))
    b = next(iter(dataset_frames("uav", layout=1, seed=0, n=1)))
    assert not np.array_equal(a.image, b.image)


def test_occluded_and_cut_objects_get_an_ignore_box_not_a_label() -> None:
    # A pedestrian hidden behind a big cube, and one mostly out of the frame.
    from anunnaki.sim import Camera

    # The frame's left edge is 30° off axis, 2.89 m to the side at 5 m: the pedestrian at
    # y = 3.0 (0.45 m wide) shows about a quarter of itself.
    people = [Placement("pedestrian", 5.0, 0.0, size=1.7), Placement("pedestrian", 5.0, 3.0)]
    wall = Placement("cube", 3.0, 0.0, size=1.6)
    camera = Camera((0.0, 0.0, 0.3), (10.0, 0.0, 0.3), fov=60.0)
    with Scene("rover", 0, placements=people) as open_scene:
        frame = open_scene.render(camera)
        assert len(frame.boxes) == 1  # the one at y=3.0 is cut ...
        assert len(frame.ignore) == 1 and frame.ignore_labels.tolist() == [0]  # ... ignored
        assert frame.ignore[0, 0] == 0.0  # at the frame's left edge
    with Scene("rover", 0, placements=[*people, wall]) as hidden:
        frame = hidden.render(camera)
        assert len(frame.boxes) == 0
        assert len(frame.ignore) >= 1  # the cut one, and the hidden one if a limb shows


def test_a_far_pedestrian_is_an_ignore_box_a_near_one_a_label() -> None:
    # The rover's smallest labelled height is 0.134 of the image (a 0.93 m deer at 6 m,
    # twice the stop distance): at 128 px, 17.2 px. A 1.7 m pedestrian 12 m ahead is about
    # 0.866 * 128 * 1.7 / 12 = 15.7 px tall: seen, not labelled. At 5 m it is ~38 px.
    from anunnaki.sim import MIN_LABEL_HEIGHT, Camera

    assert MIN_LABEL_HEIGHT["rover"] * 128 == pytest.approx(17.2, abs=0.1)
    camera = Camera((0.0, 0.0, 0.3), (10.0, 0.0, 0.3), fov=60.0)
    far = Placement("pedestrian", 12.0, 0.0, size=1.7)
    with Scene("rover", 0, placements=[far]) as scene:
        frame = scene.render(camera)
        assert len(frame.boxes) == 0 and frame.ignore_labels.tolist() == [0]
        x1, y1, x2, y2 = frame.ignore[0]
        assert 12 <= y2 - y1 < 17.2 and x2 - x1 >= 2
        # The same frame labelled with no minimum height has it as a box.
    with Scene("rover", 0, placements=[far], min_label_height=0.0) as scene:
        frame = scene.render(camera)
        assert len(frame.boxes) == 1 and len(frame.ignore) == 0
    with Scene("rover", 0, placements=[Placement("pedestrian", 5.0, 0.0, size=1.7)]) as scene:
        frame = scene.render(camera)
        assert len(frame.boxes) == 1 and len(frame.ignore) == 0
        assert frame.boxes[0, 3] - frame.boxes[0, 1] > 30
    # The UAV labels every box of at least 4 px.
    assert MIN_LABEL_HEIGHT["uav"] == 0.0


def test_scenes_live_side_by_side_in_one_process() -> None:
    with Scene("rover", 0, width=32, height=32) as a, Scene("uav", 0, width=32, height=32) as b:
        assert a.client != b.client
        rng = np.random.default_rng(0)
        a.render(a.random_camera(rng))
        b.render(b.random_camera(rng))


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="platform"):
        layout_placements("boat", 0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="kind"):
        Scene("rover", 0, placements=[Placement("dragon", 1, 1)])


def test_min_distance_brings_the_rover_camera_closer() -> None:
    """Aimed cameras come as close as min_distance to their object (1.5 m by default)."""
    import math

    with Scene("rover", 0, placements=[Placement("pedestrian", 10.0, 0.0)]) as scene:

        def close(**kwargs: float) -> int:  # cameras within 1.2 m of the object, of 300
            rng = np.random.default_rng(0)
            cams = [scene.random_camera(rng, **kwargs) for _ in range(300)]
            return sum(math.hypot(c.eye[0] - 10.0, c.eye[1]) < 1.2 for c in cams)

        # by default only the unaimed cameras (three in ten, anywhere near the route) are
        # so close
        assert close() < 15
        assert close(min_distance=0.4) > 40
