"""The package's layers import in one direction and the module graph has no cycle (style.md, rule 1)."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# lower layers never import higher ones; a layer may import itself
LAYERS = [
    ("slamrun.errors", "slamrun.results", "slamrun.plugins"),
    ("slamrun.core",),
    ("slamrun.datasets",),
    ("slamrun.methods", "slamrun.backends"),
    ("slamrun.engine",),
    ("slamrun.analysis", "slamrun.images"),
    ("slamrun.serve",),
    ("slamrun.cli",),
]


def layer(module: str) -> int | None:
    for i, prefixes in enumerate(LAYERS):
        if any(module == p or module.startswith(p + ".") for p in prefixes):
            return i
    return None


def modules() -> dict[str, Path]:
    out = {}
    for top in ("slamrun",):
        for path in (ROOT / top).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    out.pop("slamrun")  # the empty root package
    return out


def imports(path: Path, top_level_only: bool, type_only: bool = False) -> set[str]:
    """Project modules a file imports (`from a import b` counts b when b is a module), TYPE_CHECKING blocks
    excluded unless `type_only`; with `top_level_only`, only the imports run when the module loads."""
    tree = ast.parse(path.read_text())
    known = modules()
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    found = set()
    skip = {
        id(n)
        for node in ast.walk(tree)
        if not type_only and isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)
        for n in ast.walk(node)
    }
    for node in nodes:
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found |= {f"{node.module}.{a.name}" for a in node.names if f"{node.module}.{a.name}" in known}
    return {m for m in found if m in known}


def test_no_module_imports_a_higher_layer():
    upward = []
    for name, path in modules().items():
        mine = layer(name)
        assert mine is not None, f"{name} belongs to no layer of tests/test_layout.py"
        for target in imports(path, top_level_only=False):
            if layer(target) > mine:
                upward.append(f"{name} -> {target}")
    assert not upward, upward


def test_module_graph_has_no_cycle():
    """Counting every import, those inside functions and those for type hints only too: a lazy import that closes a
    circle is still a circle, and a type-only one is one in the reader's drawing."""
    graph = {name: imports(path, top_level_only=False, type_only=True) - {name} for name, path in modules().items()}
    state: dict[str, int] = {}

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        for nxt in graph.get(node, ()):
            if state.get(nxt) == 1:
                raise AssertionError("import cycle: " + " -> ".join([*stack[stack.index(nxt) :], nxt]))
            if nxt not in state:
                visit(nxt, [*stack, nxt])
        state[node] = 2

    for node in graph:
        if node not in state:
            visit(node, [node])


def test_reading_results_imports_neither_methods_nor_opencv():
    code = (
        "import sys; import slamrun.analysis.load, slamrun.analysis.summary, slamrun.analysis.stats; "
        "print(sorted(m for m in sys.modules "
        "if m.split('.')[0] == 'cv2' or m.startswith(('slamrun.methods', 'slamrun.engine'))))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True).stdout
    assert out.strip() == "[]", out


def test_backends_provide_the_whole_protocol():
    """Every backend has every call the Backend protocol declares (optional ones through Defaults), so the
    campaign never probes with hasattr."""
    from slamrun.backends.base import Backend
    from slamrun.backends.dask import DaskBackend
    from slamrun.backends.docker import DockerBackend
    from slamrun.backends.local import LocalBackend

    declared = {n for n in vars(Backend) if not n.startswith("_")} | set(Backend.__annotations__)
    for cls in (LocalBackend, DockerBackend, DaskBackend):
        missing = sorted(n for n in declared if not hasattr(cls, n) and n not in getattr(cls, "__annotations__", {}))
        assert not missing, f"{cls.__name__} lacks {missing}"


LAYOUT_MODULES = ("layouts", "euroc", "icl_nuim", "kitti", "tartanair", "tum_mono", "tum_rgbd", "tum_vi", "sequence")


def loaded_by_evaluate(*argv: str) -> tuple[str, list[str]]:
    """What `slamrun evaluate ARGV` printed, and the modules it loaded of OpenCV, PyYAML, the methods, the engine
    and the dataset layouts."""
    code = (
        "import runpy, sys\n"
        f"sys.argv = ['slamrun', 'evaluate', *{list(argv)!r}]\n"
        "try:\n    runpy.run_module('slamrun.cli', run_name='__main__')\nexcept SystemExit as e:\n    code = e.code\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('cv2', 'yaml') "
        "or m.startswith(('slamrun.methods', 'slamrun.engine')) "
        f"or m in {['slamrun.datasets.' + name for name in LAYOUT_MODULES]!r}), file=sys.stderr)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    return out.stdout, ast.literal_eval(out.stderr.strip().splitlines()[-1])


def test_evaluating_a_file_imports_neither_opencv_nor_yaml_nor_a_method_nor_a_layout(tmp_path):
    """`slamrun evaluate --gt FILE` starts lean: no OpenCV (only decoding a frame needs it), no PyYAML (only a YAML
    file), no method, no engine, no dataset layout (a folder's evaluation loads them); a layout's note on its own
    ground-truth file is still said."""
    data = Path(__file__).resolve().parents[2] / "shared" / "data" / "evo_test_data"
    gt, est = data / "fr2_desk_groundtruth.txt", data / "fr2_desk_ORB.txt"
    if not gt.is_file():
        pytest.skip(reason=f"{gt} missing: the shared test data lives beside the repository")
    for metric in (["--metric", "ate"], ["--gt-format", "tum"]):  # the second: its defaults, ate and rpe
        stdout, loaded = loaded_by_evaluate(*metric, "--gt", str(gt), str(est))
        assert "ate" in stdout and loaded == [], (metric, stdout, loaded)
    freiburg = tmp_path / "traj0.gt.freiburg"
    freiburg.write_bytes(gt.read_bytes())
    out = subprocess.run(
        [sys.executable, "-m", "slamrun.cli", "evaluate", "--gt", str(freiburg), str(est)],
        capture_output=True, text=True, cwd=ROOT,
    )  # fmt: skip
    assert "ICL-NUIM's poses as the release has them" in out.stderr, out.stderr


def test_what_a_file_is_evaluated_with_is_its_layouts_without_loading_it():
    """A ground-truth file's default metrics are its dataset's layout's, and the notes said of files are the built-in
    layouts' own: written in light modules (groundtruth.py, file_notes.py), checked against the layouts here."""
    from slamrun.datasets import file_notes
    from slamrun.datasets.groundtruth import FILE_DEFAULT_METRICS, FILE_LAYOUTS
    from slamrun.datasets.layouts import BUILT_IN, DEFAULT_METRICS

    assert FILE_DEFAULT_METRICS == {fmt: DEFAULT_METRICS[layout] for fmt, layout in FILE_LAYOUTS.items()}
    assert set(file_notes.NOTES) == {layout.file_note for layout in BUILT_IN if layout.file_note is not None}


def test_no_function_runs_over_80_lines():
    """A function a reader holds in one screen: none in slamrun/ is longer than 80 lines (the image recipes' scripts,
    upstream's style, aside)."""
    long = []
    for name, path in modules().items():
        if "/image/" in path.as_posix() or "/recipes/" in path.as_posix():
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.end_lineno - node.lineno >= 80:
                long.append(f"{name}.{node.name}: {node.end_lineno - node.lineno + 1} lines")
    assert not long, long
