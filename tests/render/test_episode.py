"""Episode renderer: recording, frame drawing (pixels checked), PNG / GIF output, policies, CLI."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from matplotlib.colors import to_rgb
from PIL import Image

from selfplaydrive.builder import make_env
from selfplaydrive.policies import infer_model_spec, make_policy
from selfplaydrive.render.episode import LIGHT_COLORS, STATUS_COLORS, EpisodeRenderer, box_corners
from selfplaydrive.render.record import record_episode
from selfplaydrive.render.video import has_mp4, png_paths, write_video

SIZE = 200  # [px] small frames keep the tests fast; 1 px per metre over the 200 m region
STEPS = 4


@pytest.fixture(scope="module")
def env():
    return make_env("default", num_worlds=2, seed=0)


@pytest.fixture(scope="module")
def rule_rec(env):
    return record_episode(env, make_policy("rule_based", env), STEPS, world=1, seed=5)


@pytest.fixture(scope="module")
def random_rec(env):
    return record_episode(env, make_policy("random", env, seed=1), STEPS, world=0, seed=6)


def _rgb(image: np.ndarray, x: float, y: float, window: tuple) -> np.ndarray:
    """Pixel of image at map point (x, y) [m] given `EpisodeRenderer.window`'s result."""
    ppm, _, _, i0, j0 = window
    return image[int(np.floor(j0 - y * ppm)), int(np.floor(x * ppm - i0))].astype(int)


def _empty(frame):
    """The frame with no vehicles, pedestrians or waypoints (only the map and the lights)."""
    a, s, p = len(frame.agent_valid), len(frame.static_valid), len(frame.ped_present)
    return dataclasses.replace(
        frame,
        agent_valid=np.zeros(a, bool),
        agent_active=np.zeros(a, bool),
        static_valid=np.zeros(s, bool),
        ped_present=np.zeros(p, bool),
    )


def test_recording_has_one_frame_per_step_and_the_region(rule_rec, env):
    assert len(rule_rec.frames) == STEPS + 1
    assert [f.index for f in rule_rec.frames] == list(range(STEPS + 1))
    np.testing.assert_allclose([f.time for f in rule_rec.frames], 0.1 * np.arange(STEPS + 1), atol=1e-9)
    r = rule_rec.frames[0].region
    assert r is not None and r[2] - r[0] == pytest.approx(200.0) and r[3] - r[1] == pytest.approx(200.0)
    # world 1's agents are the ones recorded
    A = env.agents_per_world
    f0 = rule_rec.frames[0]
    assert f0.agent_xy.shape == (A, 2) and f0.agent_valid.sum() > 0
    assert rule_rec.world == 1


def test_rule_based_episode_to_png_and_gif(rule_rec, tmp_path):
    r = EpisodeRenderer(rule_rec.maps, size=SIZE)
    pngs = write_video(r.frames(rule_rec), tmp_path / "ep.png")
    assert pngs == png_paths(tmp_path / "ep.png", STEPS + 1)
    for p in pngs:
        assert p.stat().st_size > 1000
        assert Image.open(p).size == (SIZE, SIZE)
    gif = write_video(
        EpisodeRenderer(rule_rec.maps, size=SIZE).frames(rule_rec), tmp_path / "ep.gif", fps=10
    )[0]
    with Image.open(gif) as im:
        assert im.size == (SIZE, SIZE)
        assert im.n_frames == STEPS + 1
        assert im.info["duration"] == 100  # [ms] at 10 fps
    # moving cars: consecutive frames differ
    a, b = (np.asarray(Image.open(p).convert("RGB")) for p in pngs[:2])
    assert (a != b).any()


def test_random_episode_to_gif_every_second_frame(random_rec, tmp_path):
    r = EpisodeRenderer(random_rec.maps, size=SIZE, follow=3, view=60.0)
    gif = write_video(r.frames(random_rec, every=2), tmp_path / "random.gif")[0]
    with Image.open(gif) as im:
        assert im.n_frames == len(range(0, STEPS + 1, 2)) == 3
        assert im.size == (SIZE, SIZE)


