"""The zenoh path's rmw_zenoh keys and attachments, against pyzeros (an independent
implementation of rmw_zenoh's wire format, installed in the ROS 2 environment)."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest
from ros2_support import ROS2_PYTHON, need_ros2

from anunnaki.ros2 import rmw_zenoh_attachment, ros2_key, type_hash, type_store
from anunnaki.rosbridge import ROS2_MESSAGE_TYPES

pytest.importorskip("rosbags")

PYZEROS = """
import json, sys
import numpy as np
from importlib import import_module
from pyzeros.builtin_msgs import Attachment
from pyzeros.pub import publisher_keyexpr
from pyzeros.utils import ros_type_to_dds_type
keys = {}
for name in json.loads(sys.argv[1]):
    package, msg = name.split("/")
    cls = getattr(import_module(f"ros2_pyterfaces.cyclone.{package}.msg"), msg)
    dds = ros_type_to_dds_type(cls.get_type_name())
    keys[name] = publisher_keyexpr("/robot/topic", dds, cls.hash_rihs01(), domain_id=7)
gid = np.arange(16, dtype=np.uint8)
attachment = Attachment(sequence_number=5, source_timestamp=123456789, source_gid=gid)
print(json.dumps({"keys": keys, "attachment": attachment.serialize()[4:].hex()}))
"""


def test_rmw_zenoh_keys_and_attachments_are_what_pyzeros_makes(tmp_path: Path) -> None:
    need_ros2()
    names = sorted(ROS2_MESSAGE_TYPES)
    # pyzeros's CDR code compiled by scripts/setup-ros2.sh, in the environment
    cache = ROS2_PYTHON.parents[1] / ".cydr_cache"
    done = subprocess.run(
        [str(ROS2_PYTHON), "-c", PYZEROS, json.dumps(names)],
        capture_output=True,
        text=True,
        check=False,
        cwd=tmp_path,
        env={**os.environ, "CYDR_CACHE_DIR": str(cache)},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    theirs = json.loads(done.stdout.strip().splitlines()[-1])
    store = type_store("jazzy")
    ours = {
        name: ros2_key(
            "/robot/topic",
            name,
            flavour="rmw_zenoh",
            domain=7,
            type_hash=type_hash(name, store, "jazzy"),
        )
        for name in names
    }
    assert ours == theirs["keys"]
    assert rmw_zenoh_attachment(5, 123456789, bytes(range(16))).hex() == theirs["attachment"]
