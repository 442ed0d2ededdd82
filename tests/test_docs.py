"""The README's and the docs' tables are the code's: the parameter table is docs/gen_parameters.py's
output, the spaces' sizes are SystemConfig's, the command table is the CLI's; the README's links
lead to files; the source tree page is the tree."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from uavris.cli import COMMANDS
from uavris.config import SystemConfig

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
TABLE_HEADER = "| field | default | meaning |"


def _table(text: str, header: str) -> str:
    """The Markdown table that starts with ``header`` (its lines up to the first non-table line)."""
    lines = text.splitlines()
    start = lines.index(header)
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    return "\n".join(lines[start:end]) + "\n"


@pytest.fixture(scope="module")
def generated() -> str:
    proc = subprocess.run([sys.executable, str(DOCS / "gen_parameters.py")], capture_output=True, text=True,
                          check=True, cwd=ROOT)
    return proc.stdout


def test_parameter_table_is_generated(generated: str) -> None:
    """The environment page's SystemConfig table is exactly what ``python docs/gen_parameters.py``
    prints (a field, default or comment changed in src/uavris/config.py: rerun the script)."""
    assert _table((DOCS / "environment.md").read_text(encoding="utf-8"), TABLE_HEADER) == generated


def test_generated_table_is_the_dataclass(generated: str) -> None:
    """One row per field, in order, with its default and its comment from the source."""
    import dataclasses

    rows = generated.splitlines()[2:]
    fields = dataclasses.fields(SystemConfig)
    assert [r.split("|")[1].strip().strip("`") for r in rows] == [f.name for f in fields]
    source = (ROOT / "src" / "uavris" / "config.py").read_text(encoding="utf-8")
    for row, f in zip(rows, fields):
        line = next(ln for ln in source.splitlines() if re.match(rf"\s+{f.name}: ", ln))
        if "#" in line:
            assert line.split("#", 1)[1].strip().replace("|", "\\|") == row.split(" | ")[2].rstrip(" |"), f.name
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()
        assert repr(default) in row or f"{type(default).__name__}()" in row, f.name


@pytest.mark.parametrize("system", [SystemConfig(), SystemConfig(nx=8, ny=2), SystemConfig(observe_devices=True),
                                    SystemConfig(learn_amplitudes=True),
                                    SystemConfig(users=((5, 5, 1), (15, 5, 1), (25, 5, 1)), nx=3, ny=5)])
def test_stated_space_sizes_are_the_configs(system: SystemConfig) -> None:
    """The README's formulas (action N + 6, 2N + 6 with amplitudes; observation 2KN + K^2 + 14,
    3K more with the devices) are SystemConfig.action_dim and observation_dim."""
    text = README.read_text(encoding="utf-8")
    formulas = ("`Box(-1, 1, (N + 6,), float32)`", "`2N + 6` with `learn_amplitudes`",
                "`Box((2KN + K^2 + 14,), float32)`", "`3K` more with `observe_devices`", "22 action entries and 158")
    for formula in formulas:
        assert formula in text, formula
    k, n = system.num_users, system.num_elements
    assert system.action_dim == (2 * n if system.learn_amplitudes else n) + 6
    assert system.observation_dim == 2 * k * n + k * k + 14 + (3 * k if system.observe_devices else 0)
    if (k, n, system.learn_amplitudes, system.observe_devices) == (4, 16, False, False):
        assert (system.action_dim, system.observation_dim) == (22, 158)


def _cli_listing() -> dict[str, str]:
    """``uavris --help``'s command list (the docstring of uavris.cli): name -> what it does."""
    import uavris.cli

    doc = uavris.cli.__doc__.split("Commands:")[1].split("Lives here:")[0]
    return dict(re.findall(r"^  ([\w-]+)\s{2,}(.+)$", doc, flags=re.M))


def test_command_tables_are_the_clis() -> None:
    """The README's command table and the CLI page's list every command of uavris.cli.COMMANDS,
    in its order, with the description ``uavris --help`` prints; the CLI page shows each
    command's --help."""
    listing = _cli_listing()
    assert list(listing) == list(COMMANDS)
    readme_rows = re.findall(r"^\| `uavris ([\w-]+)` \| ([^|]+) \|$", README.read_text(encoding="utf-8"), flags=re.M)
    assert [(name, what.strip()) for name, what in readme_rows] == list(listing.items())
    cli = (DOCS / "cli.md").read_text(encoding="utf-8")
    cli_rows = re.findall(r"^\| `uavris ([\w-]+)` \| ([^|]+) \|", cli, flags=re.M)
    assert [(name, what.strip()) for name, what in cli_rows] == list(listing.items())
    assert re.findall(r"^<!-- uavris-help: ([\w-]+) -->$", cli, flags=re.M) == list(COMMANDS)


