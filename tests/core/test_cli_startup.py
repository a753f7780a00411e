"""``jaxfdi --help``, ``jaxfdi run --help``, ``jaxfdi --version`` and a refused option import no
JAX and no study: the CLI's registry names each study's module, imported when the command
runs, and ``import jaxfdi`` imports its names on first use (PEP 562). Read from
``python -X importtime`` (every module a process imports, once), not from a clock."""

import ast
import os
import pathlib
import re
import subprocess
import sys
import types
from importlib import metadata

import pytest

import jaxfdi
from jaxfdi import checks, cli

#: what a start-up must not import: JAX and the libraries only the studies need
HEAVY = ("jax", "jaxlib", "optax", "scipy", "matplotlib", "pandas")
#: a fixed terminal width, so that argparse wraps the subprocess's help as it does here
COLUMNS = "100"


def run_jaxfdi(*args):
    """``python -X importtime -m jaxfdi <args>``: (exit status, stdout, stderr without the
    import lines, the modules imported)."""
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", "-m", "jaxfdi", *args],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "COLUMNS": COLUMNS},
    )
    imported, err = [], []
    for line in proc.stderr.splitlines():
        found = re.match(r"import time:\s+\d+ \|\s+\d+ \| *(\S+)$", line)
        if found:
            imported.append(found.group(1))
        elif not line.startswith("import time:"):
            err.append(line)
    return proc.returncode, proc.stdout, err, imported


def heavy(imported):
    return sorted(
        m for m in imported if m.split(".")[0] in HEAVY or m.startswith("jaxfdi.scenarios")
    )


def parser_output(monkeypatch, capsys, argv):
    """What the parser prints here for ``argv`` (help or version), at the same width."""
    monkeypatch.setenv("COLUMNS", COLUMNS)
    with pytest.raises(SystemExit) as stop:
        cli.build_parser().parse_args(argv)
    assert stop.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["tune", "--help"], ["--version"]])
def test_help_and_version_import_no_jax_and_print_what_the_parser_prints(monkeypatch, capsys, argv):
    status, out, err, imported = run_jaxfdi(*argv)
    assert status == 0 and err == [], err
    assert "jaxfdi.cli" in imported and heavy(imported) == []
    assert out == parser_output(monkeypatch, capsys, argv)
    if argv == ["--version"]:
        assert out == f"jaxfdi {metadata.version('jaxfdi')}\n"
    elif argv == ["--help"]:
        assert out.startswith("usage: jaxfdi [-h] [--version] {run,tune,list} ...")
        assert all(f"  {name}  " in out for name in [*cli.RUNNERS, *cli.TUNERS])


def test_a_refused_option_exits_2_before_importing_jax():
    status, out, err, imported = run_jaxfdi("run", "engine-chi2", "--runs", "0")
    assert status == 2 and out == ""
    assert err == ["jaxfdi: --runs: expected an integer in [1, 2147483647], got 0"]
    assert heavy(imported) == []


def test_import_jaxfdi_imports_no_jax_until_a_name_is_used():
    code = (
        "import sys, jaxfdi; assert 'jax' not in sys.modules, 'import jaxfdi'; "
        "jaxfdi.Fault; assert 'jax' in sys.modules; print(jaxfdi.Fault.__module__)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stdout == "jaxfdi._simulation.faults\n", proc.stderr


def test_every_public_name_is_its_modules_object_and_listed_by_dir():
    for name in jaxfdi.__all__:
        value = getattr(jaxfdi, name)
        if name in jaxfdi._WHERE:
            assert value is getattr(sys.modules[jaxfdi._WHERE[name]], name), name
        elif isinstance(value, types.ModuleType):
            assert value is sys.modules[f"jaxfdi.{name}"], name
        else:
            assert name in ("enable_x64", "enable_compilation_cache"), name
    assert set(jaxfdi.__all__) <= set(dir(jaxfdi))
    assert (
        jaxfdi._simulation.faults is sys.modules["jaxfdi._simulation.faults"]
    )  # a module of the package, as before
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        jaxfdi.no_such_name


def test_the_lazy_names_are_the_type_checking_imports():
    """``_EXPORTS`` (what ``__getattr__`` imports) and the ``if TYPE_CHECKING:`` imports (what
    type checkers and the API page read) name the same things."""
    tree = ast.parse(pathlib.Path(jaxfdi.__file__).read_text())
    (block,) = [
        n
        for n in tree.body
        if isinstance(n, ast.If) and getattr(n.test, "id", "") == "TYPE_CHECKING"
    ]
    imports = {n.module: tuple(a.name for a in n.names) for n in block.body}
    submodules = imports.pop("jaxfdi")
    assert {m: sorted(v) for m, v in imports.items()} == {
        m: sorted(v) for m, v in jaxfdi._EXPORTS.items()
    }
    assert sorted(jaxfdi.__all__) == sorted(
        [*jaxfdi._WHERE, *submodules, "enable_x64", "enable_compilation_cache"]
    )


def test_the_clis_seed_limit_is_the_librarys():
    assert cli.MAX_SEED == checks.MAX_SEED
