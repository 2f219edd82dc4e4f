"""Partial observability as an encoder (issue #15 item 5): the kernel of _sim/partial.pyx against
its NumPy reference on random scenes, hand-built scenes (a car behind a bus is hidden, one beside
it is not), noise statistics, misses and false positives, and the env-level encoder (off: the
paper's rows bit for bit; on: the reference applied to the paper's rows, same at 1 and 2
threads)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from selfplaydrive._sim import partial
from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.procedural import ProceduralTownLoader
from selfplaydrive.obs import PaperEncoder, PartialObsEncoder
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim import VecEnv
from selfplaydrive.testing import partial_reference as ref
from selfplaydrive.testing.check_encoder import check_encoder

POS, LEN, WID, SPEED = 100.0, 20.0, 5.0, 40.0  # the default scales (radius, length, width, max_speed)
SCALES = {"pos": POS, "length": LEN, "width": WID, "speed": SPEED}
MAX_OBJ = 16


def row(x, y, heading=0.0, length=4.5, width=1.8, speed=0.0):
    """One object row in the ego frame (scaled as the paper encoder writes it)."""
    c, s = math.cos(heading), math.sin(heading)
    return [1.0, x / POS, y / POS, c, s, length / LEN, width / WID, speed * c / SPEED, speed * s / SPEED]


def block(rows):
    out = np.zeros((MAX_OBJ, 9), dtype=np.float32)
    if len(rows):
        out[: len(rows)] = rows
    return out


def kernel(rows, enc, key=12345, step=3, slot=1):
    """The kernel's post-processing of one agent's rows: (new rows, count)."""
    b = block(rows)
    n = partial.postprocess_rows(b, len(rows), enc.args, key, step, slot, POS, LEN, WID, SPEED, POS)
    return b, n


def reference(rows, enc, key=12345, step=3, slot=1):
    return ref.postprocess(block(rows), len(rows), enc.params, key, step, slot, SCALES)


@pytest.fixture(scope="module")
def town():
    return ProceduralTownLoader(seed=0, size=400.0, num_roundabouts=0).load()


def small_spawner():
    return PaperSpawner(num_agents=12, num_static=12, num_pedestrians=4, min_region_lane_length=300,
                        episode_lengths=(4.0,))  # fmt: skip


# --- hand-built scenes -------------------------------------------------------------------------
BUS = row(15.0, 0.0, length=12.0, width=2.5)  # x 9..21 m, +-1.25 m: +-7.9 degrees


def test_a_car_directly_behind_a_bus_is_hidden():
    enc = PartialObsEncoder(occlusion=True)
    out, n = kernel([BUS, row(30.0, 0.0)], enc)
    assert n == 1 and out[0, 1] == np.float32(BUS[1])  # only the bus is left
    assert not out[1:].any()


def test_a_car_beside_the_bus_is_seen():
    enc = PartialObsEncoder(occlusion=True)
    car = row(30.0, 6.0)  # 9.0 to 14.0 degrees: clear of the bus's 7.9
    out, n = kernel([BUS, car], enc)
    assert n == 2
    np.testing.assert_array_equal(out[:2], np.array([BUS, car], dtype=np.float32))


def test_the_nearer_body_is_never_hidden_by_a_farther_one():
    """A car at 10 m in front of a bus at 30 m: the car stays, the bus (+-3 degrees) is behind
    the car (+-6.6 degrees) and goes."""
    car = row(10.0, 0.0)
    out, n = kernel([row(30.0, 0.0, length=12.0, width=2.5), car], PartialObsEncoder(occlusion=True))
    assert n == 1
    np.testing.assert_array_equal(out[0], np.array(car, dtype=np.float32))


def test_visible_fraction_by_hand():
    """Occluder spans 0..11.31 degrees, target -5.71..5.71: half of the target is visible."""
    occluder = row(10.0, 1.0, heading=math.pi / 2, length=2.0, width=1e-4)
    target = row(20.0, 0.0, heading=math.pi / 2, length=4.0, width=1e-4)
    frac = ref.visible_fractions(np.array([occluder, target]), SCALES)
    assert frac[0] == 1.0 and frac[1] == pytest.approx(0.5, abs=1e-3)
    assert kernel([occluder, target], PartialObsEncoder(occlusion=True, visible_fraction=0.45))[1] == 2
    assert kernel([occluder, target], PartialObsEncoder(occlusion=True, visible_fraction=0.55))[1] == 1


def test_a_box_around_the_ego_centre_neither_hides_nor_is_hidden():
    around = row(0.5, 0.0, length=6.0, width=3.0)
    _, n = kernel([around, row(20.0, 0.0)], PartialObsEncoder(occlusion=True))
    assert n == 2


def test_p_miss_one_hides_everything_and_p_miss_rate_matches():
    rows = [row(10.0 + 5 * k, 20.0 - 3 * k) for k in range(10)]
    assert kernel(rows, PartialObsEncoder(p_miss=1.0))[1] == 0
    enc = PartialObsEncoder(p_miss=0.3)
    kept = sum(kernel(rows, enc, step=t)[1] for t in range(400))
    assert kept / 4000 == pytest.approx(0.7, abs=0.03)


def test_noise_statistics_match_the_configured_std():
    enc = PartialObsEncoder(pos_std=1.0, heading_std=0.1, speed_std=0.5)
    car = row(30.0, 10.0, heading=0.3, speed=10.0)
    samples = np.array([kernel([car], enc, step=t)[0][0] for t in range(4000)], dtype=np.float64)
    dx = (samples[:, 1] - car[1]) * POS
    dy = (samples[:, 2] - car[2]) * POS
    dh = np.arctan2(samples[:, 4], samples[:, 3]) - 0.3
    ds = np.hypot(samples[:, 7], samples[:, 8]) * SPEED - 10.0
    for values, std in ((dx, 1.0), (dy, 1.0), (dh, 0.1), (ds, 0.5)):
        assert abs(values.mean()) < 4 * std / math.sqrt(len(values))
        assert values.std() == pytest.approx(std, rel=0.05)
    assert abs(np.corrcoef(dx, dy)[0, 1]) < 0.05


def test_false_positives_come_at_the_configured_rate_within_the_radius():
    enc = PartialObsEncoder(fp_rate=2.0)
    counts, radii = [], []
    for t in range(2000):
        out, n = kernel([], enc, step=t)
        counts.append(n)
        radii += list(np.hypot(out[:n, 1], out[:n, 2]) * POS)
        assert (out[:n, 0] == 1.0).all() and not out[n:].any()
    assert np.mean(counts) == pytest.approx(2.0, abs=0.1)
    assert np.var(counts) == pytest.approx(2.0, rel=0.15)  # Poisson
    assert max(radii) <= POS
    # uniform in the disc: half of them within R / sqrt(2)
    assert np.mean(np.array(radii) < POS / math.sqrt(2)) == pytest.approx(0.5, abs=0.04)


# --- kernel against the NumPy reference --------------------------------------------------------
@pytest.mark.parametrize("seed", range(6))
def test_kernel_matches_reference_on_random_scenes(seed):
    rng = np.random.default_rng(seed)
    enc = PartialObsEncoder(
        occlusion=True,
        visible_fraction=float(rng.uniform(0.05, 0.6)),
        pos_std=float(rng.uniform(0, 2)),
        heading_std=float(rng.uniform(0, 0.3)),
        speed_std=float(rng.uniform(0, 1)),
        p_miss=float(rng.uniform(0, 0.3)),
        fp_rate=float(rng.uniform(0, 1.5)),
        seed=int(rng.integers(0, 2**63)),
    )
    for trial in range(20):
        n = int(rng.integers(0, MAX_OBJ + 1))
        rows = [
            row(rng.uniform(-60, 60), rng.uniform(-60, 60), rng.uniform(-math.pi, math.pi),
                rng.uniform(0.5, 14), rng.uniform(0.5, 3), rng.uniform(0, 15))
            for _ in range(n)
        ]  # fmt: skip
        key, step, slot = int(rng.integers(0, 2**63)), int(rng.integers(0, 500)), int(rng.integers(0, 64))
        got, gn = kernel(rows, enc, key, step, slot)
        want, wn = reference(rows, enc, key, step, slot)
        assert gn == wn, (seed, trial)
        np.testing.assert_allclose(got, want, atol=2e-6, err_msg=f"seed {seed} trial {trial}")


def test_everything_off_leaves_the_rows_alone():
    rows = [BUS, row(30.0, 0.0), row(30.0, 6.0, speed=3.0)]
    out, n = kernel(rows, PartialObsEncoder())
    assert n == 3
    np.testing.assert_array_equal(out, block(rows))


# --- the encoder in the env --------------------------------------------------------------------
def rollout(town, obs, threads=1, steps=25, worlds=3):
    env = VecEnv(town, small_spawner(), worlds, obs=obs, seed=1, num_threads=threads)
    acts = np.random.default_rng(1).integers(0, [7, 13], size=(steps, env.num_agents, 2))
    env.reset(1)
    frames = []
    for k in range(steps):
        env.step(acts[k])
        frames.append(
            {
                name: np.array(env.buffers[name])
                for name in ("obs", "final_obs", "active", "obj_rows", "rng_key", "step", "x", "speed")
            }
        )
    return env, frames


def test_off_by_default_gives_the_paper_rows_bit_for_bit(town):
    _, paper = rollout(town, PaperEncoder())
    _, off = rollout(town, PartialObsEncoder())
    for a, b in zip(paper, off, strict=True):
        for name in a:
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_the_env_encoder_is_the_reference_applied_to_the_paper_rows(town):
    enc = PartialObsEncoder(occlusion=True, pos_std=0.7, heading_std=0.05, speed_std=0.3, p_miss=0.1,
                            fp_rate=0.3, seed=7)  # fmt: skip
    env, got = rollout(town, enc)
    _, paper = rollout(town, PaperEncoder())
    lay = env.layout
    A = env.agents_per_world
    checked = hidden = 0
    for g, p in zip(got, paper, strict=True):
        # the dynamics do not see the observation: same states
        np.testing.assert_array_equal(g["x"], p["x"])
        for i in np.flatnonzero(p["active"]):
            w, a = divmod(int(i), A)
            key = partial.stream_key(int(p["rng_key"][w]), 7)
            rows = lay.split(p["obs"][i : i + 1])["objects"][0]
            want, wn = ref.postprocess(
                rows, int(p["obj_rows"][i]), enc.params, key, int(p["step"][w]), a, SCALES
            )
            have = lay.split(g["obs"][i : i + 1])["objects"][0]
            np.testing.assert_allclose(have, want, atol=2e-6)
            assert int(g["obj_rows"][i]) == wn
            # ego and road rows are the paper's
            np.testing.assert_array_equal(
                g["obs"][i, : lay.objects_offset], p["obs"][i, : lay.objects_offset]
            )
            np.testing.assert_array_equal(g["obs"][i, lay.road_offset :], p["obs"][i, lay.road_offset :])
            checked += 1
            hidden += int(p["obj_rows"][i]) - wn
    assert checked > 100 and hidden > 0


def test_partial_encoder_passes_the_checker_at_one_and_two_threads(town):
    enc = PartialObsEncoder(occlusion=True, pos_std=0.5, heading_std=0.05, speed_std=0.2, p_miss=0.05,
                            fp_rate=0.5)  # fmt: skip
    report = check_encoder(enc, town, spawner=small_spawner(), num_worlds=3, steps=30)
    assert report.rows_checked > 100 and report.isolation_checks >= 5 and report.max_abs <= 1.0


def test_p_miss_one_in_the_env_observes_no_object(town):
    env, frames = rollout(town, PartialObsEncoder(p_miss=1.0), steps=10)
    for f in frames:
        objects = env.layout.split(f["obs"])["objects"]
        assert not objects[f["active"].astype(bool)].any()


@pytest.mark.parametrize(
    ("key", "value", "expected"),
    [("p_miss", 1.5, "[0.0, 1.0]"), ("visible_fraction", -0.1, "[0.0, 1.0]"),
     ("pos_std", float("nan"), "finite"), ("fp_width", 0.0, "(0.0"), ("occlusion", "yes", "true or false"),
     ("seed", -1, "[0, 2**64)")],
)  # fmt: skip
def test_bad_values_name_key_value_and_range(key, value, expected):
    with pytest.raises(ConfigError, match=rf"obs\.{key}.*{__import__('re').escape(expected)}"):
        PartialObsEncoder(**{key: value})


def test_hydra_obs_partial_selects_the_encoder():
    from selfplaydrive.builder import compose, instantiate

    cfg = compose("train", ["obs=partial", "obs.p_miss=0.25", "obs.max_objects=16"])
    enc = instantiate(cfg.obs)
    assert isinstance(enc, PartialObsEncoder)
    assert enc.params["occlusion"] == 1 and enc.params["p_miss"] == pytest.approx(0.25)
    assert enc.layout.max_objects == 16
