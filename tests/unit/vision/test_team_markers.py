"""A team flying the marker feed: each dock slot has its own marker (its own tag ids, under its
own dock point; mission/config/team.py), each passenger's detector keeps to its slot's ids, and
each passenger's camera, rendered with every slot's marker in view (sim/camera/publisher.py,
sim/sitl/camera.py), is published on that passenger's own key."""
from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from mission.bus.frames import camera_key, decode_frame
from mission.config.passenger import passenger_config
from mission.config.schema import load_config
from mission.config.team import slot_tag_ids
from mission.errors import ConfigError
from mission.model import vision_detector
from sim.camera.publisher import BodyTruth, CameraPublisher, DeckTruth
from sim.sitl.camera import team_eyes
from tests.conftest import CONFIGS

PATH = CONFIGS / "px4_sitl_team_relnav.toml"
TEXT = PATH.read_text()


@pytest.fixture(scope="module")
def team():
    return load_config(PATH)


def load_text(tmp_path, text: str):
    path = tmp_path / "team.toml"
    path.write_text(text)
    return load_config(path)


def test_each_passenger_looks_for_its_own_slots_marker_under_its_dock_point(team):
    alpha, bravo = passenger_config(team, "alpha"), passenger_config(team, "bravo")
    assert (alpha.vision.tag_id, alpha.vision.small_tag_id) == (0, 1)
    assert (bravo.vision.tag_id, bravo.vision.small_tag_id) == (2, 3)
    assert alpha.vision.marker_offset_ned_m == [0.0, -0.9, 0.0] and bravo.vision.marker_offset_ned_m == [0.0, 0.9, 0.0]
    assert vision_detector(alpha).layout.ids == (1, 0) and vision_detector(bravo).layout.ids == (3, 2)
    # what the team shares stays the team's: the layout, the rate
    assert alpha.vision.layout == bravo.vision.layout == "bundle" and alpha.vision.rate_hz == 15.0


def test_slots_without_their_own_ids_take_visions(team):
    cleared = team.team.model_copy(update={"slots": [s.model_copy(update={"tag_id": None}) for s in team.team.slots]})
    assert slot_tag_ids(cleared, 7, 8, bundle=True) == [(7, 1), (7, 3)]
    assert slot_tag_ids(cleared, 7, 8, bundle=False) == [(7,), (7,)]


@pytest.mark.parametrize("old, new, field", [
    ("tag_id = 2\n", "tag_id = 0\n", "team.slots[1].tag_id"),             # both big tags 0
    ("small_tag_id = 3\n", "small_tag_id = 1\n", "team.slots[1].small_tag_id"),
    ("tag_id = 2\n", "tag_id = 1\n", "team.slots[1].tag_id"),             # its big one the other's small one
    ("tag_id = 2\nsmall_tag_id = 3\n", "", "team.slots[1].tag_id"),      # unset: vision's 0 and 1, port's
])
def test_two_slots_sharing_a_tag_id_are_refused_naming_the_later_slot(tmp_path, old, new, field):
    with pytest.raises(ConfigError) as err:
        load_text(tmp_path, TEXT.replace(old, new, 1))
    assert err.value.field == field and "its passenger takes the other slot's" in err.value.rule


def test_shared_ids_are_fine_without_the_marker_feed(tmp_path):
    text = TEXT.replace("tag_id = 2\nsmall_tag_id = 3\n", "", 1).replace('feeds = ["marker"]', "feeds = []")
    cfg = load_text(tmp_path, text.replace("enabled = true\naccel", "enabled = false\naccel"))
    assert slot_tag_ids(cfg.team, 0, 1, bundle=True) == [(0, 1), (0, 1)]


def test_one_marker_offset_for_every_slot_is_refused(tmp_path):
    with pytest.raises(ConfigError) as err:
        load_text(tmp_path, TEXT.replace("[vision]\n", "[vision]\nmarker_offset_ned_m = [0.0, 0.0, 0.0]\n", 1))
    assert err.value.field == "vision.marker_offset_ned_m" and "team.slots[].marker_offset_ned_m" in err.value.rule


def test_a_slots_marker_offset_needs_three_components(tmp_path):
    with pytest.raises(ConfigError) as err:
        load_text(tmp_path, TEXT.replace("marker_offset_ned_m = [0.0, 0.9, 0.0]", "marker_offset_ned_m = [0.0, 0.9]", 1))
    assert err.value.field == "team.slots[1].marker_offset_ned_m"


