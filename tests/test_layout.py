"""The package's layout: stage folders in pipeline order, every import (module level, in a function
or under ``TYPE_CHECKING``) going to the same stage or one below, no import circle among modules, among
stages or among the subpackages of any package, no module over 600 lines, and a top level of packages
and at most five modules."""

from __future__ import annotations

import ast
from pathlib import Path

import mountcal

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "mountcal"

# The stages, lowest first; a stage imports only from itself and the stages before it. The three
# of one rank (fleet, sessions, simulate) stand side by side: each may use the others, in no circle.
STAGES: tuple[tuple[str, ...], ...] = (
    ("core",),
    ("io",),
    ("stops",),
    ("estimate",),
    ("loop",),
    ("calibration",),
    ("apply",),
    ("outputs",),
    ("fleet", "sessions", "simulate"),
    ("cli",),
)
RANK = {stage: rank for rank, names in enumerate(STAGES) for stage in names}
TOP_MODULES = {"__init__", "__main__"}  # the top level's own modules besides the stage folders
MAX_LINES = 600


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        name = ".".join(path.relative_to(SRC).with_suffix("").parts)
        out[name.removesuffix(".__init__")] = path
    return out


def _graph() -> dict[str, set[str]]:
    """Module → the mountcal modules it imports anywhere in its text: at module level, inside
    functions and under ``TYPE_CHECKING`` (relative imports resolved)."""
    modules = _modules()

    def resolve(name: str) -> str | None:
        while name not in modules and "." in name:
            name = name.rsplit(".", 1)[0]
        return name if name in modules else None

    graph: dict[str, set[str]] = {m: set() for m in modules}
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")
                    base = ".".join(parts[: len(parts) - node.level + 1] + ([node.module] if node.module else []))
                # `from pkg import sub` needs the submodule when there is one, else the package
                names = [resolve(f"{base}.{a.name}") or base for a in node.names]
            for name in names:
                target = resolve(name) if name.split(".")[0] == "mountcal" else None
                if target is not None and target != module:
                    graph[module].add(target)
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _stage(module: str) -> str | None:
    """The stage folder of a module (``mountcal.loop.terms`` → ``loop``); None for the top level."""
    parts = module.split(".")
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and parts[1] in RANK) else None


def test_the_walk_reads_imports_in_functions_and_under_type_checking() -> None:
    graph = _graph()
    assert len(graph) > 150  # the walk found the package
    # a function-level import (the worker's calibration) and a TYPE_CHECKING one (the effects' Calibration)
    assert "mountcal.calibration.pipeline" in graph["mountcal.fleet.worker"]
    assert "mountcal.core.result" in graph["mountcal.estimate.effects"]


def test_module_imports_form_no_cycle() -> None:
    assert _cycles(_graph()) == []


def test_stages_form_no_cycle() -> None:
    stages: dict[str, set[str]] = {s: set() for s in RANK}
    for module, deps in _graph().items():
        a = _stage(module)
        for d in deps:
            b = _stage(d)
            if a is not None and b is not None and a != b:
                stages[a].add(b)
    assert _cycles(stages) == []


def _children(graph: dict[str, set[str]], package: str) -> dict[str, set[str]]:
    """The imports among ``package``'s children: its modules, and each subpackage taken whole as one node."""

    def child(module: str) -> str | None:
        rest = module.removeprefix(f"{package}.")
        return None if rest == module else f"{package}.{rest.split('.')[0]}"

    children: dict[str, set[str]] = {}
    for module, deps in graph.items():
        if (a := child(module)) is not None:
            children.setdefault(a, set())
            for d in deps:
                if (b := child(d)) is not None and b != a:
                    children[a].add(b)
                    children.setdefault(b, set())
    return children


def test_subpackages_form_no_cycle() -> None:
    """Inside every package the subpackages (and modules) import one another in no circle, though no two
    modules do: io/bag sits above io/mcap (a bag may store MCAP), and MCAP reaches no bag module (#24)."""
    graph = _graph()
    packages = sorted(m for m, p in _modules().items() if p.name == "__init__.py")
    assert "mountcal.io" in packages and "mountcal.io.bag" in packages
    found = {p: c for p in packages if (c := _cycles(_children(graph, p)))}
    assert found == {}


def test_a_subpackage_cycle_is_found_without_a_module_cycle() -> None:
    graph = {"p.a.x": {"p.b.y"}, "p.b.y": {"p.a.z"}, "p.a.z": set(), "p.c": {"p.a.x"}}
    assert _cycles(graph) == []
    assert _cycles(_children(graph, "p")) == [["p.a", "p.b"]]


def test_every_import_goes_to_the_same_stage_or_below() -> None:
    upward = []
    for module, deps in sorted(_graph().items()):
        a = _stage(module)
        if a is None:
            continue  # the package's own __init__ and __main__ sit above every stage
        assert a in RANK, f"{module}: {a!r} is not a stage folder"
        upward += [f"{module} → {d}" for d in sorted(deps) if (b := _stage(d)) is None or RANK[b] > RANK[a]]
    assert upward == []


def test_a_cycle_is_found_when_there_is_one() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_the_top_level_holds_the_stage_folders_and_few_modules() -> None:
    modules = {p.stem for p in PACKAGE.glob("*.py")}
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert modules == TOP_MODULES and len(modules) <= 5
    assert folders == set(RANK)
    # an export named like a submodule would be replaced by it on import
    assert not set(mountcal.__all__) & folders


def test_no_module_is_over_600_lines() -> None:
    long = {m: n for m, p in _modules().items() if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert long == {}


def test_only_the_command_line_imports_the_command_line() -> None:
    users = {m for m, deps in _graph().items() if any(d.startswith("mountcal.cli") for d in deps)}
    assert {m for m in users if not m.startswith("mountcal.cli") and m != "mountcal.__main__"} == set()


def test_format_libraries_are_banned_outside_io() -> None:
    import tomllib

    config = tomllib.loads((SRC.parent / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["ruff"]["lint"]
    banned = set(config["flake8-tidy-imports"]["banned-api"])
    assert {"can", "cantools", "mcap", "mcap_ros2", "asammdf", "rosbags"} <= banned
    assert config["per-file-ignores"]["src/mountcal/io/**"] == ["TID251"]
