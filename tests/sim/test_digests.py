"""Pinned digests of the paper's rollout (sections 2.4, 2.6): a sha256 over every state buffer
after each of 400 steps, at 1 and 2 threads, recorded with the build before the physics models
became components (commit 458b183). A change that moves the paper configuration by one bit
fails here; a deliberate change updates the values in the same commit, saying why."""

from __future__ import annotations

import pytest
from sharedmaps import shared_map

from selfplaydrive.builder import make_env
from selfplaydrive.physics import BicycleModel, FrictionBicycleModel
from selfplaydrive.sim.actions import ContinuousActions
from selfplaydrive.testing.digest import rollout_digest

# (map, physics, actions) -> digest; 4 worlds, reset seed 0, actions from default_rng(1)
PINNED = {
    ("default", "friction", "discrete"): "0b945be3d15d0fd0b4f29a1e8327a256399c8c0bf7703495c47e42e2635ede64",
    ("default", "friction", "continuous"): "6c1c030f8a0a7be9534abc8ced4cfc5331581fa68b7625f60ac6a3bd81b66de5",
    ("default", "bicycle", "discrete"): "d06c4c0cfcebc0cb2237a280a07ff569891d34087cf4e799709534e4b85eeb0e",
    ("tartu", "friction", "discrete"): "7e2c998a7568265fb671ca46402f35f8cfdf0f32fbe890d097a18f9e0dbb20b2",
    ("tartu", "friction", "continuous"): "dc61984c20e5289fe046005f51945e35ef832ccc1adaa4c65d2a5c84eb4c0584",
    ("tartu", "bicycle", "discrete"): "db5eaf87e0381d39a7c62eb3c8d55b04be822019e44ab6df5b81221634bcb160",
}
PHYSICS = {"friction": FrictionBicycleModel, "bicycle": BicycleModel}


# every configuration at 1 thread, the paper's default (friction, discrete) at 2 threads too
CASES = [(k, 1) for k in PINNED] + [(k, 2) for k in PINNED if k[1:] == ("friction", "discrete")]


@pytest.mark.filterwarnings("ignore:PaperSpawner placed")
@pytest.mark.parametrize(("key", "threads"), CASES, ids=[f"{'-'.join(k)}-{t}t" for k, t in CASES])
def test_paper_rollout_digest_is_pinned(key, threads):
    map_name, physics, actions = key
    spec = "default" if map_name == "default" else str(shared_map("tartu_lanelet2/tartu_demo_l.osm"))
    kwargs = {"actions": ContinuousActions()} if actions == "continuous" else {}
    env = make_env(spec, num_worlds=4, seed=0, physics=PHYSICS[physics](), num_threads=threads, **kwargs)
    assert rollout_digest(env, steps=400) == PINNED[key]
