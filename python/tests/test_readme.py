"""The README's Python section: its example runs as written (given the
files it names), and it states the limits a user meets."""

from __future__ import annotations

import pathlib
import re
import shutil

import pytest

import worldgraph

README = pathlib.Path(__file__).resolve().parents[2] / "README.md"


def python_section() -> str:
    text = README.read_text()
    start = text.index("\n## Python\n")
    end = text.index("\n## ", start + 1)
    return text[start:end]


def test_the_readme_python_example_runs_as_written(discover_run: pathlib.Path, tmp_path: pathlib.Path, monkeypatch: pytest.MonkeyPatch) -> None:
    blocks = re.findall(r"```python\n(.*?)```", python_section(), re.S)
    assert len(blocks) == 1
    # The files the example names: a layout of the user's, a discover run.
    (tmp_path / "my.txt").write_text(worldgraph.maze_text("small", door_key=True))
    shutil.copytree(discover_run, tmp_path / "runs" / "discover-small")
    monkeypatch.chdir(tmp_path)
    namespace: dict[str, object] = {}
    exec(compile(blocks[0], str(README), "exec"), namespace)  # noqa: S102 - the README's own code
    end, graph = namespace["end"], namespace["graph"]
    assert isinstance(end, worldgraph.Replay) and (end.x, end.y) == graph.nodes[7]
    assert namespace["door_key"].task == "doorkey"


def test_the_readme_states_the_limits_a_user_meets() -> None:
    """The limits issue 51 found undocumented, and the conventions a user
    relies on, are in the Python section."""
    section = python_section()
    for phrase in ("64×64", "FlattenObservation", "SAME_STEP", "pickle", "ResetNeeded", "DoorClosedError", "threads"):
        assert phrase in section, phrase
