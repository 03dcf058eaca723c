"""Every subcommand's --help and every node's console script --help work (and print examples)."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ppod_nodes.cli.main import SUBCOMMANDS, main
from ppod_nodes.launch.ros_launch import EXECUTABLES


@pytest.mark.parametrize("name", sorted(SUBCOMMANDS))
def test_every_subcommand_prints_its_help_with_examples(name, capsys):
    with pytest.raises(SystemExit) as exit_:
        main([name, "--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    assert f"ppod {name}" in out and "example" in out


def test_every_benchmark_prints_its_help(capsys):
    from ppod_nodes.cli.bench import _benchmarks

    names = sorted(_benchmarks())
    assert names, "no benchmark found"
    for name in names:
        with pytest.raises(SystemExit) as exit_:
            main(["bench", name, "--help"])
        assert exit_.value.code == 0, name
        assert f"ppod bench {name}" in capsys.readouterr().out


def _script(name: str) -> str:
    found = Path(sys.executable).with_name(name)
    return str(found) if found.exists() else (shutil.which(name) or name)


@pytest.mark.parametrize("executable", sorted(EXECUTABLES.values()))
def test_every_node_console_script_prints_its_parameters(executable):
    path = _script(executable)
    assert Path(path).exists(), f"console script {executable} is not installed (pyproject [project.scripts])"
    done = subprocess.run([path, "--help"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"usage: {executable}")
    assert "parameters" in done.stdout and "example:" in done.stdout


def test_console_scripts_and_the_launch_table_agree():
    import tomllib

    pyproject = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    scripts = pyproject["project"]["scripts"]
    for module, executable in EXECUTABLES.items():
        assert scripts[executable] == f"{module}:main"
