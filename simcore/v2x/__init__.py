"""Cooperative ITS: V2X messages (CAM, CPM, DENM), their generation rules, a radio channel model and the
map → WGS84 conversion the messages' reference positions need."""
