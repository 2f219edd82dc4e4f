"""NumPy references of the spawner kernels in `selfplaydrive/_sim/` (lanes, waypoints, placement,
pedestrians and samplers .pyx; paper section 2.2).

Each function states the same rule as its kernel with plain vectorised NumPy; the tests
(tests/maps/test_routing.py, tests/scenario/test_index_parts.py) check that kernel and reference
give identical results for the same inputs and random draws.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from selfplaydrive.maps.routing import MIN_CHANGE_LENGTH, RouteBatch, RouteTables, _empty_batch
from selfplaydrive.scenario.index import Chunks, Crossings, MapIndex
from selfplaydrive.scenario.pedestrians import PedestrianBatch, PedestrianSampler
from selfplaydrive.scenario.placement import Poses

if TYPE_CHECKING:
    from selfplaydrive.scenario.spawner import PaperSpawner


def lane_points_reference(t: RouteTables, lane: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """NumPy reference of `RouteTables.points` / kernel `lane_points`: (n, 2) xy [m], (n,) heading [rad]."""
    lane = np.asarray(lane, dtype=np.int64)
    length = t.length[lane]
    g = t.base[lane] + np.minimum(np.maximum(s, 0.0), length)
    # one binary search, then linear interpolation inside the found piece of the centreline
    seg = np.searchsorted(t.gcum, g, side="right") - 1
    seg = np.minimum(np.maximum(seg, t.offsets[lane]), t.offsets[lane + 1] - 2)
    g0, g1 = t.gcum[seg], t.gcum[seg + 1]
    f = (g - g0) / (g1 - g0)
    x = t.px[seg] + f * (t.px[seg + 1] - t.px[seg])
    y = t.py[seg] + f * (t.py[seg + 1] - t.py[seg])
    xy = np.stack([x, y], axis=1)
    return xy, t.heading[seg]


def hash_uniforms(key: int, agents: int, draws: int) -> np.ndarray:
    """(agents, draws) float64 counter-based uniforms in [0, 1): splitmix64 of
    key ^ (agent << 40) ^ draw. The NumPy twin of the kernels' `hash_uniform`, so route walks
    need no pre-drawn random array and stay reproducible from one key."""
    with np.errstate(over="ignore"):
        a = np.arange(agents, dtype=np.uint64)[:, None] << np.uint64(40)
        z = np.uint64(key) ^ a ^ np.arange(draws, dtype=np.uint64)[None, :]
        z = z + np.uint64(0x9E3779B97F4A7C15)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


def sample_routes_reference(
    tables: RouteTables,
    start_lane: np.ndarray,
    start_s: np.ndarray,
    horizon_s: np.ndarray,
    key: int,
    lane_change_prob: float = 0.1,
    max_pieces: int = 128,
) -> RouteBatch:
    """NumPy reference of the route-walk kernel for the same random `key`; the tests check that
    both give identical routes. Vectorised over the agents still walking."""
    a, n = len(start_lane), max_pieces
    u = hash_uniforms(key, a, 3 * n).reshape(a, n, 3)
    out = _empty_batch(a, n)
    idx = np.arange(a)
    cur = np.asarray(start_lane, dtype=np.int64).copy()
    s_in = np.clip(np.asarray(start_s, dtype=np.float64), 0.0, tables.length[cur])
    t_acc = np.zeros(a)
    horizon = np.asarray(horizon_s, dtype=np.float64)
    prev = np.zeros(a, dtype=bool)
    changes = lane_change_prob > 0 and tables.has_changes
    for step in range(n):
        if len(idx) == 0:
            break
        uu = u[idx, step]
        length = tables.length[cur]
        target = _change_target(tables, cur, uu[:, 1]) if changes else np.full(len(idx), -1)
        lc = (uu[:, 0] < lane_change_prob) & (target >= 0) & ~prev & (length - s_in >= MIN_CHANGE_LENGTH)
        lc &= changes
        end = np.where(lc, 0.5 * (length + s_in), length)
        out.lanes[idx, step], out.s_start[idx, step], out.s_end[idx, step] = cur, s_in, end
        out.change[idx, step] = lc
        t_acc = t_acc + (end - s_in) / tables.speed[cur]
        out.t_end[idx, step] = t_acc
        nxt = np.where(lc, target, _pick(uu[:, 2], tables.succ_offsets, tables.succ_index, cur))
        s_next = np.where(lc, end * tables.length[np.maximum(nxt, 0)] / length, 0.0)
        out.dead_end[idx[nxt < 0]] = True
        go = (nxt >= 0) & (t_acc < horizon)
        out.t_end[idx[~go], step + 1 :] = t_acc[~go, None]
        idx, cur, s_in, t_acc, horizon, prev = idx[go], nxt[go], s_next[go], t_acc[go], horizon[go], lc[go]
    return out


def _pick(rng_u: np.ndarray, offsets: np.ndarray, index: np.ndarray, lane: np.ndarray) -> np.ndarray:
    """Uniform choice among the successors of `lane`; -1 where there is none (dead end)."""
    deg = offsets[lane + 1] - offsets[lane]
    k = np.minimum((rng_u * deg).astype(np.int64), np.maximum(deg - 1, 0))
    out = np.full(len(lane), -1, dtype=np.int64)
    has = deg > 0
    out[has] = index[offsets[lane[has]] + k[has]]
    return out


def _change_target(t: RouteTables, lane: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Legal lane-change target (left or right, chosen by u when both exist) or -1."""
    left, right = t.change_left[lane], t.change_right[lane]
    both = (left >= 0) & (right >= 0)
    return np.where(both, np.where(u < 0.5, left, right), np.maximum(left, right))


