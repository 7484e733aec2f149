"""The package's layering, read from its import statements (no simulator needed).

Each concept lives in one place and depends only downwards: these checks keep the boundaries
that a newcomer relies on when reading one layer without the others.
"""

import ast
from pathlib import Path

import pytest

import mani_skill_softvt
import softvt_campaign

PACKAGE = Path(mani_skill_softvt.__file__).parent
# The campaign's distribution (campaign/): the baselines and the studies, above the library.
CAMPAIGN = Path(softvt_campaign.__file__).parent


def _root(path: Path) -> Path:
    """The folder holding ``path``'s top-level package."""
    return CAMPAIGN.parent if path.is_relative_to(CAMPAIGN) else PACKAGE.parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(_root(path)).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
CAMPAIGN_MODULES = {_module_name(p): p for p in CAMPAIGN.rglob("*.py")}
# Old module paths kept for one release as thin re-exports of where their code moved (each says
# where): they are not part of the layering, and go with the next release.
ALIASES = {"mani_skill_softvt.motionplanning", "mani_skill_softvt.replay", "mani_skill_softvt.serve",
           "mani_skill_softvt.evaluation.maniskill_dp", "mani_skill_softvt.baselines", "mani_skill_softvt.studies",
           "mani_skill_softvt.evaluate", "mani_skill_softvt.compare", "mani_skill_softvt.gallery",
           "mani_skill_softvt.warmup", "mani_skill_softvt.grasp_demo", "mani_skill_softvt.calibrate", "mani_skill_softvt.demos",
           "mani_skill_softvt.campaign_alias", "mani_skill_softvt.policy", "mani_skill_softvt.observations",
           "mani_skill_softvt.actions", "mani_skill_softvt.numerics", "mani_skill_softvt.stack"}


def imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, anywhere in the file (lazy imports included), as absolute
    names (``mani_skill_softvt.physics.fem``, ``warp``). ``from . import x`` imports the module
    ``x``, not its package's ``__init__``."""
    rel = path.relative_to(_root(path)).with_suffix("")
    package = list(rel.parts[:-1])
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            names = {f"{mod}.{a.name}" for a in node.names}
            out |= names if node.module is None and names <= set(MODULES) | set(CAMPAIGN_MODULES) else {mod} | names
    return out


def imports_any(path: Path, prefixes: tuple[str, ...]) -> list[str]:
    return sorted(m for m in imported_modules(path) if any(m == p or m.startswith(p + ".") for p in prefixes))


SIMULATORS = ("warp", "newton", "sapien", "mani_skill", "mani_skill_softvt.physics.fem",
              "mani_skill_softvt.physics.coupling")


@pytest.mark.parametrize("module", ["assets/cards.py", "assets/materials.py"])
def test_asset_cards_and_their_material_type_import_no_simulator(module):
    assert imports_any(PACKAGE / module, SIMULATORS) == []


def test_the_env_reaches_its_objects_only_through_the_object_interface():
    """FEM bodies and rigid twins sit behind tasks.objects: the env imports neither back end."""
    backends = ("mani_skill_softvt.physics.fem", "mani_skill_softvt.physics.coupling", "mani_skill_softvt.physics.rigid")
    assert imports_any(PACKAGE / "tasks/soft_body_env.py", backends) == []
    source = (PACKAGE / "tasks/soft_body_env.py").read_text()
    for branch in ("self._world", "self._rigid", "self._coupling", "RigidObject", "SoftBodyWorld"):
        assert branch not in source, branch


def test_the_action_contract_needs_no_simulator():
    """A policy, a converter or a data file reads actions (modes, gripper encodings, the base frame)
    without ManiSkill's agent: contracts/actions.py imports only the pure transforms."""
    assert imports_any(PACKAGE / "contracts/actions.py", SIMULATORS) == []
    modules = {m for m in imports_any(PACKAGE / "contracts/actions.py", ("mani_skill_softvt",)) if m in MODULES}
    assert modules == {"mani_skill_softvt.physics.transforms", "mani_skill_softvt.provenance"}


