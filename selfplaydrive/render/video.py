"""Writing rendered frames: PNG files, animated GIF (Pillow), MP4 (imageio + imageio-ffmpeg).

Pillow comes with matplotlib, so PNG and GIF always work. MP4 needs the optional `video` extra
(`pip install selfplaydrive[video]`: imageio and imageio-ffmpeg, which bundles an ffmpeg
binary); without it `write_video` raises a `RuntimeError` that says so.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from selfplaydrive._optional import requires_extra
from selfplaydrive.errors import MissingExtraError

__all__ = ["FORMATS", "has_mp4", "png_paths", "write_video"]

FORMATS = (".png", ".gif", ".mp4")


def has_mp4() -> bool:
    """Whether MP4 writing is available (imageio and imageio-ffmpeg importable)."""
    try:
        with requires_extra("video"):
            import imageio  # noqa: F401
            import imageio_ffmpeg  # noqa: F401
    except MissingExtraError:  # a probe: absence is an answer here, not an error
        return False
    return True


def check_output(path: str | os.PathLike[str]) -> str:
    """The lower-case suffix of `path` if it is one of `FORMATS`.

    Raises:
        ValueError: Another suffix.
        RuntimeError: '.mp4' without imageio-ffmpeg.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(
            f"output {str(path)!r}: expected a file ending in {', '.join(FORMATS)}, got {suffix!r}"
        )
    if suffix == ".mp4" and not has_mp4():
        raise RuntimeError(
            f"output {str(path)!r}: MP4 needs imageio and imageio-ffmpeg "
            "(pip install 'selfplaydrive[video]'); write a .gif or .png instead"
        )
    return suffix


def png_paths(path: str | os.PathLike[str], count: int) -> list[Path]:
    """Files that `write_video` writes for `count` frames to a .png `path`: the path itself for
    one frame, else `<stem>_0000.png`, `<stem>_0001.png` ... beside it."""
    path = Path(path)
    if count == 1:
        return [path]
    return [path.with_name(f"{path.stem}_{i:04d}{path.suffix}") for i in range(count)]


