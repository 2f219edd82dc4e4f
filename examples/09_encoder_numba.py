"""Example 09: an observation encoder of your own, in one file: ego + the k nearest objects, no
road (a numba cfunc; needs the `numba` extra).

The cfunc has the C signature of every observation encoder (`sd_encoder_fn` in
selfplaydrive_abi.h; `numba_abi.ENCODER_SIGNATURE`), so the step calls it through a function
pointer once per world inside its parallel loop, without the GIL, in place of the paper's
encoder (paper section 2.5). It reads the state through the field offsets of the header and
writes only the rows of its world: row a at `out[a * stride]`. The encoder declares its layout
(`ObsLayout(max_objects=k, max_road=0)`: the ego's 19 features, k object slots of 9, no road
block); the Deep Sets model builds from it (an empty block pools to zeros).

Selection by one Hydra override: the script registers the encoder as the `obs` option
`ego_objects` (Hydra's ConfigStore) and composes `obs=ego_objects` (keys `obs.max_objects`,
`obs.radius`), checks it with `selfplaydrive.testing.check_encoder` and trains the Deep Sets
model for a couple of PPO updates. From the command line, without registering anything:
`selfplaydrive train obs=custom obs.target=examples/09_encoder_numba.py:ego_objects_encoder`.

Run: python examples/09_encoder_numba.py [--tiny]   (pip install 'selfplaydrive[numba]')
"""

from __future__ import annotations

import sys
import tempfile

import numpy as np
from numba import cfunc, njit

from selfplaydrive.obs import KernelEncoder, ObsLayout
from selfplaydrive.rewards.numba_abi import (
    ENCODER_SIGNATURE,
    PARAMS,
    SIM,
    f32_ptr,
    float_field,
    i32_ptr,
    int_field,
    u8_ptr,
)

EGO_DIM, OBJ_DIM, NUM_COEFFS = 19, 9, 8


@njit(inline="always")
def _clip(v):  # type: ignore[no-untyped-def]
    """v clipped to [-1, 1] (the paper's observation range)."""
    return min(max(v, np.float32(-1.0)), np.float32(1.0))


