"""Packaging: the wheel carries the committed assets and calibration cards; where the package looks
for its data (environment variable, checkout, installed copy); writers never default into it."""

import os
import shutil
import subprocess
import sys
import zipfile

import pytest

from mani_skill_softvt import paths
from mani_skill_softvt.assets.cards import ASSET_IDS, PROP_NAMES, TWIN_IDS, load_card
from mani_skill_softvt.calibration.cards import load_calibration_card
from mani_skill_softvt.paths import REPO_DIR, data_dir, inside_installed_package, writable_default

DATA = "mani_skill_softvt/_data/"


def _committed(directory: str, pattern: str = "*") -> list[str]:
    """Files under the checkout's ``directory`` (relative, posix), leaving out dot-files and dot-dirs."""
    root = REPO_DIR / directory
    return sorted(p.relative_to(root).as_posix() for p in root.glob(pattern)
                  if p.is_file() and not any(part.startswith(".") for part in p.relative_to(root).parts))


@pytest.fixture(scope="module")
def wheel(tmp_path_factory):
    """The wheel of a copy of the checkout (a build in place would leave build/ in the repo)."""
    pytest.importorskip("setuptools", minversion="70.1")  # bdist_wheel built in: no build isolation needed
    src = tmp_path_factory.mktemp("src")
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "build")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO_DIR / name, src / name)
    for name in ("mani_skill_softvt", "asset-data", "calibration-data"):
        shutil.copytree(REPO_DIR / name, src / name, ignore=ignore)
    out = tmp_path_factory.mktemp("wheels")
    run = subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "--no-build-isolation",
                          "-w", str(out), "-q"], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    (whl,) = out.glob("*.whl")
    return whl


