"""The package layout: every module in the layer table, no import upwards or sideways."""

import ast
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
from conftest import ROOT

PACKAGE = ROOT / "partcal"
TABLE = re.compile(r"^\| (\d+) \| `(partcal/[\w/]+\.py)` \|", re.MULTILINE)


def layer_table() -> dict[str, int]:
    """``{"partcal/robot/kinematics.py": 1, ...}`` from docs/architecture.md."""
    return {path: int(layer) for layer, path in TABLE.findall((ROOT / "docs" / "architecture.md").read_text())}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_modules(me: str, source: str) -> list[tuple[int, str]]:
    """Every partcal module that the file ``me`` (repo-relative) imports anywhere, as ``(line, dotted name)``."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names if a.name.split(".")[0] == "partcal"]
        elif isinstance(node, ast.ImportFrom):
            target = import_source(me, node)
            if target.split(".")[0] != "partcal":
                continue
            # "from . import x" may name a module x of that package
            for alias in node.names:
                candidate = f"{target}.{alias.name}"
                out.append((node.lineno, candidate if _file_of(candidate) else target))
    return out


def import_source(me: str, node: ast.ImportFrom) -> str:
    """The dotted module that ``from ... import`` in file ``me`` (repo-relative) imports from."""
    if not node.level:
        return node.module or ""
    path = ROOT / me
    package = module_name(path) if path.name == "__init__.py" else module_name(path).rsplit(".", 1)[0]
    base = package.split(".")[: len(package.split(".")) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


def _file_of(dotted: str) -> str | None:
    rel = Path(*dotted.split("."))
    for candidate in (rel.with_suffix(".py"), rel / "__init__.py"):
        if (ROOT / candidate).is_file():
            return candidate.as_posix()
    return None


def test_every_module_is_in_the_layer_table():
    table = layer_table()
    files = sorted(p.relative_to(ROOT).as_posix() for p in PACKAGE.rglob("*.py"))
    assert [f for f in files if f not in table] == [], "add these modules to docs/architecture.md"
    assert [f for f in table if f not in files] == [], "docs/architecture.md lists modules that do not exist"
    assert len([p for p in PACKAGE.glob("*.py")]) <= 8


def violations(me: str, source: str, table: dict[str, int]) -> list[str]:
    """The imports of file ``me`` that go to a higher layer or a sibling folder of the same layer."""
    out = []
    for line, dotted in imported_modules(me, source):
        target = _file_of(dotted)
        if target is None:
            out.append(f"{me}:{line}: imports {dotted}, which is not a module of partcal")
            continue
        same_folder = Path(target).parent == Path(me).parent
        if not (table[target] < table[me] or (table[target] == table[me] and same_folder)):
            out.append(f"{me}:{line} (layer {table[me]}) imports {dotted} (layer {table[target]})")
    return out


def test_no_module_imports_from_a_higher_layer_or_a_sibling_folder():
    table = layer_table()
    problems = []
    for path in sorted(PACKAGE.rglob("*.py")):
        me = path.relative_to(ROOT).as_posix()
        problems += violations(me, path.read_text(), table)
    assert problems == []


def import_graph(sources: dict[str, str]) -> dict[str, set[str]]:
    """``{file: files it imports}`` over ``sources`` (``{repo-relative path: source}``), every import counted."""
    graph = {}
    for me, source in sources.items():
        targets = {_file_of(dotted) for _, dotted in imported_modules(me, source)}
        graph[me] = {t for t in targets if t is not None and t != me}
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The circles of an import graph: each group of files that reach each other (Tarjan's strongly
    connected components of more than one file), sorted."""
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def package_sources() -> dict[str, str]:
    return {p.relative_to(ROOT).as_posix(): p.read_text() for p in sorted(PACKAGE.rglob("*.py"))}


def test_no_circle_of_imports():
    """No module reaches itself through what it imports (function-local and type-checking imports count:
    they hide a circle, they do not remove it)."""
    assert import_circles(import_graph(package_sources())) == []


def test_the_checker_finds_a_circle():
    sources = package_sources()
    sources["partcal/metrics.py"] += "\ndef later():\n    from .study import runner\n"
    circles = import_circles(import_graph(sources))
    assert any({"partcal/metrics.py", "partcal/study/runner.py"} <= set(c) for c in circles), circles
    sources = {"partcal/models/base.py": "from .features import x\n", "partcal/models/features.py": "def f():\n    from . import base\n"}
    assert import_circles(import_graph(sources)) == [["partcal/models/base.py", "partcal/models/features.py"]]


