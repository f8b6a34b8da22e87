"""Mutation testing of one module of partcal against the tests that guard it (``make mutation``).

    make mutation MODULE=partcal/study/check.py TESTS="tests/test_check.py"
    python tools/mutation.py partcal/study/update.py "tests/test_prior.py -k update"

cosmic-ray mutates the module one small change at a time (an operator, a comparison, a number, a
``not`` added, a loop run zero times, ...) and runs the tests on each mutant; a mutant the tests let
pass *survived*: a change of the code that no test notices. The work happens in a copy of the working
tree under ``.mutation/<module>/tree`` (cosmic-ray edits the module in place), so the checkout is never
touched and an interrupted run leaves nothing behind. A second call with the same module, tests and code
goes on where the first stopped; a change to any of them starts afresh, except with
``--retest-survivors`` (``make mutation ... RETEST=1``): after writing tests, the mutants that survived run
again with them while the module is unchanged.

What it prints: killed, survived and the score (killed / (killed + survived)); the surviving mutants'
diffs are written to ``.mutation/<module>/survivors.txt``. Each survivor either wants a test (a change of
behaviour no test sees) or is equivalent (it cannot change any result: say why in the module's notes or
CONTRIBUTING.md). A line ending in ``# pragma: no mutate`` is not mutated.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

EXCLUDED_OPERATORS = ("core/ReplaceBinaryOperator_.*_(BitAnd|BitOr|BitXor|LShift|RShift|Pow|FloorDiv|Mod)$",)
"""Not tried: an arithmetic operator replaced by a bitwise one, a shift, a power, a floor division or a modulo
(``a * b`` -> ``a >> b``). On float arrays these raise or give absurd numbers that any test kills at once: a
third of cosmic-ray's mutants, which cost a test run each and teach nothing. The replacements among ``+ - * /``
and every other operator are tried."""

SKIP = (".git", ".venv*", ".mutation", "reports", "__pycache__", ".pytest_cache", "*.egg-info", ".hypothesis")


def fingerprint(root: Path, names: list[str]) -> str:
    """A hash of the files named (pytest options and node ids' suffixes aside) and of the names themselves."""
    h = hashlib.sha256(" ".join(names).encode())
    for name in names:
        path = root / name.split("::")[0]
        if name.startswith("-") or not path.exists():
            continue
        for file in sorted(path.rglob("*.py")) if path.is_dir() else [path]:
            if file.is_file():
                h.update(file.read_bytes())
    return h.hexdigest()


def annotation_spans(module: Path) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """``((line, column), (end line, end column))`` of every type annotation of a module that postpones them
    (``from __future__ import annotations``: they are never evaluated, so a mutant inside one cannot change any
    result); none for a module that does not."""
    import ast
    tree = ast.parse(module.read_text())
    if not any(isinstance(n, ast.ImportFrom) and n.module == "__future__" and any(a.name == "annotations"
                                                                                  for a in n.names)
               for n in tree.body):
        return []
    notes = []
    for node in ast.walk(tree):
        if isinstance(node, ast.arg) and node.annotation is not None:
            notes.append(node.annotation)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.returns is not None:
            notes.append(node.returns)
        elif isinstance(node, ast.AnnAssign):
            notes.append(node.annotation)
    return [((n.lineno, n.col_offset), (n.end_lineno, n.end_col_offset)) for n in notes]


def skip_annotations(session: Path, module: Path) -> int:
    """Mark the mutants inside type annotations as skipped (:func:`annotation_spans`); how many."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult
    spans = annotation_spans(module)
    count = 0
    with use_db(str(session), WorkDB.Mode.open) as db:
        for item in list(db.pending_work_items):
            if all(any(a <= tuple(m.start_pos) and tuple(m.end_pos) <= b for a, b in spans)
                   for m in item.mutations):
                db.set_result(item.job_id, WorkResult(output="in a type annotation (never evaluated)",
                                                      worker_outcome=WorkerOutcome.SKIPPED))
                count += 1
    return count


def definition_lines(module: Path, names: list[str]) -> list[tuple[int, int]]:
    """The first and last lines of each definition named (a function, a class, ``Class.method``, a module-level
    name assigned), for a run scoped to part of a module; an unknown name is refused."""
    import ast
    tree = ast.parse(module.read_text())
    found = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            found[node.name] = (node.lineno, node.end_lineno)
            if isinstance(node, ast.ClassDef):
                for inner in node.body:
                    if isinstance(inner, (ast.FunctionDef, ast.AsyncFunctionDef)):
                        found[f"{node.name}.{inner.name}"] = (inner.lineno, inner.end_lineno)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for target in node.targets if isinstance(node, ast.Assign) else [node.target]:
                for leaf in ast.walk(target):
                    if isinstance(leaf, ast.Name):
                        found[leaf.id] = (node.lineno, node.end_lineno)
    unknown = [n for n in names if n not in found]
    if unknown:
        raise SystemExit(f"--only: {', '.join(unknown)} not defined at the top of {module}")
    return [found[n] for n in names]


def skip_outside(session: Path, ranges: list[tuple[int, int]]) -> int:
    """Mark the mutants outside the line ``ranges`` as skipped; how many."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import WorkerOutcome, WorkResult
    count = 0
    with use_db(str(session), WorkDB.Mode.open) as db:
        for item in list(db.pending_work_items):
            if not any(a <= m.start_pos[0] <= b for m in item.mutations for a, b in ranges):
                db.set_result(item.job_id, WorkResult(output="outside --only", worker_outcome=WorkerOutcome.SKIPPED))
                count += 1
    return count


def retest_survivors(session: Path) -> int:
    """Forget the results of the mutants that survived (they run again); how many."""
    import sqlite3
    with sqlite3.connect(session) as db:
        return db.execute("DELETE FROM work_results WHERE lower(test_outcome) = 'survived'").rowcount


def summary(session: Path, out: Path) -> tuple[int, int, int]:
    """Killed, survived and other (incompetent, timed out) mutants of a session; the survivors' diffs to ``out``."""
    from cosmic_ray.work_db import WorkDB, use_db
    from cosmic_ray.work_item import TestOutcome

    killed = survived = other = 0
    lines = []
    with use_db(str(session), WorkDB.Mode.open) as db:
        for item, result in db.completed_work_items:
            if result.test_outcome == TestOutcome.KILLED:
                killed += 1
            elif result.test_outcome == TestOutcome.SURVIVED:
                survived += 1
                m = item.mutations[0]
                lines.append(f"--- {m.module_path}:{m.start_pos[0]} {m.operator_name} #{m.occurrence} "
                             f"(job {item.job_id})\n{result.diff}\n")
            else:
                other += 1
    out.write_text("".join(lines))
    return killed, survived, other


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="mutation testing of one module (cosmic-ray)")
    parser.add_argument("module", help="the module to mutate, e.g. partcal/study/check.py")
    parser.add_argument("tests", help="pytest arguments selecting the tests that guard it, in one string "
                                      "(\"tests/test_prior.py -k update\")")
    parser.add_argument("--work", default=".mutation", help="where the copy and the session live")
    parser.add_argument("--only", default="", help="comma-separated definitions to mutate (functions, classes, "
                                                   "Class.method, module-level names); default the whole module")
    parser.add_argument("--retest-survivors", action="store_true",
                        help="after new tests: run the mutants that survived again (the module unchanged)")
    args = parser.parse_args(argv)
    tests = shlex.split(args.tests)
    root = Path.cwd()
    if not (root / args.module).is_file():
        parser.error(f"MODULE {args.module!r}: no such file under {root}")
    work = root / args.work / args.module.replace("/", "_").removesuffix(".py")
    tree, session, stamp = work / "tree", work / "session.sqlite", work / "fingerprint"
    key = {"module": fingerprint(root, [args.module]) + args.only, "tests": fingerprint(root, tests)}
    old = json.loads(stamp.read_text()) if stamp.is_file() and session.is_file() else {}
    if args.retest_survivors and old.get("module") == key["module"]:
        print(f"{retest_survivors(session)} surviving mutants run again, but those inside type annotations "
              f"({skip_annotations(session, root / args.module)})")
    elif old != key:
        shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True, exist_ok=True)
    shutil.rmtree(tree, ignore_errors=True)            # a fresh copy: a killed run may have left a mutant in it
    shutil.copytree(root, tree, ignore=shutil.ignore_patterns(*SKIP))
    # python -m puts the copy's directory first on sys.path: its partcal is the one imported
    command = " ".join([shlex.quote(sys.executable), "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                        *map(shlex.quote, tests)])
    began = time.perf_counter()
    baseline = subprocess.run(command, shell=True, cwd=tree, capture_output=True, text=True)
    seconds = time.perf_counter() - began
    if baseline.returncode != 0:
        print(baseline.stdout[-3000:], baseline.stderr[-3000:], sep="\n")
        print(f"the tests fail without any mutant (exit {baseline.returncode}): fix them first")
        return 2
    if not session.is_file():
        timeout = max(30.0, 5.0 * seconds)
        (work / "config.toml").write_text(              # JSON strings are TOML basic strings
            f"[cosmic-ray]\nmodule-path = {json.dumps(args.module)}\ntimeout = {timeout:.0f}\n"
            f"excluded-modules = []\ntest-command = {json.dumps(command)}\n\n"
            '[cosmic-ray.distributor]\nname = "local"\n\n[cosmic-ray.filters.operators-filter]\n'
            f"exclude-operators = {json.dumps(list(EXCLUDED_OPERATORS))}\n")
        cr = Path(sys.executable).parent
        subprocess.run([str(cr / "cosmic-ray"), "init", str(work / "config.toml"), str(session)], cwd=tree,
                       check=True)
        subprocess.run([str(cr / "cr-filter-pragma"), str(session)], cwd=tree, check=True)
        subprocess.run([str(cr / "cr-filter-operators"), str(session), str(work / "config.toml")], cwd=tree,
                       check=True)
        if args.only:
            outside = skip_outside(session, definition_lines(tree / args.module, args.only.split(",")))
            print(f"{outside} mutants outside {args.only} skipped")
        skipped = skip_annotations(session, tree / args.module)
        print(f"{skipped} mutants inside type annotations skipped (never evaluated)")
        print(f"baseline: the tests take {seconds:.1f} s; a mutant gets {timeout:.0f} s")
    else:                                              # the same mutants, maybe other tests: their command
        config = (work / "config.toml").read_text()
        line = next(x for x in config.splitlines() if x.startswith("test-command"))
        (work / "config.toml").write_text(config.replace(line, f"test-command = {json.dumps(command)}"))
    stamp.write_text(json.dumps(key))
    cr = Path(sys.executable).parent
    subprocess.run([str(cr / "cosmic-ray"), "exec", str(work / "config.toml"), str(session)], cwd=tree, check=True)
    killed, survived, other = summary(session, work / "survivors.txt")
    total = killed + survived
    score = f"{100.0 * killed / total:.1f} %" if total else "-"
    print(f"{args.module}: {killed} killed, {survived} survived, {other} incompetent or skipped; score {score}")
    print(f"survivors (diffs): {work / 'survivors.txt'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
