"""The type stubs cover the native module, and everything public has a docstring."""

from __future__ import annotations

import ast
import pathlib

import worldgraph
from worldgraph import _worldgraph

STUB = pathlib.Path(worldgraph.__file__).with_name("_worldgraph.pyi")


def stub_names() -> dict[str, set[str]]:
    tree = ast.parse(STUB.read_text())
    names: dict[str, set[str]] = {"": set()}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            names[""].add(node.name)
            names[node.name] = {n.name for n in node.body if isinstance(n, ast.FunctionDef) and not n.name.startswith("_")}
        elif isinstance(node, ast.FunctionDef):
            names[""].add(node.name)
    return names


def public(obj: object) -> set[str]:
    return {n for n in dir(obj) if not n.startswith("_")}


def test_the_stub_names_every_public_item_of_the_native_module() -> None:
    names = stub_names()
    assert public(_worldgraph) == names[""]
    for cls in ("Simulator", "WorldGraph", "Route"):
        assert public(getattr(_worldgraph, cls)) == names[cls], cls


def test_public_items_have_docstrings() -> None:
    for obj in (worldgraph.WorldGraphEnv, worldgraph.WorldGraphVectorEnv, worldgraph.Simulator, worldgraph.WorldGraph):
        assert obj.__doc__, obj
        for name in public(obj) - public(object):
            member = getattr(obj, name)
            if callable(member) and (getattr(member, "__module__", None) or "worldgraph").startswith("worldgraph"):
                assert member.__doc__, f"{obj.__name__}.{name}"
    for fn in (worldgraph.load_discover_run, worldgraph.pivotal_states, worldgraph.replay_route, worldgraph.maze_text):
        assert fn.__doc__, fn
