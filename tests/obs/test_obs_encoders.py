"""Observation encoders as components (issue #13): the paper encoder through the ABI gives the
paper's rows; one encoder written as numba cfunc and Cython package gives the same rows, equal to
the paper's ego block and nearest objects; Python encoders replace the compiled one; the layout
travels with the encoder; `check_encoder` finds broken contracts; clear errors."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest
from loadfile import load_file

from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.procedural import ProceduralTownLoader
from selfplaydrive.obs import KernelEncoder, ObsConfig, ObsLayout, PaperEncoder, as_encoder
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim import VecEnv
from selfplaydrive.testing.check_encoder import EncoderCheckError, check_encoder

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def town():
    return ProceduralTownLoader(seed=0, size=400.0, num_roundabouts=0).load()


def spawner():
    return PaperSpawner(num_agents=12, num_static=12, num_pedestrians=4, min_region_lane_length=300,
                        episode_lengths=(4.0,))  # fmt: skip


def rollout(town, obs, threads=1, steps=20, worlds=3, **kw):
    env = VecEnv(town, spawner(), worlds, obs=obs, seed=2, num_threads=threads, **kw)
    acts = np.random.default_rng(2).integers(0, [7, 13], size=(steps, env.num_agents, 2))
    env.reset(2)
    out = []
    for k in range(steps):
        env.step(acts[k])
        out.append((np.array(env.observations), np.array(env.final_observations), np.array(env.masks),
                    np.array(env.terminations | env.truncations)))  # fmt: skip
    return env, out


@pytest.fixture(scope="module")
def example09():
    pytest.importorskip("numba")
    # registered in sys.modules: the Hydra _target_ of the test names the module
    return load_file(EXAMPLES / "09_encoder_numba.py", "example_09", register=True)


@pytest.fixture(scope="module")
def cython_encoder(tmp_path_factory):
    """examples/ego_objects_cython built against get_include() in a temporary folder."""
    from selfplaydrive.testing.build import build_component_package

    target = build_component_package(EXAMPLES / "ego_objects_cython", tmp_path_factory.mktemp("cyenc"))
    sys.path.insert(0, str(target))
    try:
        yield importlib.import_module("ego_objects_encoder").ego_objects_encoder
    finally:
        sys.path.remove(str(target))


# --- the paper encoder through the ABI -------------------------------------------------------------
def test_paper_encoder_forms_agree_bit_for_bit(town):
    """None, ObsConfig and PaperEncoder select the same component: the same rows."""
    _, a = rollout(town, None)
    _, b = rollout(town, ObsConfig(63, 200, 100.0))
    _, c = rollout(town, PaperEncoder(), threads=2)
    for x, y, z in zip(a, b, c, strict=True):
        for u, v, t in zip(x, y, z, strict=True):
            np.testing.assert_array_equal(u, v)
            np.testing.assert_array_equal(u, t)


def test_paper_encoder_is_an_exported_component():
    from selfplaydrive._sim import observe

    enc = PaperEncoder(16, 64, 60.0)
    assert enc.form == "builtin" and enc.address == observe.encoder_address()
    assert enc.layout == ObsLayout(16, 64) and enc.radius == 60.0 and enc.road_gather == 64
    assert "encode_paper" in observe.__pyx_capi__


def test_layout_lives_with_the_encoder_and_old_imports_work():
    import selfplaydrive.obs as obs
    import selfplaydrive.sim as sim
    from selfplaydrive.sim.layout import ObsLayout as Old

    assert Old is obs.ObsLayout is sim.ObsLayout
    lay = ObsLayout(5, 0, 2)
    assert lay.blocks() == {"ego": (19,), "objects": (5, 9), "road": (0, 8), "extra": (2,)}
    assert lay.obs_dim == 19 + 45 + 2
    with pytest.raises(ValueError, match="max_road: expected an integer >= 0, got -1"):
        ObsLayout(5, -1)


# --- numba and Cython forms of one encoder ------------------------------------------------------
def test_numba_and_cython_forms_agree_and_match_the_paper_rows(town, example09, cython_encoder):
    k, radius = 6, 40.0
    env_n, numba_rows = rollout(town, example09.ego_objects_encoder(k, radius))
    _, cython_rows = rollout(town, cython_encoder(k, radius), threads=2)
    env_p, paper_rows = rollout(town, PaperEncoder(k, 16, radius))
    assert env_n.layout == ObsLayout(k, 0) and env_n.observations.shape[1] == 19 + 9 * k
    lay_p = env_p.layout
    checked = 0
    for n, c, p in zip(numba_rows, cython_rows, paper_rows, strict=True):
        for u, v in zip(n, c, strict=True):
            np.testing.assert_array_equal(u, v)  # same float32 arithmetic: bit for bit
        obs_n, _, masks, _ = n
        obs_p = p[0]
        for i in np.flatnonzero(masks):
            # ego: the paper's (lane_alpha / pi in float32 here, in double there)
            np.testing.assert_allclose(obs_n[i, :19], obs_p[i, :19], atol=1e-6)
            # objects: the same set as the paper's k nearest (the paper's rows are unordered)
            mine = obs_n[i, 19:].reshape(k, 9)
            theirs = lay_p.split(obs_p[i : i + 1])["objects"][0]
            key = np.lexsort(mine.T[::-1])
            np.testing.assert_allclose(mine[key], theirs[np.lexsort(theirs.T[::-1])], atol=1e-6)
            checked += 1
    assert checked > 100


def test_example_encoder_passes_the_checker(town, example09):
    report = check_encoder(example09.ego_objects_encoder(8, 50.0), town, spawner=spawner(), num_worlds=3)
    assert report.obs_dim == 19 + 72 and report.isolation_checks > 0


def test_hydra_override_selects_the_example_encoder_and_the_model_builds(example09):
    pytest.importorskip("torch")
    from selfplaydrive.builder import build_env, build_model, compose

    example09.register()
    small = ["map=procedural", "map.size=400", "map.num_roundabouts=0", "env.num_worlds=1"]
    cfg = compose(
        "train", ["obs=ego_objects", "obs.max_objects=5", *small, "spawner.min_region_lane_length=300"]
    )
    env = build_env(cfg)
    assert env.encoder.name == "ego_objects" and env.layout == ObsLayout(5, 0)
    model = build_model(cfg, env)
    import torch

    obs = torch.as_tensor(np.array(env.reset(0)))
    logits, value, _ = model(obs, model.initial_state(len(obs)), torch.ones(len(obs), dtype=torch.bool))
    assert torch.isfinite(logits).all() and value.shape == (len(obs),)


# --- Python encoders ----------------------------------------------------------------------------
class SpeedOnly:
    """A Python encoder: the ego's speed and lane offset in an ego block, nothing else."""

    name = "speed_only"
    layout = ObsLayout(0, 0)
    radius = 50.0

    def __call__(self, state):
        out = np.zeros((len(state.speed), 19), dtype=np.float32)
        out[:, 2] = np.clip(state.speed / 40.0, -1, 1)
        out[:, 8] = np.clip(state.lane_s / 5.0, -1, 1)
        return out


