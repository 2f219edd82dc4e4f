"""`RulesEncoder` (`obs=rules`): the paper's observation with the traffic-rule features the
rule reward terms depend on (issue #15 item 1; docs/observation.md "Traffic-rule features").

Same layout and values as `PaperEncoder` (section 2.5), so models and checkpoints work
unchanged, except in two road-row features:

- "type" of a stop line behind a STOP sign: `rule_features.STOP_LINE_TYPE` (0.625); YIELD lines
  keep the paper's 0.5 (section 2.1 treats every line as a yield line);
- "light_state" of a crosswalk segment whose crosswalk is occupied (a pedestrian on it or
  about to enter it, `rule_features.pedestrians_on_crosswalk`): `rule_features.CROSSWALK_OCCUPIED`
  (1); 0 otherwise, as in the paper.

Which segments are STOP lines and crosswalk outlines depends on the env's maps: the env binds
the encoder to them when it is constructed (`bind(maps, atlas)`, obs/encoders.py
`bind_encoder`); an unbound one writes the paper's rows.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence

import numpy as np

from selfplaydrive.maps.roadmap import RoadMap
from selfplaydrive.obs import rule_features as rf
from selfplaydrive.obs.config import ObsConfig
from selfplaydrive.obs.encoders import KernelEncoder, _pack_args
from selfplaydrive.obs.layout import ObsLayout

# record of RulesHead in _sim/obs_rules.pyx (same order, 136 bytes, no padding); the offsets are
# bytes from the start of the packed args, where each array follows (8-byte aligned)
RULES_HEAD_DTYPE = np.dtype(
    [
        ("num_positions", np.int32),
        ("num_maps", np.int32),
        ("num_crosswalks", np.int32),
        ("num_points", np.int32),
        ("margin", np.float32),
        ("horizon", np.float32),
        ("stop_type", np.float32),
        ("occupied", np.float32),
        ("seg_code", np.int64),
        ("map_cw", np.int64),
        ("map_stop", np.int64),
        ("cw_pts", np.int64),
        ("pts", np.int64),
        ("cw_box", np.int64),
        ("grid_origin", np.int64),
        ("grid_dims", np.int64),
        ("cell_start", np.int64),
        ("cell_items", np.int64),
        ("stop_grid", np.int64),
        ("stop_dims", np.int64),
        ("stop_sat", np.int64),
    ],
    align=True,
)
ARRAYS = (
    "seg_code",
    "map_cw",
    "map_stop",
    "cw_pts",
    "pts",
    "cw_box",
    "grid_origin",
    "grid_dims",
    "cell_start",
    "cell_items",
    "stop_grid",
    "stop_dims",
    "stop_sat",
)


class RulesEncoder(KernelEncoder):
    """The paper encoder plus STOP/YIELD line types and crosswalk occupancy on the road rows.

    Args:
        max_objects: Nearest other bodies observed (63 in the paper).
        max_road: Nearest road segments observed (200).
        radius: Observation radius [m] (100), also the position scale.

    Raises:
        ConfigError: Sizes below 1 or a radius that is not positive (as `ObsConfig`).
    """

    def __init__(self, max_objects: int = 63, max_road: int = 200, radius: float = 100.0) -> None:
        cfg = ObsConfig(max_objects, max_road, radius)
        from selfplaydrive._sim import obs_rules as rules

        if rules.head_size() != RULES_HEAD_DTYPE.itemsize:  # pragma: no cover - build mismatch
            raise RuntimeError("RulesHead of _sim/obs_rules.pyx and RULES_HEAD_DTYPE differ: rebuild")
        super().__init__(
            "rules",
            int(rules.encoder_address()),
            ObsLayout(cfg.max_objects, cfg.max_road),
            float(cfg.radius),
            form="builtin",
            doc="paper encoder with STOP/YIELD line types and crosswalk occupancy (issue #15)",
            owner=rules,
        )

    @property
    def bound(self) -> bool:
        """Whether the encoder holds the map data of an env (`bind`)."""
        return self.args is not None

    def bind(self, maps: Sequence[RoadMap], atlas: Mapping[str, np.ndarray]) -> RulesEncoder:
        """A copy holding the rule data of `maps` in atlas order (the env calls it once, when it
        is constructed, with its maps and `build_atlas(maps)`).

        Raises:
            ValueError: The atlas was not built from these maps.
        """
        data = rf.rule_map_data(maps, atlas)
        out = copy.copy(self)
        object.__setattr__(out, "args", _pack_args(self.name, pack(data)))
        # the world's scratch holds one flag per crosswalk of its map
        object.__setattr__(out, "scratch", int(np.diff(data.map_cw).max(initial=0)))
        return out


def pack(data: rf.RuleMapData) -> np.ndarray:
    """The bytes `encode_rules` reads: a `RULES_HEAD_DTYPE` record, then the arrays of `data`
    (each at an 8-byte aligned offset the record gives)."""
    head = np.zeros(1, dtype=RULES_HEAD_DTYPE)
    head["num_positions"] = len(data.seg_code)
    head["num_maps"] = len(data.map_stop)
    head["num_crosswalks"] = len(data.cw_box)
    head["num_points"] = len(data.pts)
    head["margin"] = rf.CROSSWALK_MARGIN
    head["horizon"] = rf.CROSSWALK_HORIZON
    head["stop_type"] = rf.STOP_LINE_TYPE
    head["occupied"] = rf.CROSSWALK_OCCUPIED
    parts = []
    offset = RULES_HEAD_DTYPE.itemsize
    for name in ARRAYS:
        raw = np.ascontiguousarray(getattr(data, name)).view(np.uint8).ravel()
        head[name] = offset
        pad = -len(raw) % 8
        parts += [raw, np.zeros(pad, dtype=np.uint8)]
        offset += len(raw) + pad
    return np.concatenate([head.view(np.uint8), *parts])