def test_the_checker_refuses_upward_and_sideways_imports():
    table = layer_table()
    code = textwrap.dedent("""
        from ..errors import PartcalError
        def later():
            from ..study import config
            import partcal.models.series
    """)
    assert violations("partcal/robot/kinematics.py", code, table) == [
        "partcal/robot/kinematics.py:4 (layer 1) imports partcal.study.config (layer 4)",
        "partcal/robot/kinematics.py:5 (layer 1) imports partcal.models.series (layer 3)",
    ]
    sideways = violations("partcal/data/measurements.py", "from ..models.features import varying_inputs\n", table)
    assert sideways == ["partcal/data/measurements.py:1 (layer 3) imports partcal.models.features (layer 3)"]
    assert violations("partcal/study/config.py", "from ..models import series\nfrom . import persist\n", table) == []


def test_subpackages_import():
    code = "import partcal, partcal.robot, partcal.data, partcal.models, partcal.study, partcal.report"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr


def test_old_model_files_still_load():
    """Files written by partcal 0.1.0 (before the layout change) load and predict what they predicted then.

    The Cartesian ones predict as a fresh fit does. Joint-space partitions are scaled per joint since
    (a fresh fit finds other regions), so the k-means file is held to the predictions partcal made from
    it before that change (``v0.1_fdp-ai-kmeans.expected.json``).
    """
    import json

    from partcal import ErrorModel, Octree, PartitionedErrorModel, load_predictor, read_measurements

    m = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
    fresh = {
        "v0.1_sdp-ci.json": ErrorModel(degree=2, solver="lstsq").fit(m.nominal_mm, m.errors_mm),
        "v0.1_fdp-ci-octree.json": PartitionedErrorModel(partition=Octree(max_depth=1, min_samples=12),
                                                         local=ErrorModel(solver="lstsq"), random_state=0)
                                   .fit(m.nominal_mm, m.errors_mm),
    }
    for name, model in fresh.items():
        p = load_predictor(ROOT / "tests" / "fixtures" / name)
        np.testing.assert_allclose(p.predict(positions=m.nominal_mm), model.predict(m.nominal_mm), atol=1e-9,
                                   err_msg=name)
    then = json.loads((ROOT / "tests" / "fixtures" / "v0.1_fdp-ai-kmeans.expected.json").read_text())
    now = load_predictor(ROOT / "tests" / "fixtures" / "v0.1_fdp-ai-kmeans.json").predict(joints=m.q_deg)
    np.testing.assert_allclose(now, then["predictions"], rtol=0, atol=1e-12)


def readme_python_example() -> str:
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.DOTALL)
    assert len(blocks) == 1, "the README has one Python example"
    return blocks[0]


def test_readme_python_example_runs(tmp_path):
    """The README's Python example, executed as written (after a run made the model file it loads)."""
    from partcal import read_measurements
    from partcal.robot.trajectories import paper_path
    from partcal.study.config import load_config
    from partcal.study.outputs import write_run
    from partcal.study.runner import run

    work = tmp_path / "work"
    (work / "data").mkdir(parents=True)
    (work / "data" / "sk120").symlink_to(ROOT / "data" / "sk120")
    (work / "configs").mkdir()
    text = (ROOT / "configs" / "paper_sk120.yaml").read_text()
    text = text.replace("../data/", str(ROOT / "data") + "/").replace("sk120_virtual.yaml", str(ROOT / "configs" / "sk120_virtual.yaml"))
    text = text.replace("patience: null", "patience: 30")      # a short swarm: the example needs a model file, not the paper's numbers
    (work / "configs" / "paper_sk120.yaml").write_text(text)
    write_run(run(load_config(work / "configs" / "paper_sk120.yaml")))
    assert (work / "reports" / "paper_sk120" / "models" / "sdp-ci.json").is_file()
    targets = paper_path("rectangle")[:20]
    namespace = {}
    code = readme_python_example()
    import os
    here = os.getcwd()
    os.chdir(work)
    try:
        exec(compile(code, "README.md", "exec"), namespace)      # noqa: S102 - our own README
    finally:
        os.chdir(here)
    m = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
    assert namespace["m"].errors_mm.shape == (85, 3)
    np.testing.assert_allclose(namespace["p"].compensate(targets) + namespace["p"].predict(
        positions=namespace["p"].compensate(targets)), targets, atol=1e-3)
    assert namespace["regional"].region_counts_.tolist() == [44, 20, 21]      # as the README says
    np.testing.assert_array_equal(namespace["targets_mm"], read_measurements(
        ROOT / "data" / "sk120" / "test_rectangle.csv").nominal_mm)
    np.testing.assert_array_equal(namespace["m"].q_deg, m.q_deg)