def test_wheel_ships_the_committed_assets_and_calibration_cards(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    cards = [f"objects/{a}/card.json" for a in ASSET_IDS + TWIN_IDS] + [f"props/{p}/card.json" for p in PROP_NAMES]
    assert set(cards) <= set(_committed("asset-data", "**/*"))
    missing = [f for f in _committed("asset-data", "**/*") if DATA + "assets/" + f not in names]  # cards, meshes, tets
    assert not missing, f"the wheel lacks committed asset files: {missing}"
    calibration = _committed("calibration-data", "*.json")
    assert len(calibration) == len(ASSET_IDS)
    missing = [f for f in calibration if DATA + "calibration/" + f not in names]
    assert not missing, f"the wheel lacks calibration cards: {missing}"
    # Neither the sweep logs (resuming a calibration) nor the plots (documentation) are read at run time.
    assert not [n for n in names if n.startswith(DATA + "calibration/") and n.count("/") > 3]
    # pyproject.toml lists the packages by hand: every module of the checkout must be in the wheel.
    modules = {p.relative_to(REPO_DIR).as_posix() for p in (REPO_DIR / "mani_skill_softvt").rglob("*.py")}
    assert not modules - names, f"modules missing from the wheel (add their package to pyproject.toml): " \
                                f"{sorted(modules - names)}"


def test_the_campaign_is_its_own_distribution_and_the_library_wheel_ships_none_of_it(wheel, tmp_path):
    """The baselines and the studies (campaign/) are a sibling distribution, as ManiSkill keeps its
    baselines in examples/: its wheel carries every campaign module and registers the baselines'
    policy kind; the library's wheel carries only the one-release aliases of their old paths."""
    src = tmp_path / "campaign"
    shutil.copytree(REPO_DIR / "campaign", src, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "build"))
    run = subprocess.run([sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "--no-build-isolation",
                          "-w", str(tmp_path), "-q"], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    (campaign_wheel,) = tmp_path.glob("softvt_campaign-*.whl")
    names = set(zipfile.ZipFile(campaign_wheel).namelist())
    modules = {p.relative_to(REPO_DIR / "campaign").as_posix() for p in (REPO_DIR / "campaign").rglob("*.py")}
    assert modules and not modules - names, sorted(modules - names)
    (entry_points,) = [n for n in names if n.endswith("entry_points.txt")]
    assert "diffusion_policy = softvt_campaign.baselines.agent:POLICY_FILES" in \
        zipfile.ZipFile(campaign_wheel).read(entry_points).decode()
    library = {n for n in zipfile.ZipFile(wheel).namelist() if n.endswith(".py")}
    assert {n for n in library if "/baselines/" in n or "/studies/" in n} == \
        {"mani_skill_softvt/baselines/__init__.py", "mani_skill_softvt/studies/__init__.py"}


def test_installed_wheel_finds_its_assets_and_cards(wheel, tmp_path):
    site = tmp_path / "site"
    run = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "--target", str(site),
                          str(wheel), "-q"], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    code = ("import mani_skill_softvt as m, mani_skill_softvt.paths as p\n"
            "from mani_skill_softvt.assets import load_card, load_prop\n"
            "from mani_skill_softvt.calibration.cards import load_calibration_card\n"
            "print(m.__file__, p.ASSETS_DIR, p.CALIBRATION_DIR, sep='\\n')\n"
            "assert load_card('soft_stw_cube_hq').mass > 0 and load_card('rigid_stw_cube_hq').convex_parts()\n"
            "assert load_prop('basket').convex_parts()\n"
            "assert load_calibration_card('soft_stw_cube_hq').g_max > 0\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith("SOFTVT_")} | {"PYTHONPATH": str(site)}
    run = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr
    package, assets, calibration = run.stdout.splitlines()[-3:]
    installed = site / "mani_skill_softvt"
    assert package == str(installed / "__init__.py")
    assert (assets, calibration) == (str(installed / "_data" / "assets"), str(installed / "_data" / "calibration"))


def _layouts(tmp_path):
    """A checkout (this project's pyproject.toml beside the package) and an installed package."""
    repo = tmp_path / "repo"
    (repo / "mani_skill_softvt").mkdir(parents=True)
    (repo / "pyproject.toml").write_text('[project]\nname = "mani-skill-softvt"\n')
    site = tmp_path / "site-packages"
    (site / "mani_skill_softvt" / "_data").mkdir(parents=True)
    return repo, site


def test_data_dirs_resolve_env_then_checkout_then_installed_copy(tmp_path, monkeypatch):
    repo, site = _layouts(tmp_path)
    installed = site / "mani_skill_softvt" / "_data"
    monkeypatch.delenv("SOFTVT_ASSETS_DIR", raising=False)
    assert data_dir("SOFTVT_ASSETS_DIR", "assets", repo_dir=repo, installed_dir=installed) == repo / "asset-data"
    assert data_dir("SOFTVT_ASSETS_DIR", "assets", repo_dir=site, installed_dir=installed) == installed / "assets"
    # Another project's pyproject.toml beside the package is not a checkout of this one.
    (site / "pyproject.toml").write_text('[project]\nname = "something-else"\n')
    assert data_dir("SOFTVT_ASSETS_DIR", "assets", repo_dir=site, installed_dir=installed) == installed / "assets"
    # The environment variable wins over both; an empty one counts as unset.
    monkeypatch.setenv("SOFTVT_ASSETS_DIR", str(tmp_path / "mine"))
    for repo_dir in (repo, site):
        assert data_dir("SOFTVT_ASSETS_DIR", "assets", repo_dir=repo_dir, installed_dir=installed) == tmp_path / "mine"
    monkeypatch.setenv("SOFTVT_ASSETS_DIR", "")
    assert data_dir("SOFTVT_ASSETS_DIR", "assets", repo_dir=repo, installed_dir=installed) == repo / "asset-data"
    assert paths.running_from_checkout()  # this test session


def test_writers_refuse_to_default_into_the_installed_package(tmp_path, monkeypatch, capsys):
    repo, site = _layouts(tmp_path)
    package = site / "mani_skill_softvt"
    default = package / "_data" / "calibration"
    assert inside_installed_package(default, package) and not inside_installed_package(tmp_path / "out", package)
    with pytest.raises(ValueError, match=r"inside the installed package.*pass --out DIR.*SOFTVT_CALIBRATION_DIR"):
        writable_default(default, "--out", "SOFTVT_CALIBRATION_DIR", package)
    assert writable_default(tmp_path / "out", "--out", "SOFTVT_CALIBRATION_DIR", package) == tmp_path / "out"
    # In a checkout the package directory holds code only: its top-level data dirs are writable.
    assert not inside_installed_package(repo / "mani_skill_softvt" / "x", repo / "mani_skill_softvt")

    # The commands themselves, as installed: a usage error before any work.
    from mani_skill_softvt.cli import calibrate, demos
    from mani_skill_softvt.assets import build

    monkeypatch.setattr(paths, "PACKAGE_DIR", package)
    monkeypatch.setattr(build, "ASSETS_DIR", package / "_data" / "assets")
    monkeypatch.setattr(calibrate, "CALIBRATION_DIR", default)
    monkeypatch.setattr(demos, "DEMOS_DIR", package / "_data" / "demos")
    for main, argv, var in ((build.main, ["--only", "table"], "SOFTVT_ASSETS_DIR"),
                            (calibrate.main, ["--quick"], "SOFTVT_CALIBRATION_DIR"),
                            (demos.main, ["generate", "--tasks", "3", "--num", "1"], "SOFTVT_DEMOS_DIR"),
                            (demos.main, ["render", "--tasks", "3"], "SOFTVT_DEMOS_DIR")):
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and "--out DIR" in err and var in err and str(package) in err, err
    # An explicit --out is honoured.
    build.main(["--only", "table", "--out", str(tmp_path / "assets")])
    assert (tmp_path / "assets" / "props" / "table" / "card.json").is_file()
    assert not (package / "_data" / "assets").exists()


def test_missing_cards_name_the_directory_the_variable_and_the_remedy(tmp_path, monkeypatch):
    # From a checkout: regenerate there.
    with pytest.raises(FileNotFoundError, match=rf"searched {tmp_path}; set SOFTVT_ASSETS_DIR.*assets\.build"):
        load_card("soft_pastry001", tmp_path)
    with pytest.raises(FileNotFoundError, match=rf"searched {tmp_path}; set SOFTVT_CALIBRATION_DIR.*calibrate --assets"):
        load_calibration_card("soft_pastry001", tmp_path)
    # Installed: the data comes with the package, never "rebuild into site-packages".
    monkeypatch.setattr(paths, "REPO_DIR", tmp_path / "site-packages")
    for load, var in ((load_card, "SOFTVT_ASSETS_DIR"), (load_calibration_card, "SOFTVT_CALIBRATION_DIR")):
        with pytest.raises(FileNotFoundError) as err:
            load("soft_pastry001", tmp_path)
        message = str(err.value)
        assert str(tmp_path) in message and var in message and "reinstall the package" in message, message
        assert "build" not in message and "calibrate" not in message, message


@pytest.mark.slow  # in CI's slow pass: the default run keeps under its 10-minute budget
def test_an_old_command_path_runs_the_command_and_says_where_it_moved():
    """``python -m mani_skill_softvt.compare`` (an old path, one release) runs ``cli.compare`` and
    names the new path on stderr; the paths README keeps (``.evaluate``) print no such note."""
    old = subprocess.run([sys.executable, "-m", "mani_skill_softvt.compare", "--help"], capture_output=True,
                         text=True, timeout=300, cwd=REPO_DIR)
    assert old.returncode == 0 and "--a A" in old.stdout
    assert "moved to python -m mani_skill_softvt.cli.compare (or softvt-compare)" in old.stderr
    kept = subprocess.run([sys.executable, "-m", "mani_skill_softvt.evaluate", "--help"], capture_output=True,
                          text=True, timeout=300, cwd=REPO_DIR)
    assert kept.returncode == 0 and "moved to" not in kept.stderr
