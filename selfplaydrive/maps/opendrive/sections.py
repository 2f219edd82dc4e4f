"""Sample lane sections: reference line, lane offset and the lateral position of lane borders.

A lane's border positions are lateral offsets t [m] from the reference line (+t to the left of
the direction of increasing s). Left lanes (ids 1, 2, ...) stack outward to +t from the lane
offset, right lanes (-1, -2, ...) to -t; widths are cubic polynomials in the distance from the
lane section start (OpenDRIVE 1.4-1.8, section "Lanes").
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from selfplaydrive.errors import MapError
from selfplaydrive.maps.opendrive.geometry import ReferenceLine, eval_polys
from selfplaydrive.maps.opendrive.parse import Lane, LaneSection, Road

MAX_SAMPLES_PER_SECTION = 100_000  # guards memory against corrupt lengths
MAX_COORDINATE = 1.0e8  # [m] larger |x|, |y| or |t| means a corrupt number (Earth is 4e7 m round)


@dataclass
class SectionGeom:
    """One sampled lane section.

    Attributes:
        road: The parsed road.
        index: Section index in the road.
        section: The parsed section.
        s: (n,) road positions [m], n >= 2, section start and end included.
        x, y, hdg: (n,) reference-line position [m] and heading [rad] at `s`.
        borders: lane id -> (t_inner, t_outer), two (n,) arrays [m]. The centre lane is absent.
    """

    road: Road
    index: int
    section: LaneSection
    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    hdg: np.ndarray
    borders: dict[int, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    def points(self, t: np.ndarray | float) -> np.ndarray:
        """(n, 2) global points at lateral offsets `t` [m] (scalar or (n,))."""
        t = np.broadcast_to(np.asarray(t, dtype=np.float64), self.s.shape)
        return np.stack([self.x - t * np.sin(self.hdg), self.y + t * np.cos(self.hdg)], axis=1)

    def lane(self, lane_id: int) -> Lane:
        return self.section.lanes[lane_id]

    def width(self, lane_id: int) -> np.ndarray:
        """(n,) lane width [m] (>= 0)."""
        t_in, t_out = self.borders[lane_id]
        return np.abs(t_out - t_in)

    def upper_lower(self, lane_id: int) -> tuple[np.ndarray, np.ndarray]:
        """(t of the +t border, t of the -t border) of a lane [m]."""
        t_in, t_out = self.borders[lane_id]
        return (t_out, t_in) if lane_id > 0 else (t_in, t_out)

    def ordered_ids(self) -> list[int]:
        """Lane ids from the +t side to the -t side (left outermost first), centre excluded."""
        return sorted(self.borders, reverse=True)


def section_samples(road: Road, ref: ReferenceLine, s0: float, s1: float, step: float) -> np.ndarray:
    """Sample positions in [s0, s1] [m]: uniform with spacing <= step, plus geometry breakpoints."""
    n = int(min(MAX_SAMPLES_PER_SECTION, max(1, np.ceil((s1 - s0) / step - 1e-9))))
    s = np.linspace(s0, s1, n + 1)
    bp = ref.breakpoints()
    bp = bp[(bp > s0 + 1e-6) & (bp < s1 - 1e-6)]
    if len(bp):
        s = np.unique(np.concatenate([s, bp]))
    return s


def _side_borders(sec: LaneSection, ids: list[int], s: np.ndarray, offset: np.ndarray, sign: float) -> dict:
    """Stack the lanes of one side outward from the lane offset. sign = +1 left, -1 right."""
    out = {}
    t_inner = offset
    for lid in ids:
        lane = sec.lanes[lid]
        if lane.widths:
            w = np.maximum(eval_polys(lane.widths, s, origin=sec.s, below=s[-1] if len(s) > 1 else None), 0.0)
            t_outer = t_inner + sign * w
        elif lane.borders:
            # <border> gives the outer border's distance from the lane offset directly
            t_outer = offset + sign * np.abs(eval_polys(lane.borders, s, origin=sec.s))
        else:
            t_outer = t_inner.copy()
        out[lid] = (t_inner, t_outer)
        t_inner = t_outer
    return out


def sample_section(road: Road, ref: ReferenceLine, index: int, step: float) -> SectionGeom:
    """Evaluate the reference line and every lane border of section `index` of `road`."""
    sec = road.sections[index]
    s0 = min(max(sec.s, 0.0), road.length)
    s1 = min(max(sec.s_end, s0), road.length)
    s = section_samples(road, ref, s0, s1, step)
    x, y, hdg = ref.evaluate(s)
    offset = eval_polys(road.lane_offsets, s, below=s1 if s1 > s0 else None)
    geom = SectionGeom(road=road, index=index, section=sec, s=s, x=x, y=y, hdg=hdg)
    left = sorted(i for i in sec.lanes if i > 0)
    right = sorted((i for i in sec.lanes if i < 0), reverse=True)
    geom.borders.update(_side_borders(sec, left, s, offset, 1.0))
    geom.borders.update(_side_borders(sec, right, s, offset, -1.0))
    _check_finite(geom, ref)
    return geom


def _check_finite(geom: SectionGeom, ref: ReferenceLine) -> None:
    """Raise MapError naming the road/section/lane whose positions are not finite and sane."""
    where = f"road {geom.road.id}/section {geom.index}"
    for name, v in (("x", geom.x), ("y", geom.y)):
        if not np.all(np.abs(v) < MAX_COORDINATE):
            raise MapError(
                f"reference line {name} is not finite or exceeds {MAX_COORDINATE:g} m", ref.path, where
            )
    for lid, (t_in, t_out) in geom.borders.items():
        if not (np.all(np.abs(t_in) < MAX_COORDINATE) and np.all(np.abs(t_out) < MAX_COORDINATE)):
            raise MapError(
                f"lane border offset is not finite or exceeds {MAX_COORDINATE:g} m (check width/laneOffset)",
                ref.path,
                f"{where}/lane {lid}",
            )


def sample_road(road: Road, ref: ReferenceLine, step: float) -> list[SectionGeom]:
    """All lane sections of a road, sampled every `step` [m] at most."""
    return [sample_section(road, ref, i, step) for i in range(len(road.sections))]
