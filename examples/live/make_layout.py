"""Writes examples/live/foxglove-layout.json, the Foxglove layout for `carlos run --live` and recordings.

3D view following the ego (TF, ground-truth boxes, lidar points, a detector's boxes, the lidar of a roadside
unit named `rsu` as in examples/runs/cooperative-perception.yaml), the ego's speed and the gap metrics as
plots, the run status, and the V2X messages the ego receives (CPMs, DENMs; `spec.v2x`). Built with
foxglove-sdk's typed layout API, so it stays valid;
`python examples/live/make_layout.py` regenerates it (a test fails when the file drifts).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import foxglove.layouts as fl

HERE = Path(__file__).resolve().parent
EGO = "Ego"
RSU = "rsu"


def layout() -> fl.Layout:
    three_d = fl.ThreeDeePanel(
        title="World",
        config=fl.ThreeDeeConfig(
            follow_tf=f"{EGO}/base_link",
            follow_mode="follow-position",
            topics={
                "/carlos/objects/markers": fl.BaseRendererRosMarkerTopicSettings(visible=True),
                "/carlos/detections/markers": fl.BaseRendererRosMarkerTopicSettings(visible=True),
                f"/carlos/{EGO}/lidar/points": fl.BaseRendererPointCloudTopicSettings(visible=True),
                f"/carlos/infrastructure/{RSU}/lidar/points": fl.BaseRendererPointCloudTopicSettings(
                    visible=True
                ),
            },
        ),
    )
    speed = fl.PlotPanel(
        title="Ego speed (m/s)",
        config=fl.PlotConfig(
            paths=[fl.PlotSeries(value=f"/carlos/{EGO}/odometry.twist.twist.linear.x", label="speed")],
            show_legend=True,
        ),
    )
    status = fl.RawMessagesPanel(title="Run status", config=fl.RawMessagesConfig(topic_path="/carlos/status"))
    cpm = fl.RawMessagesPanel(
        title="Ego V2X: CPMs received", config=fl.RawMessagesConfig(topic_path=f"/carlos/{EGO}/v2x/cpm")
    )
    denm = fl.RawMessagesPanel(
        title="Ego V2X: DENMs received", config=fl.RawMessagesConfig(topic_path=f"/carlos/{EGO}/v2x/denm")
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[
                fl.SplitItem(proportion=3, content=three_d),
                fl.SplitItem(
                    proportion=1,
                    content=fl.SplitContainer(
                        direction="column",
                        items=[
                            fl.SplitItem(proportion=2, content=speed),
                            fl.SplitItem(proportion=1, content=status),
                            fl.SplitItem(proportion=1, content=cpm),
                            fl.SplitItem(proportion=1, content=denm),
                        ],
                    ),
                ),
            ],
        ),
    )


def render() -> str:
    return json.dumps(json.loads(layout().to_json()), indent=2, sort_keys=True) + "\n"


if __name__ == "__main__":
    (HERE / "foxglove-layout.json").write_text(render())
    sys.exit(0)
