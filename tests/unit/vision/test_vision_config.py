"""[vision] in the configuration: the detector and the simulated sensor built from it, and an
impossible camera refused at load, naming the field."""
from __future__ import annotations

import numpy as np
import pytest

from mission.config.schema import from_dict
from mission.errors import ConfigError
from mission.model import vision_detector
from sim.camera.sensor import sensor_model


def test_the_detector_and_the_sensor_come_from_the_section():
    cfg = from_dict({"vision": {"layout": "single", "tag_size_m": 0.3, "tag_id": 7, "hfov_deg": 70.0,
                                "mount_offset_body_m": [0.1, 0.0, 0.05], "mount_rpy_deg": [0.0, 10.0, 0.0],
                                "max_tilt_deg": 20.0, "dropout_probability": 0.1}})
    detector = vision_detector(cfg)
    assert detector.layout.ids == (7,) and detector.layout.tags[0].size_m == 0.3
    assert detector.camera.fov_deg()[0] == pytest.approx(70.0) and detector.settings.max_tilt_deg == 20.0
    assert np.allclose(detector.camera.mount.offset_body_m, [0.1, 0.0, 0.05])
    assert sensor_model(cfg.vision).dropout_probability == 0.1


def test_a_calibration_file_replaces_the_field_of_view(tmp_path):
    path = tmp_path / "cam.json"
    path.write_text('{"camera_matrix": [[500, 0, 320], [0, 500, 240], [0, 0, 1]], "distortion_coefficients": [0, 0, 0, 0, 0],'
                    ' "image_width": 640, "image_height": 480}')
    detector = vision_detector(from_dict({"vision": {"calibration_file": str(path)}}))
    assert detector.camera.focal_px == 500.0


@pytest.mark.parametrize("section,field,words", [
    ({"vision": {"layout": "single"}, "recovery": {"decision_height_m": 0.4}}, "vision.tag_size_m", "never wholly in view"),
    ({"vision": {"small_tag_size_m": 0.3}, "recovery": {"decision_height_m": 0.2}}, "vision.small_tag_size_m",
     "never wholly in view"),
    ({"vision": {"small_tag_size_m": 0.6}}, "vision.small_tag_size_m", "smaller than vision.tag_size_m"),
    ({"vision": {"small_tag_id": 0}}, "vision.small_tag_id", "must differ"),
    ({"vision": {"mount_rpy_deg": [0.0, 10.0]}}, "vision.mount_rpy_deg", "3 components"),
    ({"vision": {"marker_offset_ned_m": [0.0, 0.0]}}, "vision.marker_offset_ned_m", "3 components"),
    # the marker 1 m over the dock point: at the 0.6 m decision height the camera is below it
    ({"vision": {"marker_offset_ned_m": [0.0, 0.0, -2.5]}}, "vision.marker_offset_ned_m", "not above it"),
])
def test_an_impossible_camera_is_refused_naming_the_field(section, field, words):
    with pytest.raises(ConfigError) as exc:
        from_dict(section)
    assert exc.value.field == field and words in str(exc.value)


def test_the_same_camera_passes_where_the_tag_fits():
    from_dict({"vision": {"layout": "single"}, "recovery": {"decision_height_m": 0.6}})  # 0.62 m tag, 0.75 m of view
    from_dict({"vision": {"layout": "single", "hfov_deg": 100.0}, "recovery": {"decision_height_m": 0.4}})
    # the single tag that does not fit at 0.4 m over the dock point does 1.5 m further down, on the deck
    from_dict({"vision": {"layout": "single", "marker_offset_ned_m": [0.0, 0.0, 0.0]}, "recovery": {"decision_height_m": 0.4}})
