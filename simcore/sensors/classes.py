"""Semantic classes of sensor labels (lidar `label` field, camera label image, ground truth).

Class ids are small integers (uint8) so that a label image is `mono8`; id 0 means "nothing" (no return).
Scenario entities take the class of their OpenSCENARIO category; the road surface takes `road` for drivable
lanes and `roadside`/`sidewalk` for the others. Each class has a reflectivity (0…1) for lidar intensity.
"""

from __future__ import annotations

#: class name → (id, reflectivity). Ids are part of the recorded data: append, never renumber.
CLASSES: dict[str, tuple[int, float]] = {
    "none": (0, 0.0),
    "road": (1, 0.12),  # asphalt
    "roadside": (2, 0.2),  # shoulders, borders, restricted lanes, medians
    "sidewalk": (3, 0.3),  # concrete
    "car": (10, 0.55),  # car paint
    "van": (11, 0.55),
    "truck": (12, 0.55),
    "trailer": (13, 0.5),
    "semitrailer": (14, 0.5),
    "bus": (15, 0.55),
    "motorbike": (16, 0.5),
    "bicycle": (17, 0.4),
    "train": (18, 0.5),
    "tram": (19, 0.5),
    "pedestrian": (30, 0.35),
    "wheelchair": (31, 0.35),
    "animal": (32, 0.3),
    "obstacle": (40, 0.3),
    "pole": (41, 0.4),
    "barrier": (42, 0.6),
    "object": (49, 0.3),  # any other miscObject category
    "building": (43, 0.35),
    "vegetation": (44, 0.25),
}
CLASS_IDS: dict[str, int] = {name: cid for name, (cid, _) in CLASSES.items()}
CLASS_NAMES: dict[int, str] = {cid: name for name, (cid, _) in CLASSES.items()}
REFLECTIVITY: dict[int, float] = {cid: refl for _, (cid, refl) in CLASSES.items()}

_SIDEWALK_LANES = frozenset({"sidewalk", "walking", "curb"})


def entity_class(object_type: str, category: str) -> str:
    """The class name of a scenario entity from its OpenSCENARIO object type and category."""
    if category in CLASSES and category not in ("none", "road", "roadside", "sidewalk"):
        return category
    if object_type == "pedestrian":
        return "pedestrian"
    if object_type == "vehicle":
        return "car"
    return "object"


def lane_class(lane_type: str, drivable: bool) -> str:
    """The class name of a lane's surface."""
    if drivable:
        return "road"
    if lane_type.lower() in _SIDEWALK_LANES:
        return "sidewalk"
    return "roadside"


#: OpenDRIVE `<object type>` → class name (static scenery); flat types (markings, surfaces) are left out.
SCENERY_CLASSES: dict[str, str] = {
    "pole": "pole",
    "streetlamp": "pole",
    "barrier": "barrier",
    "railing": "barrier",
    "soundbarrier": "barrier",
    "building": "building",
    "gantry": "building",
    "tree": "vegetation",
    "vegetation": "vegetation",
    "obstacle": "obstacle",
    "trafficisland": "roadside",
}