def batch_waypoints_reference(
    tables: RouteTables, routes: RouteBatch, times: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """NumPy reference of `batch_waypoints` (identical results; used by the tests)."""
    a, k = times.shape
    total = routes.t_end[:, -1]
    count = np.maximum((times <= total[:, None]).sum(axis=1), 1)
    t = np.minimum(times, total[:, None])  # clamp: the fallback waypoint sits at the route end
    idx = np.minimum((routes.t_end[:, None, :] < t[:, :, None]).sum(axis=2), routes.t_end.shape[1] - 1)
    rows = np.arange(a)[:, None]
    lane = routes.lanes[rows, idx]
    t_before = np.where(idx > 0, routes.t_end[rows, np.maximum(idx - 1, 0)], 0.0)
    lane_safe = np.maximum(lane, 0)
    s = routes.s_start[rows, idx] + (t - t_before) * tables.speed[lane_safe]
    s = np.minimum(s, routes.s_end[rows, idx])
    xy, _ = lane_points_reference(tables, lane_safe.ravel(), s.ravel())
    xy = xy.reshape(a, k, 2)
    pad = np.arange(k)[None, :] >= count[:, None]
    last = xy[np.arange(a), count - 1]
    xy = np.where(pad[:, :, None], last[:, None, :], xy)
    return xy.astype(np.float32), count.astype(np.int32)


def sample_on_chunks_reference(
    index: MapIndex, chunks: Chunks, box: np.ndarray, rng: np.random.Generator, n: int
) -> Poses:
    """NumPy reference of `sample_on_chunks` (same draws, same poses; used by the tests)."""
    u = rng.random((max(n, 0), 2)).T
    ids = chunks.cells.query_box(box)
    if len(ids) == 0 or n <= 0:
        z = np.zeros(0, dtype=np.int64)
        return Poses(z, np.zeros(0), np.zeros((0, 2)), np.zeros(0), z)
    length = chunks.s1[ids] - chunks.s0[ids]
    cdf = np.cumsum(length)
    pick = ids[np.minimum(np.searchsorted(cdf, u[0] * cdf[-1], side="right"), len(ids) - 1)]
    s = chunks.s0[pick] + u[1] * (chunks.s1[pick] - chunks.s0[pick])
    lane = chunks.lane[pick]
    xy, heading = lane_points_reference(index.routes, lane, s)
    inside = (xy[:, 0] >= box[0]) & (xy[:, 0] <= box[2]) & (xy[:, 1] >= box[1]) & (xy[:, 1] <= box[3])
    return Poses(lane, s, xy, heading, pick).take(np.flatnonzero(inside))


def _sq_dist(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    dx = p[:, None, 0] - q[None, :, 0]
    dy = p[:, None, 1] - q[None, :, 1]
    return dx * dx + dy * dy


def greedy_separated_reference(
    xy: np.ndarray,
    radius: np.ndarray,
    need: int,
    fixed_xy: np.ndarray | None = None,
    fixed_radius: np.ndarray | None = None,
    gap: float = 0.0,
    batch: int = 128,
) -> np.ndarray:
    """Greedy selection of candidates that keep apart from each other and from fixed objects.

    Candidates i and j are compatible when |xy_i - xy_j| >= radius_i + radius_j + gap; a
    candidate and fixed object k likewise with fixed_radius_k. With radius = min_distance / 2
    and gap = 0 this is the paper's "at least 15 m between any two vehicles". Candidates are
    tried in order, `batch` at a time (one pairwise matrix per batch), so the work is bounded
    by the number of candidates.

    Args:
        xy: (n, 2) candidate centres [m] in the order they are tried.
        radius: (n,) candidate radii [m].
        need: Stop after this many accepted.
        fixed_xy: (k, 2) centres of already placed objects [m].
        fixed_radius: (k,) their radii [m].
        gap: Extra clearance [m].
        batch: Candidates per pairwise matrix.

    Returns:
        (m,) int64 accepted candidate indices, m <= need, in acceptance order.
    """
    acc_xy = np.zeros((0, 2)) if fixed_xy is None else np.asarray(fixed_xy, dtype=np.float64).reshape(-1, 2)
    acc_r = np.zeros(0) if fixed_radius is None else np.asarray(fixed_radius, dtype=np.float64)
    accepted: list[int] = []
    for start in range(0, len(xy), batch):
        if len(accepted) >= need:
            break
        p, r = xy[start : start + batch], radius[start : start + batch]
        blocked = np.zeros(len(p), dtype=bool)
        if len(acc_xy):
            blocked |= np.any(_sq_dist(p, acc_xy) < (r[:, None] + acc_r[None, :] + gap) ** 2, axis=1)
        conflict = _sq_dist(p, p) < (r[:, None] + r[None, :] + gap) ** 2
        new: list[int] = []
        for i in np.flatnonzero(~blocked).tolist():
            if blocked[i]:
                continue
            new.append(i)
            if len(accepted) + len(new) >= need:
                break
            blocked |= conflict[i]
        accepted.extend(start + i for i in new)
        acc_xy = np.concatenate([acc_xy, p[new]])
        acc_r = np.concatenate([acc_r, r[new]])
    return np.asarray(accepted, dtype=np.int64)


def pedestrian_paths_reference(
    crosswalks: Crossings,
    crossings: Crossings,
    box: np.ndarray,
    u: np.ndarray,
    share: float,
    margin: float,
    max_approach: float,
    vehicle_xy: np.ndarray,
    clear_r: np.ndarray,
    still: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """NumPy reference of the pedestrian kernel `_sim.pedestrians.pedestrian_paths` (with the site
    query `pedestrian_sites`): for draws u (n, 9), the (n, 3, 2) paths (approach point,
    crossing start, crossing end) and (n,) ok: the first point keeps clear_r from every
    vehicle centre (squared distances compared) and no leg passes within clear_r of a vehicle
    with `still` set."""
    cw, other = crosswalks.cells.query_box(box), crossings.cells.query_box(box)
    n_cw, n_other = len(cw), len(other)
    use_cw = (u[:, 0] < share) if n_cw else np.zeros(len(u), dtype=bool)
    site = np.where(use_cw, u[:, 1] * n_cw, n_cw + u[:, 1] * n_other).astype(np.int64)
    pick = np.minimum(site, np.where(use_cw, n_cw, n_cw + n_other) - 1)  # u * n may round up to n
    start = np.concatenate([crosswalks.start[cw], crossings.start[other]])[pick]
    end = np.concatenate([crosswalks.end[cw], crossings.end[other]])[pick]
    half = np.concatenate([crosswalks.half_width[cw], crossings.half_width[other]])[pick]
    # sideways shift inside a crosswalk, walking direction, kerb side and length of the approach
    d = end - start
    d = d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)[:, None]
    side = np.stack([-d[:, 1], d[:, 0]], axis=1)
    shift = (half * (2.0 * u[:, 2] - 1.0))[:, None] * side
    flip = (u[:, 3] < 0.5)[:, None]
    a = np.where(flip, end, start) + shift
    b = np.where(flip, start, end) + shift
    d = np.where(flip, -d, d)
    a = a - d * margin
    b = b + d * margin
    sign = np.where(u[:, 4] < 0.5, -1.0, 1.0)
    approach = a + side * (sign * max_approach * u[:, 5])[:, None]
    path = np.stack([approach, a, b], axis=1)
    ok = np.ones(len(u), dtype=bool)
    if len(vehicle_xy):
        p = path[:, 0]
        dx = p[:, None, 0] - vehicle_xy[None, :, 0]
        dy = p[:, None, 1] - vehicle_xy[None, :, 1]
        ok &= np.all(dx * dx + dy * dy >= (clear_r * clear_r)[None, :], axis=1)
    if np.any(still):
        xy, r = vehicle_xy[still], clear_r[still]
        a = path[:, :-1, None, :]  # (n, T-1, 1, 2)
        d = path[:, 1:, None, :] - a
        w = xy[None, None, :, :] - a  # (n, T-1, V, 2)
        t = np.clip(np.sum(w * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-12), 0.0, 1.0)
        gap = w - t[..., None] * d
        ok &= np.all(np.sum(gap * gap, axis=-1) >= (r**2)[None, None, :], axis=(1, 2))
    return path, ok


def vehicle_sizes_reference(
    u: np.ndarray, cdf: np.ndarray, length: np.ndarray, width: np.ndarray, jitter: float, max_width: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """NumPy reference of `_sim.samplers.vehicle_sizes` (`VehicleSizeSampler.sample` after its
    (3, n) draw): category, then jittered length and capped width."""
    cat = np.minimum(np.searchsorted(cdf, u[0], side="right"), len(cdf) - 1)
    j = jitter
    return (
        length[cat] * (1.0 - j + 2.0 * j * u[1]),
        np.minimum(width[cat] * (1.0 - j + 2.0 * j * u[2]), max_width),
        cat,
    )


def aligned_candidates_reference(
    lane: np.ndarray,
    s: np.ndarray,
    xy: np.ndarray,
    heading: np.ndarray,
    length: np.ndarray,
    width: np.ndarray,
    u: np.ndarray,
    lane_width: np.ndarray,
    speed_limit: np.ndarray,
    lateral_noise: float,
    heading_noise: float,
    speed: tuple[float, float],
) -> np.ndarray:
    """NumPy reference of `_sim.placement.aligned_candidates`: (n, 10) agent rows (lane, s, x, y,
    heading, speed, length, width, parked, on lane) of aligned candidates."""
    from selfplaydrive.scenario.placement import offset_right, wrap_angle

    lane_w = lane_width[lane].astype(np.float64)
    lateral = np.minimum(lateral_noise, np.maximum(lane_w - width, 0.0) / 2) * (2 * u[0] - 1)
    lo, hi = speed
    return np.column_stack(
        [
            lane,
            s,
            offset_right(xy, heading, lateral),
            wrap_angle(heading + heading_noise * (2 * u[1] - 1)),
            np.minimum(lo + (hi - lo) * u[2], speed_limit[lane]),
            length,
            width,
            np.zeros(len(lane)),
            np.ones(len(lane)),
        ]
    ).astype(np.float64)


def roadside_poses_reference(
    lane: np.ndarray,
    chunk: np.ndarray,
    xy: np.ndarray,
    heading: np.ndarray,
    width: np.ndarray,
    lane_width: np.ndarray,
    edge: np.ndarray,
    curb_gap: float,
    max_shoulder: float,
    min_free: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """NumPy reference of `_sim.placement.roadside_poses`: centres, offsets and the free-lane test
    of vehicles parked at the roadside (`roadside_offset` then `offset_right`)."""
    from selfplaydrive.scenario.placement import offset_right, roadside_offset

    lane_w = lane_width[lane].astype(np.float64)
    off = roadside_offset(lane_w, edge[chunk], width, curb_gap, max_shoulder)
    fits = off - width / 2 + lane_w / 2 >= min_free
    return offset_right(xy, heading, off), off, fits


def bimodal_uniform_reference(
    u: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    c: int,
    c_range: tuple[float, float],
    p_c: float,
    a: int,
    a_range: tuple[float, float],
    p_a: float,
) -> np.ndarray:
    """NumPy reference of `_sim.samplers.bimodal_uniform` (`ConditioningSampler.sample` after
    its draw): per-agent ranges, columns c and a switched to their low mode by the last two
    columns of u, then lo + (hi - lo) u as float32."""
    k = len(lo)
    lo = np.broadcast_to(lo, (len(u), k)).copy()
    hi = np.broadcast_to(hi, lo.shape).copy()
    low_c, low_a = u[:, k] < p_c, u[:, k + 1] < p_a
    lo[low_c, c], hi[low_c, c] = c_range
    lo[low_a, a], hi[low_a, a] = a_range
    return (lo + (hi - lo) * u[:, :k]).astype(np.float32)


def pedestrian_batch_reference(
    sampler: PedestrianSampler,
    rng: np.random.Generator,
    crossings: Crossings,
    crosswalks: Crossings,
    box: np.ndarray,
    slots: int,
    vehicle_xy: np.ndarray,
    vehicle_radius: np.ndarray,
    stationary: np.ndarray,
) -> PedestrianBatch:
    """NumPy reference of `PedestrianSampler.sample` (kernel `_sim.pedestrians.pedestrian_batch`):
    the count draw, the sites, one (want, 9) draw when there are any, paths and clearance
    tests (`pedestrian_paths_reference`), the kept pedestrians in order."""
    from selfplaydrive.scenario.pedestrians import PATH_POINTS

    out = PedestrianBatch(
        valid=np.zeros(slots, dtype=bool),
        path=np.zeros((slots, PATH_POINTS, 2), dtype=np.float32),
        num_points=np.zeros(slots, dtype=np.int32),
        speed=np.zeros(slots, dtype=np.float32),
        start_time=np.zeros(slots, dtype=np.float32),
        size=np.zeros((slots, 2), dtype=np.float32),
    )
    want = min(int(rng.integers(sampler.count[0], sampler.count[1] + 1)), slots)
    n_cw, n_other = len(crosswalks.cells.query_box(box)), len(crossings.cells.query_box(box))
    if want == 0 or n_cw + n_other == 0:
        return out
    u = rng.random((want, 9))
    share = sampler.crosswalk_share if n_other else 1.0
    path, ok = pedestrian_paths_reference(
        crosswalks, crossings, box, u, share, sampler.sidewalk_margin, sampler.max_approach,
        vehicle_xy, vehicle_radius + sampler.vehicle_clearance, stationary,
    )  # fmt: skip
    n = int(ok.sum())
    u = u[ok]
    out.valid[:n] = True
    out.path[:n] = path[ok]
    out.num_points[:n] = PATH_POINTS
    out.speed[:n] = sampler.speed[0] + (sampler.speed[1] - sampler.speed[0]) * u[:, 6]
    out.start_time[:n] = sampler.start_time[0] + (sampler.start_time[1] - sampler.start_time[0]) * u[:, 7]
    out.size[:n] = (sampler.size[0] + (sampler.size[1] - sampler.size[0]) * u[:, 8])[:, None]
    return out


def waypoint_draws_reference(
    rng: np.random.Generator, a: int, k: int, spacing: float, jitter: float
) -> tuple[np.ndarray, int]:
    """The draws of `_sim.waypoints.RouteKernel.draw_waypoints` made with NumPy's own calls:
    (`maps.routing.waypoint_times(rng, a, k, spacing, jitter)`, `rng.integers(0, 2**63)`)."""
    from selfplaydrive.maps.routing import waypoint_times

    times = waypoint_times(rng, a, k, spacing, jitter)
    return times, int(rng.integers(0, 2**63))


# -- agent and static-vehicle placement (kernel `_sim.placement.Placer`) -------------------------------


def _gathered(chunks: Chunks, box: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The chunks whose midpoint lies in `box` (cell order) and their cumulative lengths."""
    ids = chunks.cells.query_box(box)
    return ids, np.cumsum(chunks.s1[ids] - chunks.s0[ids])


def _pose(index: MapIndex, chunks: Chunks, ids: np.ndarray, cdf: np.ndarray, box: np.ndarray, u: np.ndarray):
    """(inside box, lane, s, xy (1, 2), heading (1,), chunk) of the pose of draws u[0:2]: the
    chunk is picked with probability proportional to its length, the arc length inside it."""
    pick = ids[min(int(np.searchsorted(cdf, u[0] * cdf[-1], side="right")), len(ids) - 1)]
    s = chunks.s0[pick] + u[1] * (chunks.s1[pick] - chunks.s0[pick])
    lane = int(chunks.lane[pick])
    xy, heading = lane_points_reference(index.routes, np.array([lane]), np.array([s]))
    inside = bool(box[0] <= xy[0, 0] <= box[2] and box[1] <= xy[0, 1] <= box[3])
    return inside, lane, s, xy, heading, pick


def _size(sampler, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(1,) length and width of one vehicle from the draws u[0:3]."""
    length, width, _ = vehicle_sizes_reference(
        u[:3, None], sampler._cdf, sampler.length, sampler.width, sampler.jitter, sampler.max_width
    )
    return length, width


def _far(xy: np.ndarray, radius: np.ndarray, p: np.ndarray, r: float, gap: float) -> bool:
    """Whether point p (2,) of radius r keeps radius + r + gap from every row of xy (k, 2)."""
    if len(xy) == 0:
        return True
    dx = p[0] - xy[:, 0]
    dy = p[1] - xy[:, 1]
    lim = r + radius + gap
    return bool(np.all(~(dx * dx + dy * dy < lim * lim)))


def place_agents_reference(
    spawner: PaperSpawner, index: MapIndex, box: np.ndarray, rng: np.random.Generator, n_parked: int
) -> tuple[np.ndarray, int]:
    """NumPy reference of `_sim.placement.Placer.agents` with `spawner`'s settings: the same draws
    from `rng` in the same order, one candidate at a time.

    Returns:
        (n, 10) float64 agent rows (`scenario.spawner.AGENT_COLUMNS`) in slot order, and how
        many of them are parked.
    """
    from selfplaydrive.scenario.spawner import AGENT_COLUMNS

    lanes = index.road_map.lanes
    want, per = spawner.num_agents, spawner.candidates_per_agent
    half = np.full(want, spawner.min_agent_distance / 2)
    rows = np.zeros((0, len(AGENT_COLUMNS)))
    ids, cdf = _gathered(index.roadside, box)
    for _ in range(n_parked * per if len(ids) and n_parked > 0 else 0):
        u = rng.random(5)
        inside, lane, s, xy, heading, chunk = _pose(index, index.roadside, ids, cdf, box, u)
        if not inside:
            continue
        length, width = _size(spawner.sizes, u[2:])
        pos, off, _ = roadside_poses_reference(
            np.array([lane]), np.array([chunk]), xy, heading, width, lanes.width, index.roadside.edge,
            spawner.curb_gap, spawner.max_shoulder, 0.0,
        )  # fmt: skip
        if not _far(rows[:, 2:4], half[: len(rows)], pos[0], half[0], 0.0):
            continue
        on_lane = off[0] <= lanes.width[lane].astype(np.float64) / 2
        row = [lane, s, pos[0, 0], pos[0, 1], heading[0], 0.0, length[0], width[0], 1.0, float(on_lane)]
        rows = np.vstack([rows, row])
        if len(rows) >= n_parked:
            break
    parked = len(rows)
    need = want - parked
    ids, cdf = _gathered(index.spawn, box)
    first = min(spawner.first_round_candidates, per)
    block = rng.random((need * first, 8)) if len(ids) and need > 0 else np.zeros((0, 8))
    for j in range(need * per if len(ids) and need > 0 else 0):
        u = block[j] if j < len(block) else rng.random(8)
        inside, lane, s, xy, heading, chunk = _pose(index, index.spawn, ids, cdf, box, u)
        if not inside:
            continue
        length, width = _size(spawner.sizes, u[2:])
        row = aligned_candidates_reference(
            np.array([lane]), np.array([s]), xy, heading, length, width, u[5:8, None], lanes.width,
            lanes.speed_limit, spawner.lateral_noise, spawner.heading_noise, spawner.initial_speed,
        )  # fmt: skip
        if not _far(rows[:, 2:4], half[: len(rows)], row[0, 2:4], half[0], 0.0):
            continue
        rows = np.vstack([rows, row])
        if len(rows) >= want:
            break
    order = np.arange(len(rows))
    for i in range(len(rows) - 1, 0, -1):  # Fisher-Yates, one draw per slot from the last down
        j = min(int(rng.random() * (i + 1)), i)
        order[i], order[j] = order[j], order[i]
    return rows[order], parked


def boxes_overlap_reference(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two rectangles overlap, by projecting their corners on the four edge normals.
    a, b: (centre x, centre y, heading [rad], half length, half width)."""

    def corners(r: np.ndarray) -> np.ndarray:
        c, s = np.cos(r[2]), np.sin(r[2])
        f, left = np.array([c, s]), np.array([-s, c])
        signs = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], dtype=np.float64)
        return r[:2] + signs[:, :1] * r[3] * f + signs[:, 1:] * r[4] * left

    ca, cb = corners(a), corners(b)
    for r in (a, b):
        c, s = np.cos(r[2]), np.sin(r[2])
        for axis in (np.array([c, s]), np.array([-s, c])):
            pa, pb = ca @ axis, cb @ axis
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


def place_statics_reference(
    spawner: PaperSpawner,
    index: MapIndex,
    box: np.ndarray,
    rng: np.random.Generator,
    want: int,
    agents: dict[str, np.ndarray],
    clear_ahead: float,
    headway: float,
) -> np.ndarray:
    """NumPy reference of `_sim.placement.Placer.statics` with `spawner`'s settings.

    Args:
        agents: The placed agents as stored in the scenario: "xy" (n, 2), "heading", "speed",
            "length", "width" (n,) (float32 arrays).
        clear_ahead, headway: The keep-clear zone ahead of each agent: its box grown by
            `static_gap` and stretched forward by clear_ahead + speed * headway [m].

    Returns:
        (m, 5) float64 rows x, y, heading, length, width of the static vehicles in slot order.
    """
    lanes = index.road_map.lanes
    gap = spawner.static_gap
    a_xy = agents["xy"].astype(np.float64).reshape(-1, 2)
    a_len, a_w = agents["length"].astype(np.float64), agents["width"].astype(np.float64)
    a_h, a_v = agents["heading"].astype(np.float64), agents["speed"].astype(np.float64)
    a_r = 0.5 * np.hypot(a_len, a_w)
    ahead = clear_ahead + a_v * headway
    zone = np.column_stack(
        [
            a_xy[:, 0] + 0.5 * ahead * np.cos(a_h),
            a_xy[:, 1] + 0.5 * ahead * np.sin(a_h),
            a_h,
            0.5 * a_len + gap + 0.5 * ahead,
            0.5 * a_w + gap,
        ]
    )
    out = np.zeros((0, 5))
    radius = np.zeros(0)
    ids, cdf = _gathered(index.roadside, box)
    for _ in range(want * spawner.static_candidates_per_vehicle if len(ids) and want > 0 else 0):
        u = rng.random(5)
        inside, lane, _, xy, heading, chunk = _pose(index, index.roadside, ids, cdf, box, u)
        if not inside:
            continue
        length, width = _size(spawner.static_sizes, u[2:])
        pos, _, fits = roadside_poses_reference(
            np.array([lane]), np.array([chunk]), xy, heading, width, lanes.width, index.roadside.edge,
            spawner.curb_gap, spawner.max_shoulder, spawner.min_free_lane_width,
        )  # fmt: skip
        if not fits[0]:
            continue
        r = 0.5 * np.hypot(length[0], width[0])
        if not _far(a_xy, a_r, pos[0], r, gap) or not _far(out[:, :2], radius, pos[0], r, gap):
            continue
        box_s = np.array([pos[0, 0], pos[0, 1], heading[0], 0.5 * length[0], 0.5 * width[0]])
        if any(boxes_overlap_reference(z, box_s) for z in zone):
            continue
        out = np.vstack([out, [pos[0, 0], pos[0, 1], heading[0], length[0], width[0]]])
        radius = np.append(radius, r)
        if len(out) >= want:
            break
    return out
