"""The "Sections" list of ``reports/README.md``, generated from what exists.

Every report page ``reports/<section>/README.md`` (and one level deeper, e.g.
``roundtrip/relief/README.md``) is linked with its title; a section folder without a
page (``benchmarks/``) links its JSON and Markdown files. Known sections come in
pipeline order, any other (a new stage) after them, alphabetically.
"""
from __future__ import annotations

from pathlib import Path

from orokit._typing import PathLike

__all__ = ["SECTION_ORDER", "report_sections", "render_sections"]

#: pipeline order of the known sections (others follow alphabetically)
SECTION_ORDER = ("datasets", "analysis", "classification", "synthesis", "roundtrip", "generators", "realism",
                 "benchmarks")


def _title(page: Path) -> str:
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            return line.lstrip("#").strip()
    return page.parent.name


def report_sections(reports_dir: PathLike) -> list[tuple[str, str]]:
    """``(relative link, title)`` of every report page and loose result file under ``reports_dir``."""
    root = Path(reports_dir)
    if not root.is_dir():
        return []
    folders = [p for p in root.iterdir() if p.is_dir() and p.name != "datasets" and not p.name.startswith(".")]
    rank = {name: i for i, name in enumerate(SECTION_ORDER)}
    folders.sort(key=lambda p: (rank.get(p.name, len(rank)), p.name))
    out: list[tuple[str, str]] = []
    for folder in folders:
        page = folder / "README.md"
        if page.is_file():
            out.append((page.relative_to(root).as_posix(), _title(page)))
            for sub in sorted(folder.glob("*/README.md")):
                out.append((sub.relative_to(root).as_posix(), _title(sub)))
        else:
            for f in sorted(folder.glob("*")):
                if f.is_file() and f.suffix in (".json", ".md", ".csv"):
                    out.append((f.relative_to(root).as_posix(), f"{folder.name}: {f.stem}"))
    return out


def render_sections(reports_dir: PathLike) -> str:
    """Markdown list of :func:`report_sections` (empty string when there is none)."""
    rows = report_sections(reports_dir)
    if not rows:
        return ""
    lines = ["## Sections", "", "- [Datasets](#datasets): summary and hillshade of every DEM (below)"]
    for link, title in rows:
        name = link[: -len("/README.md")] if link.endswith("/README.md") else link
        lines.append(f"- [{name}]({link}): {title}")
    return "\n".join(lines) + "\n"