@cfunc(ENCODER_SIGNATURE)
def ego_objects(sim, prm, atlas, args, w, out, stride):  # type: ignore[no-untyped-def]
    """Ego features as the paper's, then the k = sim->max_obj nearest bodies (agents, static
    vehicles, pedestrians) within obs_radius as the paper's object rows; zero padding."""
    A, S, P, K = int_field(sim, SIM.A), int_field(sim, SIM.S), int_field(sim, SIM.P), int_field(sim, SIM.K)
    k_max, cap = int_field(sim, SIM.max_obj), int_field(sim, SIM.cand_cap)
    x, y, hc, hs = f32_ptr(sim, SIM.x), f32_ptr(sim, SIM.y), f32_ptr(sim, SIM.hcos), f32_ptr(sim, SIM.hsin)
    speed, length, width = f32_ptr(sim, SIM.speed), f32_ptr(sim, SIM.length), f32_ptr(sim, SIM.width)
    active, obstacle = u8_ptr(sim, SIM.active), u8_ptr(sim, SIM.obstacle)
    wps, num_wp, wp_idx = f32_ptr(sim, SIM.waypoints), i32_ptr(sim, SIM.num_wp), i32_ptr(sim, SIM.wp_idx)
    lane_s, lane_alpha, lane_valid = (
        f32_ptr(sim, SIM.lane_s),
        f32_ptr(sim, SIM.lane_alpha),
        u8_ptr(sim, SIM.lane_valid),
    )
    coeffs = f32_ptr(sim, SIM.coeffs)
    st_x, st_y, st_c, st_s = (
        f32_ptr(sim, SIM.st_x),
        f32_ptr(sim, SIM.st_y),
        f32_ptr(sim, SIM.st_cos),
        f32_ptr(sim, SIM.st_sin),
    )
    st_len, st_wid, st_valid = f32_ptr(sim, SIM.st_len), f32_ptr(sim, SIM.st_wid), u8_ptr(sim, SIM.st_valid)
    p_x, p_y, p_c, p_s = (
        f32_ptr(sim, SIM.ped_x),
        f32_ptr(sim, SIM.ped_y),
        f32_ptr(sim, SIM.ped_cos),
        f32_ptr(sim, SIM.ped_sin),
    )
    p_vx, p_vy = f32_ptr(sim, SIM.ped_vx), f32_ptr(sim, SIM.ped_vy)
    p_len, p_wid = f32_ptr(sim, SIM.ped_len), f32_ptr(sim, SIM.ped_wid)
    p_valid, p_here = u8_ptr(sim, SIM.ped_valid), u8_ptr(sim, SIM.ped_here)
    dist = f32_ptr(sim, SIM.cand_d)  # the world's scratch, as the contract allows
    R = float_field(prm, PARAMS.obs_radius)
    pos_s, max_v = float_field(prm, PARAMS.pos_scale), float_field(prm, PARAMS.max_speed)
    len_s, wid_s = float_field(prm, PARAMS.length_scale), float_field(prm, PARAMS.width_scale)
    wp_s, lat_s = float_field(prm, PARAMS.wp_scale), float_field(prm, PARAMS.lateral_scale)
    cscale = f32_ptr(prm, PARAMS.coeff_scale)
    NB = A + S + P
    base = w * cap
    for a in range(A):
        i = w * A + a
        if not active[i]:
            continue
        o = a * stride
        c, s, ex, ey = hc[i], hs[i], x[i], y[i]
        # ego (EGO_FEATURES of selfplaydrive.obs.layout, as the paper encoder writes them)
        k, n = wp_idx[i], num_wp[i]
        d0x = d0y = d1x = d1y = np.float32(0.0)
        if k < n:
            k1 = k + 1 if k + 1 < n else k
            ux, uy = wps[(i * K + k) * 2] - ex, wps[(i * K + k) * 2 + 1] - ey
            d0x, d0y = c * ux + s * uy, -s * ux + c * uy
            ux, uy = wps[(i * K + k1) * 2] - ex, wps[(i * K + k1) * 2 + 1] - ey
            d1x, d1y = c * ux + s * uy, -s * ux + c * uy
        out[o + 0] = _clip(width[i] / wid_s)
        out[o + 1] = _clip(length[i] / len_s)
        out[o + 2] = _clip(speed[i] / max_v)
        out[o + 3], out[o + 4] = _clip(d0x / wp_s), _clip(d0y / wp_s)
        out[o + 5], out[o + 6] = _clip(d1x / wp_s), _clip(d1y / wp_s)
        out[o + 7] = _clip(np.float32(n - k) / np.float32(K)) if K > 0 else np.float32(0.0)
        out[o + 8] = _clip(lane_s[i] / lat_s)
        out[o + 9] = _clip(lane_alpha[i] / np.float32(np.pi))
        out[o + 10] = np.float32(lane_valid[i])
        for j in range(NUM_COEFFS):
            out[o + 11 + j] = _clip(coeffs[i * NUM_COEFFS + j] / cscale[j])
        # squared distance of every body within the radius (inf: not a candidate)
        for b in range(NB):
            dx = dy = np.float32(np.inf)
            if b < A:
                j = w * A + b
                if b != a and (active[j] or obstacle[j]):
                    dx, dy = x[j] - ex, y[j] - ey
            elif b < A + S:
                j = w * S + b - A
                if st_valid[j]:
                    dx, dy = st_x[j] - ex, st_y[j] - ey
            else:
                j = w * P + b - A - S
                if p_valid[j] and p_here[j]:
                    dx, dy = p_x[j] - ex, p_y[j] - ey
            d2 = dx * dx + dy * dy
            dist[base + b] = d2 if d2 <= R * R else np.float32(np.inf)
        # the k nearest, one selection pass each (k is small); ties to the lower body index
        for t in range(k_max):
            r = o + EGO_DIM + t * OBJ_DIM
            best, bd = -1, np.float32(np.inf)
            for b in range(NB):
                if dist[base + b] < bd:
                    best, bd = b, dist[base + b]
            if best < 0:
                for f in range(OBJ_DIM):
                    out[r + f] = np.float32(0.0)
                continue
            dist[base + best] = np.float32(np.inf)
            if best < A:
                j = w * A + best
                bx, by, bc, bs = x[j], y[j], hc[j], hs[j]
                vx, vy, bl, bw = speed[j] * hc[j], speed[j] * hs[j], length[j], width[j]
            elif best < A + S:
                j = w * S + best - A
                bx, by, bc, bs = st_x[j], st_y[j], st_c[j], st_s[j]
                vx, vy, bl, bw = np.float32(0.0), np.float32(0.0), st_len[j], st_wid[j]
            else:
                j = w * P + best - A - S
                bx, by, bc, bs = p_x[j], p_y[j], p_c[j], p_s[j]
                vx, vy, bl, bw = p_vx[j], p_vy[j], p_len[j], p_wid[j]
            ux, uy = bx - ex, by - ey
            out[r + 0] = np.float32(1.0)
            out[r + 1] = _clip((c * ux + s * uy) / pos_s)
            out[r + 2] = _clip((-s * ux + c * uy) / pos_s)
            out[r + 3] = _clip(bc * c + bs * s)  # cos and sin of the heading relative to the ego's
            out[r + 4] = _clip(bs * c - bc * s)
            out[r + 5] = _clip(bl / len_s)
            out[r + 6] = _clip(bw / wid_s)
            out[r + 7] = _clip((c * vx + s * vy) / max_v)
            out[r + 8] = _clip((-s * vx + c * vy) / max_v)


