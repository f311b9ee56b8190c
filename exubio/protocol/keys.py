"""The keys of a protocol file, one list per part (the format: the top of protocols/upper_limb_21.yaml)."""
from __future__ import annotations

SCHEMA_VERSION = 1
THORAX_SEGMENT = "thorax"  # the fixed segment: its markers only build the thorax frame

_TOP_KEYS = ("schema_version", "name", "description", "thorax_frame", "filter", "defaults", "markers", "hold",
             "relabel", "extends", "side", "other_arm", "analog_loads", "signs",
             "uncertainty_model")
_FRAME_KEYS = ("ij", "px", "c7", "t8")
_MIDPOINT_FRAME_KEYS = ("ij", "ij_c7_midpoint", "px_t8_midpoint")
_FILTER_KEYS = ("cutoff_hz", "order")
_DEFAULT_KEYS = ("stiffness_n_per_m", "damping_ns_per_m", "pf_inertia_scale")
_MARKER_KEYS = (
    "segment",
    "point",
    "local_position_mm",
    "aliases",
    "stiffness_n_per_m",
    "damping_ns_per_m",
    "optional",
    "landmark",
    "landmark_offset_mm",
    "cluster",
)
