"""No dangling references: every docs/ file and config/ file the sources and docs name exists."""

import re
from pathlib import Path

ROOT = Path(__file__).parents[2]
SOURCES = ("*.py", "*.md", "*.msg", "*.srv", "*.action", "*.yaml", "*.toml", "*.sh", "*.cfg")
#: Files a user creates from an example (named in help texts as what to write), not shipped ones.
USER_FILES = re.compile(r"config/(lab\.yaml|my_\w+\.yaml|motions/NAME\.yaml)$")


def _sources():
    for pattern in SOURCES:
        for path in ROOT.rglob(pattern):
            rel = path.relative_to(ROOT)
            if rel.parts[0] in (".venv", ".git", "build", "out") or ".egg-info" in str(rel):
                continue
            yield rel, path.read_text(errors="replace")
    yield Path("run.sh"), (ROOT / "run.sh").read_text()


def test_every_referenced_doc_and_config_file_exists():
    missing = []
    for rel, text in _sources():
        for ref in set(re.findall(r"\b(?:docs/[\w.-]+\.(?:md|dbc)|config/[\w./-]+\.(?:yaml|py))\b", text)):
            if not USER_FILES.search(ref) and not (ROOT / ref).exists():
                missing.append(f"{rel}: {ref}")
    assert not missing, "\n".join(sorted(missing))
