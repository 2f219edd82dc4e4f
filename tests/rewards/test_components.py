"""Reward terms as components (paper section 2.3, issue #13): the paper's terms through the ABI
give the paper's reward; one term written as Python, numba cfunc and Cython package gives the
same values; composition by name and weight; clear errors for bad components."""

from __future__ import annotations

import hashlib
import importlib
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from loadfile import load_file

import selfplaydrive
from selfplaydrive.builder import build_env, compose
from selfplaydrive.errors import ConfigError
from selfplaydrive.maps.loader import load_map
from selfplaydrive.rewards import TERM_NAMES, KernelTerm, LinearReward, get_term, registered_terms
from selfplaydrive.scenario.spawner import PaperSpawner
from selfplaydrive.sim import VecEnv

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
COEF, LIMIT = 0.05, 6.0  # a low limit, so random driving exceeds it


class SpeedLimit:
    """The example term in NumPy (examples/06_term_python.py)."""

    name = "speed_limit"

    def __call__(self, state):
        return -np.float32(COEF) * np.maximum(state.speed - np.float32(LIMIT), np.float32(0.0))


@pytest.fixture(scope="module")
def road_map():
    return load_map("default")


@pytest.fixture(scope="module")
def cython_term(tmp_path_factory):
    """examples/speed_limit_cython built against get_include() in a temporary folder."""
    from selfplaydrive.testing.build import build_component_package

    target = build_component_package(EXAMPLES / "speed_limit_cython", tmp_path_factory.mktemp("cy"))
    sys.path.insert(0, str(target))
    try:
        module = importlib.import_module("speed_limit_term")
        yield module.speed_limit_term(COEF, LIMIT)
    finally:
        sys.path.remove(str(target))
        from selfplaydrive.rewards import components

        components._REGISTRY.pop("speed_limit", None)  # loaded from the entry point by a test


@pytest.fixture(scope="module")
def numba_term():
    pytest.importorskip("numba")
    module = load_file(EXAMPLES / "07_term_numba.py", "example_07")
    return module.speed_limit_term(COEF, LIMIT)


def rollout(road_map, reward=None, steps=60, threads=1, worlds=3, **kw):
    """(digest of every output buffer, per-step reward_terms, the env) of a fixed random rollout."""
    env = VecEnv(road_map, PaperSpawner(), worlds, seed=5, num_threads=threads, reward=reward, **kw)
    env.reset(5)
    rng = np.random.default_rng(2)
    h, terms = hashlib.sha256(), []
    for _ in range(steps):
        env.step(np.stack([rng.integers(3, 7, env.num_agents), rng.integers(0, 13, env.num_agents)], axis=1))
        for a in (
            env.observations,
            env.rewards,
            env.reward_terms,
            env.terminations,
            env.truncations,
            env.masks,
        ):
            h.update(np.ascontiguousarray(a).tobytes())
        terms.append(env.reward_terms.copy())
    return h.hexdigest(), np.stack(terms), env


def test_paper_reward_is_the_default_in_python_and_hydra(road_map):
    default, _, env = rollout(road_map)
    assert env.term_names == TERM_NAMES and env.reward_terms.shape == (env.num_agents, 8)
    explicit, _, _ = rollout(road_map, LinearReward({n: 1.0 for n in TERM_NAMES}))
    assert explicit == default
    cfg = compose("sim")
    assert dict(cfg.reward.terms) == {n: 1.0 for n in TERM_NAMES}
    assert build_env(cfg, maps=[road_map], num_worlds=1).reward.names == TERM_NAMES


def test_hydra_reward_terms_select_and_weigh(road_map):
    env = build_env(compose("sim", ["reward.terms.collision=0.5", "~reward.terms.comfort"]), maps=[road_map])
    assert "comfort" not in env.term_names and len(env.term_names) == 7
    assert dict((c.name, c.weight) for c in env.reward.columns)["collision"] == 0.5
    with pytest.raises(ConfigError, match=r"'nope' is unknown; valid terms: waypoint, collision"):
        build_env(compose("sim", ["+reward.terms.nope=1.0"]), maps=[road_map])


