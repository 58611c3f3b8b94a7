"""Conda environments (envs/<stage>.yaml) and the cluster profile: every rule names an env that exists, is pinned,
covers every third-party import of the rule's script (its redsup modules included), and holds no path, so it
builds the same from Snakemake's copy .snakemake/conda/<hash>.yaml; redsup itself comes from PYTHONPATH."""
from __future__ import annotations

import ast
import hashlib
import os
import platform
import re
import shutil
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
import yaml

from redsup import jobenv

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "workflow"
ENV_FILES = sorted((ROOT / "envs").glob("*.yaml"))
# import name -> distribution on PyPI
DISTRIBUTIONS = {"cv2": "opencv-contrib-python-headless", "yaml": "pyyaml", "torch": "torch", "numpy": "numpy",
                 "pandas": "pandas", "matplotlib": "matplotlib", "scipy": "scipy", "shapely": "shapely",
                 "jsonschema": "jsonschema", "tqdm": "tqdm", "mlflow": "mlflow", "PIL": "pillow"}
PINNED = re.compile(r"^(?P<name>[A-Za-z0-9_.\-]+)==(?P<version>[0-9][0-9A-Za-z.+\-]*)$")


def _env(path: Path) -> dict:
    return yaml.safe_load(path.read_text())


def _pip(env: dict) -> list[str]:
    return next((d["pip"] for d in env["dependencies"] if isinstance(d, dict) and "pip" in d), [])


def _rules() -> dict[str, dict]:
    """rule name -> {env, script} from the rule files (the conda: and script: directives as written)."""
    out = {}
    for smk in sorted((PKG / "rules").glob("*.smk")):
        for block in re.split(r"\n(?=rule \w+:)", smk.read_text()):
            m = re.match(r"rule (\w+):", block)
            if not m:
                continue
            env = re.search(r'    conda:\n        ENVS\["(\w+)"\]', block)
            script = re.search(r'    script:\n        "\.\./scripts/(\w+\.py)"', block)
            out[m.group(1)] = {"file": smk.name, "env": env and env.group(1), "script": script and script.group(1)}
    return out


def _module_file(name: str) -> Path | None:
    p = PKG / Path(*name.split("."))
    if (p / "__init__.py").is_file():
        return p / "__init__.py"
    return p.with_suffix(".py") if p.with_suffix(".py").is_file() else None


def third_party_imports(script: Path) -> set[str]:
    """Top-level third-party modules imported by ``script`` and, transitively, by the redsup modules it imports
    (every import statement, function-level ones too: an over-approximation, never an omission)."""
    seen, found, todo = set(), set(), [script]
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            for name in names:
                top = name.split(".")[0]
                if top == "redsup":
                    parts = name.split(".")
                    todo += [f for i in range(1, len(parts) + 1) if (f := _module_file(".".join(parts[:i])))]
                elif top not in sys.stdlib_module_names and top != "snakemake":
                    found.add(top)
    return found


def unresolvable_entries(env_copy: Path) -> list[str]:
    """pip entries of an env file that name a local path which does not exist seen from where the file lies
    (conda runs pip from the env file's folder: ``-e ..`` in .snakemake/conda/ points at .snakemake/)."""
    bad = []
    for entry in _pip(_env(env_copy)):
        target = entry.removeprefix("-e").strip()
        if target.startswith((".", "/", "file:")):
            path = Path(target.removeprefix("file://"))
            if not (env_copy.parent / path).resolve().joinpath("pyproject.toml").is_file():
                bad.append(entry)
    return bad


def _snakemake_copy(env_file: Path, workdir: Path) -> Path:
    """Where Snakemake puts an env file: .snakemake/conda/<hash of its content>.yaml under the working directory."""
    digest = hashlib.md5(env_file.read_bytes()).hexdigest()
    copy = workdir / ".snakemake" / "conda" / f"{digest}.yaml"
    copy.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(env_file, copy)
    return copy