def test_readme_links_lead_to_files() -> None:
    """Every relative link of the README names a file of the repository, and a link into a
    page's section names a heading of that page (GitHub's anchors: the MkDocs build checks
    the docs' own links, not the README's)."""
    text = README.read_text(encoding="utf-8")
    links = re.findall(r"\]\(([^)#\s]+)(?:#([\w-]+))?\)", text)
    assert links
    for target, anchor in links:
        if re.match(r"\w+://", target):
            continue
        path = ROOT / target
        assert path.exists(), target
        if anchor:
            headings = re.findall(r"^#+ (.+)$", path.read_text(encoding="utf-8"), flags=re.M)
            slugs = {re.sub(r"[^\w\- ]", "", h).strip().lower().replace(" ", "-") for h in headings}
            assert anchor in slugs, f"{target}#{anchor}"


def test_readme_has_no_layout_section() -> None:
    """"Layouts" are halls in uavris; the source tree is docs/architecture.md's "Source tree"."""
    assert not re.search(r"^#+ Layout\b", README.read_text(encoding="utf-8"), flags=re.M)


# ------------------------------------------------------------------------------ docs/architecture.md
def _architecture_tree() -> dict[str, list[str]]:
    """The package tree of docs/architecture.md: each folder (relative to src/uavris, "" the
    top) with its entries in the page's order (files and sub-folders)."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    block = text.split("```\nsrc/uavris/\n", 1)[1].split("```", 1)[0]
    tree: dict[str, list[str]] = {"": []}
    stack: list[str] = []
    for line in block.splitlines():
        name = line.strip().split()[0]
        depth = (len(line) - len(line.lstrip())) // 2 - 1
        del stack[depth:]
        folder = "/".join(stack)
        tree.setdefault(folder, []).append(name.rstrip("/"))
        if name.endswith("/"):
            stack.append(name.rstrip("/"))
            tree.setdefault("/".join(stack), [])
    return tree


def _imports(path: Path) -> set[str]:
    """The uavris modules ``path`` imports (anywhere in it), as paths relative to src/uavris."""
    import ast

    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("uavris"):
            names = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names if a.name.startswith("uavris")]
        else:
            continue
        out |= {"/".join(n.split(".")[1:]) for n in names}
    return out


def test_the_source_tree_page_names_every_module_and_its_layers_hold():
    tree = _architecture_tree()
    package = ROOT / "src" / "uavris"
    listed = {f"{folder}/{name}".lstrip("/") for folder, names in tree.items() for name in names}
    files = {str(p.relative_to(package)) for p in package.rglob("*.py") if p.name != "__init__.py"}
    folders = {str(p.parent.relative_to(package)) for p in package.rglob("__init__.py") if p.parent != package}
    assert listed == files | folders, (sorted((files | folders) - listed), sorted(listed - files - folders))
    for folder, names in tree.items():
        rank = {name.removesuffix(".py"): i for i, name in enumerate(names)}
        for i, name in enumerate(names):
            here = package / folder / name
            for source in ([here] if name.endswith(".py") else here.rglob("*.py")):
                for target in _imports(source):
                    parts = target.split("/")
                    depth = len([p for p in folder.split("/") if p])
                    if parts[:depth] != [p for p in folder.split("/") if p] or len(parts) <= depth:
                        continue  # outside this folder: its own level's rule covers it
                    entry = parts[depth]
                    if entry in rank:
                        assert rank[entry] <= i, f"{source.relative_to(package)} imports {target}, listed below it"


def _imports_inside_functions(path: Path) -> set[str]:
    """The modules ``path`` imports inside a function body (at any depth in it)."""
    import ast

    out: set[str] = set()

    def visit(node: ast.AST, inside: bool) -> None:
        for child in ast.iter_child_nodes(node):
            here = inside or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            if here and isinstance(child, ast.Import):
                out.update(a.name for a in child.names)
            elif here and isinstance(child, ast.ImportFrom):
                out.add("." * child.level + (child.module or ""))
            visit(child, here)

    visit(ast.parse(path.read_text()), False)
    return out


def test_every_import_inside_a_function_is_listed_with_its_reason():
    """docs/architecture.md's table names, per module, every module it imports inside a function,
    each row with a reason; a lazy import added (or one moved to the top) without the table is a
    failure, as is a row the code no longer needs."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    table = text.split("## Imports inside functions", 1)[1].split("\n## ", 1)[0]
    listed: dict[str, set[str]] = {}
    for line in table.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")] if line.startswith("| `") else []
        if cells:
            assert len(cells) == 3 and cells[2], f"a row without its reason: {line}"
            listed[cells[0].strip("`")] = {t.strip().strip("`") for t in cells[1].split(",")}
    package = ROOT / "src" / "uavris"
    found = {str(p.relative_to(package)): names for p in sorted(package.rglob("*.py"))
             if (names := _imports_inside_functions(p))}
    assert found == listed, {k: (found.get(k), listed.get(k)) for k in found.keys() | listed.keys()
                             if found.get(k) != listed.get(k)}