def test_three_forms_of_one_term_agree(road_map, numba_term, cython_term):
    paper = {n: 1.0 for n in TERM_NAMES}
    cols = {}
    for form, term in (("python", SpeedLimit()), ("numba", numba_term), ("cython", cython_term)):
        _, terms, env = rollout(road_map, LinearReward({**paper, "speed_limit": 1.0}, terms=[term]))
        assert env.term_names[-1] == "speed_limit"
        cols[form] = terms[:, :, -1]
    assert (cols["python"] < 0).sum() > 50  # the term is not trivially zero
    np.testing.assert_allclose(cols["numba"], cols["python"], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(cols["cython"], cols["python"], rtol=1e-6, atol=1e-7)


def test_compiled_terms_are_deterministic_across_threads(road_map, numba_term, cython_term):
    reward = LinearReward(
        {"collision": 1.0, "speed_limit": 0.5, "sl2": 2.0}, terms=[numba_term, cython_term.renamed("sl2")]
    )
    one, terms, _ = rollout(road_map, reward, threads=1)
    assert one == rollout(road_map, reward, threads=2)[0]
    np.testing.assert_allclose(terms[:, :, 2], 4.0 * terms[:, :, 1], rtol=1e-6)  # weights 0.5 and 2


def test_weights_scale_columns_and_the_reward_is_their_sum(road_map):
    _, base, _ = rollout(road_map)
    _, half, env = rollout(road_map, LinearReward({**{n: 1.0 for n in TERM_NAMES}, "center": 0.5}))
    k = TERM_NAMES.index("center")
    np.testing.assert_array_equal(half[:, :, k], (base[:, :, k] * np.float32(0.5)).astype(np.float32))
    np.testing.assert_allclose(env.rewards, env.reward_terms.sum(axis=1), rtol=1e-5, atol=1e-7)
    stats = env.pop_episode_stats() or []
    for rec in stats:
        assert list(rec["terms"]) == list(TERM_NAMES)


def test_a_python_term_replaces_a_registered_one(road_map):
    class Collision:
        """The paper's collision term in NumPy: -C_collision (1 + 0.1 v) on contact."""

        name = "collision"

        def __call__(self, state):
            hit = (state.events & 3) != 0
            c = state.coeffs[:, 1]
            return np.where(hit, -c * (np.float32(1.0) + np.float32(0.1) * state.speed), 0).astype(np.float32)

    _, base, _ = rollout(road_map, steps=80)
    _, replaced, env = rollout(
        road_map, LinearReward({n: 1.0 for n in TERM_NAMES}, terms=[Collision()]), steps=80
    )
    assert not env.reward.columns[1].native and env.term_names == TERM_NAMES
    k = TERM_NAMES.index("collision")
    assert (base[:, :, k] < 0).sum() > 0
    np.testing.assert_allclose(replaced[:, :, k], base[:, :, k], rtol=1e-5, atol=1e-6)


def test_unknown_names_and_bad_weights_are_config_errors():
    with pytest.raises(ConfigError, match="'colision' is unknown; valid terms: waypoint, collision, offroad"):
        LinearReward({"colision": 1.0})
    with pytest.raises(ConfigError, match="finite"):
        LinearReward({"collision": float("nan")})
    with pytest.raises(ConfigError, match="expected a number"):
        LinearReward({"collision": "1"})
    with pytest.raises(ConfigError, match="two terms are named"):
        LinearReward({"speed_limit": 1.0}, terms=[SpeedLimit(), SpeedLimit()])
    many = [KernelTerm(f"t{k}", get_term("collision").address) for k in range(65)]
    with pytest.raises(ConfigError, match="at most 64"):
        LinearReward({t.name: 1.0 for t in many}, terms=many)
    with pytest.raises(ConfigError, match="LinearReward"):
        VecEnv(load_map("default"), PaperSpawner(), 1, reward=["collision"])
    assert registered_terms()[:8] == TERM_NAMES
    from selfplaydrive.rewards import describe_terms

    assert describe_terms()[1][:2] == ("collision", "builtin") and "C_collision" in describe_terms()[1][2]


def test_wrong_signatures_are_refused():
    from selfplaydrive._sim import reward as kernels

    with pytest.raises(ConfigError, match=r"signature is 'void \(sd_sim \*, sd_params const \*, int\)'"):
        KernelTerm.from_capsule("x", kernels.__pyx_capi__["finalize_world"])
    with pytest.raises(ConfigError, match="exports no cdef function 'nope'"):
        KernelTerm.from_cython("x", kernels, "nope")
    with pytest.raises(ConfigError, match="expected a PyCapsule"):
        KernelTerm.from_capsule("x", 1234)
    with pytest.raises(ConfigError, match="positive integer"):
        KernelTerm("x", 0)


def test_wrong_numba_signature_is_refused():
    numba = pytest.importorskip("numba")

    @numba.cfunc(numba.types.void(numba.types.voidptr, numba.types.int32))
    def wrong(p, w):  # pragma: no cover - never called
        pass

    with pytest.raises(ConfigError, match=r"the cfunc's signature is .*expected"):
        KernelTerm.from_numba("x", wrong)
    with pytest.raises(ConfigError, match="expected a numba cfunc"):
        KernelTerm.from_numba("x", lambda: None)


def test_python_term_errors_name_the_term(road_map):
    class Bad:
        name = "bad_term"

        def __init__(self, out):
            self.out = out

        def __call__(self, state):
            return self.out(state)

    for out, match in (
        (lambda s: np.zeros(3, np.float32), r"'bad_term': expected an output of shape \(\d+,\)"),
        (lambda s: np.full(s.speed.shape, np.nan, np.float32), r"'bad_term': wrote nan for agent slot"),
    ):
        env = VecEnv(road_map, PaperSpawner(), 1, reward=LinearReward({"bad_term": 1.0}, terms=[Bad(out)]))
        env.reset(0)
        with pytest.raises(ValueError, match=match):
            env.step(np.zeros((env.num_agents, 2), np.int64))
    with pytest.raises(ConfigError, match="__call__"):
        LinearReward({"x": 1.0}, terms=[type("T", (), {"name": "x"})()])


def test_abi_declarations_ship_with_the_package_and_agree():
    """The header and the .pxd declare the same fields in the same order (the C compiler only
    sees the header; Cython only the .pxd)."""
    inc = Path(selfplaydrive.get_include())
    header = (inc / "selfplaydrive_abi.h").read_text()
    pxd = (inc / "selfplaydrive_abi.pxd").read_text()
    text = re.sub(r"/\*.*?\*/", "", header, flags=re.S)
    for struct, cname in (("Sim", "sim"), ("Params", "params"), ("Atlas", "atlas")):
        body = re.search(rf"typedef struct sd_{cname} \{{(.*?)\}}", text, flags=re.S).group(1)
        c_fields = [" ".join(d.split()).replace(" *", "*") for d in body.split(";") if d.strip()]
        block = re.search(rf'ctypedef struct {struct} "sd_{cname}":\n((?:        .*\n)+)', pxd).group(1)
        pxd_fields = [" ".join(line.split()) for line in block.splitlines()]
        assert c_fields == pxd_fields, struct
    for name in re.findall(r"\bSD_([A-Z_0-9]+) = ", header):
        assert f'{name} "SD_{name}"' in pxd
    from selfplaydrive.rewards import ABI_VERSION

    assert re.search(r"#define SELFPLAYDRIVE_ABI_VERSION (\d+)", header).group(1) == str(ABI_VERSION)


def test_numba_view_has_the_c_layout():
    pytest.importorskip("numba")
    from selfplaydrive._sim.reward import abi_sizes
    from selfplaydrive.rewards.numba_abi import struct_dtype

    sizes = abi_sizes()
    for struct in ("sim", "params", "atlas"):
        assert struct_dtype(struct).itemsize == sizes[struct], struct


def test_single_term_components_equal_the_fused_pass(road_map):
    """The default plan writes the paper's eight columns in one call (`term_paper`); the eight
    single-term components (used when the terms are selected in another order, or apart) give
    the same values bit for bit."""
    from selfplaydrive._sim.reward import paper_group_address

    assert LinearReward().plan()[0][0] == paper_group_address()
    assert [p[0] for p in LinearReward().plan()[1:]] == [0] * 7
    reversed_reward = LinearReward({n: 1.0 for n in reversed(TERM_NAMES)})
    assert all(p[0] not in (0, paper_group_address()) for p in reversed_reward.plan())
    _, base, _ = rollout(road_map, steps=80)
    _, rev, env = rollout(road_map, reversed_reward, steps=80)
    assert env.term_names == TERM_NAMES[::-1]
    np.testing.assert_array_equal(rev[:, :, ::-1], base)
    # a weight other than 1 keeps the fused call
    weighted = LinearReward({**{n: 1.0 for n in TERM_NAMES}, "align": 3.0})
    assert weighted.plan()[0][0] == paper_group_address()


def test_an_installed_term_is_found_by_name_with_args_from_hydra(road_map, cython_term):
    """The Cython package declares an entry point (selfplaydrive.reward_terms): installed, its
    term is named like a built-in one, from Python and from the Hydra reward group, and its
    parameters come from the config."""
    from selfplaydrive.rewards import registered_terms

    assert "speed_limit" in registered_terms()
    base = {n: 1.0 for n in TERM_NAMES}
    _, want, _ = rollout(road_map, LinearReward({**base, "speed_limit": 1.0}, terms=[cython_term]))
    _, got, _ = rollout(
        road_map, LinearReward({**base, "speed_limit": {"weight": 1.0, "args": [COEF, LIMIT]}})
    )
    np.testing.assert_array_equal(got, want)
    cfg = compose("sim", [f"+reward.terms.speed_limit={{weight:2.0,args:[{COEF},{LIMIT}]}}"])
    env = build_env(cfg, maps=[road_map], num_worlds=1)
    assert env.term_names[-1] == "speed_limit" and env.reward.columns[-1].term.args == (
        pytest.approx(COEF),
        pytest.approx(LIMIT),
    )
    assert env.reward.columns[-1].weight == 2.0
    with pytest.raises(ConfigError, match="args are for compiled terms"):
        LinearReward({"speed_limit": {"args": [1.0]}}, terms=[SpeedLimit()])
    with pytest.raises(ConfigError, match="unknown keys"):
        LinearReward({"collision": {"wieght": 1.0}})
    with pytest.raises(ConfigError, match="args must be finite numbers"):
        LinearReward({"speed_limit": {"args": ["fast"]}})


def test_compare_terms_checks_a_port_and_names_the_first_difference(road_map, numba_term):
    from selfplaydrive.testing.terms import compare_terms

    assert compare_terms(SpeedLimit(), numba_term, road_map, steps=30) <= 1e-6

    class Off(SpeedLimit):
        def __call__(self, state):
            return super().__call__(state) * np.float32(1.01)

    with pytest.raises(AssertionError, match=r"'speed_limit': step \d+, agent slot \d+: reference"):
        compare_terms(SpeedLimit(), Off(), road_map, steps=30)


def test_a_compiled_term_writing_nan_is_reported_by_name(road_map):
    numba = pytest.importorskip("numba")
    from selfplaydrive.rewards.numba_abi import SIGNATURE, SIM, int_field, u8_ptr

    @numba.cfunc(SIGNATURE)
    def broken(sim, prm, atlas, args, w, out, stride):  # pragma: no cover - compiled
        A = int_field(sim, SIM.A)
        active = u8_ptr(sim, SIM.active)
        for a in range(A):
            if active[w * A + a]:
                out[a * stride] = np.float32(np.nan)

    term = KernelTerm.from_numba("broken", broken)
    env = VecEnv(
        road_map, PaperSpawner(), 1, reward=LinearReward({"collision": 1.0, "broken": 1.0}, terms=[term])
    )
    env.reset(0)
    with pytest.raises(ValueError, match=r"reward term 'broken' \(numba\): wrote nan for agent slot"):
        env.step(np.zeros((env.num_agents, 2), np.int64))
    assert not VecEnv(road_map, PaperSpawner(), 1)._check_compiled  # the paper's terms: no check


def test_register_term_makes_a_name_selectable():
    from selfplaydrive.rewards import components, register_term

    class Zero:
        name = "zero_term_for_test"

        def __call__(self, state):
            return np.zeros_like(state.speed)

    try:
        register_term(Zero())
        assert "zero_term_for_test" in registered_terms()
        assert LinearReward({"collision": 1.0, "zero_term_for_test": 1.0}).names[-1] == "zero_term_for_test"
        with pytest.raises(ConfigError, match="already registered"):
            register_term(Zero())
        register_term(Zero(), replace=True)
    finally:
        components._REGISTRY.pop("zero_term_for_test", None)
    with pytest.raises(ConfigError, match="is not registered"):
        get_term("zero_term_for_test")