def test_light_colour_follows_the_light_state(rule_rec):
    frame = _empty(rule_rec.frames[0])
    m = rule_rec.maps[frame.map_id]
    r = EpisodeRenderer(rule_rec.maps, size=800, text=False)  # 4 px/m: a light line is 4 px wide
    win = r.window(frame)
    _, xmin, ymax, _, _ = win
    mids = np.array([m.light_lines[i].mean(0) for i in range(len(m.light_lines))])
    inside = (
        (mids[:, 0] > xmin + 10)
        & (mids[:, 0] < xmin + 190)
        & (mids[:, 1] < ymax - 10)
        & (mids[:, 1] > ymax - 190)
    )
    line = int(
        np.flatnonzero(inside & (np.array([len(m.light_lines[i]) for i in range(len(inside))]) == 2))[0]
    )
    group = int(m.light_group[line])
    mid = m.light_lines[line].mean(0)
    seen = {}
    for state in (1, 2, 3, 0):
        lights = frame.light_state.copy()
        lights[group] = state
        img = r.draw(dataclasses.replace(frame, light_state=lights))
        seen[state] = _rgb(img, mid[0], mid[1], win)
    for state, rgb in seen.items():
        expected = np.round(255 * np.array(to_rgb(LIGHT_COLORS[state])))
        assert np.abs(rgb - expected).max() <= 12, (state, rgb, expected)
    assert len({tuple(v) for v in seen.values()}) == 4


def test_agent_box_colour_by_status(rule_rec):
    base = _empty(rule_rec.frames[0])
    r = EpisodeRenderer(rule_rec.maps, size=800, text=False, waypoints=False, tail=0)
    x0, y0 = 0.5 * (base.region[0] + base.region[2]), 0.5 * (base.region[1] + base.region[3])
    one = np.zeros(len(base.agent_valid), bool)
    one[0] = True
    xy = base.agent_xy.copy()
    xy[0] = (x0, y0)
    heading = base.agent_heading.copy()
    heading[0] = 0.0
    length, width = base.agent_length.copy(), base.agent_width.copy()
    length[0], width[0] = 6.0, 2.0
    events = np.zeros_like(base.agent_events)
    common = dict(
        agent_xy=xy, agent_heading=heading, agent_length=length, agent_width=width, agent_events=events
    )
    cases = {
        "active": dict(agent_valid=one, agent_active=one, agent_parked=~one),
        "parked": dict(agent_valid=one, agent_active=one, agent_parked=one),
        "ended": dict(agent_valid=one, agent_active=~one, agent_parked=~one, agent_obstacle=one),
    }
    for status, flags in cases.items():
        frame = dataclasses.replace(base, **common, **flags)
        win = r.window(frame)
        img = r.draw(frame)
        # 1.5 m behind the centre: inside the box, behind the heading triangle (front half)
        rgb = _rgb(img, x0 - 1.5, y0, win)
        expected = np.round(255 * np.array(to_rgb(STATUS_COLORS[status])))
        assert np.abs(rgb - expected).max() <= 12, (status, rgb, expected)
        # 2 m in front of the bumper: not the car
        assert np.abs(_rgb(img, x0 + 5.0, y0, win) - expected).max() > 40
        if status != "ended":  # a driving car shows its heading: white triangle near the front
            assert _rgb(img, x0 + 2.4, y0, win).min() >= 240


def test_box_corners_hand_computed():
    # centre (1, 2), heading 90 deg, length 4, width 2: front-left local (2, 1) -> (-1, 2) + centre
    c = box_corners(
        np.array([[1.0, 2.0]]), np.array([0.0]), np.array([1.0]), np.array([4.0]), np.array([2.0])
    )
    np.testing.assert_allclose(c[0], [[0, 4], [0, 0], [2, 0], [2, 4]], atol=1e-12)


def test_follow_camera_centres_the_agent(random_rec):
    r = EpisodeRenderer(random_rec.maps, size=400, follow=2, view=40.0)
    frame = random_rec.frames[-1]
    assert frame.agent_valid[2]
    ppm, xmin, ymax, _, _ = r.window(frame)
    assert ppm == pytest.approx(10.0)
    x, y = frame.agent_xy[2]
    assert abs((x - xmin) * ppm - 200) <= 0.5 and abs((ymax - y) * ppm - 200) <= 0.5
    with pytest.raises(ValueError, match="agent slot 99"):
        EpisodeRenderer(random_rec.maps, size=400, follow=99).draw(frame)