def test_provenance_imports_nothing_of_the_package():
    """Every module that writes or reads a file may take its markers from provenance/; the numerics are
    pinned from there before anything else loads, so neither imports anything of the package."""
    for module in ("provenance/__init__.py", "provenance/numerics.py"):
        assert imports_any(PACKAGE / module, ("mani_skill_softvt",)) == [], module
    for consumer in (PACKAGE / "evaluation/policies.py", CAMPAIGN / "baselines/features.py",
                     PACKAGE / "integrations/openpi/remote.py"):
        assert "mani_skill_softvt.tasks.robot" not in imported_modules(consumer), consumer


@pytest.mark.parametrize("module", ["rollout.py", "integrations/lerobot/env.py", "expert/grasp_script.py"])
def test_handling_a_blow_up_needs_no_fem(module):
    """The rollout, the LeRobot env and the grasp script catch SimulationInstabilityError; they take it
    from physics/errors.py, not from the FEM (Warp, Newton)."""
    assert imports_any(PACKAGE / module, ("mani_skill_softvt.physics.fem",)) == []


def test_the_policy_contract_imports_nothing_of_the_package():
    assert imports_any(PACKAGE / "contracts/policy.py", ("mani_skill_softvt",)) == []


def test_galleries_are_commands_not_part_of_the_concepts_they_picture():
    assert not (PACKAGE / "assets/gallery.py").exists() and not (PACKAGE / "tactile/gallery.py").exists()
    for path in (PACKAGE / "assets").glob("*.py"):
        assert imports_any(path, ("mani_skill_softvt.cli.gallery", "mani_skill_softvt.gallery")) == [], path


# Observation keys are spelled in the contract (mani_skill_softvt/contracts/observations.py) and nowhere a
# consumer reads them.
CONSUMERS = [PACKAGE / m for m in ("integrations/openpi/remote.py", "integrations/openpi/serve.py",
                                    "integrations/lerobot/export.py", "evaluation/videos.py", "demonstrations/render.py",
                                    "evaluation/policies.py")] + \
            [CAMPAIGN / m for m in ("baselines/features.py", "baselines/dataset.py", "baselines/agent.py")]
KEY_SPELLINGS = ('"agent/qpos"', '"extra/tcp_pose"', "sensor_data/", '"tactile/', "tactile/{", '"base_camera"',
                 '"hand_camera"', '"marker_initial"', '["agent"]', '["extra"]', '["sensor_data"]')


@pytest.mark.parametrize("module", CONSUMERS, ids=lambda p: _module_name(p))
def test_consumers_take_observation_keys_from_the_contract(module):
    source = module.read_text()
    assert [k for k in KEY_SPELLINGS if k in source] == []
    assert "mani_skill_softvt.contracts.observations" in imported_modules(module)


def test_one_flattener_and_one_info_reader():
    for path in [*PACKAGE.rglob("*.py"), *CAMPAIGN.rglob("*.py")]:
        if path == PACKAGE / "contracts" / "observations.py":
            continue
        tree = ast.parse(path.read_text())
        names = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
        assert not names & {"flatten_batch", "info_bool", "_flag", "_np", "unbatch"}, path