def test_a_python_encoder_replaces_the_compiled_one(town):
    env, frames = rollout(town, SpeedOnly())
    assert env.observations.shape == (env.num_agents, 19)
    seen_final = 0
    for obs, final, masks, ended in frames:
        assert not obs[masks][:, [0, 1, 3, 4]].any()  # nothing the paper encoder would write
        assert obs[masks][:, 2].any()
        seen_final += int(ended.sum())
        assert not final[ended][:, [0, 1]].any()
    assert seen_final > 0
    report = check_encoder(SpeedOnly(), town, spawner=spawner(), num_worlds=2, steps=10)
    assert report.isolation_checks == 0  # read-only views: nothing to compare


def test_a_python_encoder_with_hooks_after_it(town):
    class Clock:
        name, dim = "clock", 1

        def __call__(self, state):
            return np.repeat(state.step.astype(np.float32), len(state.speed) // len(state.step))[:, None]

    env, frames = rollout(town, SpeedOnly(), obs_hooks=[Clock()])
    assert env.layout == ObsLayout(0, 0, 1) and env.observations.shape[1] == 20
    obs, _, masks, _ = frames[3]
    assert (obs[masks, 19] > 0).all()


# --- the checker catches broken contracts --------------------------------------------------------
class TooBig(SpeedOnly):
    name = "too_big"

    def __call__(self, state):
        out = super().__call__(state)
        out[:, 5] = 3.0
        return out


def test_checker_names_an_out_of_bound_value(town):
    with pytest.raises(
        EncoderCheckError, match=r"'too_big' \(bound\).*column 5 exceeds the declared bound 1.0"
    ):
        check_encoder(TooBig(), town, spawner=spawner(), num_worlds=2, steps=5)


def test_checker_catches_a_compiled_encoder_writing_the_state(town):
    numba = pytest.importorskip("numba")
    from selfplaydrive.rewards.numba_abi import ENCODER_SIGNATURE, SIM, f32_ptr, int_field, u8_ptr

    @numba.cfunc(ENCODER_SIGNATURE)
    def sneaky(sim, prm, atlas, args, w, out, stride):  # pragma: no cover - compiled
        A = int_field(sim, SIM.A)
        speed, active = f32_ptr(sim, SIM.speed), u8_ptr(sim, SIM.active)
        for a in range(A):
            if active[w * A + a]:
                out[a * stride + 2] = np.float32(0.5)
                speed[w * A + a] = speed[w * A + a] * np.float32(0.999)

    enc = KernelEncoder.from_numba("sneaky", sneaky, ObsLayout(0, 0))
    with pytest.raises(EncoderCheckError, match=r"'sneaky' \(isolation\): wrote buffer 'speed'"):
        check_encoder(enc, town, spawner=spawner(), num_worlds=2, steps=10)


# --- errors ------------------------------------------------------------------------------------------
def test_bad_encoders_are_config_errors():
    with pytest.raises(ConfigError, match="obs: expected an ObsConfig, a KernelEncoder"):
        as_encoder("paper")
    with pytest.raises(ConfigError, match="encoder 'x': expected a numba cfunc"):
        KernelEncoder.from_numba("x", lambda: None, ObsLayout())
    with pytest.raises(ConfigError, match="encoder 'x': address must be a positive integer"):
        KernelEncoder("x", 0, ObsLayout())
    with pytest.raises(ConfigError, match="encoder 'x': radius must be a number > 0"):
        KernelEncoder("x", 1, ObsLayout(), radius=-1.0)
    with pytest.raises(ConfigError, match="encoder 'x': layout must be an ObsLayout"):
        KernelEncoder("x", 1, {"max_objects": 3})
    with pytest.raises(ConfigError, match="encoder 'x': args must be finite numbers"):
        KernelEncoder("x", 1, ObsLayout(), args=[1.0, float("nan")])
    with pytest.raises(ConfigError, match=r"obs: expected max_objects >= 1"):
        PaperEncoder(0, 10, 100.0)


def test_a_cython_function_of_another_signature_is_refused():
    from selfplaydrive._sim import reward

    with pytest.raises(ConfigError, match=r"encoder 'x': the function's signature is .*expected"):
        KernelEncoder.from_cython("x", reward, "term_collision", ObsLayout())
    with pytest.raises(ConfigError, match="exports no cdef function 'nope'"):
        KernelEncoder.from_cython("x", reward, "nope", ObsLayout())


def test_a_python_encoder_of_the_wrong_width_or_nan_is_named(town):
    class Narrow(SpeedOnly):
        name = "narrow"

        def __call__(self, state):
            return super().__call__(state)[:, :5]

    with pytest.raises(ValueError, match=r"encoder 'narrow': expected an output of shape \(\d+, 19\)"):
        VecEnv(town, spawner(), 1, obs=Narrow()).reset(0)

    class Nan(SpeedOnly):
        name = "nan"

        def __call__(self, state):
            out = super().__call__(state)
            out[:, 4] = np.nan
            return out

    with pytest.raises(ValueError, match=r"encoder 'nan': non-finite values in the row of agent slot \d+"):
        VecEnv(town, spawner(), 1, obs=Nan()).reset(0)


@pytest.mark.parametrize("layout", [ObsLayout(5, 0), ObsLayout(0, 0), ObsLayout(0, 4, 2)])
@pytest.mark.parametrize("model_name", ["DeepSetsModel", "TransformerModel"])
def test_models_build_from_layouts_with_empty_blocks(layout, model_name):
    torch = pytest.importorskip("torch")
    from selfplaydrive import models

    model = getattr(models, model_name)(layout, (7, 13))
    obs = torch.rand(2, 3, layout.obs_dim) * 2 - 1
    state = model.initial_state(3)
    logits, values, _ = model.forward_sequence(obs, state, torch.zeros(2, 3, dtype=torch.bool))
    assert logits.shape == (2, 3, 20) and torch.isfinite(logits).all() and torch.isfinite(values).all()


def test_the_encoder_changes_only_the_observation(town, example09):
    """Dynamics, events, lane association and rewards do not depend on the encoder, nor on its
    road gather (1 segment for an encoder without road rows, 16 for the paper's here)."""
    names = ("x", "y", "speed", "reward", "terms", "events", "lane_s", "lane_alpha", "term", "trunc")

    def states(obs):
        env = VecEnv(town, spawner(), 3, obs=obs, seed=4)
        acts = np.random.default_rng(4).integers(0, [7, 13], size=(30, env.num_agents, 2))
        env.reset(4)
        out = []
        for k in range(30):
            env.step(acts[k])
            out.append({n: env.buffers[n].copy() for n in names})
        return out

    for a, b in zip(
        states(PaperEncoder(6, 16, 40.0)), states(example09.ego_objects_encoder(6, 40.0)), strict=True
    ):
        for n in names:
            np.testing.assert_array_equal(a[n], b[n], err_msg=n)
