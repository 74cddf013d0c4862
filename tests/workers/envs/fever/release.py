"""Run the authors' released ``WikiEnv`` + ``FeverWrapper`` against the stand-in, to get their exact strings.

The release's two files are written to a temporary folder with ``git show`` from the mirror and
imported there; ``gym`` (which they subclass, nothing more) is replaced by a minimal stand-in, and
their hard-coded ``https://en.wikipedia.org`` is pointed at the stand-in server by wrapping the
``requests.get`` they call. Without the mirror the comparison is skipped with the reason; the
tests also hold the core strings themselves, so they never pass on nothing.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import types
from pathlib import Path
from typing import Any

import pytest
import requests

MIRROR = Path("/work/.mirror/ReCAP-Stanford+ReCAP/repo")
FILES = ("fever-recap/hotpotqa/wikienv.py", "fever-recap/hotpotqa/wrappers.py")


def _gym_stub() -> types.ModuleType:
    gym = types.ModuleType("gym")
    spaces = types.ModuleType("gym.spaces")

    class Space:
        pass

    class Env:
        def __init__(self) -> None:
            pass

    class Wrapper(Env):
        def __init__(self, env: Any) -> None:
            self.env = env

        def __getattr__(self, name: str) -> Any:  # gym.Wrapper hands unknown attributes to the wrapped env
            if name.startswith("_") or name == "env":
                raise AttributeError(name)
            return getattr(self.env, name)

    spaces.Space = Space  # type: ignore[attr-defined]
    gym.spaces = spaces  # type: ignore[attr-defined]
    gym.Env = Env  # type: ignore[attr-defined]
    gym.Wrapper = Wrapper  # type: ignore[attr-defined]
    gym.ObservationWrapper = Wrapper  # type: ignore[attr-defined]
    return gym


def _load(name: str, path: Path) -> types.ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class ReleaseEnv:
    """The release's FeverWrapper(WikiEnv()) on ``claims_file``, searching ``base_url`` instead of Wikipedia."""

    def __init__(self, tmp: Path, base_url: str, claims_file: Path, monkeypatch: pytest.MonkeyPatch) -> None:
        if not MIRROR.is_dir():
            pytest.skip(
                f"the authors' release mirror {MIRROR} is absent: no comparison with their code (hard-coded strings still checked)"
            )
        code = tmp / "release_code"
        code.mkdir()
        for rel in FILES:
            text = subprocess.run(
                ["git", "-C", str(MIRROR), "show", f"HEAD:{rel}"], check=True, capture_output=True, text=True
            ).stdout
            (code / Path(rel).name).write_text(text, encoding="utf-8")
        monkeypatch.setitem(sys.modules, "gym", _gym_stub())
        wikienv = _load("release_wikienv", code / "wikienv.py")
        wrappers = _load("release_wrappers", code / "wrappers.py")

        def get(url: str, *args: Any, **kwargs: Any) -> requests.Response:
            return requests.get(url.replace("https://en.wikipedia.org", base_url, 1), *args, timeout=10, **kwargs)

        wikienv.requests = types.SimpleNamespace(get=get)  # type: ignore[attr-defined]
        data = tmp / "release_cwd" / "data"
        data.mkdir(parents=True)
        (data / "paper_dev.jsonl").write_bytes(claims_file.read_bytes())
        monkeypatch.chdir(data.parent)  # the release reads ./data/paper_dev.jsonl (wrappers.py:143)
        self.env = wrappers.FeverWrapper(wikienv.WikiEnv(), "dev")

    def play(self, index: int, actions: list[str]) -> tuple[str, list[tuple[str, int, bool]]]:
        """The first observation and (observation, reward, done) after each action."""
        first = self.env.reset(idx=index)
        out = []
        for action in actions:
            obs, reward, done, _info = self.env.step(action)
            out.append((obs, reward, done))
        return first, out
