"""The Foxglove layout of a marsupial flight (``configs/foxglove/marsupial.json``), built with the
foxglove-sdk's layout types from the topics of :mod:`mission.flightdata.topics`.

Left, the 3D panel in the ENU ``map`` frame: both robots (turned by their heading), the target,
the obstacles, the b c circle, the dock point and the anchor (``scene``), moved by the frame
transforms; under it the passenger's camera as the marker feed saw it, with the tags it found
drawn on it (empty in a flight without the marker feed). Right, top to bottom: the phase, the safety filter's activity and the carrier's mode
over time (State Transitions); the distances |e_pc|, |e_tc|, |e_pt| with b c and the carrier's own
distance to the target; the law's command and the safe command (north and east) with the
filter's change; the relative estimate's standard deviation (``[relnav]``: the deck from the
vehicle, its largest and per axis; empty in a flight without it); the log (phase changes and events). The carrier's rows come from
``carrier.mcap``: open it with ``flight.mcap`` (their log times are both epoch time). ``python -m mission.flightdata.layout``
rewrites the file (a test holds the two together).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from mission.flightdata.topics import CAMERA_CHANNELS, CARRIER_CHANNELS, MAP_FRAME, RELNAV_CHANNELS, topics

LAYOUT_FILE = Path(__file__).resolve().parents[2] / "configs" / "foxglove" / "marsupial.json"


def layout(pair: str = "pair0") -> dict[str, Any]:
    """The layout for pair ``pair``'s topics, as the JSON object the Foxglove app imports."""
    import foxglove.layouts as fl

    t = topics(pair)
    c = topics(pair, CARRIER_CHANNELS)
    cam = topics(pair, CAMERA_CHANNELS)
    rel = topics(pair, RELNAV_CHANNELS)["relnav"]
    three_d = fl.ThreeDeePanel(title="marsupial: carrier, passenger, target (map = ENU above map_ned = NED)",
                               config=fl.ThreeDeeConfig(
                                   follow_tf=MAP_FRAME, fixed_frame=MAP_FRAME, follow_mode="follow-none",
                                   camera_state=fl.ThreeDeeCameraState(distance=45.0, phi=55.0, theta_offset=-60.0,
                                                                       target_offset=(9.0, 12.0, 0.0), perspective=True),
                                   scene=fl.BaseRendererSceneSettings(transforms=fl.BaseRendererTransforms(
                                       show_label=True, axis_size=0.6, label_size=0.12)),
                                   topics={t["scene"]: fl.BaseRendererSceneUpdateTopicSettings(visible=True)}))

    def series(path: str, label: str, color: str, style: str = "solid") -> Any:
        return fl.PlotSeries(value=path, label=label, color=color, line_style=style, enabled=True)  # type: ignore[arg-type]

    states = fl.StateTransitionsPanel(title="phase and safety filter", config=fl.StateTransitionsConfig(
        paths=[fl.StateTransitionsSeries(value=f"{t['phase']}.phase", label="phase"),
               fl.StateTransitionsSeries(value=f"{t['safety']}.acted", label="filter acted"),
               fl.StateTransitionsSeries(value=f"{c['status']}.mode", label="carrier mode (carrier.mcap)")],
        is_synced=True, show_points=False))
    distances = fl.PlotPanel(title="distances [m]: the law's carrier is the dock point", config=fl.PlotConfig(
        paths=[series(f"{t['distances']}.e_pc_m", "|e_pc| passenger-dock", "#4e98e2"),
               series(f"{t['distances']}.e_tc_m", "|e_tc| target-dock", "#f5774d"),
               series(f"{t['distances']}.e_pt_m", "|e_pt| passenger-target", "#61cbff"),
               series(f"{t['distances']}.bc_m", "b c", "#f7df71", "dashed"),
               series(f"{c['status']}.target_distance_m", "carrier-target (carrier.mcap)", "#cfcfe0", "dotted")],
        is_synced=True, show_legend=True, legend_display="top", y_axis_label="m"))
    command = fl.PlotPanel(title="command [m/s]: the law's and the safe (sent) one", config=fl.PlotConfig(
        paths=[series(f"{t['command']}.law.n", "law n", "#4e98e2", "dashed"),
               series(f"{t['command']}.safe.n", "safe n", "#4e98e2"),
               series(f"{t['command']}.law.e", "law e", "#f5774d", "dashed"),
               series(f"{t['command']}.safe.e", "safe e", "#f5774d"),
               series(f"{t['safety']}.change_m_s", "|safe - law|", "#9cd86b")],
        is_synced=True, show_legend=True, legend_display="top", y_axis_label="m/s"))
    relnav = fl.PlotPanel(title="relative estimate [m]: standard deviation of the deck from the vehicle", config=fl.PlotConfig(
        paths=[series(f"{rel}.position_sigma_m", "sigma (largest)", "#f7df71"),
               series(f"{rel}.position_sigma.n", "sigma n", "#4e98e2", "dashed"),
               series(f"{rel}.position_sigma.e", "sigma e", "#f5774d", "dashed"),
               series(f"{rel}.position_sigma.d", "sigma d", "#9cd86b", "dashed")],
        is_synced=True, show_legend=True, legend_display="top", y_axis_label="m"))
    log = fl.LogPanel(title="mission log", config=fl.LogConfig(topic_to_render=t["log"], show_name=False))
    right = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=1, content=states), fl.SplitItem(proportion=2, content=distances),
        fl.SplitItem(proportion=2, content=command), fl.SplitItem(proportion=1.5, content=relnav),
        fl.SplitItem(proportion=1.5, content=log)])
    camera = fl.ImagePanel(title="passenger camera: the tags the detector found", config=fl.ImageConfig(
        image_mode=fl.ImageModeConfig(image_topic=cam["image"], calibration_topic=cam["calibration"],
                                      annotations={cam["detections"]: fl.ImageAnnotationSettings(visible=True)})))
    left = fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=2, content=three_d), fl.SplitItem(proportion=1, content=camera)])
    root = fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=3, content=left), fl.SplitItem(proportion=2, content=right)]))
    return json.loads(root.to_json())


def layout_text(pair: str = "pair0") -> str:
    """The layout as the text of ``configs/foxglove/marsupial.json``."""
    return json.dumps(layout(pair), indent=2) + "\n"


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else LAYOUT_FILE
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(layout_text())
    print(f"layout written to {out}")