def ego_objects_encoder(max_objects: int = 8, radius: float = 50.0, max_road: int = 0) -> KernelEncoder:
    """The cfunc as an encoder with its layout (Hydra's `_target_` of `obs=ego_objects`).

    Args:
        max_objects: k, the nearest bodies observed.
        radius: [m] observation radius and position scale.
        max_road: Accepted so that experiment files sized for the paper encoder compose
            (experiment=laptop, the default, sets obs.max_road=64); this encoder observes no
            road whatever its value.
    """
    del max_road
    return KernelEncoder.from_numba(
        "ego_objects", ego_objects, ObsLayout(max_objects=int(max_objects), max_road=0), radius=float(radius)
    )


def register() -> None:
    """Make `obs=ego_objects` a Hydra option of this process (keys: max_objects, radius)."""
    from hydra.core.config_store import ConfigStore

    node = {"_target_": f"{__name__}.ego_objects_encoder", "max_objects": 8, "radius": 50.0, "max_road": 0}
    ConfigStore.instance().store(group="obs", name="ego_objects", node=node)


TINY = (
    "trainer.total_steps=256",
    "trainer.rollout_length=16",
    "trainer.num_epochs=1",
    "trainer.eval_episodes=0",
    "trainer.progress_bar=false",
    "trainer.checkpoint_interval=0",
    "env.num_worlds=1",
    "spawner.num_agents=8",
    "spawner.num_static=8",
    "spawner.num_pedestrians=2",
    "spawner.episode_lengths=[2.0]",
    "spawner.min_region_lane_length=300",
    "map=procedural",
    "map.size=400",
    "map.num_roundabouts=0",
    "model=deepsets",
    "model.input_size=16",
    "model.hidden_size=32",
    "model.lstm_size=32",
)


def main(tiny: bool) -> None:
    from selfplaydrive.builder import build_env, build_model, compose, instantiate
    from selfplaydrive.testing.check_encoder import check_encoder
    from selfplaydrive.trainers.run import seed_everything, train_run

    register()
    overrides = ["obs=ego_objects", *(TINY if tiny else ("trainer.total_steps=20000",))]
    cfg = compose("train", overrides)
    env = build_env(cfg)
    report = check_encoder(env.encoder, env.maps[0], num_worlds=2, steps=20 if tiny else 60)
    print(f"check_encoder: {report}")
    print(f"layout {env.layout.blocks()} -> obs_dim {env.layout.obs_dim}")
    trainer = instantiate(cfg.trainer)
    seed_everything(int(cfg.seed), trainer.torch_threads)
    model = build_model(cfg, env)
    with tempfile.TemporaryDirectory() as run_dir:
        logger = instantiate(cfg.logger, _partial_=True)
        result = train_run(env, model, trainer, run_dir, logger=logger)
    print(f"trained {type(model).__name__} on obs=ego_objects: {result}")


if __name__ == "__main__":
    main(tiny="--tiny" in sys.argv or __import__("os").environ.get("SELFPLAYDRIVE_EXAMPLE_TINY") == "1")
