"""The layers and what each may import, from scripts/import_graph.py's rules and each package's
own docstring, so the architecture page says what the checker enforces.
"""

from __future__ import annotations

import ast
import importlib.util
import re
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[2]
# The top layer is "everything else under service/"; its routes package speaks for it.
DOC_OF = {
    "service": "service/api/__init__.py",
    "armfleet_ros": "packaging/armfleet-ros/armfleet_ros/__init__.py",
}


def import_graph() -> ModuleType:
    spec = importlib.util.spec_from_file_location("import_graph", ROOT / "scripts/import_graph.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _path(prefix: str) -> Path:
    """The file that speaks for a layer: a package's `__init__.py`, or a module ranked alone
    (`service.core.metrics`) itself."""
    if prefix in DOC_OF:
        return ROOT / DOC_OF[prefix]
    package = ROOT / prefix.replace(".", "/") / "__init__.py"
    return package if package.exists() else package.parent.with_suffix(".py")


def _docstring(package: str) -> str:
    return ast.get_docstring(ast.parse(_path(package).read_text())) or ""


def _paragraphs(text: str) -> list[str]:
    return [" ".join(p.split()) for p in text.split("\n\n") if p.strip()]


def render() -> str:
    ig = import_graph()
    lines = [
        "| rank | package | what lives there | may import |",
        "|---:|---|---|---|",
    ]
    for prefix, rank in sorted(ig.LAYERS, key=lambda x: x[1]):
        paras = _paragraphs(_docstring(prefix))
        found = re.search(r"May import:?\s*(.*)", " ".join(paras))
        may = found.group(1) if found else ""
        what = re.sub(r"\s*May import.*", "", paras[0]) if paras else ""
        folder = (
            "`service/` (api/, app, runtime, serving, settings, cli)"
            if prefix == "service"
            else f"`{_path(prefix).relative_to(ROOT).as_posix().removesuffix('__init__.py')}`"
        )
        lines.append(f"| {rank} | {folder} | {what} | {may} |")
    return "\n".join(lines)


# The packages whose modules the architecture page lists (with every package below them, found
# on disk, so a new package shows up without an edit here).
TOPS = ("service", "clients", "bench")


def folders() -> list[str]:
    found = []
    for top in TOPS:
        for init in sorted((ROOT / top).rglob("__init__.py")):
            found.append(str(init.parent.relative_to(ROOT)))
    return found


def _summary(path: Path) -> str:
    """A module's docstring: its first sentence (up to a full stop or a blank line)."""
    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    first = " ".join(doc.split("\n\n")[0].split())
    found = re.match(r"(.+?\.)(\s|$)", first)
    return (found.group(1) if found else first).replace("|", "\\|")


def modules() -> str:
    """Every module of the packages above, folder by folder, from its own docstring."""
    lines: list[str] = []
    for folder in folders():
        paths = sorted(p for p in (ROOT / folder).glob("*.py") if p.name != "__init__.py")
        lines += [f"### `{folder}/`", "", "| module | what |", "|---|---|"]
        lines += [f"| `{p.name}` | {_summary(p)} |" for p in paths]
        lines.append("")
    return "\n".join(lines)