# ----------------------------------------------------------------------------------------------- tests
def test_every_rule_names_an_existing_stage_env():
    rules = _rules()
    assert len(rules) > 30
    stems = {p.stem for p in ENV_FILES}
    missing = {r: spec for r, spec in rules.items() if spec["env"] not in stems}
    assert not missing
    assert not (ROOT / "envs" / "redsup.yaml").exists()  # the old single env with "-e .." is gone
    assert {spec["env"] for spec in rules.values()} == stems  # no unused env file


def test_each_env_covers_its_rules_script_imports():
    envs = {p.stem: {PINNED.match(e).group("name").lower() for e in _pip(_env(p))} for p in ENV_FILES}
    for rule, spec in _rules().items():
        if spec["script"] is None:
            continue
        needed = third_party_imports(PKG / "scripts" / spec["script"])
        unknown = needed - set(DISTRIBUTIONS)
        assert not unknown, f"{rule}: add {unknown} to DISTRIBUTIONS"
        lacking = {DISTRIBUTIONS[m] for m in needed} - envs[spec["env"]]
        assert not lacking, f"rule {rule} ({spec['script']}) imports {sorted(lacking)}, not in envs/{spec['env']}.yaml"


def test_import_scan_sees_function_level_and_transitive_imports(tmp_path):
    script = tmp_path / "s.py"
    script.write_text("import os\nfrom redsup.jobenv import put_on_pythonpath\ndef f():\n    import torch\n")
    assert third_party_imports(script) == {"torch"}
    assert "torch" in third_party_imports(PKG / "scripts" / "depth_train.py")
    assert "torch" not in third_party_imports(PKG / "scripts" / "world_scene.py")


def test_the_venv_is_built_under_the_envs_pins():
    """`make venv` installs under envs/constraints.txt, which pins exactly the versions the envs pin (one each)."""
    lines = [x.strip() for x in (ROOT / "envs" / "constraints.txt").read_text().splitlines()]
    constraints = {x for x in lines if x and not x.startswith("#")}
    assert all(PINNED.match(x) for x in constraints)
    assert constraints == {e for p in ENV_FILES for e in _pip(_env(p))}
    makefile = (ROOT / "Makefile").read_text()
    assert makefile.count("pip install --quiet -c envs/constraints.txt -e") == 2  # venv, and cluster-test's extra


def test_envs_are_pinned_to_the_tested_versions():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "torch==2.13.0" in pyproject["project"]["dependencies"]
    for path in ENV_FILES:
        env = _env(path)
        assert env["channels"][0] == "conda-forge"
        assert "python=3.11" in env["dependencies"] and "pip" in env["dependencies"]
        for entry in _pip(env):
            m = PINNED.match(entry)
            assert m, f"{path.name}: {entry!r} is not pinned (name==version)"
            installed = metadata.version(m.group("name")).split("+")[0]
            assert m.group("version") == installed, f"{path.name}: {entry} but the tests run {installed}"
    assert "torch==2.13.0" in _pip(_env(ROOT / "envs" / "depth.yaml"))
    assert not any(e.startswith("torch") for e in _pip(_env(ROOT / "envs" / "data.yaml")))  # data stays torch-free


def test_envs_resolve_from_snakemakes_copy(tmp_path):
    for path in ENV_FILES:
        copy = _snakemake_copy(path, tmp_path)
        assert _env(copy) == _env(path)
        assert unresolvable_entries(copy) == [], path.name
    # the check fails on what the old env did: "-e .." seen from .snakemake/conda/ is .snakemake/
    old = tmp_path / "old.yaml"
    old.write_text("channels: [conda-forge]\ndependencies: [python=3.11, pip, {pip: ['-e ..']}]\n")
    assert (old.parent / "..").resolve() != ROOT
    assert unresolvable_entries(_snakemake_copy(old, tmp_path)) == ["-e .."]