def test_each_team_passenger_has_its_own_camera_key():
    keys = {camera_key("pair0"), camera_key("pair0", "alpha"), camera_key("pair0", "bravo")}
    assert camera_key("pair0") == "marsupial/pair0/passenger/camera"  # the single pair's, as before
    assert camera_key("pair0", "alpha") == "marsupial/pair0/passenger/alpha/camera" and len(keys) == 3


def test_the_camera_node_gives_each_passenger_its_vehicle_key_and_the_other_marker(team):
    eyes = team_eyes(team, ["alpha", "bravo"])
    assert [(e.name, e.sysid, e.passenger) for e in eyes] == [("alpha", 1, "alpha"), ("bravo", 2, "bravo")]
    assert [[o.vision.tag_id for o in e.others] for e in eyes] == [[2], [0]]


class Session:
    def __init__(self) -> None:
        self.keys: list[str] = []
        self.payloads: list[bytes] = []

    def declare_publisher(self, key: str, **_: Any) -> Session:
        self.keys.append(key)
        return self

    def put(self, payload: bytes, attachment: Any = None) -> None:
        self.payloads.append(payload)

    def undeclare(self) -> None:
        pass


def measured(team, name: str, camera_east_m: float) -> tuple[list[np.ndarray], list[int], str]:
    """What passenger ``name``'s detector measures in the frames of its camera, rendered with both
    slots' markers: the camera 2.4 m above the rover's reference point and ``camera_east_m`` east
    of it (the deck still, level, heading north). Its measurements (the deck centre from the
    vehicle [m] NED), the tag ids it kept, its camera's key."""
    eye = next(e for e in team_eyes(team, ["alpha", "bravo"]) if e.name == name)
    session = Session()
    camera = CameraPublisher(eye.cfg, session, "pair0", seed=3, lockstep=False, passenger=eye.passenger,  # type: ignore[arg-type]
                             others=eye.others)
    body = BodyTruth.level(np.array([0.0, camera_east_m, -2.4]), 0.0, np.zeros(3))
    deck = DeckTruth(np.zeros(3), np.zeros(3), 0.0)
    for k in range(20):
        camera.sample(k / eye.cfg.vision.rate_hz, body, deck)
    detector = vision_detector(eye.cfg)
    seen, ids = [], set()
    for payload in session.payloads:
        frame, q = decode_frame(payload)
        if frame.image.size:
            found = detector.corners(frame.image)
            ids.update(int(i) for i in found.ids)
            m = detector.measure_corners(found, frame.capture_t_s, q)
            if m is not None:
                seen.append(np.asarray(m.deck_rel_ned_m))
    return seen, sorted(ids), session.keys[0]


@pytest.mark.parametrize("name, marker_east_m, own_ids", [("alpha", -0.9, [0, 1]), ("bravo", 0.9, [2, 3])])
@pytest.mark.parametrize("camera_east_m", [0.0, 0.6])  # between the slots (both markers wholly in view), over bravo's side
def test_each_passenger_measures_its_own_slots_marker_with_both_in_view(team, name, marker_east_m, own_ids, camera_east_m):
    seen, ids, key = measured(team, name, camera_east_m)
    assert key == f"marsupial/pair0/passenger/{name}/camera"
    assert own_ids[0] in ids and set(ids) <= set(own_ids)  # the other slot's tags are in the frame, and dropped
    assert len(seen) >= 15
    expected = [0.0, marker_east_m - camera_east_m, 2.4]
    assert np.allclose(np.median(seen, axis=0), expected, atol=0.03), (np.median(seen, axis=0), expected)


def test_the_frames_show_the_other_slots_marker(team):
    """The control: a detector of the other slot's ids finds its marker in the same frames (the
    renderer draws both; the selection is the detector's, by id)."""
    eye, other = team_eyes(team, ["alpha", "bravo"])
    session = Session()
    camera = CameraPublisher(eye.cfg, session, "pair0", seed=3, lockstep=False, passenger="alpha",  # type: ignore[arg-type]
                             others=eye.others)
    for k in range(5):
        camera.sample(k / 15.0, BodyTruth.level(np.array([0.0, 0.0, -2.4]), 0.0, np.zeros(3)),
                      DeckTruth(np.zeros(3), np.zeros(3), 0.0))
    detector = vision_detector(other.cfg)
    found = [decode_frame(p) for p in session.payloads]
    m = [detector.measure_corners(detector.corners(f.image), f.capture_t_s, q) for f, q in found if f.image.size]
    got = [np.asarray(x.deck_rel_ned_m) for x in m if x is not None]
    assert got and np.allclose(np.median(got, axis=0), [0.0, 0.9, 2.4], atol=0.03)
