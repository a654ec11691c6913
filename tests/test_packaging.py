"""Installed like any package (issue 15, item 8): one import name, and every file of the data folders
shipped. The install itself is checked by .ci/run (README "Using it"): pip install . into a fresh venv,
then watflex-sim list / run laser_arm_step / diagnose from another directory."""
import fnmatch
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_one_import_name_and_every_data_file_is_package_data():
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert {p.split(".")[0] for p in tool["packages"]} == {"watflex_sim"}
    for package, folder in tool["package-dir"].items():
        if not package.startswith("watflex_sim.data."):
            continue
        patterns = tool["package-data"][package]
        files = [p.name for p in (ROOT / folder).iterdir() if p.is_file()]
        assert files and all(any(fnmatch.fnmatch(f, pat) for pat in patterns) for f in files), (folder, files)
    assert {tool["package-dir"][f"watflex_sim.data.{d}"] for d in ("models", "rigs", "scenarios", "sweeps")} \
        == {"models", "rigs", "scenarios", "sweeps"}


def test_every_python_package_of_the_project_is_installed():
    """Every folder of watflex_sim/ and controllers/ with an __init__.py is a package pyproject names: setuptools
    installs the listed ones only, and until 2026-12-07 `watflex_sim.diagnosis` was not listed, so `diagnose` failed
    on import in every non-editable install (the wheel had no file of it)."""
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    where = {folder: package for package, folder in tool["package-dir"].items()}
    found = set()
    for init in [*(ROOT / "watflex_sim").rglob("__init__.py"), *(ROOT / "controllers").rglob("__init__.py")]:
        folder = init.parent.relative_to(ROOT).as_posix()
        found.add(where.get(folder, folder.replace("/", ".")))
    assert "watflex_sim.diagnosis" in found and found <= set(tool["packages"]), found - set(tool["packages"])
