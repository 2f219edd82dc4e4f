"""The pymunk rigid-body model (ablations) and the `selfplaydrive bench` command."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from helpers import FixedSpawner, make_scenario

from selfplaydrive.physics import BicycleModel, PymunkModel
from selfplaydrive.sim import VecEnv
from selfplaydrive.sim.actions import ContinuousActions


def run(road_map, agent, steps, action, physics):
    env = VecEnv(
        road_map,
        FixedSpawner(make_scenario([agent], episode_length=1000.0)),
        1,
        physics=physics,
        actions=ContinuousActions(),
    )
    env.reset(0)
    acts = np.tile(np.asarray(action, np.float32), (env.num_agents, 1))
    track = []
    for _ in range(steps):
        env.step(acts)
        b = env.buffers
        track.append((b["x"][0], b["y"][0], b["heading"][0], b["speed"][0], b["px"][0]))
    return np.array(track, np.float64), env


def test_pymunk_moves_20m_at_10mps_in_2s(straight_map):
    t, env = run(straight_map, dict(xy=(-50.0, -2.0), speed=10.0), 20, (0.0, 0.0), PymunkModel())
    assert t[-1, 0] == pytest.approx(-30.0, abs=1e-3)
    assert t[-1, 1] == pytest.approx(-2.0, abs=1e-6)
    assert t[-1, 3] == pytest.approx(10.0, abs=1e-4)
    assert t[-1, 4] == pytest.approx(t[-2, 0], abs=1e-5)  # px: the position before the step
    assert env.state.dist[0] == pytest.approx(20.0, abs=1e-3)


def test_pymunk_accelerates_and_turns_like_the_bicycle(straight_map):
    agent = dict(xy=(0.0, 0.0), speed=5.0)
    left, _ = run(straight_map, agent, 30, (0.0, 0.2), PymunkModel())
    right, _ = run(straight_map, agent, 30, (0.0, -0.2), PymunkModel())
    bike, _ = run(straight_map, agent, 30, (0.0, 0.2), BicycleModel())
    assert left[-1, 2] > 0.5 and left[-1, 1] > 1.0  # turned left: heading and y grow
    assert right[-1, 2] == pytest.approx(-left[-1, 2], abs=1e-4)
    # yaw rate v kappa as in the bicycle model; the integrated velocity lags the heading a
    # little (semi-implicit Euler), so the speed and the heading drift by about 1 % in 3 s
    assert left[-1, 2] == pytest.approx(bike[-1, 2], rel=0.03)
    fast, _ = run(straight_map, dict(xy=(0.0, 0.0), speed=0.0), 10, (2.0, 0.0), PymunkModel())
    assert fast[-1, 3] == pytest.approx(2.0, abs=1e-4)  # 2 m/s^2 for 1 s


def test_pymunk_friction_circle_understeers(straight_map):
    agent = dict(xy=(0.0, 0.0), speed=20.0, hidden=(0.3, 1.0, 1.0))
    slip, _ = run(straight_map, agent, 10, (0.0, 0.3), PymunkModel())
    grip, _ = run(straight_map, dict(agent, hidden=(1.0, 1.0, 1.0)), 10, (0.0, 0.3), PymunkModel())
    assert 0.0 < slip[-1, 2] < grip[-1, 2]


def test_bench_cli_json_keys(tmp_path):
    cmd = [sys.executable, "-m", "selfplaydrive.cli", "bench", "--json", "env.num_worlds=2", "steps=3"]
    cmd += ["warmup=1", "threads=[1,2]", "repeats=1", "stages=false", f"hydra.run.dir={tmp_path}"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["map"] == "default"
    assert out["num_agents"] == 64 and out["obs_dim"] == 19 + 63 * 9 + 200 * 8
    assert [r["threads"] for r in out["results"]] == [1, 2]
    assert all(r["agent_steps_per_s"] > 0 and r["agent_steps_per_cpu_s"] > 0 for r in out["results"])
    assert out["reset_ms_per_world"]["pack_and_kernels"] > 0
    assert 0 < out["bytes_per_world"] < 1_000_000
    assert json.loads((tmp_path / "bench.json").read_text()) == out


def test_bench_cli_bad_map_exits_1(tmp_path):
    cmd = [sys.executable, "-m", "selfplaydrive.cli", "bench", "map=file", "map.spec=/nonexistent/x.osm"]
    cmd += [f"hydra.run.dir={tmp_path}"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1
    assert "x.osm" in proc.stderr
