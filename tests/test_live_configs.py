"""The shipped Foxglove layout and RViz config stay valid and show the topics CARLOS publishes."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
LIVE = ROOT / "examples" / "live"


def test_foxglove_layout_is_generated_and_current() -> None:
    spec = importlib.util.spec_from_file_location("make_layout", LIVE / "make_layout.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert (LIVE / "foxglove-layout.json").read_text() == module.render(), "run examples/live/make_layout.py"
    layout = json.loads((LIVE / "foxglove-layout.json").read_text())
    text = json.dumps(layout)
    for topic in (
        "/carlos/objects/markers",
        "/carlos/Ego/odometry",
        "/carlos/status",
        "/carlos/Ego/v2x/cpm",
        "/carlos/infrastructure/rsu/lidar/points",
    ):
        assert topic in text


def test_rviz_config_shows_map_frame_and_carlos_topics() -> None:
    config = yaml.safe_load((LIVE / "carlos.rviz").read_text())
    manager = config["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "map"
    topics = {d["Topic"]["Value"] for d in manager["Displays"] if "Topic" in d}
    assert {"/carlos/objects/markers", "/carlos/Ego/odometry", "/carlos/Ego/lidar/points"} <= topics
    assert manager["Views"]["Current"]["Target Frame"] == "Ego/base_link"