# ---------------------------------------------------------------------- private names stay in their module
def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _own_names(tree: ast.AST) -> set[str]:
    """The names a module defines itself: functions, classes, assigned names, attributes set on self/cls."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            out.add(node.id)
        elif (isinstance(node, ast.Attribute) and isinstance(node.ctx, (ast.Store, ast.Del))
              and isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
            out.add(node.attr)
    return out


def private_uses(me: str, source: str) -> list[str]:
    """The private names (one leading underscore, not a dunder) that file ``me`` takes from another module:
    ``x._name`` where ``x`` is not ``self``, ``cls`` or ``super()`` and ``_name`` is not defined in the file
    itself, and ``from partcal.x import _name`` (a private module, such as ``_io``, may be imported: it is the
    package's own). Each as ``"file:line: what"``."""
    tree = ast.parse(source)
    own = _own_names(tree)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr) and node.attr not in own:
            x = node.value
            if isinstance(x, ast.Name) and x.id in ("self", "cls"):
                continue
            if isinstance(x, ast.Call) and isinstance(x.func, ast.Name) and x.func.id == "super":
                continue
            out.append(f"{me}:{node.lineno}: {ast.unparse(x)}.{node.attr}")
        elif isinstance(node, ast.ImportFrom):
            target = import_source(me, node)
            for alias in node.names:
                if _private(alias.name) and target.split(".")[0] == "partcal" and not _file_of(f"{target}.{alias.name}"):
                    out.append(f"{me}:{node.lineno}: from {'.' * node.level}{node.module or ''} import {alias.name}")
    return sorted(out, key=lambda s: (s.split(":")[0], int(s.split(":")[1])))




def test_no_private_name_is_used_across_modules():
    """Objects talk through public names: no module reaches into another's private functions, methods or
    attributes (tests may)."""
    uses = [u for me, source in package_sources().items() for u in private_uses(me, source)]
    assert uses == [], "give these a public name"


def test_the_checker_finds_private_uses():
    code = textwrap.dedent("""
        from .ik import _take_step, solve
        from .. import _io
        from ._io import write_atomic
        class Robot:
            def _walk(self):
                return self._rows, super()._x, cls._y
        def f(robot, other):
            robot._trig(1)
            other._walk()
            return robot.__class__, np.random._bit_generator
    """)
    assert private_uses("partcal/robot/compensation.py", code) == [
        "partcal/robot/compensation.py:2: from .ik import _take_step",
        "partcal/robot/compensation.py:9: robot._trig",
        "partcal/robot/compensation.py:11: np.random._bit_generator",
    ]


NUMERIC = ("numpy", "scipy", "pandas", "sklearn")


def numeric_imports(source: str) -> list[str]:
    """The numeric libraries a file imports anywhere (functions included), as ``line: name``."""
    out = []
    for node in ast.walk(ast.parse(source)):
        names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                 [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else [])
        out += [f"{node.lineno}: {n}" for n in names if n.split(".")[0] in NUMERIC]
    return out


def test_the_command_line_parses_and_calls_the_layer_below():
    """cli.py parses arguments, calls the study layer and maps errors to exit codes: it stays under 400 lines,
    imports no numeric library, and building its parser (every subcommand, the choices read from their
    tables) loads none either (a table's module is read when its option is used)."""
    source = (PACKAGE / "cli.py").read_text()
    assert len(source.splitlines()) < 400
    assert numeric_imports(source) == []
    code = ("import sys; from partcal.cli import build_parser; build_parser(); "
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {NUMERIC!r}))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 0 and res.stdout.strip() == "[]", res.stderr + res.stdout


def test_the_numeric_import_check_finds_them():
    code = "import argparse\ndef f():\n    import numpy as np\n    from scipy.optimize import least_squares\n"
    assert numeric_imports(code) == ["3: numpy", "4: scipy.optimize"]
    assert numeric_imports("from .metrics import pooled_rms\nimport numbers\n") == []
