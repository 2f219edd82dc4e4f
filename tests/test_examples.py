"""The examples under examples/: each runs end to end in its tiny setting (a subprocess, exit
code and a key line of its output), and the user components they define do what they claim
(hand-computed values)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from loadfile import load_file

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TERMS = ("waypoint", "collision", "offroad", "red_light", "comfort", "center", "align", "velocity")


def run_example(name: str, tmp_path: Path, via_env: bool = False, timeout: float = 240) -> str:
    """Run examples/<name> in its tiny setting (--tiny, or the environment variable)."""
    import selfplaydrive

    env = dict(os.environ)
    # the examples run against the selfplaydrive under test (a source tree first on sys.path
    # here may differ from the installed one)
    root = str(Path(selfplaydrive.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join([root, *filter(None, [env.get("PYTHONPATH")])])
    args = [sys.executable, str(EXAMPLES / name)]
    if via_env:
        env["SELFPLAYDRIVE_EXAMPLE_TINY"] = "1"
    else:
        args.append("--tiny")
    done = subprocess.run(args, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=timeout)
    out = done.stdout + done.stderr
    assert done.returncode == 0, f"{name} exited with {done.returncode}:\n{out[-4000:]}"
    return out


def load_example(name: str):
    """Import examples/<name> as a module (the file names start with digits)."""
    return load_file(EXAMPLES / name, f"example_{name[:2]}")


@pytest.fixture(scope="module")
def town():
    from selfplaydrive.maps.procedural import ProceduralTownLoader

    return ProceduralTownLoader(seed=0, size=400.0, num_roundabouts=0).load()


# --- 01: custom env --------------------------------------------------------------------------
def test_01_custom_env_runs(tmp_path):
    out = run_example("01_custom_env.py", tmp_path, via_env=True)
    assert "one-lane spawner:" in out and "per-term reward sums over 40 steps" in out
    for term in TERMS:
        assert f"  {term} " in out, term


def test_01_one_lane_spawner_puts_every_agent_on_one_lane(town):
    ex = load_example("01_custom_env.py")
    from selfplaydrive.scenario.spawner import PaperSpawner

    base = PaperSpawner(num_agents=8, num_static=8, num_pedestrians=2, min_region_lane_length=300.0)
    spawner = ex.OneLaneSpawner(base, gap=15.0, waypoint_gap=10.0)
    sc = spawner.sample(town, np.random.default_rng(4))
    n = int(sc.agent_valid.sum())
    assert n >= 2 and not sc.agent_valid[n:].any()
    lane = int(sc.agent_lane[0])
    assert (sc.agent_lane[:n] == lane).all() and (sc.agent_lane[n:] == -1).all()
    xy = sc.agent_xy[:n].astype(np.float64)
    gaps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    np.testing.assert_allclose(gaps, 15.0, atol=0.5)  # chords of a curved lane are a bit shorter
    line = town.lanes.centerlines[lane].astype(np.float64)
    for p in np.concatenate([xy, sc.waypoints[:n].reshape(-1, 2)]):  # all on the centreline
        assert np.min(_distance_to_polyline(p, line)) < 1e-3
    assert (sc.num_waypoints[:n] >= 1).all()


def _distance_to_polyline(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    a, b = line[:-1], line[1:]
    t = np.clip(np.einsum("nd,nd->n", p - a, b - a) / np.einsum("nd,nd->n", b - a, b - a), 0, 1)
    return np.linalg.norm(a + t[:, None] * (b - a) - p, axis=1)


def test_01_episode_clock_feature():
    ex = load_example("01_custom_env.py")
    state = SimpleNamespace(step=np.array([5, 0]), max_steps=np.array([10, 20]), x=np.zeros(4))
    np.testing.assert_allclose(ex.EpisodeClock()(state)[:, 0], [0.5, 0.5, 1.0, 1.0])


# --- 02: reward term -------------------------------------------------------------------------
def test_02_reward_term_runs(tmp_path):
    out = run_example("02_reward_term.py", tmp_path)
    assert (
        "term names: waypoint, collision, offroad, red_light, comfort, center, align, velocity, speeding"
        in out
    )
    assert "term/speeding" in out  # the trainer logged the hook's term


def test_02_speeding_penalty_by_hand(town):
    from selfplaydrive.maps.roadmap import SegmentType

    ex = load_example("02_reward_term.py")
    hook = ex.SpeedingPenalty([town], coef=0.01, tolerance=1.0)
    seg = town.segments
    i = int(np.flatnonzero(seg.type == SegmentType.LANE_CENTER)[0])
    limit = float(town.lanes.speed_limit[seg.owner[i]])
    mid, d = seg.mid[i].astype(np.float64), seg.dir[i].astype(np.float64)
    far = np.asarray(town.bounds[2:]) + 1000.0
    state = SimpleNamespace(
        x=np.array([mid[0], mid[0], far[0]], np.float32),
        y=np.array([mid[1], mid[1], far[1]], np.float32),
        hcos=np.array([d[0], d[0], 1.0], np.float32),
        hsin=np.array([d[1], d[1], 0.0], np.float32),
        speed=np.array([limit + 4.0, limit + 0.5, 50.0], np.float32),
        map_id=np.array([0, 0, 0]),
    )
    # 4 m/s over minus 1 m/s tolerance -> -0.01 * 3; within tolerance -> 0; off the map -> 0
    np.testing.assert_allclose(hook(state), [-0.03, 0.0, 0.0], atol=1e-5)
    with pytest.raises(ValueError, match="coef >= 0"):
        ex.SpeedingPenalty([town], coef=-1.0)


# --- 03: SB3 baseline ------------------------------------------------------------------------
def test_03_sb3_baseline_runs(tmp_path):
    out = run_example("03_sb3_baseline.py", tmp_path)
    assert "trained 512 slot-steps" in out and "saved and reloaded: DeepSetsExtractor" in out
    assert "eval waypoint_completion" in out


# --- 04: Hydra sweep -------------------------------------------------------------------------
def test_04_hydra_sweep_runs(tmp_path):
    out = run_example("04_hydra_sweep.py", tmp_path)
    assert "sweep done: 4 runs" in out
    assert "physics BicycleModel, C_collision ~ U(0.0, 0.5)" in out
    assert "physics FrictionBicycleModel, C_collision ~ U(0.0, 1.0)" in out
    assert out.count("resolved_config.yaml, run_info.json, run_meta.json") == 4


# --- 05: ablation ----------------------------------------------------------------------------
def test_05_experiment_file_composes():
    from selfplaydrive.builder import build_spawner, compose

    cfg = compose("train", ["experiment=ablate_collision"])
    assert (cfg.reward.collision.low, cfg.reward.collision.high) == (0.0, 1.0)
    assert cfg.reward.mode == "train" and cfg.trainer.total_steps == 20_000_000
    cfg = compose("train", ["experiment=ablate_collision", "reward.collision.low=0.5"])
    # the builder hands the reward group's sampler to the spawner
    assert build_spawner(cfg).conditioning.collision == (0.5, 1.0)


def test_05_ablation_runs_and_reads_the_logs(tmp_path):
    out = run_example("05_ablation.py", tmp_path)
    assert "ablation: 2 runs" in out
    header = next(line for line in out.splitlines() if line.startswith("tag "))
    assert "U(0,1) s0" in header and "U(0.5,1) s0" in header
    rows = {
        line.split()[0]: line.split()[1:]
        for line in out.splitlines()
        if line.startswith(("term/", "charts/"))
    }
    assert set(rows) >= {f"term/{t}" for t in TERMS} | {"charts/collision_rate"}
    assert all(len(v) == 2 for v in rows.values())
    assert float(rows["term/offroad"][0]) <= 0.0 and 0.0 <= float(rows["charts/collision_rate"][1]) <= 1.0


# --- 06-08: one reward term, three forms ---------------------------------------------------
@pytest.mark.parametrize("name", ["06_term_python.py", "07_term_numba.py", "08_term_cython.py"])
def test_06_08_speed_limit_term_runs(name, tmp_path):
    if name == "07_term_numba.py":
        pytest.importorskip("numba")
    out = run_example(name, tmp_path)
    assert "reward columns of" in out and "  speed_limit " in out
    for term in TERMS:
        assert f"  {term} " in out, term


# --- 09: an observation encoder of one's own ---------------------------------------------------
def test_09_encoder_numba_selects_checks_and_trains(tmp_path):
    pytest.importorskip("numba")
    pytest.importorskip("torch")
    out = run_example("09_encoder_numba.py", tmp_path)
    assert "check_encoder: EncoderReport(name='ego_objects'" in out
    assert "'road': (0, 8)" in out and "trained DeepSetsModel on obs=ego_objects" in out
    assert "'updates': 2" in out


def test_09_is_selected_by_one_hydra_override():
    """`obs=custom obs.target=<file>:<factory>` from the command line, keys passed to the factory."""
    pytest.importorskip("numba")
    from selfplaydrive.builder import build_env, compose

    target = f"{EXAMPLES / '09_encoder_numba.py'}:ego_objects_encoder"
    cfg = compose("sim", ["obs=custom", f"obs.target={target}", "+obs.max_objects=4", "env.num_worlds=1"])
    env = build_env(cfg)
    assert env.encoder.name == "ego_objects" and env.layout.max_objects == 4 and env.layout.max_road == 0
    assert env.observation_space.shape == (19 + 4 * 9,)
    env.reset(seed=0)
    env.step(np.zeros((env.num_agents, 2), np.int64))
    assert np.all(np.isfinite(env.observations))


# --- 10: a physics model as a numba cfunc ----------------------------------------------------
def test_10_physics_numba_runs_and_passes_the_checker(tmp_path):
    pytest.importorskip("numba")
    out = run_example("10_physics_numba.py", tmp_path)
    assert "check_physics: passed" in out and "unicycle:" in out


def test_10_is_selected_by_one_hydra_override():
    pytest.importorskip("numba")
    from selfplaydrive.builder import build_env, compose

    target = f"{EXAMPLES / '10_physics_numba.py'}:unicycle"
    cfg = compose("sim", ["physics=custom", f"physics.model.target={target}", "env.num_worlds=1"])
    env = build_env(cfg)
    assert env.physics.name == "unicycle" and env.physics.form == "numba"
    assert env.action_space.nvec.tolist() == [7, 9] and env.action_table.names == ("accel", "yaw_rate")
    env.reset(seed=0)
    env.step(np.zeros((env.num_agents, 2), np.int64))
    assert np.all(np.isfinite(env.buffers["x"]))


def test_10_unicycle_hand_computed():
    """No acceleration, no drag, no turn: every car moves v * 2 s in 2 s along its heading; then
    a yaw rate of 10 deg/s for 1 s turns it by 10 deg (gains set to 1)."""
    pytest.importorskip("numba")
    from selfplaydrive import make_env

    ex = load_example("10_physics_numba.py")
    env = make_env("default", num_worlds=2, physics=ex.unicycle(drag=0.0), seed=0)
    env.reset(seed=0)
    b = env.buffers
    b["hidden"][:, 1:] = 1.0
    x0, y0, h0, v0 = b["x"].copy(), b["y"].copy(), b["heading"].copy(), b["speed"].copy()
    for _ in range(20):
        env.step(np.tile([3, 4], (env.num_agents, 1)))  # accel 0, yaw rate 0
    on = env.masks.copy()
    assert on.sum() > 10
    np.testing.assert_allclose(b["x"][on], (x0 + 2.0 * v0 * np.cos(h0))[on], atol=2e-3)
    np.testing.assert_allclose(b["y"][on], (y0 + 2.0 * v0 * np.sin(h0))[on], atol=2e-3)
    for _ in range(10):
        env.step(np.tile([3, 6], (env.num_agents, 1)))  # yaw rate +10 deg/s
    on &= env.masks
    turned = np.angle(np.exp(1j * (b["heading"] - h0)))[on]
    np.testing.assert_allclose(turned, np.deg2rad(10.0), atol=1e-5)


# --- 11: the same physics model in Cython, as its own package ---------------------------------
def test_11_physics_cython_runs(tmp_path):
    out = run_example("11_physics_cython.py", tmp_path)
    assert "check_physics: passed" in out and "unicycle (cython):" in out


def test_11_cython_package_matches_the_numba_model_and_loads_by_name(tmp_path, monkeypatch):
    """Built against get_include(), the package's model is selected by `load_physics` (what
    `physics=custom physics.model.target=unicycle_physics:unicycle` calls) and drives the same
    rollout as example 10's numba cfunc, to float32 rounding."""
    from selfplaydrive import make_env
    from selfplaydrive.physics import load_physics
    from selfplaydrive.testing.build import build_component_package

    build_component_package(EXAMPLES / "unicycle_cython", tmp_path / "pkg")
    monkeypatch.syspath_prepend(str(tmp_path / "pkg"))
    model = load_physics("unicycle_physics:unicycle")
    assert model.form == "cython" and model.actions.names == ("accel", "yaw_rate")
    envs = [make_env("default", num_worlds=2, physics=model, seed=0)]
    if importlib.util.find_spec("numba") is not None:
        envs.append(
            make_env("default", num_worlds=2, physics=load_example("10_physics_numba.py").unicycle(), seed=0)
        )
    rng = np.random.default_rng(0)
    for env in envs:
        env.reset(seed=0)
    for _ in range(30):
        a = np.stack([rng.integers(0, 7, envs[0].num_agents), rng.integers(0, 9, envs[0].num_agents)], axis=1)
        for env in envs:
            env.step(a)
    for env in envs[1:]:
        np.testing.assert_allclose(env.buffers["x"], envs[0].buffers["x"], atol=1e-3)
        np.testing.assert_allclose(env.buffers["speed"], envs[0].buffers["speed"], atol=1e-4)
