"""A folder's record of the sensor that measured its training depth, and the default
sensor each dataset format implies without one (vbgs.data.sensor_record)."""

import json

import pytest

from vbgs.data.blender import write_blender
from vbgs.data.sensor_record import (
    SENSOR_RECORD,
    data_sensor,
    read_sensor_record,
    write_sensor_record,
)
from vbgs.data.synthetic import room_scene
from vbgs.data.writers import write_replica, write_tum


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    room = room_scene(size=16, n_train=4, n_test=1, n_val=1, seed=0)
    root = tmp_path_factory.mktemp("formats")
    return {"blender": write_blender(room, root / "blender"),
            "replica": write_replica(room.train, root / "replica"),
            "tum": write_tum(room.train, root / "rgbd_dataset_freiburg1_room")}


def test_each_format_has_its_default_and_a_record_wins(folders, tmp_path):
    assert data_sensor(folders["tum"])[:4] == ("kinect", 1.0, "tum default", False)
    assert data_sensor(folders["replica"]).sensor == "exact"
    assert data_sensor(folders["blender"])[:4] == ("exact", 1.0, "blender default", False)
    assert data_sensor(folders["tum"], "blender").sensor == "exact"  # the format as given
    assert data_sensor("object").sensor == "exact"  # a synthetic scene by name
    assert data_sensor(tmp_path).sensor == "exact"  # an empty folder: the loader refuses it
    write_sensor_record(tmp_path, "realsense", 0.5, "none", 3, {"train": "realsense"}, "test",
                        {"depth_sensor_holes": 0.25, "depth_sensor": "realsense"})
    assert data_sensor(tmp_path) == ("realsense", 0.5, f"the folder's {SENSOR_RECORD}", True,
                                     {"depth_sensor_holes": 0.25})
    record = read_sensor_record(tmp_path)
    assert (record["holes"], record["seed"], record["splits"]) == ("none", 3,
                                                                   {"train": "realsense"})


@pytest.mark.parametrize("text, words", [
    ("{", "not a depth-sensor record"),
    ('{"level": 1}', "'sensor'"),
    ('{"sensor": "lidar", "level": 1}', "unknown sensor 'lidar'"),
    ('{"sensor": "kinect", "level": -1}', "sensor level must be"),
    ('{"sensor": "kinect", "level": 1, "holes": "some"}', "hole"),
])
def test_a_malformed_record_is_refused_naming_the_file(tmp_path, text, words):
    (tmp_path / SENSOR_RECORD).write_text(text)
    with pytest.raises(ValueError, match=SENSOR_RECORD) as err:
        data_sensor(tmp_path)
    assert words in str(err.value)


def test_writing_refuses_an_unknown_sensor(tmp_path):
    with pytest.raises(ValueError, match="unknown depth sensor 'lidar'"):
        write_sensor_record(tmp_path, "lidar", 1.0, "sensor", 0, {}, "")
    assert not (tmp_path / SENSOR_RECORD).exists()
    write_sensor_record(tmp_path, "mono", 2, "sensor", 0, {"train": "mono"}, "x")
    assert json.loads((tmp_path / SENSOR_RECORD).read_text())["level"] == 2.0