def write_video(frames: Iterable[np.ndarray], path: str | os.PathLike[str], fps: float = 10.0) -> list[Path]:
    """Write RGB frames to `path`; the suffix picks the format.

    - `.png`: one PNG per frame (`png_paths`); frames are written as they come.
    - `.gif`: animated GIF, looping, `1000 / fps` ms per frame (GIF stores delays in 10 ms
      units, so 10 fps is exact). Frames are quantised to 256 colours each (adaptive palette)
      and kept in memory until the end (about size^2 bytes per frame).
    - `.mp4`: H.264 (yuv420p) via imageio-ffmpeg, streamed; the frame size must be divisible
      by 16 or ffmpeg scales it up to the next multiple.

    Args:
        frames: (H, W, 3) uint8 arrays, all the same size.
        path: Output file; parent folders are created.
        fps: Frames per second of the animation (default 10 = real time at dt = 0.1 s).

    Returns:
        The files written.

    Raises:
        ValueError: Bad suffix or fps, no frames, or frames of another shape or dtype.
        RuntimeError: '.mp4' without imageio-ffmpeg.
    """
    suffix = check_output(path)
    if not (np.isfinite(fps) and 0 < fps <= 1000):
        raise ValueError(f"fps: expected a number in (0, 1000], got {fps!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    checked = _checked(frames)
    if suffix == ".png":
        return _write_pngs(checked, path)
    if suffix == ".gif":
        return [_write_gif(checked, path, fps)]
    return [_write_mp4(checked, path, fps)]


def _checked(frames: Iterable[np.ndarray]) -> Iterable[np.ndarray]:
    shape = None
    for i, f in enumerate(frames):
        f = np.asarray(f)
        if f.dtype != np.uint8 or f.ndim != 3 or f.shape[2] != 3:
            raise ValueError(f"frame {i}: expected an (H, W, 3) uint8 RGB array, got {f.shape} {f.dtype}")
        if shape is not None and f.shape != shape:
            raise ValueError(f"frame {i}: shape {f.shape} differs from the first frame's {shape}")
        shape = f.shape
        yield f
    if shape is None:
        raise ValueError("frames: expected at least one frame, got none")


def _write_pngs(frames: Iterable[np.ndarray], path: Path) -> list[Path]:
    # frame count unknown up front: write numbered files, rename to the bare path if only one
    written = []
    for i, f in enumerate(frames):
        out = path.with_name(f"{path.stem}_{i:04d}{path.suffix}")
        Image.fromarray(f).save(out, compress_level=1)  # fast; PNG stays lossless
        written.append(out)
    if len(written) == 1:
        os.replace(written[0], path)
        written = [path]
    return written


def _write_gif(frames: Iterable[np.ndarray], path: Path, fps: float) -> Path:
    images = [Image.fromarray(f).quantize(colors=256, method=Image.Quantize.FASTOCTREE) for f in frames]
    duration = round(1000.0 / fps)
    images[0].save(
        path, save_all=True, append_images=images[1:], duration=duration, loop=0, optimize=False, disposal=1
    )
    return path


def _write_mp4(frames: Iterable[np.ndarray], path: Path, fps: float) -> Path:
    with requires_extra("video"):
        import imageio.v2 as imageio

    with imageio.get_writer(path, fps=fps, codec="libx264", quality=7, pixelformat="yuv420p") as writer:
        for f in frames:
            writer.append_data(f)
    return path


# the whole pipeline: what `selfplaydrive render` runs ----------------------------------------
def render_episode(
    output: str | os.PathLike[str],
    map_spec: str = "default",
    driver: str = "rule_based",
    steps: int = 200,
    world: int = 0,
    num_worlds: int | None = None,
    seed: int = 0,
    fps: float = 10.0,
    follow: int | None = None,
    size: int = 800,
    view: float | None = None,
    tail: int = 30,
    every: int = 1,
    waypoints: bool = True,
    text: bool = True,
    deterministic: bool = True,
    env: Any = None,
) -> dict[str, object]:
    """Build an env on `map_spec` (or take `env`), drive it with `driver` for `steps` steps,
    draw world `world` and write `output` (.png frames, .gif or .mp4).

    Args:
        output: Output file (suffix picks the format, see `write_video`).
        map_spec: `load_map` spec: "default", a .osm/.xodr/.npz path, "procedural:seed=S".
        driver: "rule_based", "random", "static" or a checkpoint path (`make_policy`).
        steps: Env steps (frames: steps + 1, then every `every`-th is kept).
        world: The world drawn.
        num_worlds: Worlds in the env (default world + 1).
        seed: Seed of the env's reset (and of the random driver).
        fps: Frames per second of GIF / MP4.
        follow: Agent slot the camera follows (None: the whole 200 m region).
        size, view, tail, waypoints, text: `EpisodeRenderer` arguments.
        every: Keep every `every`-th frame.
        deterministic: Checkpoint policies take the most likely action.
        env: A `VecEnv` to drive instead of building one with `make_env(map_spec,
            num_worlds)` (`selfplaydrive render` passes the env of its Hydra config); it is
            reset with `seed`.

    Returns:
        {"files": written paths, "frames": count, "record_s": seconds stepping the env,
        "render_s": seconds drawing and writing, "render_fps": frames / render_s}.

    Raises:
        ValueError, RuntimeError: Bad arguments (named in the message); MapError for bad maps.
    """
    import time

    from selfplaydrive.builder import make_env
    from selfplaydrive.policies import make_policy
    from selfplaydrive.render.episode import EpisodeRenderer
    from selfplaydrive.render.record import record_episode

    check_output(output)
    renderer_args = {"size": size, "follow": follow, "view": view, "tail": tail, "waypoints": waypoints}
    renderer_args["text"] = text
    if int(world) != world or world < 0:
        raise ValueError(f"world: expected an integer >= 0, got {world!r}")
    if env is None:
        env = make_env(map_spec, num_worlds=num_worlds or world + 1, seed=seed)
    elif world >= env.num_worlds:
        raise ValueError(f"world: expected a world in [0, {env.num_worlds}) (env.num_worlds), got {world!r}")
    if follow is not None and not 0 <= follow < env.agents_per_world:
        raise ValueError(f"follow: expected an agent slot in [0, {env.agents_per_world}), got {follow!r}")
    policy = make_policy(driver, env, seed=seed, deterministic=deterministic)
    t0 = time.perf_counter()
    rec = record_episode(env, policy, steps, world=world, seed=seed)
    t1 = time.perf_counter()
    renderer = EpisodeRenderer(rec.maps, **renderer_args)
    files = write_video(renderer.frames(rec, every=every), output, fps=fps)
    t2 = time.perf_counter()
    count = len(range(0, len(rec.frames), every))
    return {
        "files": files,
        "frames": count,
        "record_s": t1 - t0,
        "render_s": t2 - t1,
        "render_fps": count / max(t2 - t1, 1e-9),
    }