def test_bad_arguments_are_named(rule_rec, tmp_path, env):
    with pytest.raises(ValueError, match="size"):
        EpisodeRenderer(rule_rec.maps, size=10)
    with pytest.raises(ValueError, match="view"):
        EpisodeRenderer(rule_rec.maps, view=-1.0)
    with pytest.raises(ValueError, match="expected a file ending in"):
        write_video([np.zeros((8, 8, 3), np.uint8)], tmp_path / "x.avi")
    with pytest.raises(ValueError, match="at least one frame"):
        write_video([], tmp_path / "x.gif")
    with pytest.raises(ValueError, match="frame 1"):
        write_video([np.zeros((8, 8, 3), np.uint8), np.zeros((8, 9, 3), np.uint8)], tmp_path / "y.gif")
    with pytest.raises(ValueError, match="driver 'nope'"):
        make_policy("nope", env)
    with pytest.raises(ValueError, match="world"):
        record_episode(env, make_policy("static", env), 1, world=2)


def test_cli_writes_gif_and_reports_errors(tmp_path, capsys):
    from selfplaydrive.cli import main

    out = tmp_path / "cli.gif"
    run = f"hydra.run.dir={tmp_path / 'run'}"
    assert main(["render", "steps=2", f"output={out}", "size=128", "driver=random", run]) == 0
    with Image.open(out) as im:
        assert im.n_frames == 3 and im.size == (128, 128)
    assert "wrote 3 frames" in capsys.readouterr().out
    assert main(["render", "steps=1", f"output={tmp_path / 'x.txt'}", run]) == 2
    assert "expected a file ending in" in capsys.readouterr().err
    if not has_mp4():
        assert main(["render", "steps=1", f"output={tmp_path / 'x.mp4'}", run]) == 2
        assert "imageio-ffmpeg" in capsys.readouterr().err


def test_checkpoint_policy_round_trip(env, tmp_path):
    from selfplaydrive.models import DeepSetsModel
    from selfplaydrive.trainers.ppo import checkpoint as ckpt

    model = DeepSetsModel(
        env.layout, tuple(env.action_space.nvec), input_size=8, hidden_size=16, lstm_size=12
    )
    spec = infer_model_spec(model.state_dict())
    assert spec == {
        "_target_": "selfplaydrive.models.DeepSetsModel",
        "input_size": 8,
        "hidden_size": 16,
        "lstm_size": 12,
    }
    path = ckpt.save(tmp_path / "ckpt_0000001.pt", {"model": model.state_dict(), "config": {}})
    policy = make_policy(path, env)
    env.reset(seed=3)
    policy.reset()
    actions = policy(env.observations, env)
    assert actions.shape == (env.num_agents, 2)
    # deterministic: the argmax of the same model on the same observations, fresh LSTM state
    with torch.no_grad():
        obs = torch.from_numpy(env.observations.copy())
        logits, _, _ = model(
            obs, model.initial_state(env.num_agents), torch.ones(env.num_agents, dtype=torch.bool)
        )
    np.testing.assert_array_equal(actions[:, 0], logits[:, :7].argmax(1).numpy())
    np.testing.assert_array_equal(actions[:, 1], logits[:, 7:].argmax(1).numpy())
    env.step(actions)  # the actions are valid for the env
    # weights of another action table (5 x 9 choices) do not fit the env's 7 x 13
    other = DeepSetsModel(env.layout, (5, 9), input_size=8, hidden_size=16, lstm_size=12)
    bad = ckpt.save(tmp_path / "bad.pt", {"model": other.state_dict(), "config": {}})
    with pytest.raises(ValueError, match="do not fit this env"):
        make_policy(bad, env)


def test_transformer_sizes_are_read_off_the_weights(env):
    from selfplaydrive.models import TransformerModel

    model = TransformerModel(
        env.layout, (7, 13), embed_size=16, num_heads=2, num_encoder_blocks=3, ffn_size=24, film_hidden=8
    )
    assert infer_model_spec(model.state_dict()) == {
        "_target_": "selfplaydrive.models.TransformerModel",
        "embed_size": 16,
        "num_encoder_blocks": 3,
        "num_decoder_blocks": 1,
        "ffn_size": 24,
        "film_hidden": 8,
    }
    with pytest.raises(ValueError, match="expected a DeepSetsModel"):
        infer_model_spec({"w": torch.zeros(1)})