def test_one_episode_loop():
    """Evaluation episodes, expert demonstrations and calibration trials are rollouts
    (mani_skill_softvt/rollout.py); the only other env.step calls are the DSR wrapper passing a
    step on, the LeRobot env passing on a step of LeRobot's own loop (lerobot-eval), ManiSkill's
    action converters' signature (replay.py) and the kernel warm-up."""
    stepping = sorted(str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py") if "env.step(" in p.read_text())
    assert stepping == ["cli/warmup.py", "evaluation/wrapper.py", "integrations/lerobot/env.py", "integrations/maniskill/replay.py",
                        "rollout.py"]


def test_data_keeps_file_formats_and_does_not_plan():
    for path in (PACKAGE / "data").glob("*.py"):
        assert imports_any(path, ("mani_skill_softvt.expert", "mani_skill_softvt.evaluation",
                                  "mani_skill_softvt.calibration")) == [], path


def _module_graph() -> dict[str, set[str]]:
    """Every package module -> the package modules it imports (lazy imports included)."""
    return {name: {m for m in imported_modules(path) if m in MODULES and m not in (name, "mani_skill_softvt")}
            for name, path in MODULES.items() if name not in ALIASES}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan)."""
    index, low, stack, on, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_module_imports_itself_back():
    """No two modules import each other, through any chain (lazy imports count: they hide a
    dependency, they do not remove it)."""
    assert _cycles(_module_graph()) == []


def _package_graph() -> dict[str, set[str]]:
    """Every subpackage (``physics``, ``tasks``...) or top-level module -> those it imports."""
    def unit(module: str) -> str:
        parts = module.split(".")
        return parts[1] if len(parts) > 1 else parts[0]

    graph: dict[str, set[str]] = {}
    for name, deps in _module_graph().items():
        graph.setdefault(unit(name), set()).update(unit(d) for d in deps if unit(d) != unit(name))
    return graph


def test_no_package_imports_itself_back():
    """The packages form layers: assets below physics (the FEM reads the materials), the
    calibration cards and their statistics below the tasks that read them; what drives the
    simulator to calibrate sits above (expert/calibration_trials.py, expert/grasp_script.py)."""
    graph = _package_graph()
    assert _cycles(graph) == []
    assert "physics" not in graph["assets"]
    assert not graph["calibration"] & {"tasks", "expert", "data", "evaluation"}


def test_the_core_library_imports_no_integration():
    """ManiSkill's tools, LeRobot and openpi plug into the library (integrations/); the library's own
    packages never reach up into them: the commands and the baselines may use them."""
    core = ("assets", "physics", "tactile", "calibration", "tasks", "expert", "data", "evaluation", "demonstrations",
            "rollout",
            "contracts", "provenance", "parallel", "fileio", "paths", "version", "settings")
    for name, deps in _module_graph().items():
        if name != "mani_skill_softvt" and name.split(".")[1] in core:
            assert not [d for d in deps if d.startswith("mani_skill_softvt.integrations")], name


def test_the_commands_sit_on_top():
    """cli/ holds the commands (argument parsing and output); no library module imports one."""
    for name, path in MODULES.items():
        if name not in ALIASES and not name.startswith("mani_skill_softvt.cli"):
            assert imports_any(path, ("mani_skill_softvt.cli",)) == [], name


def test_the_library_never_imports_the_campaign():
    """The campaign (campaign/: the baselines and the studies) sits above the library as its own
    distribution: policies load through the evaluation's door (evaluation/policies.py), where the
    baselines register their policy files as an entry point, so the dependency points one way. Only
    the one-release aliases of the old paths name it."""
    for name, path in MODULES.items():
        if name not in ALIASES:
            assert imports_any(path, ("softvt_campaign",)) == [], name
    agent = imported_modules(CAMPAIGN / "baselines/agent.py")
    assert "softvt_campaign.baselines.train" not in agent  # evaluating a policy needs no trainer


def test_the_campaign_has_no_cycle_and_reaches_the_library_only_through_its_public_modules():
    graph = {name: {m for m in imported_modules(path) if m in CAMPAIGN_MODULES and m not in (name, "softvt_campaign")}
             for name, path in CAMPAIGN_MODULES.items()}
    assert _cycles(graph) == []
    for name, path in CAMPAIGN_MODULES.items():
        assert not [m for m in imported_modules(path) if m.startswith("mani_skill_softvt") and
                    any(part.startswith("_") and not part.startswith("__") for part in m.split("."))], name


@pytest.mark.parametrize("old,new", [("policy", "contracts.policy"), ("observations", "contracts.observations"),
                                     ("actions", "contracts.actions"), ("numerics", "provenance.numerics"),
                                     ("stack", "provenance.stack")])
def test_a_moved_module_is_its_old_path_for_one_release(old, new):
    """Code (and a pickle) naming the old path gets the moved module itself, not a copy of it."""
    import importlib

    assert importlib.import_module(f"mani_skill_softvt.{old}") is importlib.import_module(f"mani_skill_softvt.{new}")
    assert f"mani_skill_softvt.{new}" in (PACKAGE / f"{old}.py").read_text()
