"""docs/reference.md is what `jassy doc --markdown` prints for the code as it is: a parameter,
default, range or docstring changed without regenerating the page fails here, naming the
entries that differ and the command that regenerates it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from jassy.apps.doc import reference_markdown

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "reference.md"
REGENERATE = "PYTHONPATH=. python -m jassy doc --markdown > docs/reference.md"


def entries(text: str) -> dict[str, str]:
    """The page's sections by heading ("" for the text before the first ugen's heading)."""
    sections: dict[str, list[str]] = {"": []}
    current = ""
    for line in text.splitlines():
        if line.startswith("## "):
            current = line[3:].strip()
            sections[current] = []
        sections[current].append(line)
    return {name: "\n".join(lines).strip() for name, lines in sections.items()}


def differing_entries(page: str, generated: str) -> list[str]:
    """Headings whose text differs, missing from the page or no longer generated."""
    old, new = entries(page), entries(generated)
    out = []
    for name in dict.fromkeys([*new, *old]):
        label = name or "(page header)"
        if name not in old:
            out.append(f"{label}: missing from the page")
        elif name not in new:
            out.append(f"{label}: no longer generated")
        elif old[name] != new[name]:
            out.append(f"{label}: differs")
    return out


@pytest.mark.timeout(120)
def test_the_reference_page_is_what_jassy_doc_markdown_prints():
    # A fresh process, as the regenerating command runs: ugens that tests register are not in it.
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    generated = subprocess.run(
        [sys.executable, "-m", "jassy", "doc", "--markdown"],
        cwd=ROOT, env=env, capture_output=True, text=True, check=True, timeout=100,
    ).stdout  # fmt: skip
    page = PAGE.read_text()
    if page == generated:
        return
    differ = differing_entries(page, generated) or ["(whitespace only)"]
    pytest.fail(
        f"docs/reference.md is out of date in {len(differ)} entr{'y' if len(differ) == 1 else 'ies'}:\n  "
        + "\n  ".join(differ)
        + f"\nregenerate it with:\n  {REGENERATE}",
        pytrace=False,
    )


def test_a_changed_default_is_named_as_a_differing_entry():
    generated = reference_markdown()
    bank = generated.index("## ModalBank")
    row = generated.index("| `gain` |", bank)
    end = generated.index("\n", row)
    stale = generated[:row] + generated[row:end].replace("| 1 |", "| 2 |") + generated[end:]
    assert stale != generated
    start = stale.index("## Gain\n")
    stale = stale[:start] + stale[stale.index("\n## ", start) + 1 :]  # the whole Gain entry
    assert sorted(differing_entries(stale, generated)) == [
        "Gain: missing from the page",
        "ModalBank: differs",
    ]
    assert differing_entries(generated, generated) == []
