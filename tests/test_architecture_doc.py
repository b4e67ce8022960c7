"""docs/ARCHITECTURE.md lists every module with its length: the list stays the code's (a module added, removed or
grown by a tenth shows here)."""

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = {"sb3_dtdpg/": REPO / "sb3_dtdpg", "envs/noma_radiomap/": REPO / "envs" / "noma_radiomap"}


def _listed() -> dict[Path, int]:
    """The modules of the layout block of docs/ARCHITECTURE.md with their line counts (rows that give one)."""
    listed, package = {}, None
    for line in (REPO / "docs" / "ARCHITECTURE.md").read_text().splitlines():
        header = next((root for prefix, root in PACKAGES.items() if line.startswith(prefix)), None)
        if header is not None or (line and not line.startswith(" ")):
            package = header
            continue
        row = re.match(r"^\s+(\S+\.py(?:, \S+\.py)*)\s+(\d+(?:, \d+)*)\s", line)  # also "a.py, b.py   10, 20"
        if package is not None and row:
            names, counts = row.group(1).split(", "), row.group(2).split(", ")
            listed.update({package / name: int(count) for name, count in zip(names, counts, strict=True)})
    return listed


def test_every_module_is_listed_with_its_length():
    listed = _listed()
    modules = {p for root in PACKAGES.values() for p in root.rglob("*.py") if "__pycache__" not in p.parts}
    assert sorted(map(str, modules - set(listed))) == [], "modules missing from docs/ARCHITECTURE.md"
    assert sorted(map(str, set(listed) - modules)) == [], "docs/ARCHITECTURE.md lists modules that do not exist"
    drifted = {
        str(path.relative_to(REPO)): (count, sum(1 for _ in path.open()))
        for path, count in listed.items()
        if abs(sum(1 for _ in path.open()) - count) > max(10, count // 10)
    }
    assert drifted == {}, "line counts in docs/ARCHITECTURE.md (listed, actual)"