def test_redsup_comes_from_pythonpath_in_a_bare_interpreter(tmp_path):
    """What a conda env's python sees: no site-packages (-S), only the PYTHONPATH the Snakefile sets, run from
    the env copy's folder."""
    environ = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    environ["PYTHONPATH"] = "/elsewhere"
    jobenv.put_on_pythonpath(str(PKG), environ)
    assert environ["PYTHONPATH"].split(os.pathsep) == [str(PKG), "/elsewhere"]
    jobenv.put_on_pythonpath(str(PKG), environ)  # once only
    assert environ["PYTHONPATH"].split(os.pathsep) == [str(PKG), "/elsewhere"]
    copy_dir = _snakemake_copy(ENV_FILES[0], tmp_path).parent
    out = subprocess.run([sys.executable, "-S", "-c", "import redsup, sys; print(redsup.__file__)"], cwd=copy_dir,
                         env=environ, capture_output=True, text=True, check=True).stdout.strip()
    assert Path(out) == PKG / "redsup" / "__init__.py"
    bare = subprocess.run([sys.executable, "-S", "-c", "import redsup"], cwd=copy_dir,
                          env={k: v for k, v in environ.items() if k != "PYTHONPATH"}, capture_output=True)
    assert bare.returncode != 0  # without it, a bare interpreter has no redsup: the variable is what makes it work
    assert 'redsup.jobenv.put_on_pythonpath(os.path.join(workflow.basedir, "workflow"))' in \
        (ROOT / "Snakefile").read_text()


_FAULTS = """
import resource
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    block = bytearray(40 << 20)             # above glibc's largest dynamic mmap threshold (32 MiB)
    block[::4096] = bytes(len(block) // 4096)  # touch every page
    del block
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's allocator variables")
def test_jobs_keep_freed_memory_instead_of_faulting_it_in_again():
    """A job that frees and reallocates a large block every step (a training step's activations) faults its pages in
    once with the Snakefile's allocator variables, and on every step without them."""
    base = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    tuned = dict(base)
    assert jobenv.keep_freed_memory(tuned) == jobenv.ALLOCATOR_ENV
    faults = [int(subprocess.run([sys.executable, "-c", _FAULTS], env=env, capture_output=True, text=True,
                                 check=True).stdout) for env in (base, tuned)]
    pages = (40 << 20) // 4096
    assert faults[0] > 15 * pages and faults[1] < 3 * pages, faults
    mine = {**base, "MALLOC_TRIM_THRESHOLD_": "0"}
    assert jobenv.keep_freed_memory(mine)["MALLOC_TRIM_THRESHOLD_"] == "0"  # a user's own setting stays
    assert "redsup.jobenv.keep_freed_memory()" in (ROOT / "Snakefile").read_text()


def test_slurm_profile_and_cluster_extra():
    """The SLURM profile works as written on a cluster without conda or accounting (docs/cluster.md): no software
    deployment (`--sdm conda` adds it), squeue for job status, no fixed threads or memory (they follow the size
    profile: config.yaml's `jobs`), only rules that exist; and the guide runs it without profiles/default."""
    assert not (ROOT / "profiles" / "slurm" / "config.yaml").exists()
    profile = yaml.safe_load((ROOT / "profiles" / "slurm" / "profile.yaml").read_text())
    assert profile["executor"] == "slurm" and "software-deployment-method" not in profile
    assert profile["slurm-status-command"] == "squeue"
    assert "set-threads" not in profile and "cores" not in profile
    rules = _rules()
    for rule, res in profile.get("set-resources", {}).items():
        assert rule in rules, f"profiles/slurm/profile.yaml names rule {rule!r}, which does not exist"
        assert not {"mem_mb", "runtime"} & set(res), f"{rule}: memory and time come from config.yaml's jobs"
    assert not {"mem_mb", "runtime", "slurm_account"} & set(profile.get("default-resources", {}))
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert any(e.startswith("snakemake-executor-plugin-slurm") for e in extras["cluster"])
    guide = (ROOT / "docs" / "cluster.md").read_text()
    assert "pip install -c envs/constraints.txt -e \".[cluster]\"" in guide
    assert "snakemake --workflow-profile none --profile profiles/slurm --config profile=paper" in guide
    assert yaml.safe_load((ROOT / "profiles" / "default" / "profile.yaml").read_text())["cores"] == "all"
