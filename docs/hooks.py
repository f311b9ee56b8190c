"""MkDocs hook: the site shows files that live elsewhere in the repository without copying them
into docs/: studies/README.md as the page `measurements.md`, benchmarks/README.md as `benchmarks.md`, and the figures and screenshots of
reports/ under `figures/` (the validation page and the report pages link them)."""
from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ("reports/validation", "reports/screenshots")


def on_files(files: Files, config) -> Files:
    files.append(File.generated(config, "measurements.md", abs_src_path=str(ROOT / "studies" / "README.md")))
    files.append(File.generated(config, "benchmarks.md", abs_src_path=str(ROOT / "benchmarks" / "README.md")))
    for folder in FIGURES:
        for png in sorted((ROOT / folder).glob("*.png")):
            files.append(File.generated(config, f"figures/{png.name}", abs_src_path=str(png)))
    return files
