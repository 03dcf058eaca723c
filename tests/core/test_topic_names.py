"""Every topic and service name lives in nodes/common/topics.py (one source of truth)."""

import re
from pathlib import Path

ROOT = Path(__file__).parents[2]
# A string literal that is a ROS name of ours or a well-known one we use.
NAME = re.compile(r"""["'](/?ppod/[\w/]+|/clock|/tf|/rosout|/diagnostics)["']""")


def test_no_topic_or_service_name_is_spelled_outside_topics_py():
    found = []
    for folder in ("nodes", "sim_backend", "benchmarks", "ppod_ros"):
        for path in (ROOT / folder).rglob("*.py"):
            if path.name == "topics.py":
                continue
            for i, line in enumerate(path.read_text().splitlines(), 1):
                code = line.split("#", 1)[0]
                if NAME.search(code) and '"""' not in line:
                    found.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not found, "\n".join(found)
